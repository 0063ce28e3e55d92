"""``mocapkit track``: run a tracker over a recording (``hybrid``; ``mono``/``stereo`` later)."""

from __future__ import annotations

import argparse
from typing import Any

from mocapkit.cli.args import given, number, output_folder, shows_default
from mocapkit.cli.track_stereo import register_method as register_stereo

# the line of `mocapkit --help` (shown without importing this module's pipeline)
HELP = "track a recording with one of the methods"


def register(subparsers: Any) -> None:
    """Add ``track`` with its ``hybrid`` sub-subcommand."""
    parser = subparsers.add_parser("track", help=HELP)
    methods = parser.add_subparsers(dest="method", metavar="METHOD")
    methods.required = True
    hyb = methods.add_parser(
        "hybrid",
        help="head and hand marker sets plus one camera (Zhang et al. 2011)",
        description="Track a session folder (markers + video), or with --markers a raw "
        "marker file (IK only). Writes motion.npz, joints.csv, motion.bvh and fit.csv to --out.",
    )
    hyb.add_argument("session", nargs="?", help="session folder (omit with --markers)")
    hyb.add_argument("--out", required=True, type=output_folder, help="result folder")
    hyb.add_argument("--no-video", action="store_true", help="skip the video refinement")
    hyb.add_argument(
        "--paper",
        action="store_true",
        help="follow the paper literally (no smoothing, proportional balance, marker-set "
        "positions only, no clavicles)",
    )
    hyb.add_argument(
        "--positions-only",
        action="store_true",
        help="use the marker sets' positions only, not the orientation their members show "
        "(= --oriented-sets none)",
    )
    hyb.add_argument(
        "--oriented-sets",
        metavar="SETS",
        help="marker sets whose orientation the IK uses, comma-separated (head, left_hand, "
        "right_hand) or 'none' (default: all that session.json declares members for)",
    )
    shows_default(
        hyb.add_argument(
            "--max-elbow-speed",
            type=float,
            default=None,
            metavar="MM_PER_S",
            help="elbow speed the video refinement takes as free when it keeps elbows from "
            "jumping between frames (default %(stated_default)s; raise it for fast sports, "
            "0 turns the penalty off)",
        ),
        "mocapkit.tracking.hybrid.arm_refinement:RefineConfig.elbow_speed_mm_per_s",
    )
    hyb.add_argument("--markers", help="raw marker file (.c3d, .trc, .csv) instead of a session")
    hyb.add_argument(
        "--marker-set",
        action="append",
        default=[],
        metavar="NAME=M1+M2[/T1]",
        help="marker set for --markers (head, left_hand, right_hand; optionally pelvis, "
        "left_foot, right_foot, which drive the legs, and thorax, which holds the "
        "trunk's twist); markers after '/' "
        "turn the set without placing it (e.g. a forearm marker with a wrist bar: "
        "left_hand=LWRA+LWRB/LFRM); repeat",
    )
    hyb.add_argument(
        "--height-mm",
        type=float,
        default=None,
        help="subject stature for --markers (default: estimated from the head markers)",
    )
    hyb.add_argument(
        "--free-feet",
        action="store_true",
        help="with --markers: do not hold the feet at their first positions",
    )
    hyb.add_argument(
        "--up",
        default=None,
        metavar="AXIS",
        help="with --markers: the file's up axis (x, y, z, -x, -y, -z; default: found from "
        "the head markers, printed)",
    )
    hyb.add_argument(
        "--floor-mm",
        type=number(float),
        default=None,
        metavar="MM",
        help="with --markers: the floor's coordinate along the up axis in the file (mm; "
        "default: found from the lowest markers, printed; give it for a file with no marker "
        "near the floor, such as head and hands only)",
    )
    hyb.add_argument(
        "--world-frame",
        action="store_true",
        help="with --markers: write joints in the library's Z-up world (floor at 0) instead "
        "of the file's frame",
    )
    hyb.add_argument(
        "--posture",
        choices=("standing", "seated", "auto"),
        default="auto",
        help="standing, seated (pelvis on a seat whose height is estimated from the head "
        "set, legs held bent and left out: NaN, no feet planted, no balance step) or auto "
        "(seated when the head set's upright height is low for the stature; prints which "
        "and why; default %(default)s)",
    )
    hyb.add_argument(
        "--static",
        default=None,
        metavar="FILE",
        help="with --markers: a separate static trial (same lab, same marker names) to "
        "calibrate the marker sets' member offsets on (default: the stillest 1 s of the "
        "take's first 5 s)",
    )
    hyb.add_argument(
        "--calibration",
        choices=("auto", "static", "dynamic", "none"),
        default=None,
        help="with --markers: how the marker sets' member offsets are calibrated: static "
        "(on a still second, positions only where none is found), dynamic (on the motion: "
        "the take tracked from the set centres, each member's median place on its joint over "
        "the frames that agree on the set's layout), "
        "auto (default: static where a still second is found, else dynamic where a hand "
        "set has two or more members) or none (the sets' positions only); the run prints "
        "which was used",
    )
    hyb.add_argument(
        "--no-static-calibration",
        action="store_true",
        help="with --markers: the same as --calibration none",
    )
    shows_default(
        hyb.add_argument(
            "--proportions",
            choices=("anthropometric", "preset"),
            default=None,
            help="with --markers: the body model's proportions: a population's scaled to the "
            "stature (anthropometric: Drillis & Contini via Winter) or the preset's (zhang21, "
            "Table 1) scaled by the stature alone (default %(stated_default)s)",
        ),
        "mocapkit.pipelines.hybrid_markers:track_hybrid_marker_file.proportions",
    )
    shows_default(
        hyb.add_argument(
            "--warn-mm",
            type=float,
            default=None,
            metavar="MM",
            help="fit report: a marker set further than this from the model is off on that "
            "frame (default %(stated_default)s)",
        ),
        "mocapkit.pipelines.fit_report:WARN_MM",
    )
    shows_default(
        hyb.add_argument(
            "--warn-fraction",
            type=float,
            default=None,
            metavar="SHARE",
            help="fit report: warn when a set is off on more than this share of its frames "
            "(default %(stated_default)s)",
        ),
        "mocapkit.pipelines.fit_report:WARN_FRACTION",
    )
    hyb.set_defaults(func=_run_hybrid)
    from mocapkit.cli.track_mono import add_mono_parser

    add_mono_parser(methods)
    register_stereo(methods)


def _run_hybrid(args: argparse.Namespace) -> int:
    import sys

    from mocapkit.io.lab_frame import parse_up
    from mocapkit.io.marker_files import read_markers
    from mocapkit.pipelines.fit_report import (
        WARN_FRACTION,
        WARN_MM,
        summarize_fit,
        warn_implausible,
    )
    from mocapkit.pipelines.hybrid import track_hybrid_session_run
    from mocapkit.pipelines.hybrid_markers import track_hybrid_marker_file
    from mocapkit.pipelines.hybrid_options import HybridRunOptions
    from mocapkit.pipelines.run import find_gaps

    warn_mm = WARN_MM if args.warn_mm is None else args.warn_mm
    warn_fraction = WARN_FRACTION if args.warn_fraction is None else args.warn_fraction

    options = HybridRunOptions(
        session=args.session,
        markers=args.markers,
        no_video=args.no_video,
        paper=args.paper,
        positions_only=args.positions_only,
        oriented_sets=args.oriented_sets,
        max_elbow_speed_mm_per_s=args.max_elbow_speed,
        marker_set=tuple(args.marker_set),
        height_mm=args.height_mm,
        free_feet=args.free_feet,
        up=args.up,
        floor_mm=args.floor_mm,
        world_frame=args.world_frame,
        static=args.static,
        no_static_calibration=args.no_static_calibration,
        calibration=args.calibration,
    )
    if args.markers:
        # checked before the long run (summarize_fit and the pipeline check them again)
        summarize_fit([], warn_mm, warn_fraction)
        if args.up is not None:
            parse_up(args.up)
        run = track_hybrid_marker_file(
            read_markers(args.markers),
            args.marker_set,
            args.height_mm,
            args.out,
            plant_feet=not args.free_feet,
            up=args.up,
            floor_mm=args.floor_mm,
            world_output=args.world_frame,
            posture=args.posture,
            calibration=options.member_calibration,
            static=None if args.static is None else read_markers(args.static),
            **given(proportions=args.proportions),
        )
        print(run.frame.summary())
        if run.posture is not None:
            print(_posture_line(run.posture))
        print(f"member calibration: {run.calibration_note}")
        if run.floor_warning:
            print(f"WARNING: {args.markers}: {run.floor_warning}", file=sys.stderr)
        if not run.frame.sure:
            print(
                f"WARNING: the up axis {run.frame.up!r} of {args.markers} is a guess; "
                "give --up if it is wrong",
                file=sys.stderr,
            )
        motion, results = run.motion, run.results
    else:
        summarize_fit([], warn_mm, warn_fraction)
        session_run = track_hybrid_session_run(
            args.session,
            args.out,
            use_video=not args.no_video,
            paper=args.paper,
            oriented_sets=options.oriented,
            max_elbow_speed_mm_per_s=args.max_elbow_speed,
            posture=args.posture,
            on_posture=lambda choice: print(_posture_line(choice)),
        )
        motion, results = session_run.motion, session_run.results
    # frames where a marker set was not observed have no joints of its limb (NaN in
    # joints.csv, the status in fit.csv): say where
    for gap in find_gaps(results):
        print(f"gap: {gap}")
    print(f"tracked {motion.n_frames} frames -> {args.out}")
    report = summarize_fit(results, warn_mm, warn_fraction)
    print("\n".join(report.lines()))
    for line in report.warnings():
        print(line, file=sys.stderr)
    warn_implausible(args.out)
    return 0


def _posture_line(choice: Any) -> str:
    """The terminal line saying which posture a run used and why."""
    seat = (
        f", pelvis on a seat at {choice.seat_height_mm:.0f} mm above the floor"
        if choice.posture == "seated"
        else ""
    )
    return f"posture: {choice.posture}{seat} ({choice.reason})"
