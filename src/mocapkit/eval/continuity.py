"""Continuity of a motion: how fast each joint moves and each bone turns about its own axis
from frame to frame, against how fast the inputs move (a pop is a joint or a bone roll
faster than anything the inputs show)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ShapeError
from mocapkit.skeleton.kinematics import forward_kinematics
from mocapkit.skeleton.model import Skeleton
from mocapkit.skeleton.roll import roll_steps

FloatArray = NDArray[np.float64]


def speeds_mm_s(time_s: ArrayLike, points_mm: ArrayLike) -> FloatArray:
    """Speed of each point between consecutive frames, shape (T - 1, K), mm/s; NaN where
    either frame lacks the point."""
    t = np.asarray(time_s, dtype=float)
    p = np.asarray(points_mm, dtype=float)
    if p.ndim != 3 or p.shape[0] != t.shape[0] or p.shape[2] != 3:
        raise ShapeError(f"points_mm: expected shape ({t.shape[0]}, K, 3), found {p.shape}")
    dt = np.diff(t)
    return np.linalg.norm(np.diff(p, axis=0), axis=2) / dt[:, None]


@dataclass(frozen=True)
class Peak:
    """The largest value of a per-frame series: its value, the frame it ends on, its name."""

    value: float
    frame: int
    name: str


def peak(values: ArrayLike, names: tuple[str, ...]) -> Peak:
    """The largest finite entry of ``values`` (T, K), with its frame (the later of the
    two the step joins) and its column's name."""
    v = np.asarray(values, dtype=float)
    if v.size == 0 or not np.isfinite(v).any():
        return Peak(float("nan"), -1, "")
    i, k = np.unravel_index(int(np.nanargmax(v)), v.shape)
    return Peak(float(v[i, k]), int(i) + 1, names[int(k)])


def roll_steps_deg(skeleton: Skeleton, q: ArrayLike) -> tuple[tuple[str, ...], FloatArray]:
    """Each roll-free bone's turn about its own axis per frame (deg, absolute), from the
    poses ``q`` (T, D); returns the bones' joint names and (T - 1, B)."""
    world = forward_kinematics(skeleton, np.asarray(q, dtype=float))
    bones, steps = roll_steps(skeleton, world[..., :3, :3])
    return tuple(skeleton.joint_names[b] for b in bones), np.abs(np.rad2deg(steps))


__all__ = ["Peak", "peak", "roll_steps_deg", "speeds_mm_s"]
