"""``mocapkit bench detect``: frames per second of ``mocapkit detect`` as shipped.

A short synthetic session (a built-in motion, one camera) is rendered once at each image
size (640x480 landscape and 1080x1920 portrait, a phone's video), then `detect_session`
runs on it end to end with the default backend: decode, detect, follow, write the
OpenPose JSON, the keypoints CSV and the 3-D file. The figure is frames over wall time,
median over the repeats, after a warm-up run (the model's first load).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

#: Image sizes of the benchmark (width, height).
DETECT_BENCH_SIZES: tuple[tuple[int, int], ...] = ((640, 480), (1080, 1920))
#: Length of the benchmark's video (s at 30 frames/s).
DETECT_BENCH_SECONDS = 2.0


def bench_detect(repeats: int = 3, detector: str | None = None) -> dict[str, Any]:
    """Frames per second of `mocapkit.detect.run.detect_session` per image size.

    Returns ``{"backend": name, "<W>x<H>_fps": median, "<W>x<H>_fps_min": slowest, ...}``
    or ``{"skipped": reason}`` when no detector is installed.
    """
    from mocapkit.detect.backend import default_backend, install_hint
    from mocapkit.detect.run import detect_session
    from mocapkit.synth.session_writer import SynthOptions, synthesize_session

    name = detector or default_backend()
    if name is None:
        return {"skipped": install_hint()}
    out: dict[str, Any] = {"backend": name, "pipeline": "mocapkit detect SESSION (defaults)"}
    with tempfile.TemporaryDirectory(prefix="mocapkit-bench-detect-") as tmp:
        for w, h in DETECT_BENCH_SIZES:
            session = Path(tmp) / f"s{w}x{h}"
            synthesize_session(
                "builtin:wave",
                session,
                SynthOptions(seconds=DETECT_BENCH_SECONDS, image_size=(w, h)),
            )
            n = 0
            rates = []
            for k in range(repeats + 1):
                t0 = time.perf_counter()
                res = detect_session(session, name, out_dir=Path(tmp) / "out", overwrite=True)
                dt = time.perf_counter() - t0
                n = sum(d.keypoints.shape[0] for d in res.cameras.values())
                if k:  # the first run warms up
                    rates.append(n / dt)
            out[f"{w}x{h}_fps"] = float(np.median(rates))
            out[f"{w}x{h}_fps_min"] = float(np.min(rates))
            out[f"{w}x{h}_frames"] = float(n)
    return out


__all__ = ["DETECT_BENCH_SECONDS", "DETECT_BENCH_SIZES", "bench_detect"]
