"""The monocular tracker's memory is flat with the recording's length, legs or not."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from mocapkit.camera.pinhole import Camera, intrinsics_from_fov
from mocapkit.tracking.mono.stick import stick_model
from mocapkit.tracking.mono.tracker import MonoConfig, MonoTracker
from tests.tracking.mono.conftest import LENGTHS, REST, _rotate

FPS = 30.0
#: Offline, the most frames left open (the default is 300: shorter here, to keep the
#: test fast; the swinging stick's mirror-image paths do not merge by themselves).
WINDOW = 20


def _moving_stick(n: int, legs: bool) -> tuple[np.ndarray, np.ndarray, Camera]:
    """A stick whose links swing smoothly about their rest directions, 3 m in front of a
    camera: its joints' pixels (n, K, 2), its link lengths and the camera."""
    model = stick_model(legs=legs)
    rng = np.random.default_rng(5)
    lengths = np.array([LENGTHS[s] for s in model.segments])
    axes = rng.normal(size=(model.n_links, 3))
    amp = np.radians(rng.uniform(15.0, 40.0, model.n_links))
    freq = rng.uniform(0.5, 2.0, model.n_links)
    t = np.arange(n) / FPS
    pos = np.zeros((n, model.n_joints, 3))
    pos[:, 0] = (0.0, -300.0, 3000.0)
    for i, (_, _, seg) in enumerate(model.links):
        rest = np.asarray(REST[seg], dtype=float)
        rest /= np.linalg.norm(rest)
        for k in range(n):
            d = _rotate(rest, axes[i], amp[i] * np.sin(2 * np.pi * freq[i] * t[k]))
            pos[k, model.child[i]] = pos[k, model.parent[i]] + lengths[i] * d
    cam = Camera("c", (1280, 960), intrinsics_from_fov((1280, 960), 70.0), np.zeros(5), np.eye(4))
    px = pos[..., :2] / pos[..., 2:] * cam.K[0, 0] + cam.K[:2, 2]
    return px, lengths, cam


def _peak_bytes(n: int, legs: bool, lag: int | None) -> tuple[int, int]:
    """Peak of Python-allocated memory while tracking ``n`` frames (the answers are
    dropped as they come, as a file writer would), and the frames answered."""
    px, lengths, cam = _moving_stick(n, legs)
    cfg = MonoConfig(legs=legs, lag=lag, window=WINDOW, arm_prior_weight=0.0)
    answered = 0
    tracemalloc.start()
    try:
        tracker = MonoTracker(lengths, cam, 1 / FPS, cfg)
        for k in range(n):
            answered += len(tracker.push(k / FPS, px[k]))
        answered += len(tracker.finish())
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    return peak, answered


@pytest.mark.parametrize(("legs", "lag"), [(False, None), (True, None), (True, 10)])
def test_memory_is_flat_with_the_recordings_length(legs: bool, lag: int | None) -> None:
    """Four times the frames: the same peak within 10 % (only open frames are kept), and
    with legs (14 links) a few MB, not the 2^14 poses a frame of one search over all."""
    _peak_bytes(10, legs, lag)  # compile and warm up
    short, n_short = _peak_bytes(30, legs, lag)
    long, n_long = _peak_bytes(120, legs, lag)
    assert (n_short, n_long) == (30, 120)
    assert long <= 1.1 * short
    assert long < 30e6
