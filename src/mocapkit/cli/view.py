"""``mocapkit view``: write the visual report (one offline HTML page) of a result folder."""

from __future__ import annotations

import argparse
import sys

from mocapkit.cli.args import output_folder

# the line of `mocapkit --help` (shown without importing this module's pipeline)
HELP = "write an HTML report of a result: overlay videos, 3D view, errors, files"


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``view`` subcommand."""
    p = subparsers.add_parser(
        "view",
        help=HELP,
        description="Write RESULT/report/index.html (or --out DIR): the overlay video per "
        "camera of the session, an animated 3D view of the captured skeleton (with the "
        "truth and the markers), error and fit-quality plots, the accuracy table and links "
        "to the BVH, TRC and CSV files. The page works offline (open it in a browser).",
    )
    p.add_argument("result", metavar="RESULT", help="result folder (motion.npz or joints.csv)")
    p.add_argument(
        "--truth",
        metavar="SESSION",
        help="session folder with truth.npz (also the session of the videos and markers)",
    )
    p.add_argument(
        "--session",
        metavar="SESSION",
        help="session the result was tracked from, for its videos and markers (when it has "
        "no truth)",
    )
    p.add_argument("--markers", metavar="FILE", help="marker file to show (raw-marker results)")
    p.add_argument(
        "--out", metavar="DIR", type=output_folder, help="report folder (default RESULT/report)"
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Build the report and print the page's path."""
    from mocapkit.pipelines.report import build_report

    page = build_report(
        args.result,
        args.truth,
        args.out,
        session=args.session,
        markers=args.markers,
        say=lambda line: print(f"mocapkit view: warning: {line}", file=sys.stderr),
    )
    print(page)
    return 0
