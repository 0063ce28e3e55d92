"""The fixed-lag smoother equals RTS on the same window (errata M6)."""

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from mocapkit.errors import ConfigError, ShapeError
from mocapkit.tracking.mono.smoother import (
    KeypointSmoother,
    constant_velocity_model,
    smooth_keypoints,
)

DT = 1 / 30


def _rts(track: np.ndarray, upto: int, noise: float, accel: float) -> np.ndarray:
    """Plain RTS over measurements 0..upto of one point (T, 2), NaN = missing."""
    f, q, h, r = constant_velocity_model(DT, noise, accel)
    kf = KalmanFilter(dim_x=4, dim_z=2)
    kf.F, kf.Q, kf.H, kf.R = f, q, h, r
    first = track[np.isfinite(track).all(axis=1)][0]
    kf.x = np.array([[first[0]], [0.0], [first[1]], [0.0]])
    kf.P = np.eye(4) * 1e8
    zs = [None if np.isnan(z).any() else z.reshape(2, 1) for z in track[: upto + 1]]
    mu, cov, _, _ = kf.batch_filter(zs)
    xs, _, _, _ = kf.rts_smoother(mu, cov)
    return xs[:, [0, 2], 0]


@pytest.mark.parametrize("gap", [False, True])
def test_fixed_lag_equals_rts_on_the_same_window(gap: bool) -> None:
    rng = np.random.default_rng(3)
    t_frames, lag = 40, 5
    truth = np.cumsum(rng.normal(scale=4.0, size=(t_frames, 2, 2)), axis=0) + 300
    z = truth + rng.normal(scale=2.0, size=truth.shape)
    if gap:
        z[17:20, 1] = np.nan
    sm = KeypointSmoother(2, DT, lag=lag, noise_px=3.0, accel_px_s2=2000.0, max_gap=10)
    for k in range(t_frames):
        sm.push(z[k])
        if k >= lag:
            for j in range(2):
                ref = _rts(z[:, j], k, 3.0, 2000.0)
                np.testing.assert_allclose(sm.smoothed(k - lag)[j], ref[k - lag], atol=1e-6)


def test_smoothing_reduces_noise_and_long_gaps_are_missing() -> None:
    rng = np.random.default_rng(4)
    t = np.arange(120) * DT
    truth = np.stack([200 + 80 * np.sin(2 * t), 240 + 60 * np.cos(1.5 * t)], axis=-1)[:, None]
    z = truth + rng.normal(scale=2.0, size=truth.shape)
    z[50:60] = np.nan
    out = smooth_keypoints(z, DT, lag=5, noise_px=3.0, max_gap=5)
    seen = np.isfinite(z[:, 0, 0])
    err_raw = np.linalg.norm(z - truth, axis=-1)[seen].mean()
    err_s = np.linalg.norm(out - truth, axis=-1)[seen].mean()
    assert err_s < 0.8 * err_raw
    assert np.isnan(out[56:60]).all() and np.isfinite(out[50:55]).all()


def test_bad_settings_and_shapes_are_refused() -> None:
    with pytest.raises(ConfigError, match="lag"):
        KeypointSmoother(3, DT, lag=-1)
    sm = KeypointSmoother(3, DT)
    with pytest.raises(ShapeError, match=r"\(3, 2\)"):
        sm.push(np.zeros((2, 2)))
