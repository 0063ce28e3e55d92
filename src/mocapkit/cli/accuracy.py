"""``mocapkit accuracy``: a tracker's accuracy on sessions rendered from real motion clips."""

from __future__ import annotations

import argparse
from typing import Any

from mocapkit.cli.accuracy_detect import register_method as register_detect
from mocapkit.cli.accuracy_stereo import register_method as register_stereo
from mocapkit.cli.args import (
    MOCAP_HELP,
    add_clip_options,
    chosen_clips,
    imported,
    mocap_folder,
    number,
    parsed_by,
    shows_default,
)

# the line of `mocapkit --help` (shown without importing this module's pipeline)
HELP = "render sessions from real motion clips, track them and report the accuracy"


def register(subparsers: Any) -> None:
    """Add ``accuracy hybrid``."""
    from mocapkit.pipelines.harness import JITTER_MM  # light: the argument's own default

    p = subparsers.add_parser(
        "accuracy",
        help=HELP,
    )
    methods = p.add_subparsers(dest="method", metavar="METHOD")
    methods.required = True
    h = methods.add_parser(
        "hybrid",
        help="elbow and upper-body errors of the hybrid tracker, IK only and with video",
    )
    h.add_argument("--mocap", help=MOCAP_HELP)
    add_clip_options(h)
    h.add_argument(
        "--work",
        default="accuracy-output",
        help="folder for sessions and results (default %(default)s)",
    )
    shows_default(
        h.add_argument("--seed", type=int, default=None, help="seed (default %(stated_default)s)"),
        "mocapkit.pipelines.accuracy:hybrid_accuracy_repeats.seed",
    )
    h.add_argument("--json", action="store_true", help="print JSON instead of a table")
    h.add_argument(
        "--jitter-repeats",
        metavar="N",
        type=number(int, at_least=0),
        default=0,
        help="track N copies of each session with every marker moved by a seeded amount "
        "up to --jitter-mm and report the mean over them and their spread (the figures "
        "are chaotic in round-off; default %(default)s: one run on the sessions as rendered)",
    )
    shows_default(
        h.add_argument(
            "--jitter-mm",
            metavar="MM",
            type=number(above=0.0),
            default=JITTER_MM,
            help="half-width of the marker jitter of --jitter-repeats (default "
            "%(stated_default)s mm)",
        ),
        "mocapkit.pipelines.harness:JITTER_MM",
    )
    orientation = h.add_mutually_exclusive_group()
    orientation.add_argument(
        "--positions-only",
        action="store_true",
        help="use the marker sets' positions only, as the paper does (not their orientation)",
    )
    orientation.add_argument(
        "--oriented-sets",
        metavar="SETS",
        type=parsed_by(imported("mocapkit.pipelines.hybrid:parse_oriented_sets"), "marker sets"),
        help="marker sets whose orientation the tracker sees, comma-separated (head, "
        "left_hand, right_hand) or 'none' (default: all)",
    )
    h.set_defaults(func=run)
    from mocapkit.cli.accuracy_mono import add_mono_accuracy_parser

    add_mono_accuracy_parser(methods)
    register_stereo(methods)
    register_detect(methods)


def run(args: argparse.Namespace) -> int:
    """Run the accuracy study and print it."""
    from mocapkit.cli.args import given
    from mocapkit.pipelines.accuracy import (
        format_rows,
        hybrid_accuracy_repeats,
        repeat_summary,
        repeats_to_json,
        summary,
        to_json,
    )

    mocap = mocap_folder(args.mocap)
    say = (lambda _line: None) if args.json else print
    if not args.json:
        print(format_rows([]))
    runs = hybrid_accuracy_repeats(
        mocap,
        args.work,
        chosen_clips(args),
        say=say,
        oriented_sets=() if args.positions_only else args.oriented_sets,
        repeats=args.jitter_repeats,
        jitter_mm=args.jitter_mm,
        **given(seed=args.seed),
    )
    if args.json:
        print(to_json(runs[0]) if args.jitter_repeats == 0 else repeats_to_json(runs))
        return 0
    for r, rows in enumerate(runs):
        s = summary(rows)
        change_pct = round(-100.0 * s["elbow_reduction"])  # 0, not -0, when unchanged
        label = "mean" if args.jitter_repeats == 0 else f"[{r}] mean"
        print(
            f"{label}: elbow {s['elbow_ik_mm']:.1f} -> {s['elbow_video_mm']:.1f} mm "
            f"({change_pct:+d} % with video); upper-body MPJPE "
            f"{s['mpjpe_ik_mm']:.1f} -> {s['mpjpe_video_mm']:.1f} mm"
        )
    if args.jitter_repeats > 0:
        rs = repeat_summary(runs)

        def fig(key: str) -> str:
            f = rs[key]
            return f"{f['mean']:.1f} ({f['min']:.1f}-{f['max']:.1f}, sem {f['sem']:.1f})"

        print(
            f"over {args.jitter_repeats} jittered repeats (+-{args.jitter_mm:g} mm), mean "
            f"(min-max, standard error): elbow {fig('elbow_ik_mm')} -> "
            f"{fig('elbow_video_mm')} mm; upper-body MPJPE {fig('mpjpe_ik_mm')} -> "
            f"{fig('mpjpe_video_mm')} mm"
        )
    return 0
