"""``mocapkit accuracy detect``: a 2-D detector against the true keypoints of rendered
sessions. Registered under ``accuracy`` by `mocapkit.cli.accuracy` (one line)."""

from __future__ import annotations

import argparse
import json
from typing import Any

from mocapkit.cli.args import LazyChoices


def register_method(methods: Any) -> None:
    """Add ``detect`` to the ``accuracy`` methods."""
    p = methods.add_parser(
        "detect",
        help="2-D detector error per joint, left/right swaps and misses on rendered sessions",
    )
    p.add_argument("sessions", nargs="+", metavar="SESSION", help="synthetic session folders")
    p.add_argument(
        "--detector",
        metavar="NAME",
        choices=LazyChoices("mocapkit.detect.backend:backend_names"),
        help="backend: %(choices)s (default: mediapipe)",
    )
    p.add_argument("--model", help="model file of the rtmpose backend (.onnx)")
    p.add_argument(
        "--work",
        default="accuracy-output/detect",
        help="folder for the detections (default %(default)s)",
    )
    p.add_argument("--overwrite", action="store_true", help="detect again where done before")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from mocapkit.detect.backend import make_detector
    from mocapkit.pipelines.detect_accuracy import detect_accuracy, format_table

    options = {"model_path": args.model} if args.model is not None else {}
    det = make_detector(args.detector, **options)
    try:
        acc = detect_accuracy(args.sessions, det, args.work, overwrite=args.overwrite)
    finally:
        det.close()
    if args.json:
        print(json.dumps({"backend": det.name, "joints": acc.rows(), **acc.shares()}, indent=1))
    else:
        print(format_table(acc, det.name))
    return 0
