"""``mocapkit bench NAME``: speed figures (medians over repeats)."""

from __future__ import annotations

import argparse
import json

from mocapkit.pipelines.bench import BENCHMARKS, format_table, run_benchmarks, save_results


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``bench`` subcommand."""
    p = subparsers.add_parser(
        "bench",
        help="time the kinematics and the hybrid, stereo and mono trackers",
        description="Run a speed benchmark (after a warm-up; medians over repeats) and print "
        "a table, or JSON with --json.",
    )
    p.add_argument("name", choices=[*BENCHMARKS, "all"], help="benchmark to run")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.add_argument("--repeats", type=int, default=3, help="timed repeats (default 3)")
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
        help="also write FOLDER/<name>.json (default folder bench/results)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the benchmark(s), print, optionally save."""
    results = run_benchmarks(args.name, repeats=args.repeats, work_dir=args.work)
    if args.save is not None:
        save_results(results, args.save)
    print(json.dumps(results, indent=2) if args.json else format_table(results))
    return 0
