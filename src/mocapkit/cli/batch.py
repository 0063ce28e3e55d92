"""``mocapkit batch``: track and evaluate every take of a study on Dask, with a study table."""

from __future__ import annotations

import argparse
import sys

from mocapkit.cli.args import checked_by, given, imported, number, output_folder, shows_default
from mocapkit.pipelines.registry import AUTO, TRACKERS

# the line of `mocapkit --help` (shown without importing this module's pipeline)
HELP = "track and evaluate a whole study (every session under a folder) on Dask"


_EPILOG = """\
A take is a folder holding session.json (at any depth under STUDY_DIR) or, with
--markers-glob, a raw marker file (tracked by hybrid IK with the --marker-set specs).
Each take is one Dask task; its result folder OUT/<take>/ is written atomically and
ends with take.json. A take whose folder is complete for the same source and options
is skipped (--force redoes it). OUT/study.csv holds one row per take; a failed take's
row has its error and the others go on. Exit code: the number of failed takes (at most
100); 2 also when the batch cannot start (bad options, no take).
"""


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``batch`` subcommand."""
    p = subparsers.add_parser(
        "batch",
        help=HELP,
        description="Track every take of a study with one method (or the one each session "
        "suits), evaluate it where it has truth, and write one result folder per take and "
        "study.csv.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("study", metavar="STUDY_DIR", help="folder searched for sessions")
    p.add_argument(
        "--out", required=True, metavar="RESULTS_DIR", type=output_folder, help="results folder"
    )
    shows_default(
        p.add_argument(
            "--method",
            default=AUTO,
            choices=(*TRACKERS, AUTO),
            help=f"tracking method; {AUTO}: hybrid for markers + video, stereo for two or more "
            "cameras without markers, mono for one camera (default %(stated_default)s)",
        ),
        "mocapkit.pipelines.batch:batch.method",
    )
    p.add_argument(
        "--markers-glob",
        metavar="PATTERN",
        help="also track raw marker files matching PATTERN under STUDY_DIR (e.g. '**/*.c3d')",
    )
    p.add_argument(
        "--marker-set",
        action="append",
        default=[],
        type=checked_by(imported("mocapkit.io.marker_sets:parse_marker_set"), "marker set"),
        metavar="NAME=M1+M2[/T1]",
        help="marker set of the --markers-glob files (head, left_hand, right_hand); markers "
        "after '/' turn the set without placing it; repeat",
    )
    shows_default(
        p.add_argument(
            "--joints",
            default=None,
            type=checked_by(imported("mocapkit.eval.metrics:joint_subset"), "joints"),
            help="joints evaluated against truth: 'upper', 'all' or a list (default "
            "%(stated_default)s)",
        ),
        "mocapkit.pipelines.batch:batch.joints",
    )
    p.add_argument("--force", action="store_true", help="redo takes that are complete")
    p.add_argument(
        "--scheduler", metavar="ADDRESS", help="use a running Dask scheduler (tcp://host:8786)"
    )
    p.add_argument(
        "--workers",
        type=number(int, at_least=1),
        default=None,
        metavar="N",
        help="workers of the local cluster (default: one per core)",
    )
    p.add_argument(
        "--in-process",
        action="store_true",
        help="run the local cluster's workers as threads of this process",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the study; print the table; exit with the number of failed takes."""
    from mocapkit.errors import ConfigError
    from mocapkit.pipelines.batch import batch

    if args.scheduler and (args.workers is not None or args.in_process):
        raise ConfigError("batch: --workers and --in-process size a local cluster, not --scheduler")
    result = batch(
        args.study,
        args.out,
        args.method,
        markers_glob=args.markers_glob,
        marker_sets=args.marker_set,
        force=args.force,
        scheduler=args.scheduler,
        n_workers=None if args.workers is None else int(args.workers),
        processes=not args.in_process,
        say=lambda line: print(line, file=sys.stderr),
        **given(joints=args.joints),
    )
    print(result.table())
    c = result.counts
    print(
        f"{len(result.rows)} takes: {c['done']} done, "
        + (
            f"{c['poor']} poor (a joint far from its detections: its fit.csv), "
            if c["poor"]
            else ""
        )
        + f"{c['skipped']} skipped, "
        f"{c['failed']} failed; wall {result.wall_s:.1f} s -> {result.study_csv}"
    )
    return min(result.n_failed, 100)
