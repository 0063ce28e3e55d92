"""``mocapkit demo``: render, track and evaluate a built-in example (no data files needed)."""

from __future__ import annotations

import argparse
from typing import Any

from mocapkit.cli.args import given, number, output_folder, shows_default

_RUN = "mocapkit.pipelines.demo:run_demo"

# the line of `mocapkit --help` (shown without importing this module's pipeline)
HELP = (
    "render a built-in table-tennis rally, track it with hybrid, stereo and mono, "
    "compare them and write an HTML report"
)


def register(subparsers: Any) -> None:
    """Add the ``demo`` subcommand."""
    p = subparsers.add_parser(
        "demo",
        help=HELP,
        description="Renders builtin:table-tennis as a synthetic session seen by a mono camera "
        "and a stereo pair (video, head and hand markers, 2-D keypoints), tracks it with the "
        "hybrid (markers + mono video), stereo (stereo pair + keypoints) and mono (mono "
        "keypoints) methods, prints one table of upper-body accuracy and speed, writes a "
        "report per tracker under OUT/report and prints the path of its index page.",
    )
    shows_default(
        p.add_argument(
            "--out",
            default=None,
            type=output_folder,
            help="output folder (default: %(stated_default)s)",
        ),
        f"{_RUN}.out_dir",
    )
    shows_default(
        p.add_argument(
            "--seconds",
            type=number(above=0.0),
            default=None,
            help="length of the excerpt (default %(stated_default)s s)",
        ),
        f"{_RUN}.seconds",
    )
    p.add_argument(
        "--quiet",
        action="store_true",
        help="print only the table and the report's path (no progress, no narration)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the demo."""
    from mocapkit.pipelines.demo import run_demo

    run_demo(quiet=args.quiet, **given(out_dir=args.out, seconds=args.seconds))
    return 0
