"""CPU time of the mono tracker on fixed frames, for before/after comparisons of checkouts.

    python tools/mono_speed_compare.py write /tmp/mono_bench_frames.npz
    PYTHONPATH=/path/to/other/checkout/src python tools/mono_speed_compare.py time \
        /tmp/mono_bench_frames.npz before
    python tools/mono_speed_compare.py time /tmp/mono_bench_frames.npz after

``write`` (needs this checkout) stores the `mocapkit bench mono` sequence's noisy 2-D
joints and its drawn 640x480 skin frames; ``time`` runs whatever ``mocapkit`` is
imported on them: online pair-state (lag 10) and offline exact `MonoTracker` over the
keypoints (5 and 3 runs), `SkinTracker` over the frames (3 runs); prints medians of CPU
fps (``time.process_time``, OpenCV on one thread).
"""

from __future__ import annotations

import sys
import time

import cv2
import numpy as np


def write(path: str) -> None:
    from mocapkit.pipelines.mono_bench import _camera, mono_sequence, skin_frames

    joints, cam, model, _ = mono_sequence(150)
    rng = np.random.default_rng(0)
    px = cam.project(joints) + rng.normal(scale=2.0, size=(150, model.n_joints, 2))
    frames = np.stack(skin_frames(_camera(+1.0).project(joints), model))
    np.savez(path, px=px, frames=frames)


def time_it(path: str, tag: str) -> None:
    from mocapkit.pipelines.mono_bench import mono_sequence
    from mocapkit.tracking.mono.skin_tracking import SkinTracker
    from mocapkit.tracking.mono.tracker import MonoConfig, MonoTracker

    cv2.setNumThreads(1)
    data = np.load(path)
    px, frames = data["px"], data["frames"]
    _, cam, model, lengths = mono_sequence(150)

    def run(cfg: MonoConfig) -> float:
        tr = MonoTracker(lengths, cam, 1 / 30, cfg, model)
        c0 = time.process_time()
        for k in range(px.shape[0]):
            tr.push(k / 30, px[k])
        tr.finish()
        return time.process_time() - c0

    def skin() -> float:
        st = SkinTracker()
        c0 = time.process_time()
        for f in frames:
            st.update(f)
        return time.process_time() - c0

    run(MonoConfig(lag=10))  # compile
    on = [run(MonoConfig(lag=10)) for _ in range(5)]
    off = [run(MonoConfig()) for _ in range(3)]
    sk = [skin() for _ in range(3)]
    n = px.shape[0]
    print(
        f"{tag}: online pair-state {n / np.median(on):.0f} fps CPU, offline "
        f"{n / np.median(off):.0f} fps, skin 2-D {n / np.median(sk):.0f} fps"
    )


if __name__ == "__main__":
    if len(sys.argv) >= 3 and sys.argv[1] == "write":
        write(sys.argv[2])
    elif len(sys.argv) >= 3 and sys.argv[1] == "time":
        time_it(sys.argv[2], sys.argv[3] if len(sys.argv) > 3 else "")
    else:
        raise SystemExit(__doc__)
