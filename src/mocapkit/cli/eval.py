"""``mocapkit eval``: accuracy of a tracker's result folder against a synthetic session's truth."""

from __future__ import annotations

import argparse

from mocapkit.cli.args import imported, parsed_by

# the line of `mocapkit --help` (shown without importing this module's pipeline)
HELP = "compare a tracking result with a session's ground truth"


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``eval`` subcommand."""
    p = subparsers.add_parser(
        "eval",
        help=HELP,
        description="Per-joint error, MPJPE, PA-MPJPE, elbow error, jitter and coverage of a "
        "result (motion.npz or joints.csv) against truth.npz, matched by time stamp.",
    )
    p.add_argument("result", metavar="RESULT", help="result folder, motion.npz or joints.csv")
    p.add_argument(
        "--truth", required=True, metavar="SESSION", help="session folder with truth.npz"
    )
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.add_argument(
        "--joints",
        type=parsed_by(imported("mocapkit.eval.metrics:joint_subset"), "joints"),
        default=None,
        help="joints to compare: 'all' (default), 'upper' (head, neck, pelvis, shoulders, elbows, "
        "wrists) or a comma-separated list of canonical names",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Evaluate and print."""
    from mocapkit.eval.metrics import evaluate_result

    report = evaluate_result(args.result, args.truth, joints=args.joints)
    print(report.to_json() if args.json else report.table())
    return 0
