"""``mocapkit accuracy stereo``: the stereo tracker on sessions rendered from real clips.

Registered under ``accuracy`` by `mocapkit.cli.accuracy` (one line).
"""

from __future__ import annotations

import argparse
import json
from typing import Any


def register_method(methods: Any) -> None:
    """Add ``stereo`` to the ``accuracy`` methods."""
    p = methods.add_parser(
        "stereo",
        help="arm joint and torso yaw errors of the stereo tracker on rendered excerpts",
    )
    p.add_argument("--mocap", help="folder of motion clips (default: ../shared/data/mocap)")
    p.add_argument("--work", default="accuracy-output/stereo", help="sessions folder")
    p.add_argument(
        "--modes",
        default="keypoints+torso",
        help="comma-separated: keypoints+torso, keypoints+torso+static, keypoints, skin "
        "(default keypoints+torso)",
    )
    p.add_argument(
        "--cameras",
        default="stereo_left,stereo_right",
        help="views (the sessions have stereo_left, stereo_right, mono)",
    )
    p.add_argument("--json", action="store_true", help="print JSON rows instead of a table")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from mocapkit.cli.args import mocap_folder
    from mocapkit.pipelines.stereo import accuracy_header, stereo_accuracy

    mocap = mocap_folder(args.mocap)
    if not args.json:
        print(accuracy_header())
    rows = stereo_accuracy(
        mocap,
        args.work,
        modes=[m.strip() for m in args.modes.split(",") if m.strip()],
        cameras=args.cameras,
        say=None if args.json else print,
    )
    if args.json:
        print(json.dumps(rows, indent=2))
    return 0
