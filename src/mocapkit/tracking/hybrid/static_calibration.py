"""Member-marker offsets of the hybrid tracker's marker sets, calibrated on a static interval.

A session declares where each member marker of a set sits on the body
(``session.json`` ``members_mm``), which lets the IK see the set's orientation (the
glasses' turn, the wrist bar's direction). A raw marker file does not; labs record a
static trial instead. Here the subject's pose over a still interval is tracked from the
set centres alone (positions only, as the tracker does without members), and each member
is then expressed in its effector joint's frame and averaged over the interval: that is
its offset (``HybridConfig.member_offsets_mm``, from the effector's default point).

The calibration assumes that over the interval the subject stands (or sits) in the
relaxed pose the tracker takes when nothing else tells it (head straight over the trunk,
arms hanging), facing the way the hands say (the body's right from the left to the right
hand set): the members' offsets are exactly right when the subject holds that pose, and
rotated by however much the head (or forearm) is turned from it.

The interval (`find_static_interval`) is the window of `STATIC_WINDOW_S` within the first
`STATIC_SEARCH_S` of the take (or of a separate static trial) where the set centres move
least: smallest root-mean-square distance of the sets from their own mean over the window,
among windows where every set is seen on at least 90 % of the frames; none when even
that one moves more than `MAX_STATIC_RMS_MM` (the calibration is then not done, and the
run says so).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ConfigError, ShapeError
from mocapkit.geometry.transforms import points_in_frame
from mocapkit.skeleton.kinematics import forward_kinematics
from mocapkit.skeleton.model import Skeleton
from mocapkit.tracking.hybrid.tracker import (
    HybridConfig,
    HybridSample,
    HybridTracker,
    default_marker_effectors,
)

FloatArray = NDArray[np.float64]

#: Length (s) of the static window.
STATIC_WINDOW_S = 1.0
#: Where the window is searched: the first seconds of the take (s).
STATIC_SEARCH_S = 5.0
#: Least share of a window's frames on which each set must be seen.
MIN_SEEN_FRACTION = 0.9
#: Most motion (RMS distance of the sets from their window mean, mm) a window may have to
#: count as static: quiet standing sways the head by 5-10 mm; a take that starts moving
#: (the wheelchair sprint's stillest second in its first 5 s: 282 mm) has no static window.
MAX_STATIC_RMS_MM = 25.0


@dataclass(frozen=True)
class StaticInterval:
    """A still window of a take: frames ``start:stop`` and how still it was."""

    start: int
    stop: int
    start_s: float
    stop_s: float
    rms_motion_mm: float

    def summary(self) -> str:
        """One line for the terminal."""
        return (
            f"{self.start_s:.2f}-{self.stop_s:.2f} s ({self.stop - self.start} frames; the "
            f"sets move {self.rms_motion_mm:.1f} mm RMS about their mean)"
        )


def find_static_interval(
    time_s: ArrayLike,
    sets_mm: ArrayLike,
    window_s: float = STATIC_WINDOW_S,
    search_s: float = STATIC_SEARCH_S,
    max_rms_mm: float = MAX_STATIC_RMS_MM,
) -> StaticInterval | None:
    """The stillest window of ``window_s`` starting within ``search_s`` of the first frame.

    Parameters
    ----------
    time_s : array_like, shape (T,)
    sets_mm : array_like, shape (T, S, 3)
        Set centres (NaN where unseen).
    window_s, search_s : float
        Window length and search span (s, > 0).
    max_rms_mm : float
        Most motion of a static window (`MAX_STATIC_RMS_MM`).

    Returns
    -------
    StaticInterval or None
        None when no window has every set seen on `MIN_SEEN_FRACTION` of its frames and
        moves less than ``max_rms_mm``.
    """
    t = np.asarray(time_s, dtype=float)
    p = np.asarray(sets_mm, dtype=float)
    if p.ndim != 3 or p.shape[0] != t.size or p.shape[2] != 3:
        raise ShapeError(f"sets_mm: expected shape ({t.size}, S, 3), found {p.shape}")
    if not (window_s > 0 and search_s > 0):
        raise ConfigError(
            f"static interval: expected window and search spans > 0 s, found {window_s}, {search_s}"
        )
    if t.size == 0:
        return None
    seen = np.all(np.isfinite(p), axis=2)  # (T, S)
    best: StaticInterval | None = None
    for start in range(t.size):
        if t[start] - t[0] > search_s:
            break
        stop = int(np.searchsorted(t, t[start] + window_s, side="left"))
        if stop - start < 2 or t[stop - 1] - t[start] < 0.5 * window_s:
            break
        ok = seen[start:stop]
        if np.any(ok.mean(axis=0) < MIN_SEEN_FRACTION):
            continue
        w = p[start:stop]
        dev = w - np.nanmean(w, axis=0)
        rms = float(np.sqrt(np.nanmean(np.sum(dev * dev, axis=2))))
        if rms <= max_rms_mm and (best is None or rms < best.rms_motion_mm):
            best = StaticInterval(start, stop, float(t[start]), float(t[stop - 1]), rms)
    return best


@dataclass(frozen=True)
class MemberCalibration:
    """Calibrated member offsets and their spread over the static interval.

    Attributes
    ----------
    offsets_mm : dict of str to dict of str to tuple
        Per set, per member: offset (mm) in the effector joint's frame from the effector's
        default point (``HybridConfig.member_offsets_mm``).
    spread_mm : dict of str to float
        Per set: the largest over its members of the RMS distance of the per-frame
        offsets from their mean (how still the interval and how rigid the set were).
    interval : StaticInterval
    """

    offsets_mm: dict[str, dict[str, tuple[float, float, float]]]
    spread_mm: dict[str, float]
    interval: StaticInterval


def calibrate_member_offsets(
    skeleton: Skeleton,
    config: HybridConfig,
    time_s: ArrayLike,
    sets_mm: Mapping[str, ArrayLike],
    members_mm: Mapping[str, Mapping[str, ArrayLike]],
    interval: StaticInterval,
) -> MemberCalibration:
    """Member offsets from a static interval (see the module docstring).

    Parameters
    ----------
    skeleton : Skeleton
        The model the tracker will use (scaled; seated or not).
    config : HybridConfig
        The tracker's configuration; it runs here without members and without video.
    time_s : array_like, shape (T,)
    sets_mm : mapping of str to array_like (T, 3)
        Set centres by set name (NaN where unseen).
    members_mm : mapping of str to mapping of str to array_like (T, 3)
        Per set, its member markers' trajectories; sets with fewer than two members are
        not calibrated (no orientation to see).
    interval : StaticInterval

    Returns
    -------
    MemberCalibration

    Raises
    ------
    ConfigError
        No set has two members seen in the interval.
    """
    t = np.asarray(time_s, dtype=float)
    rows = slice(interval.start, interval.stop)
    cfg = HybridConfig(
        ik=config.ik,
        use_video=False,
        plant_feet=config.plant_feet,
        start_upright=config.start_upright,
        replant_mm=config.replant_mm,
        posture=config.posture,
        paper=config.paper,
        marker_offsets_mm=config.marker_offsets_mm,
    )
    effectors = default_marker_effectors(skeleton)
    arrays = {n: np.asarray(a, dtype=float)[rows] for n, a in sets_mm.items()}
    tracker = HybridTracker(skeleton, None, cfg, marker_effectors={n: effectors[n] for n in arrays})
    qs = []
    for i, ti in enumerate(t[rows]):
        pose = tracker.update(HybridSample(float(ti), {n: a[i] for n, a in arrays.items()}))
        qs.append(pose.q)
    world = forward_kinematics(skeleton, np.asarray(qs))  # (N, J, 4, 4)
    offsets: dict[str, dict[str, tuple[float, float, float]]] = {}
    spread: dict[str, float] = {}
    for name, members in members_mm.items():
        if name not in arrays or len(members) < 2:
            continue
        eff = effectors[name]
        world_from_joint = world[:, skeleton.joint_index(eff.joint)]
        out: dict[str, tuple[float, float, float]] = {}
        worst = 0.0
        for member, traj in members.items():
            m = np.asarray(traj, dtype=float)[rows]
            local = points_in_frame(world_from_joint, m) - np.asarray(eff.point_mm)
            ok = np.all(np.isfinite(local), axis=1)
            if not ok.any():
                continue
            mean = local[ok].mean(axis=0)
            out[member] = (float(mean[0]), float(mean[1]), float(mean[2]))
            dev = local[ok] - mean
            worst = max(worst, float(np.sqrt(np.mean(np.sum(dev * dev, axis=1)))))
        if len(out) >= 2:
            offsets[name] = out
            spread[name] = worst
    if not offsets:
        raise ConfigError(
            f"static calibration over {interval.summary()}: expected a marker set with at "
            "least two member markers seen, found none"
        )
    return MemberCalibration(offsets, spread, interval)


def rotation_between_deg(a_mm: ArrayLike, b_mm: ArrayLike) -> float:
    """Angle (deg) of the rotation that best maps point set ``a`` (N, 3) onto ``b``
    (both centred first; Kabsch), e.g. calibrated against true member offsets."""
    a = np.asarray(a_mm, dtype=float)
    b = np.asarray(b_mm, dtype=float)
    a = a - a.mean(axis=0)
    b = b - b.mean(axis=0)
    u, _s, vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return math.degrees(math.acos(float(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0))))


__all__ = [
    "MAX_STATIC_RMS_MM",
    "STATIC_SEARCH_S",
    "STATIC_WINDOW_S",
    "MemberCalibration",
    "StaticInterval",
    "calibrate_member_offsets",
    "find_static_interval",
    "rotation_between_deg",
]
