"""Fixed-lag smoothing of tracked 2-D joints (Mamania et al. 2004, §3.3; errata M6).

The paper cites Kalman (1960) for "a fixed-lag Kalman smoother"; that is the filter, not
a smoother (errata M6). This is the augmented-state fixed-lag smoother: a Kalman filter
(`AugmentedFilter`, a few lines of numpy, all points at once) whose state holds the
current and the ``lag`` previous states, so that its estimate of frame k - lag after
measurement k equals the Rauch-Tung-Striebel smoothed estimate over measurements 0..k
(tested against a plain RTS pass). The update uses the Joseph form of the covariance.

Model: constant velocity per image coordinate, white-noise acceleration (recipe M:
R = (3 px)^2, lag 5). One filter per joint (4 states x (lag + 1)). A missing
measurement (NaN) is skipped (predict only), which is exact; a joint unseen for more than
``max_gap`` frames in a row is reported NaN there rather than extrapolated.
"""

from __future__ import annotations

from collections import deque

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ConfigError, ShapeError

FloatArray = NDArray[np.float64]

_PRIOR_VAR = 1e8


def constant_velocity_model(
    dt_s: float, noise_px: float, accel_px_s2: float
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """F, Q, H, R of one image point, state (x, vx, y, vy) in px and px/s."""
    f1 = np.array([[1.0, dt_s], [0.0, 1.0]])
    q1 = accel_px_s2**2 * np.array([[dt_s**4 / 4, dt_s**3 / 2], [dt_s**3 / 2, dt_s**2]])
    h = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
    f = np.asarray(np.kron(np.eye(2), f1), dtype=float)
    q = np.asarray(np.kron(np.eye(2), q1), dtype=float)
    return f, q, h, np.asarray(noise_px**2 * np.eye(2), dtype=float)


class AugmentedFilter:
    """Kalman filters of K points over the state stacked with its ``lag`` predecessors.

    All points share the model (F, Q, H, R); each has its own state ``x`` (K, m) and
    covariance ``p`` (K, m, m), m = n (lag + 1), starting at zero with variance
    ``_PRIOR_VAR``.
    """

    def __init__(
        self, f: FloatArray, q: FloatArray, h: FloatArray, r: FloatArray, lag: int, n_points: int
    ) -> None:
        n = f.shape[0]
        m = n * (lag + 1)
        self.f = np.zeros((m, m))
        self.f[:n, :n] = f
        self.f[n:, :-n] = np.eye(m - n)  # shift: block i+1 <- block i
        self.q = np.zeros((m, m))
        self.q[:n, :n] = q
        self.h = np.zeros((h.shape[0], m))
        self.h[:, :n] = h
        self.r = r
        self.x = np.zeros((n_points, m))
        self.p = np.broadcast_to(np.eye(m) * _PRIOR_VAR, (n_points, m, m)).copy()

    def predict(self) -> None:
        """x <- F x, P <- F P F' + Q for every point."""
        self.x = self.x @ self.f.T
        self.p = self.f @ self.p @ self.f.T + self.q

    def update(self, z: FloatArray, seen: NDArray[np.bool_]) -> None:
        """Take the measurements ``z`` (K, 2) of the points where ``seen``."""
        if not seen.any():
            return
        x, p, h, r = self.x[seen], self.p[seen], self.h, self.r
        pht = p @ h.T
        k = pht @ np.linalg.inv(h @ pht + r)
        x = x + (k @ (z[seen] - x @ h.T)[:, :, None])[:, :, 0]
        i_kh = np.eye(x.shape[1]) - k @ h
        self.x[seen] = x
        self.p[seen] = i_kh @ p @ np.swapaxes(i_kh, 1, 2) + k @ r @ np.swapaxes(k, 1, 2)


class KeypointSmoother:
    """Streaming constant-velocity fixed-lag smoother of K image points.

    Parameters
    ----------
    n_points : int
        K.
    dt_s : float
        Frame interval.
    lag : int
        Frame k - lag is final once frame k has been pushed.
    noise_px : float
        Measurement standard deviation (px).
    accel_px_s2 : float
        Standard deviation of the white-noise acceleration (px/s^2).
    max_gap : int
        Longest run of missing frames bridged by the motion model.
    """

    def __init__(
        self,
        n_points: int,
        dt_s: float,
        lag: int = 5,
        noise_px: float = 3.0,
        accel_px_s2: float = 3000.0,
        max_gap: int = 5,
    ) -> None:
        if lag < 0 or dt_s <= 0 or noise_px <= 0 or accel_px_s2 <= 0 or n_points < 1:
            raise ConfigError(
                f"KeypointSmoother: expected n_points >= 1, dt_s > 0, lag >= 0, noise_px > 0, "
                f"accel_px_s2 > 0; found {n_points}, {dt_s}, {lag}, {noise_px}, {accel_px_s2}"
            )
        self.n_points = n_points
        self.lag = lag
        self.max_gap = max_gap
        model = constant_velocity_model(dt_s, noise_px, accel_px_s2)
        self._filter = AugmentedFilter(*model, lag, n_points)
        self._started = np.zeros(n_points, dtype=bool)
        self._gap = np.zeros(n_points, dtype=np.int64)
        # the estimates of the last lag + 1 frames only: older ones are final and were
        # read (memory stays flat however long the recording)
        self._n_pushed = 0
        self._valid: deque[NDArray[np.bool_]] = deque(maxlen=lag + 1)
        self._out: deque[FloatArray] = deque(maxlen=lag + 1)

    @property
    def n_frames(self) -> int:
        """Frames pushed so far."""
        return self._n_pushed

    def push(self, points_px: ArrayLike) -> None:
        """Add one frame of points (K, 2), NaN where missing."""
        z = np.asarray(points_px, dtype=float)
        if z.shape != (self.n_points, 2):
            raise ShapeError(
                f"KeypointSmoother.push: expected ({self.n_points}, 2), found {z.shape}"
            )
        seen = np.isfinite(z).all(axis=1)
        self._gap = np.where(seen, 0, self._gap + 1)
        self._valid.append(self._gap <= self.max_gap)
        self._n_pushed += 1
        k = self._n_pushed - 1
        kf = self._filter
        first = seen & ~self._started
        kf.x[first, 0::4] = z[first, 0:1]  # every stacked copy starts at the first sighting
        kf.x[first, 2::4] = z[first, 1:2]
        self._started |= seen
        kf.predict()
        kf.update(z, seen)
        est = np.full((self.lag + 1, self.n_points, 2), np.nan)
        est[:, self._started, 0] = kf.x[self._started, 0::4].T
        est[:, self._started, 1] = kf.x[self._started, 2::4].T
        self._out.append(np.full((self.n_points, 2), np.nan))
        for i in range(min(self.lag, k) + 1):
            self._out[-1 - i] = est[i]

    def smoothed(self, frame: int) -> FloatArray:
        """The current estimate (K, 2) of a pushed frame: final once ``lag`` more are pushed.

        NaN for joints never seen yet or unseen for more than ``max_gap`` frames. Only
        the last ``lag + 1`` pushed frames are kept (read each frame once it is final).

        Raises
        ------
        ShapeError
            ``frame`` is not among the last ``lag + 1`` pushed frames.
        """
        first = self._n_pushed - len(self._out)
        if not first <= frame < self._n_pushed:
            raise ShapeError(
                f"KeypointSmoother.smoothed: frame {frame} is not kept; expected one of the "
                f"last lag + 1 = {self.lag + 1} pushed frames, {first}..{self._n_pushed - 1}"
            )
        x = self._out[frame - first].copy()
        x[~self._valid[frame - first]] = np.nan
        return x


def smooth_keypoints(
    points_px: ArrayLike,
    dt_s: float,
    lag: int = 5,
    noise_px: float = 3.0,
    accel_px_s2: float = 3000.0,
    max_gap: int = 5,
) -> FloatArray:
    """Fixed-lag smoothed tracks (T, K, 2) of points (T, K, 2); see `KeypointSmoother`."""
    p = np.asarray(points_px, dtype=float)
    if p.ndim != 3 or p.shape[2] != 2:
        raise ShapeError(f"smooth_keypoints: expected (T, K, 2), found {p.shape}")
    sm = KeypointSmoother(p.shape[1], dt_s, lag, noise_px, accel_px_s2, max_gap)
    out = np.full(p.shape, np.nan)
    for k, z in enumerate(p):
        sm.push(z)
        if k >= lag:
            out[k - lag] = sm.smoothed(k - lag)
    for k in range(max(len(p) - lag, 0), len(p)):
        out[k] = sm.smoothed(k)
    return out
