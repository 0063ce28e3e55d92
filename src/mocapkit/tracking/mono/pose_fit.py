"""Joint parameters of a skeleton that follow the stick figure's joints (for BVH export).

The monocular tracker estimates joint positions; exports that need joint angles (BVH)
get them here, for skeletons with a free root, ball shoulders, hinge elbows and a ball
head joint (``upper_stick``), all found through canonical names (`mocapkit.skeleton.limbs`):

- root: translation to the pelvis and the rotation that best aligns (Kabsch) the rest
  pelvis, neck and shoulders onto the tracked ones;
- shoulder ball + elbow hinge: the upper arm along the tracked one, the hinge axis
  normal to the tracked arm's plane, flexion the angle between upper arm and forearm
  (clipped to the hinge's limits; a straight arm keeps the trunk's forward direction);
- head ball: the smallest turn of the rest neck->head direction onto the tracked one.

The shoulders' rest offsets are rigid in such a skeleton, so its joints differ from the
tracked ones where the tracked clavicles move; the tracker's own joints are what a result
reports (`Motion.joints_mm`), these angles only drive the export.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ShapeError
from mocapkit.geometry.rotations import rotvec_from_matrix
from mocapkit.skeleton.kinematics import canonical_positions
from mocapkit.skeleton.limbs import arm, head_joint
from mocapkit.skeleton.model import PRISMATIC, Skeleton

FloatArray = NDArray[np.float64]


def _unit(v: FloatArray) -> FloatArray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.asarray(v / np.where(n > 0, n, 1.0), dtype=float)


def _kabsch(src: FloatArray, dst: FloatArray) -> FloatArray:
    """Rotation R minimising |R src - dst| over centred point sets (N, 3)."""
    h = src.T @ dst
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    return np.asarray(vt.T @ np.diag([1.0, 1.0, d]) @ u.T, dtype=float)


def _turn(a: FloatArray, b: FloatArray) -> FloatArray:
    """Smallest rotation taking unit a onto unit b."""
    v = np.cross(a, b)
    c = float(a @ b)
    if c < -1.0 + 1e-12:
        axis = _unit(np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0]))
        return np.asarray(2.0 * np.outer(axis, axis) - np.eye(3), dtype=float)
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.asarray(np.eye(3) + k + k @ k / (1.0 + c), dtype=float)


def fit_stick_pose(
    skeleton: Skeleton, joint_names: Sequence[str], joints_mm: ArrayLike
) -> FloatArray:
    """Joint parameters (T, D) that follow tracked canonical joints (T, K, 3) (world, mm).

    Frames whose pelvis, neck or shoulders are NaN get a NaN row (no pose).
    """
    names = list(joint_names)
    j = np.asarray(joints_mm, dtype=float)
    if j.ndim != 3 or j.shape[1:] != (len(names), 3):
        raise ShapeError(f"fit_stick_pose: expected joints (T, {len(names)}, 3), found {j.shape}")
    torso = ["pelvis", "neck", "left_shoulder", "right_shoulder"]
    missing = [n for n in [*torso, "head"] if n not in names]
    if missing:
        raise ShapeError(f"fit_stick_pose: joints {missing} are needed, found {names}")
    zero = skeleton.zero_pose()
    rest_names = [*torso, "head", "left_elbow", "left_wrist", "right_elbow", "right_wrist"]
    rest = dict(zip(rest_names, canonical_positions(skeleton, zero, rest_names)))
    root_dofs = np.flatnonzero(skeleton.dof_joint == 0)
    trans = root_dofs[skeleton.dof_kind[root_dofs] == PRISMATIC]
    rot = root_dofs[skeleton.dof_kind[root_dofs] != PRISMATIC]
    root_offset = skeleton.offsets_mm[0]
    h = head_joint(skeleton)
    head_dofs = np.flatnonzero(skeleton.dof_joint == h)
    arms = {side: arm(skeleton, side) for side in ("left", "right")}
    q = np.full((j.shape[0], skeleton.n_dofs), np.nan)
    src = np.stack([rest[n] for n in torso])
    src_c = src - src.mean(axis=0)
    forward0 = np.array([0.0, 1.0, 0.0])  # the model faces +y at rest (README conventions)
    for t in range(j.shape[0]):
        pts = {n: j[t, names.index(n)] for n in names}
        dst = np.stack([pts[n] for n in torso])
        if not np.isfinite(dst).all():
            continue
        qt = zero.copy()
        r_root = _kabsch(src_c, dst - dst.mean(axis=0))
        qt[rot] = rotvec_from_matrix(r_root)
        # the root joint sits at the pelvis: place it where the fit puts the rest pelvis
        pelvis_fit = dst.mean(axis=0) + r_root @ (rest["pelvis"] - src.mean(axis=0))
        qt[trans] = pelvis_fit - root_offset
        if head_dofs.size == 3 and np.isfinite(pts["head"]).all():
            d0 = r_root @ _unit(rest["head"] - rest["neck"])
            d = _unit(pts["head"] - pts["neck"])
            qt[head_dofs] = rotvec_from_matrix(r_root.T @ _turn(d0, d) @ r_root)
        for side, limb in arms.items():
            chain = [f"{side}_{n}" for n in ("shoulder", "elbow", "wrist")]
            if any(n not in pts for n in chain):
                continue
            s, e, w = (pts[n] for n in chain)
            if not np.isfinite(np.stack([s, e, w])).all():
                continue
            if limb.dofs.size != 4:
                continue  # not a ball shoulder + hinge elbow
            ball, hinge = limb.dofs[:3], limb.dofs[3]
            a0 = _unit(rest[f"{side}_elbow"] - rest[f"{side}_shoulder"])
            h0 = _unit(np.asarray(skeleton.dof_axis[hinge], dtype=float))
            b0 = np.cross(h0, a0)
            u = _unit(e - s)
            f = _unit(w - e)
            theta = float(np.arccos(np.clip(u @ f, -1.0, 1.0)))
            wv = f - np.cos(theta) * u
            if np.linalg.norm(wv) < 1e-6:
                wv = r_root @ forward0 - (r_root @ forward0 @ u) * u
            wv = _unit(wv)
            r_world = np.column_stack([u, wv, np.cross(u, wv)]) @ np.column_stack([a0, b0, h0]).T
            qt[ball] = rotvec_from_matrix(r_root.T @ r_world)
            qt[hinge] = np.clip(theta, skeleton.lower[hinge], skeleton.upper[hinge])
        q[t] = qt
    return q
