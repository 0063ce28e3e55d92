"""``mocapkit accuracy stereo``: the stereo tracker on sessions rendered from real clips.

Registered under ``accuracy`` by `mocapkit.cli.accuracy` (one line).
"""

from __future__ import annotations

import argparse
import json
from typing import Any

from mocapkit.cli.args import MOCAP_HELP, add_clip_options, chosen_clips, given, shows_default

_RUN = "mocapkit.pipelines.stereo:stereo_accuracy"


def register_method(methods: Any) -> None:
    """Add ``stereo`` to the ``accuracy`` methods."""
    from mocapkit.pipelines.harness import HARNESS_DETECTORS  # light: names only

    p = methods.add_parser(
        "stereo",
        help="arm joint and torso yaw errors of the stereo tracker on rendered excerpts",
    )
    p.add_argument("--mocap", help=MOCAP_HELP)
    add_clip_options(p)
    p.add_argument(
        "--work", default="accuracy-output/stereo", help="sessions folder (default %(default)s)"
    )
    shows_default(
        p.add_argument(
            "--modes",
            default=None,
            help="comma-separated: keypoints+torso, keypoints+torso+static, keypoints, skin "
            "(default %(stated_default)s)",
        ),
        f"{_RUN}.modes",
    )
    shows_default(
        p.add_argument(
            "--cameras",
            default=None,
            help="views (the sessions have stereo_left, stereo_right, mono; default "
            "%(stated_default)s)",
        ),
        f"{_RUN}.cameras",
    )
    shows_default(
        p.add_argument(
            "--seed",
            type=int,
            default=None,
            help="the filters' random seed (default %(stated_default)s)",
        ),
        f"{_RUN}.seed",
    )
    shows_default(
        p.add_argument(
            "--particles",
            type=int,
            default=None,
            help="particles per arm and run (default %(stated_default)s; not with --ablations)",
        ),
        "mocapkit.tracking.stereo.arm_filter:ArmFilterConfig.n_particles",
    )
    p.add_argument(
        "--detector",
        default=None,
        help="the keypoint modes take this 2-D detector's keypoints "
        f"({', '.join(HARNESS_DETECTORS)}), run on the tracked views' rendered video "
        "(kept in each session folder and reused) instead of the true ones (default: the "
        "true 2-D)",
    )
    p.add_argument(
        "--ablations",
        action="store_true",
        help="instead of the modes: the ablation study (keypoints+torso variants on the "
        "clips): arm mean error and frames to converge after both arms are reset to a "
        "hanging arm at 1 s",
    )
    p.add_argument(
        "--variants",
        default=None,
        help="with --ablations: comma-separated variants (default all: default, no IK "
        "sampling, constant noise, static shoulders, conventional fusion, eq. (1) edges, "
        "weighted mean estimate, no shoulder pull)",
    )
    p.add_argument("--json", action="store_true", help="print JSON rows instead of a table")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from mocapkit.cli.args import mocap_folder
    from mocapkit.errors import ConfigError
    from mocapkit.pipelines.stereo import (
        accuracy_header,
        accuracy_means,
        format_accuracy_row,
        stereo_accuracy,
    )

    if args.particles is not None and args.particles < 2:
        raise ConfigError(f"--particles: expected at least 2, found {args.particles}")
    if args.detector is not None and args.ablations:
        raise ConfigError("--detector: not with --ablations (they track from the true 2-D)")
    mocap = mocap_folder(args.mocap)
    if args.ablations:
        return _ablations(args, mocap)
    if not args.json:
        print(accuracy_header())
    rows = stereo_accuracy(
        mocap,
        args.work,
        chosen_clips(args),
        say=None if args.json else print,
        n_particles=args.particles,
        **given(
            modes=None if args.modes is None else [m.strip() for m in args.modes.split(",")],
            cameras=args.cameras,
            seed=args.seed,
            detector=args.detector,
        ),
    )
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    for row in accuracy_means(rows):
        print(format_accuracy_row(row))
    return 0


def _ablations(args: argparse.Namespace, mocap: Any) -> int:
    from mocapkit.pipelines.stereo import ABLATIONS, stereo_ablations

    variants = (
        [v.strip() for v in args.variants.split(",") if v.strip()]
        if args.variants
        else list(ABLATIONS)
    )
    if not args.json:
        print(f"{'clip':<16}{'variant':<24}{'mean':>7}{'frames':>7}{'at reset':>9}")
    rows = stereo_ablations(
        mocap,
        args.work,
        variants=variants,
        clips=chosen_clips(args),
        say=None if args.json else print,
        **given(cameras=args.cameras, seed=args.seed),
    )
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print(f"{'variant':<24}{'mean mm':>8}{'frames to converge (per clip)':>32}")
    for v in variants:
        mine = [r for r in rows if r["variant"] == v]
        mean = sum(r["arm_mean_mm"] for r in mine) / len(mine)
        frames = ", ".join(str(r["frames_to_converge"]) for r in mine)
        print(f"{v:<24}{mean:8.1f}  {frames}")
    return 0
