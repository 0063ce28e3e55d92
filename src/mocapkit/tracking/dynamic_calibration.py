"""Member-marker offsets of the hybrid tracker's marker sets, calibrated on the motion itself.

A raw marker file does not say where each member marker of a set sits on the body; the
static calibration (`mocapkit.tracking.static_calibration`) finds it on a still second.
Where a take has none (or none is wanted), the offsets are calibrated on the motion, as
biomechanics does with a functional calibration or OpenSim's marker placement on a
dynamic trial: the take is tracked from the set centres alone (positions only), each
member is put in its effector joint's frame on every frame, and the median over the
frames where the set's centre fits the model (within `MAX_FIT_MM`) is its offset.

Why the median: with positions only the head's turn and the forearm's (the elbow's swivel
about the shoulder-wrist line) come from the IK's relaxed-pose task, and they are wrong on
part of a moving take (the tennis serve's ball-tossing arm swings down with its elbow
up, the head looks up at the ball); the per-frame offsets of those frames are outliers
that the median leaves out where the mean would be pulled by them. The calibration
assumes on most of the fitting frames what the static one assumes on one still second:
the head faces the way the trunk does and the forearm is turned as the relaxed pose turns
it. Offsets are from the effector's default point, as ``HybridConfig.member_offsets_mm``.

One pass only: tracking again with the offsets and calibrating again returns nearly the
offsets it started from (the IK now follows the members: per-frame offsets within 1 mm of
their median), and on the tennis serve it moved the right elbow's error 114 -> 123 mm.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ConfigError, ShapeError
from mocapkit.skeleton.kinematics import forward_kinematics
from mocapkit.skeleton.model import Skeleton
from mocapkit.tracking.hybrid import default_marker_effectors

FloatArray = NDArray[np.float64]

#: Largest distance (mm) of a set's centre from its model point on a frame that is used:
#: frames where the positions-only model does not reach the set (the tennis serve's
#: racket drop: 30-110 mm) say nothing about where the members sit on it. The tennis
#: serve's figures at 5 / 10 / 30 mm: elbows 94 / 123, 91 / 114, 89 / 126 mm (left /
#: right mean).
MAX_FIT_MM = 10.0
#: Fewest such frames a set needs to be calibrated (2 s at 50 Hz).
MIN_FRAMES = 100


@dataclass(frozen=True)
class DynamicCalibration:
    """Member offsets calibrated on a moving take.

    Attributes
    ----------
    offsets_mm : dict of str to dict of str to tuple
        Per set, per member: offset (mm) in the effector joint's frame from the effector's
        default point (``HybridConfig.member_offsets_mm``).
    spread_mm : dict of str to float
        Per set: the largest over its members of the median distance of the per-frame
        offsets from their median (how much the positions-only model's turn of the
        joint wandered: the tennis serve's glasses 33-40 mm, wrist bars 18-25 mm).
    frames_used : dict of str to int
        Per set: the frames the median is over.
    n_frames : int
        Frames of the take.
    """

    offsets_mm: dict[str, dict[str, tuple[float, float, float]]]
    spread_mm: dict[str, float]
    frames_used: dict[str, int]
    n_frames: int

    def summary(self) -> str:
        """One line for the terminal."""
        sets = ", ".join(
            f"{n} on {self.frames_used[n]} frames (spread {self.spread_mm[n]:.1f} mm)"
            for n in self.offsets_mm
        )
        return (
            f"member offsets calibrated on the motion (median over the {self.n_frames} "
            f"frames' positions-only poses where the set fits within {MAX_FIT_MM:g} mm): "
            f"{sets}"
        )


def calibrate_members_on_motion(
    skeleton: Skeleton,
    q: ArrayLike,
    fit_mm: Mapping[str, ArrayLike],
    members_mm: Mapping[str, Mapping[str, ArrayLike]],
    max_fit_mm: float = MAX_FIT_MM,
    min_frames: int = MIN_FRAMES,
) -> DynamicCalibration:
    """Member offsets from a tracked motion (see the module docstring).

    Parameters
    ----------
    skeleton : Skeleton
        The model ``q`` poses; its effector joints' frames are the offsets' frames (a model
        with more DoFs that has the same frames at those DoFs' zero, as
        ``raw_marker_skeleton``'s oriented one, takes the same offsets).
    q : array_like, shape (T, D)
        The poses tracked from the set centres alone (rad, mm); rows with NaN are skipped.
    fit_mm : mapping of str to array_like (T,)
        Per set: its centre's distance (mm) to its model point on each frame (the
        tracker's ``fit["<set>_mm"]``), NaN where the set was not in the task.
    members_mm : mapping of str to mapping of str to array_like (T, 3)
        Per set, its member markers' trajectories (mm, the tracker's world), NaN where
        unseen; sets with fewer than two members are not calibrated.
    max_fit_mm : float
        Largest set fit (mm) of a frame that is used (`MAX_FIT_MM`).
    min_frames : int
        Fewest usable frames for a set to be calibrated (`MIN_FRAMES`).

    Returns
    -------
    DynamicCalibration

    Raises
    ------
    ShapeError
        ``q``, a fit or a trajectory of the wrong shape.
    ConfigError
        No set has two members seen on ``min_frames`` frames that fit.
    """
    qs = np.asarray(q, dtype=float)
    if qs.ndim != 2 or qs.shape[1] != len(skeleton.dof_names):
        raise ShapeError(f"q: expected shape (T, {len(skeleton.dof_names)}), found {qs.shape}")
    if not max_fit_mm > 0 or min_frames < 1:
        raise ConfigError(
            f"dynamic calibration: expected max_fit_mm > 0 and min_frames >= 1, found "
            f"{max_fit_mm}, {min_frames}"
        )
    n = qs.shape[0]
    posed = np.all(np.isfinite(qs), axis=1)
    world = np.full((n, len(skeleton.joint_names), 4, 4), np.nan)
    if posed.any():
        world[posed] = forward_kinematics(skeleton, qs[posed])
    effectors = default_marker_effectors(skeleton)
    offsets: dict[str, dict[str, tuple[float, float, float]]] = {}
    spread: dict[str, float] = {}
    used: dict[str, int] = {}
    for name, members in members_mm.items():
        if len(members) < 2:
            continue
        if name not in effectors:
            raise ConfigError(
                f"dynamic calibration: expected marker sets {sorted(effectors)}, found {name!r}"
            )
        fit = np.asarray(fit_mm[name], dtype=float)
        if fit.shape != (n,):
            raise ShapeError(f"fit_mm[{name!r}]: expected shape ({n},), found {fit.shape}")
        eff = effectors[name]
        j = skeleton.joint_index(eff.joint)
        rot = world[:, j, :3, :3]
        origin = world[:, j, :3, 3]
        # NaN fits (set not in the task) compare False: not used
        good = posed & (fit <= max_fit_mm)
        local: dict[str, FloatArray] = {}
        for member, traj in members.items():
            m = np.asarray(traj, dtype=float)
            if m.shape != (n, 3):
                raise ShapeError(
                    f"members_mm[{name!r}][{member!r}]: expected shape ({n}, 3), found {m.shape}"
                )
            local[member] = np.einsum("nji,nj->ni", rot, m - origin) - np.asarray(eff.point_mm)
            good &= np.all(np.isfinite(local[member]), axis=1)
        if int(good.sum()) < min_frames:
            continue
        out: dict[str, tuple[float, float, float]] = {}
        worst = 0.0
        for member, loc in local.items():
            med = np.median(loc[good], axis=0)
            out[member] = (float(med[0]), float(med[1]), float(med[2]))
            worst = max(worst, float(np.median(np.linalg.norm(loc[good] - med, axis=1))))
        offsets[name] = out
        spread[name] = worst
        used[name] = int(good.sum())
    if not offsets:
        raise ConfigError(
            f"dynamic calibration: expected a marker set with two or more members seen on "
            f"at least {min_frames} frames where it fits within {max_fit_mm:g} mm, found none"
        )
    return DynamicCalibration(offsets, spread, used, n)


__all__ = [
    "MAX_FIT_MM",
    "MIN_FRAMES",
    "DynamicCalibration",
    "calibrate_members_on_motion",
]
