"""Smoothing a pose sequence without filtering across an Euler branch switch.

A joint of three revolute DoFs about orthogonal axes is an Euler triple, and two triples
(and every whole turn added to each) give one rotation. A fit that goes from one to the
other between frames, or slides along the gimbal near the middle axis's +-90 deg, moves
the triple by up to 180 deg while the bone barely moves; a filter run on each DoF then
draws the bone through the rotations in between, a pop of the output that no input
shows. `filter_poses` filters such a joint's rotation as a unit quaternion (signs made
continuous), and takes back the triple nearest the unfiltered one; every other DoF is
filtered as it is.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from mocapkit.skeleton.model import REVOLUTE, FloatArray, Skeleton

#: Axes this close to orthogonal (|cos|) make an Euler triple.
_ORTHOGONAL_COS = 1e-6


def euler_groups(skeleton: Skeleton) -> list[tuple[int, int, int]]:
    """The DoF indices of each joint made of exactly three revolute DoFs about
    orthogonal axes (the joint's Euler triples), in the skeleton's order."""
    out: list[tuple[int, int, int]] = []
    for j in range(skeleton.n_joints):
        idx = np.flatnonzero(skeleton.dof_joint == j)
        if idx.size != 3 or np.any(skeleton.dof_kind[idx] != REVOLUTE):
            continue
        a = skeleton.dof_axis[idx]
        gram = np.abs(a @ a.T - np.eye(3))
        if float(gram.max()) <= _ORTHOGONAL_COS:
            out.append((int(idx[0]), int(idx[1]), int(idx[2])))
    return out


def _frame(axes: FloatArray) -> tuple[FloatArray, float]:
    """A proper rotation P whose columns are the first two axes and their cross product,
    and the sign (+-1) of the third axis along that product: R(a1, t1) R(a2, t2) R(a3, t3)
    = P Rx(t1) Ry(t2) Rz(s t3) P^T."""
    a1, a2, a3 = axes
    c = np.cross(a1, a2)
    return np.column_stack([a1, a2, c]), float(np.sign(np.dot(a3, c)))


def _nearest_turn(angle: FloatArray, ref: FloatArray) -> FloatArray:
    """``angle`` plus the whole turns that bring it nearest ``ref``."""
    return angle + 2.0 * np.pi * np.round((ref - angle) / (2.0 * np.pi))


def _triples_from_quat(quat: FloatArray, p: FloatArray, sign: float, ref: FloatArray) -> FloatArray:
    """The Euler triples (T, 3) of unit quaternions (T, 4) in the joint's axes, each of
    the two solutions (and whole turns) taken nearest ``ref`` (T, 3)."""
    local = p.T @ Rotation.from_quat(quat).as_matrix() @ p
    # intrinsic x-y-z: R = Rx(a) Ry(b) Rz(c)
    b = np.arcsin(np.clip(local[:, 0, 2], -1.0, 1.0))
    a = np.arctan2(-local[:, 1, 2], local[:, 2, 2])
    c = np.arctan2(-local[:, 0, 1], local[:, 0, 0])
    one = np.stack([a, b, sign * c], axis=1)
    two = np.stack([a + np.pi, np.pi - b, sign * (c + np.pi)], axis=1)
    one = _nearest_turn(one, ref)
    two = _nearest_turn(two, ref)
    pick = np.sum((two - ref) ** 2, axis=1) < np.sum((one - ref) ** 2, axis=1)
    return np.where(pick[:, None], two, one)


def filter_poses(
    skeleton: Skeleton, q: FloatArray, filt: Callable[[FloatArray], FloatArray]
) -> FloatArray:
    """Poses (T, D) with ``filt`` applied over time: the Euler triples of `euler_groups`
    as unit quaternions (their signs continuous, normalised after), each other DoF as it
    is. ``filt`` maps a (T, K) array to a (T, K) array filtered along axis 0."""
    q = np.asarray(q, dtype=float)
    out = np.array(q, copy=True)
    groups = euler_groups(skeleton)
    in_group = np.zeros(q.shape[1], dtype=bool)
    for g in groups:
        in_group[list(g)] = True
    plain = np.flatnonzero(~in_group)
    if plain.size:
        out[:, plain] = filt(q[:, plain])
    for g in groups:
        idx = list(g)
        p, sign = _frame(skeleton.dof_axis[idx])
        t = q[:, idx]
        local = Rotation.from_euler("XYZ", t * np.array([1.0, 1.0, sign])).as_matrix()
        quat = Rotation.from_matrix(p @ local @ p.T).as_quat()
        flip = np.cumprod(np.where(np.sum(quat[1:] * quat[:-1], axis=1) < 0.0, -1.0, 1.0))
        quat[1:] *= flip[:, None]
        smooth = filt(quat)
        smooth /= np.linalg.norm(smooth, axis=1, keepdims=True)
        out[:, idx] = _triples_from_quat(smooth, p, sign, t)
    return out


__all__ = ["euler_groups", "filter_poses"]
