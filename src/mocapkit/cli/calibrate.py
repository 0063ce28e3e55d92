"""``mocapkit calibrate``: chessboard images -> ``cameras.json`` (one camera or a stereo pair)."""

from __future__ import annotations

import argparse

from mocapkit.cli.args import checked_by, imported, number, output_file, shows_default

# the line of `mocapkit --help` (shown without importing this module's pipeline)
HELP = "calibrate one camera or a stereo pair from chessboard images"


_EPILOG = """\
One image set (a folder or a quoted glob such as 'shots/left*.jpg') calibrates one
camera; two sets calibrate a stereo pair, matched by sorted file name. Without
--board-pose the (first) camera's frame is the world. A board-pose file is JSON:
  {"origin_mm": [x, y, z], "x_axis": [1, 0, 0], "y_axis": [0, 1, 0], "image": "left01.jpg"}
giving the world position (mm) of the board's first detected inner corner, the world
directions of the board's rows (x) and columns (y) of corners, and (optionally) the
image of the first set that shows the board at that pose. The report prints each
image's first-corner pixel to check which corner OpenCV took as origin.
"""


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``calibrate`` subcommand."""
    from mocapkit.pipelines.calibrate_config import DEFAULT_MAX_RMS_PX, DEFAULT_MIN_BOARDS

    parse_board = imported("mocapkit.camera.calibration:parse_board")

    p = subparsers.add_parser(
        "calibrate",
        help=HELP,
        description="Calibrate one camera or a stereo pair from chessboard images and "
        "write cameras.json (mm, camera_from_world).",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("images", nargs="+", metavar="IMAGES", help="image folder or glob (1 or 2)")
    p.add_argument(
        "--board",
        required=True,
        type=checked_by(lambda spec: parse_board(spec, 1.0), "board"),
        help="inner corners as COLUMNSxROWS, e.g. 9x6",
    )
    p.add_argument("--square-mm", type=number(above=0.0), required=True, help="square side in mm")
    p.add_argument("--out", required=True, type=output_file, help="output cameras.json")
    p.add_argument("--board-pose", default=None, help="JSON file with the board's world pose")
    p.add_argument(
        "--names",
        default=None,
        help="comma-separated camera names (default cam0, or left,right)",
    )
    shows_default(
        p.add_argument(
            "--min-boards",
            type=number(int, at_least=3),
            default=DEFAULT_MIN_BOARDS,
            help="fewest images (pairs) with a detected board (default %(stated_default)s)",
        ),
        "mocapkit.pipelines.calibrate_config:DEFAULT_MIN_BOARDS",
    )
    shows_default(
        p.add_argument(
            "--max-rms-px",
            type=number(above=0.0),
            default=DEFAULT_MAX_RMS_PX,
            help="refuse a camera or stereo fit whose RMS reprojection error is above this "
            "(default %(stated_default)s px)",
        ),
        "mocapkit.pipelines.calibrate_config:DEFAULT_MAX_RMS_PX",
    )
    p.add_argument(
        "--refine-intrinsics",
        action="store_true",
        help="stereo: refine intrinsics jointly instead of keeping the per-camera ones",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Calibrate, print the report, write the cameras file."""
    from mocapkit.camera.calibration import parse_board
    from mocapkit.io.cameras import write_cameras
    from mocapkit.pipelines.calibrate import calibrate_from_images

    report = calibrate_from_images(
        args.images,
        parse_board(args.board, args.square_mm),
        names=None if args.names is None else [n.strip() for n in args.names.split(",")],
        board_pose=args.board_pose,
        min_boards=args.min_boards,
        refine_stereo_intrinsics=args.refine_intrinsics,
        max_rms_px=args.max_rms_px,
    )
    for line in report.lines():
        print(line)
    write_cameras(args.out, report.cameras)
    print(f"wrote {len(report.cameras)} camera(s) to {args.out}")
    return 0
