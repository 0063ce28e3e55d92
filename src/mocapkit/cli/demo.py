"""``mocapkit demo``: render, track and evaluate a built-in example (no data files needed)."""

from __future__ import annotations

import argparse
from typing import Any

from mocapkit.cli.args import number, output_folder
from mocapkit.pipelines.demo import run_demo


def register(subparsers: Any) -> None:
    """Add the ``demo`` subcommand."""
    p = subparsers.add_parser(
        "demo",
        help="render a built-in table-tennis rally, track it and report the accuracy",
        description="Renders builtin:table-tennis as a synthetic session (video, head and "
        "hand markers), tracks it with the hybrid method with and without video, using the "
        "marker sets' orientation (default) and their positions only (the paper's input), "
        "and evaluates all four against the ground truth.",
    )
    p.add_argument(
        "--out",
        default="demo-output",
        type=output_folder,
        help="output folder (default: demo-output)",
    )
    p.add_argument(
        "--seconds", type=number(above=0.0), default=4.0, help="length of the excerpt (s)"
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the demo."""
    run_demo(args.out, seconds=args.seconds)
    return 0
