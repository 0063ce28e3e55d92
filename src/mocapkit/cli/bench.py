"""``mocapkit bench NAME|all``: speed figures (medians over repeats)."""

from __future__ import annotations

import argparse
import json

from mocapkit.cli.args import LazyChoices, given, shows_default

# the line of `mocapkit --help` (shown without importing this module's pipeline)
HELP = "time the kinematics, the hybrid, stereo and mono trackers and the 2-D detector"


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``bench`` subcommand."""
    p = subparsers.add_parser(
        "bench",
        help=HELP,
        description="Run a speed benchmark (after a warm-up; medians over repeats) and print "
        "a table, or JSON with --json.",
    )
    p.add_argument(
        "name",
        metavar="NAME",
        choices=LazyChoices("mocapkit.pipelines.bench:benchmark_choices"),
        help="benchmark to run: %(choices)s",
    )
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    shows_default(
        p.add_argument(
            "--repeats", type=int, default=None, help="timed repeats (default %(stated_default)s)"
        ),
        "mocapkit.pipelines.bench:run_benchmarks.repeats",
    )
    p.add_argument(
        "--work",
        default=None,
        metavar="FOLDER",
        help="hybrid: folder where the benchmark sessions are rendered once and re-used "
        "(default: mocapkit-bench-hybrid in the temporary folder)",
    )
    p.add_argument(
        "--save",
        nargs="?",
        const="bench/results",
        default=None,
        metavar="FOLDER",
        help="also write FOLDER/<name>.json (default folder %(const)s)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the benchmark(s), print, optionally save."""
    from mocapkit.pipelines.bench import format_table, run_benchmarks, save_results

    results = run_benchmarks(args.name, work_dir=args.work, **given(repeats=args.repeats))
    if args.save is not None:
        save_results(results, args.save)
    print(json.dumps(results, indent=2) if args.json else format_table(results))
    return 0
