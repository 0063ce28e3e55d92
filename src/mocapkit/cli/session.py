"""``mocapkit session``: videos + a calibration (+ OpenPose keypoints) -> a session folder."""

from __future__ import annotations

import argparse

from mocapkit.cli.args import number, output_folder

HELP = "make a session folder from videos, a calibration and OpenPose keypoints"

_EPILOG = """\
Each video's file name names its camera (cam01.mp4 is camera cam01), which must be in the
calibration (case, '_', '-' and leading zeros aside: cam_01 = cam01). Calibrations read:
Pose2Sim/anipose/FreeMoCap Calib.toml, Qualisys .qca.txt, OpenCV YAML/XML (one file per
camera, named by its stem; give --calibration once per file) and cameras.json.
A video smaller than its calibration by an encoder's padding (the calibrated size is the
video's rounded up to a multiple of {pad} px, e.g. 1080 -> 1088) is taken with a
warning, its frames padded back in black on the right and bottom; other size differences,
different frame counts and different frame rates are refused before anything is written.
--keypoints DIR holds one OpenPose JSON folder per camera, named <camera> or
<camera>_json (as Pose2Sim's pose/ folder), one file per video frame.
"""


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``session`` subcommand."""
    from mocapkit.io.session_options import PAD_MULTIPLE_PX, UNITS_MM

    p = subparsers.add_parser(
        "session",
        help=HELP,
        description="Make a session folder (session.json, cameras.json, video/, "
        "keypoints/) from one video per camera, a calibration file and, optionally, "
        "OpenPose JSON keypoints; every check runs before anything is written.",
        epilog=_EPILOG.format(pad=PAD_MULTIPLE_PX),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("videos", nargs="+", metavar="VIDEO", help="one video per camera")
    p.add_argument(
        "--calibration",
        required=True,
        action="append",
        metavar="FILE",
        help="calibration file (repeat for one OpenCV YAML/XML file per camera)",
    )
    p.add_argument(
        "--keypoints", default=None, metavar="DIR", help="folder of OpenPose JSON folders"
    )
    p.add_argument("--out", required=True, type=output_folder, help="session folder to write")
    p.add_argument(
        "--calibration-unit",
        choices=sorted(UNITS_MM),
        default=None,
        help="unit of a Calib.toml's translations (default: read from their size: "
        "Pose2Sim writes m, anipose and FreeMoCap the board's unit)",
    )
    p.add_argument(
        "--rate-hz",
        type=number(above=0.0),
        default=None,
        help="frame rate of the videos (default: the files' own; needed for image folders)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Build the session and say what it holds."""
    from mocapkit.io.session_build import build_session

    built = build_session(
        args.videos,
        args.calibration,
        args.out,
        keypoints=args.keypoints,
        calibration_unit=args.calibration_unit,
        rate_hz=args.rate_hz,
    )
    print(
        f"wrote session {built.path}: cameras {', '.join(built.cameras)}, {built.n_frames} "
        f"frames at {built.rate_hz:g} Hz"
        + (", keypoints from OpenPose" if built.keypoints else ", no keypoints")
    )
    return 0
