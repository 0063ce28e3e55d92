"""``mocapkit accuracy``: a tracker's accuracy on sessions rendered from real motion clips."""

from __future__ import annotations

import argparse
from typing import Any

from mocapkit.cli.accuracy_stereo import register_method as register_stereo
from mocapkit.cli.args import mocap_folder, parsed_by
from mocapkit.pipelines.accuracy import format_rows, hybrid_accuracy, summary, to_json
from mocapkit.pipelines.hybrid import parse_oriented_sets


def register(subparsers: Any) -> None:
    """Add ``accuracy hybrid``."""
    p = subparsers.add_parser(
        "accuracy",
        help="render sessions from real motion clips, track them and report the accuracy",
    )
    methods = p.add_subparsers(dest="method", metavar="METHOD")
    methods.required = True
    h = methods.add_parser(
        "hybrid",
        help="elbow and upper-body errors of the hybrid tracker, IK only and with video",
    )
    h.add_argument("--mocap", help="folder of motion clips (default: ../shared/data/mocap)")
    h.add_argument("--clips", nargs="*", help="clip file names (default: the standard set)")
    h.add_argument("--work", default="accuracy-output", help="folder for sessions and results")
    h.add_argument("--seed", type=int, default=0)
    h.add_argument("--json", action="store_true", help="print JSON instead of a table")
    orientation = h.add_mutually_exclusive_group()
    orientation.add_argument(
        "--positions-only",
        action="store_true",
        help="use the marker sets' positions only, as the paper does (not their orientation)",
    )
    orientation.add_argument(
        "--oriented-sets",
        metavar="SETS",
        type=parsed_by(parse_oriented_sets, "marker sets"),
        help="marker sets whose orientation the tracker sees, comma-separated (head, "
        "left_hand, right_hand) or 'none' (default: all)",
    )
    h.set_defaults(func=run)
    from mocapkit.cli.accuracy_mono import add_mono_accuracy_parser

    add_mono_accuracy_parser(methods)
    register_stereo(methods)


def run(args: argparse.Namespace) -> int:
    """Run the accuracy study and print it."""
    mocap = mocap_folder(args.mocap)
    say = (lambda _line: None) if args.json else print
    if not args.json:
        print(format_rows([]))
    rows = hybrid_accuracy(
        mocap,
        args.work,
        args.clips,
        args.seed,
        say=say,
        oriented_sets=() if args.positions_only else args.oriented_sets,
    )
    if args.json:
        print(to_json(rows))
    else:
        s = summary(rows)
        change_pct = round(-100.0 * s["elbow_reduction"])  # 0, not -0, when unchanged
        print(
            f"mean: elbow {s['elbow_ik_mm']:.1f} -> {s['elbow_video_mm']:.1f} mm "
            f"({change_pct:+d} % with video); upper-body MPJPE "
            f"{s['mpjpe_ik_mm']:.1f} -> {s['mpjpe_video_mm']:.1f} mm"
        )
    return 0
