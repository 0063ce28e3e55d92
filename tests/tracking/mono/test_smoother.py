"""The fixed-lag smoother equals RTS on the same window (errata M6)."""

import numpy as np
import pytest

from mocapkit.errors import ConfigError, ShapeError
from mocapkit.tracking.mono.smoother import (
    KeypointSmoother,
    constant_velocity_model,
    smooth_keypoints,
)

DT = 1 / 30


def _rts(track: np.ndarray, upto: int, noise: float, accel: float) -> np.ndarray:
    """Plain RTS over measurements 0..upto of one point (T, 2), NaN = missing: a forward
    Kalman filter, then the backward pass x_s = x + C (x_s' - x_pred'), C = P F' P_pred'^-1."""
    f, q, h, r = constant_velocity_model(DT, noise, accel)
    first = track[np.isfinite(track).all(axis=1)][0]
    x, p = np.array([first[0], 0.0, first[1], 0.0]), np.eye(4) * 1e8
    xs, ps, x_pred, p_pred = [], [], [], []
    for z in track[: upto + 1]:
        x, p = f @ x, f @ p @ f.T + q
        x_pred.append(x)
        p_pred.append(p)
        if np.isfinite(z).all():
            k = p @ h.T @ np.linalg.inv(h @ p @ h.T + r)
            x, p = x + k @ (z - h @ x), (np.eye(4) - k @ h) @ p
        xs.append(x)
        ps.append(p)
    for i in range(len(xs) - 2, -1, -1):
        c = ps[i] @ f.T @ np.linalg.inv(p_pred[i + 1])
        xs[i] = xs[i] + c @ (xs[i + 1] - x_pred[i + 1])
    return np.array(xs)[:, [0, 2]]


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


# smooth_keypoints of the seeded input of `test_known_values` as computed with
# filterpy 2.0.0's KalmanFilter (the implementation this module replaced), frame by frame:
# point 0 (x, y), point 1 (x, y)
KNOWN = [
    [199.63164855938908, 208.6865016906361, 204.56341335439936, 195.2014451614321],
    [200.839297889486, 202.44650668590754, 210.60222966592238, 195.79648596479853],
    [203.0678348650324, 197.4336278154776, 214.47563065118715, 198.49999185017708],
    [206.12391193291475, 194.1724664434347, 216.93210206368855, 200.75611807386207],
    [209.44475437261656, 192.45251438861672, 216.75453277803769, 201.40293924054626],
    [204.66769796007702, 191.04057381219314, 215.60858886866717, 199.18684211969756],
    [199.3844062382965, 189.2545236835021, 216.11001354054648, 194.98812294690268],
    [np.nan, np.nan, 218.49766150415155, 191.16473156499274],
    [188.80894319288782, 188.7693880674846, 222.2045798934402, 187.58437726503655],
    [186.38232595821728, 189.37221323342635, 223.75602671729905, 184.2695068251972],
    [185.71748230425402, 188.33087459215156, 223.32439869291827, 182.76420889405347],
    [186.34160143109057, 185.9898694444547, 223.39112742559055, 182.15211066571422],
    [188.06774525920267, 182.97231357787928, 225.40786346365576, 181.99862677428737],
    [190.5244352627199, 180.2398402970453, 229.33699515537185, 181.16661452786482],
]


def test_known_values() -> None:
    """Late first sighting, a gap bridged and one too long: as the filterpy version gave."""
    rng = np.random.default_rng(11)
    truth = np.cumsum(rng.normal(scale=5.0, size=(14, 2, 2)), axis=0) + 200
    z = truth + rng.normal(scale=2.0, size=truth.shape)
    z[0, 1] = np.nan  # point 1 first seen at frame 1
    z[5:8, 0] = np.nan  # point 0 unseen for 3 frames: the third is past max_gap
    out = smooth_keypoints(z, 1 / 30, lag=3, noise_px=3.0, accel_px_s2=2500.0, max_gap=2)
    np.testing.assert_allclose(out.reshape(14, 4), np.array(KNOWN), rtol=1e-12, atol=1e-9)


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


def test_keeps_only_the_frames_its_lag_needs() -> None:
    rng = np.random.default_rng(5)
    lag = 3
    sm = KeypointSmoother(2, DT, lag=lag)
    for _ in range(50):
        sm.push(rng.normal(200.0, 5.0, size=(2, 2)))
    assert sm.n_frames == 50 and len(sm._out) == len(sm._valid) == lag + 1
    assert np.isfinite(sm.smoothed(50 - lag - 1)).all()
    with pytest.raises(ShapeError, match=r"frame 45 is not kept.*46\.\.49"):
        sm.smoothed(45)
