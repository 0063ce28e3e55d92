"""Forward kinematics, point Jacobians and mass properties over any leading batch shape.

All functions are pure: they take a `Skeleton` and joint parameters ``q`` of shape
``(..., D)`` and return arrays with the same leading shape. One compiled (Numba)
kernel serves a single pose, a sequence and a cloud of particles alike.

Jacobian columns follow the geometric form (Buss 2004; Zhang et al. 2011 eq. 4,
corrected per errata Z3): for a rotation about world axis ``v_j`` through pivot
``p_j``, ``ds/dq_j = v_j x (s - p_j)``; for a prismatic DoF, ``ds/dq_j = v_j``; for a
ball joint stored as a rotation vector ``r``, the world angular velocity of
component ``k`` is ``R_parent @ J_l(r)[:, k]`` (SO(3) left Jacobian). Columns are zero
unless the DoF's joint is the point's joint or one of its ancestors.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ShapeError
from mocapkit.geometry.rotations import (
    axis_angle_matrix_nb,
    left_jacobian_so3_nb,
    rotvec_matrix_nb,
)
from mocapkit.skeleton.derived import PerSkeleton, readonly_copy
from mocapkit.skeleton.model import BALL, PRISMATIC, REVOLUTE, Skeleton

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


class KinematicArrays(NamedTuple):
    """Flat, contiguous arrays of a skeleton in the layout the compiled kernels take.

    A `typing.NamedTuple`, so a Numba kernel takes the whole skeleton as one argument
    (``kin``) and reads ``kin.parents``, ``kin.dof_axis``, ... Build it with
    `kinematic_arrays` (cached per skeleton) or `KinematicArrays.from_skeleton`.

    Attributes
    ----------
    parents : ndarray of int64, shape (J,)
        Parent joint of each joint (-1 for the root); parents precede children.
    offsets : ndarray of float64, shape (J, 3)
        Joint origin in the parent's frame at zero pose (mm).
    dof_start, dof_count : ndarray of int64, shape (J,)
        The DoFs of joint ``j`` are ``dof_start[j] : dof_start[j] + dof_count[j]``.
    dof_kind : ndarray of int64, shape (D,)
        ``REVOLUTE`` (0), ``PRISMATIC`` (1) or ``BALL`` (2, three consecutive DoFs).
    dof_axis : ndarray of float64, shape (D, 3)
        Unit axis of each DoF in its joint's frame.
    dof_joint : ndarray of int64, shape (D,)
        Joint each DoF belongs to.
    ancestors : ndarray of bool, shape (J, J)
        ``ancestors[a, j]``: joint ``a`` is ``j`` or one of its ancestors.
    """

    parents: IntArray
    offsets: FloatArray
    dof_start: IntArray
    dof_count: IntArray
    dof_kind: IntArray
    dof_axis: FloatArray
    dof_joint: IntArray
    ancestors: NDArray[np.bool_]

    @classmethod
    def from_skeleton(cls, skeleton: Skeleton) -> KinematicArrays:
        """Build the arrays of ``skeleton`` (uncached; prefer `kinematic_arrays`)."""
        counts = np.bincount(skeleton.dof_joint, minlength=skeleton.n_joints)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        return cls(
            parents=readonly_copy(skeleton.parents, np.int64),
            offsets=readonly_copy(skeleton.offsets_mm, np.float64),
            dof_start=readonly_copy(starts, np.int64),
            dof_count=readonly_copy(counts, np.int64),
            dof_kind=readonly_copy(skeleton.dof_kind, np.int64),
            dof_axis=readonly_copy(skeleton.dof_axis, np.float64),
            dof_joint=readonly_copy(skeleton.dof_joint, np.int64),
            ancestors=readonly_copy(skeleton.ancestors_mask(), np.bool_),
        )


_KINEMATIC_ARRAYS: PerSkeleton[KinematicArrays] = PerSkeleton()


def kinematic_arrays(skeleton: Skeleton) -> KinematicArrays:
    """The kernel layout of a skeleton, cached per skeleton object.

    The cache holds skeletons weakly, so a process that fits many subjects does not keep
    every model alive.
    """
    return _KINEMATIC_ARRAYS.get(skeleton, None, KinematicArrays.from_skeleton)


# ------------------------------------------------------------------ kernels


@numba.njit(cache=True, inline="always")
def _matmul3_nb(a: FloatArray, b: FloatArray, out: FloatArray) -> None:
    """``out = a @ b`` for 3x3 matrices without allocating (``out`` must not alias)."""
    for i in range(3):
        a0, a1, a2 = a[i, 0], a[i, 1], a[i, 2]
        for j in range(3):
            out[i, j] = a0 * b[0, j] + a1 * b[1, j] + a2 * b[2, j]


@numba.njit(cache=True)
def fk_pose_nb(
    q: FloatArray,
    kin: KinematicArrays,
    world: FloatArray,
    axis_world: FloatArray,
    pivot_world: FloatArray,
) -> None:
    """Forward kinematics of one pose ``q`` (D,) of the skeleton ``kin``.

    Writes ``world`` (J, 4, 4) world_from_joint transforms, and for every DoF its
    world axis ``axis_world`` (D, 3) and pivot ``pivot_world`` (D, 3). Allocation
    per call is a few 3x3 scratch matrices; nothing is allocated per joint.
    """
    parents = kin.parents
    offsets = kin.offsets
    dof_start = kin.dof_start
    dof_count = kin.dof_count
    dof_kind = kin.dof_kind
    dof_axis = kin.dof_axis
    n_joints = parents.shape[0]
    rot_acc = np.empty((3, 3))
    rot_step = np.empty((3, 3))
    tmp = np.empty((3, 3))
    pr = np.empty((3, 3))
    jl = np.empty((3, 3))
    rv = np.empty(3)
    for j in range(n_joints):
        p = parents[j]
        # parent rotation pr and origin (px, py, pz)
        if p < 0:
            for a in range(3):
                for b in range(3):
                    pr[a, b] = 1.0 if a == b else 0.0
            px = py = pz = 0.0
        else:
            for a in range(3):
                for b in range(3):
                    pr[a, b] = world[p, a, b]
            px, py, pz = world[p, 0, 3], world[p, 1, 3], world[p, 2, 3]
        # local translation: offset plus prismatic DoFs, expressed in the parent's orientation
        lx, ly, lz = offsets[j, 0], offsets[j, 1], offsets[j, 2]
        start = dof_start[j]
        stop = start + dof_count[j]
        for d in range(start, stop):
            if dof_kind[d] == 1:  # PRISMATIC
                ax, ay, az = dof_axis[d, 0], dof_axis[d, 1], dof_axis[d, 2]
                lx += ax * q[d]
                ly += ay * q[d]
                lz += az * q[d]
                for a in range(3):
                    axis_world[d, a] = pr[a, 0] * ax + pr[a, 1] * ay + pr[a, 2] * az
                pivot_world[d, 0], pivot_world[d, 1], pivot_world[d, 2] = px, py, pz
        ox = px + pr[0, 0] * lx + pr[0, 1] * ly + pr[0, 2] * lz
        oy = py + pr[1, 0] * lx + pr[1, 1] * ly + pr[1, 2] * lz
        oz = pz + pr[2, 0] * lx + pr[2, 1] * ly + pr[2, 2] * lz
        # world rotation accumulates as pr @ R_1 @ R_2 ...; tmp holds the running product
        for a in range(3):
            for b in range(3):
                rot_acc[a, b] = pr[a, b]
        d = start
        while d < stop:
            kind = dof_kind[d]
            if kind == 0:  # REVOLUTE: world axis is the running product applied to the local axis
                ax, ay, az = dof_axis[d, 0], dof_axis[d, 1], dof_axis[d, 2]
                for a in range(3):
                    axis_world[d, a] = rot_acc[a, 0] * ax + rot_acc[a, 1] * ay + rot_acc[a, 2] * az
                pivot_world[d, 0], pivot_world[d, 1], pivot_world[d, 2] = ox, oy, oz
                axis_angle_matrix_nb(dof_axis[d], q[d], rot_step)
                _matmul3_nb(rot_acc, rot_step, tmp)
                rot_acc[:, :] = tmp
                d += 1
            elif kind == 2:  # BALL: q[d:d+3] is a rotation vector in the joint frame
                rv[0], rv[1], rv[2] = q[d], q[d + 1], q[d + 2]
                left_jacobian_so3_nb(rv, jl)
                for k in range(3):
                    for a in range(3):
                        axis_world[d + k, a] = (
                            pr[a, 0] * jl[0, k] + pr[a, 1] * jl[1, k] + pr[a, 2] * jl[2, k]
                        )
                    pivot_world[d + k, 0] = ox
                    pivot_world[d + k, 1] = oy
                    pivot_world[d + k, 2] = oz
                rotvec_matrix_nb(rv, rot_step)
                _matmul3_nb(pr, rot_step, rot_acc)
                d += 3
            else:
                d += 1
        for a in range(3):
            for b in range(3):
                world[j, a, b] = rot_acc[a, b]
        world[j, 0, 3], world[j, 1, 3], world[j, 2, 3] = ox, oy, oz
        world[j, 3, 0] = world[j, 3, 1] = world[j, 3, 2] = 0.0
        world[j, 3, 3] = 1.0


@numba.njit(cache=True)
def fk_batch_nb(q: FloatArray, kin: KinematicArrays, world: FloatArray) -> None:
    """Forward kinematics of N poses ``q`` (N, D) into ``world`` (N, J, 4, 4)."""
    n_dofs = q.shape[1]
    axis_world = np.empty((n_dofs, 3))
    pivot_world = np.empty((n_dofs, 3))
    for n in range(q.shape[0]):
        fk_pose_nb(q[n], kin, world[n], axis_world, pivot_world)


@numba.njit(cache=True)
def points_jacobian_pose_nb(
    kin: KinematicArrays,
    world: FloatArray,
    axis_world: FloatArray,
    pivot_world: FloatArray,
    target_joint: IntArray,
    target_point: FloatArray,
    points_out: FloatArray,
    jac_out: FloatArray,
) -> None:
    """Points (K, 3) and their Jacobian (3K, D) from one pose's FK results.

    ``target_joint`` (K,) and ``target_point`` (K, 3) give each point's joint and its
    position in that joint's frame (mm).
    """
    dof_kind = kin.dof_kind
    dof_joint = kin.dof_joint
    ancestors = kin.ancestors
    n_dofs = axis_world.shape[0]
    for k in range(target_joint.shape[0]):
        jk = target_joint[k]
        tx, ty, tz = target_point[k, 0], target_point[k, 1], target_point[k, 2]
        s0 = world[jk, 0, 0] * tx + world[jk, 0, 1] * ty + world[jk, 0, 2] * tz + world[jk, 0, 3]
        s1 = world[jk, 1, 0] * tx + world[jk, 1, 1] * ty + world[jk, 1, 2] * tz + world[jk, 1, 3]
        s2 = world[jk, 2, 0] * tx + world[jk, 2, 1] * ty + world[jk, 2, 2] * tz + world[jk, 2, 3]
        points_out[k, 0], points_out[k, 1], points_out[k, 2] = s0, s1, s2
        for d in range(n_dofs):
            if not ancestors[dof_joint[d], jk]:
                jac_out[3 * k, d] = 0.0
                jac_out[3 * k + 1, d] = 0.0
                jac_out[3 * k + 2, d] = 0.0
                continue
            v0, v1, v2 = axis_world[d, 0], axis_world[d, 1], axis_world[d, 2]
            if dof_kind[d] == 1:  # PRISMATIC
                jac_out[3 * k, d] = v0
                jac_out[3 * k + 1, d] = v1
                jac_out[3 * k + 2, d] = v2
            else:
                r0 = s0 - pivot_world[d, 0]
                r1 = s1 - pivot_world[d, 1]
                r2 = s2 - pivot_world[d, 2]
                jac_out[3 * k, d] = v1 * r2 - v2 * r1
                jac_out[3 * k + 1, d] = v2 * r0 - v0 * r2
                jac_out[3 * k + 2, d] = v0 * r1 - v1 * r0


@numba.njit(cache=True)
def fk_points_jacobian_pose_nb(
    q: FloatArray,
    kin: KinematicArrays,
    target_joint: IntArray,
    target_point: FloatArray,
    world: FloatArray,
    axis_world: FloatArray,
    pivot_world: FloatArray,
    points_out: FloatArray,
    jac_out: FloatArray,
) -> None:
    """FK of one pose ``q`` (D,) into the scratch arrays, then its points (K, 3) and
    Jacobian (3K, D): `fk_pose_nb` followed by `points_jacobian_pose_nb`."""
    fk_pose_nb(q, kin, world, axis_world, pivot_world)
    points_jacobian_pose_nb(
        kin, world, axis_world, pivot_world, target_joint, target_point, points_out, jac_out
    )


@numba.njit(cache=True)
def points_jacobian_batch_nb(
    q: FloatArray,
    kin: KinematicArrays,
    target_joint: IntArray,
    target_point: FloatArray,
    points_out: FloatArray,
    jac_out: FloatArray,
) -> None:
    """Points (N, K, 3) and Jacobians (N, 3K, D) of N poses ``q`` (N, D)."""
    n_joints = kin.parents.shape[0]
    n_dofs = q.shape[1]
    world = np.empty((n_joints, 4, 4))
    axis_world = np.empty((n_dofs, 3))
    pivot_world = np.empty((n_dofs, 3))
    for n in range(q.shape[0]):
        fk_points_jacobian_pose_nb(
            q[n],
            kin,
            target_joint,
            target_point,
            world,
            axis_world,
            pivot_world,
            points_out[n],
            jac_out[n],
        )


# ------------------------------------------------------------------ public API


def _flat_q(skeleton: Skeleton, q: ArrayLike) -> tuple[FloatArray, tuple[int, ...]]:
    qa = np.asarray(q, dtype=np.float64)
    skeleton.check_q(qa)
    batch = qa.shape[:-1]
    return np.ascontiguousarray(qa.reshape(-1, skeleton.n_dofs)), batch


def forward_kinematics(skeleton: Skeleton, q: ArrayLike) -> FloatArray:
    """World transforms of every joint.

    Parameters
    ----------
    skeleton : Skeleton
    q : array_like, shape (..., D)
        Joint parameters (rad, mm).

    Returns
    -------
    ndarray, shape (..., J, 4, 4)
        ``world_from_joint`` for each joint (mm).
    """
    flat, batch = _flat_q(skeleton, q)
    kin = kinematic_arrays(skeleton)
    world = np.empty((flat.shape[0], skeleton.n_joints, 4, 4))
    fk_batch_nb(flat, kin, world)
    return world.reshape(*batch, skeleton.n_joints, 4, 4)


def joint_positions(skeleton: Skeleton, q: ArrayLike) -> FloatArray:
    """World positions of every joint origin, shape (..., J, 3) in mm."""
    return forward_kinematics(skeleton, q)[..., :3, 3]


def _targets(
    skeleton: Skeleton, joints: Sequence[int | str] | ArrayLike, points_in_joint: ArrayLike | None
) -> tuple[IntArray, FloatArray]:
    if isinstance(joints, np.ndarray) and joints.dtype.kind in "iu":
        idx = np.array(joints.ravel(), dtype=np.int64)  # indices already: no per-item loop
    else:
        idx = np.array(
            [skeleton.joint_index(j) if isinstance(j, str) else int(j) for j in np.ravel(joints)],
            dtype=np.int64,
        )
    if np.any(idx < 0) or np.any(idx >= skeleton.n_joints):
        raise ShapeError(f"joint indices must lie in [0, {skeleton.n_joints}), found {idx}")
    if points_in_joint is None:
        pts = np.zeros((len(idx), 3))
    else:
        pts = np.ascontiguousarray(points_in_joint, dtype=np.float64)
        if pts.shape != (len(idx), 3):
            raise ShapeError(
                f"points_in_joint: expected shape ({len(idx)}, 3) to match the joints, "
                f"found {pts.shape}"
            )
    return idx, pts


def points_and_jacobian(
    skeleton: Skeleton,
    q: ArrayLike,
    joints: Sequence[int | str] | ArrayLike,
    points_in_joint: ArrayLike | None = None,
) -> tuple[FloatArray, FloatArray]:
    """World positions of points fixed to joints and their position Jacobian.

    Parameters
    ----------
    skeleton : Skeleton
    q : array_like, shape (..., D)
    joints : sequence of int or str, length K
        Joint carrying each point.
    points_in_joint : array_like, shape (K, 3), optional
        Point in its joint's frame (mm); the joint origin when omitted.

    Returns
    -------
    points : ndarray, shape (..., K, 3)
        World positions (mm).
    jacobian : ndarray, shape (..., 3K, D)
        ``d points / d q``; rows are ``x, y, z`` of point 0, then point 1, ...
    """
    flat, batch = _flat_q(skeleton, q)
    idx, pts = _targets(skeleton, joints, points_in_joint)
    kin = kinematic_arrays(skeleton)
    n, k, d = flat.shape[0], len(idx), skeleton.n_dofs
    points_out = np.empty((n, k, 3))
    jac_out = np.empty((n, 3 * k, d))
    points_jacobian_batch_nb(flat, kin, idx, pts, points_out, jac_out)
    return points_out.reshape(*batch, k, 3), jac_out.reshape(*batch, 3 * k, d)


def jacobian(
    skeleton: Skeleton,
    q: ArrayLike,
    joints: Sequence[int | str] | ArrayLike,
    points_in_joint: ArrayLike | None = None,
) -> FloatArray:
    """Position Jacobian ``(..., 3K, D)`` of points fixed to joints; see `points_and_jacobian`."""
    return points_and_jacobian(skeleton, q, joints, points_in_joint)[1]


def points_on_joints(
    skeleton: Skeleton,
    q: ArrayLike,
    joints: Sequence[int | str] | ArrayLike,
    points_in_joint: ArrayLike | None = None,
    world: FloatArray | None = None,
) -> FloatArray:
    """World positions (..., K, 3) of points fixed in the given joints' frames; ``world``:
    `forward_kinematics` of ``q`` if already computed."""
    if world is None:
        world = forward_kinematics(skeleton, q)
    idx, pts = _targets(skeleton, joints, points_in_joint)
    sel = world[..., idx, :, :]
    return np.einsum("...kij,kj->...ki", sel[..., :3, :3], pts) + sel[..., :3, 3]


def _all_canonical_points(skeleton: Skeleton) -> tuple[IntArray, FloatArray]:
    idx, pts = skeleton.canonical_points()
    return readonly_copy(idx, np.int64), readonly_copy(pts, np.float64)


#: `Skeleton.canonical_points` of all the canonical joints, per skeleton.
_ALL_CANONICAL_POINTS: PerSkeleton[tuple[IntArray, FloatArray]] = PerSkeleton()


def canonical_positions(
    skeleton: Skeleton,
    q: ArrayLike,
    names: Sequence[str] | None = None,
    world: FloatArray | None = None,
) -> FloatArray:
    """Positions (..., K, 3) of canonical joints (default: all the skeleton provides);
    ``world``: `forward_kinematics` of ``q`` if already computed."""
    if names is None:  # every frame's output: the lookup kept per skeleton
        idx, pts = _ALL_CANONICAL_POINTS.get(skeleton, None, _all_canonical_points)
    else:
        idx, pts = skeleton.canonical_points(names)
    return points_on_joints(skeleton, q, idx, pts, world)


# ------------------------------------------------------------------ mass properties


def segment_com(skeleton: Skeleton, q: ArrayLike) -> FloatArray:
    """World centre of mass of every segment, shape (..., J, 3) in mm."""
    world = forward_kinematics(skeleton, q)
    local = skeleton.bone_end_mm * skeleton.com_fraction[:, None]
    return np.einsum("...jik,jk->...ji", world[..., :3, :3], local) + world[..., :3, 3]


def center_of_mass(skeleton: Skeleton, q: ArrayLike) -> FloatArray:
    """Whole-body centre of mass, shape (..., 3) in mm."""
    m = skeleton.mass_kg
    if m.sum() <= 0:
        raise ShapeError(f"skeleton {skeleton.name!r} has no mass; centre of mass undefined")
    return np.einsum("j,...jk->...k", m, segment_com(skeleton, q)) / m.sum()


def center_of_mass_jacobian(skeleton: Skeleton, q: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Whole-body centre of mass and its Jacobian with respect to the pose.

    Parameters
    ----------
    skeleton : Skeleton
    q : array_like, shape (D,)

    Returns
    -------
    com : ndarray, shape (3,)
        Centre of mass (mm), as `center_of_mass`.
    jacobian : ndarray, shape (3, D)
        ``d com / d q``: the mass-weighted mean of the segment centres' position
        Jacobians (mm per rad for rotations, mm per mm for translations).
    """
    m = skeleton.mass_kg
    total = float(m.sum())
    if total <= 0:
        raise ShapeError(f"skeleton {skeleton.name!r} has no mass; centre of mass undefined")
    qa = np.asarray(q, dtype=float)
    if qa.shape != (skeleton.n_dofs,):
        raise ShapeError(f"q: expected shape ({skeleton.n_dofs},), found {qa.shape}")
    massive = np.flatnonzero(m > 0)
    local = skeleton.bone_end_mm[massive] * skeleton.com_fraction[massive, None]
    pts, jac = points_and_jacobian(skeleton, qa, massive, local)
    w = m[massive] / total
    com = w @ pts
    jcog = np.einsum("k,kid->id", w, jac.reshape(len(massive), 3, skeleton.n_dofs))
    return com, jcog


def subtree_mass(skeleton: Skeleton) -> FloatArray:
    """Mass (kg) of each joint's segment plus all segments below it, shape (J,)."""
    out = skeleton.mass_kg.astype(float).copy()
    for j in range(skeleton.n_joints - 1, 0, -1):
        out[skeleton.parents[j]] += out[j]
    return out


def subtree_com(skeleton: Skeleton, q: ArrayLike) -> FloatArray:
    """Centre of mass of each joint's subtree, shape (..., J, 3) in mm (NaN for massless)."""
    seg = segment_com(skeleton, q)
    weighted = seg * skeleton.mass_kg[:, None]
    for j in range(skeleton.n_joints - 1, 0, -1):
        weighted[..., skeleton.parents[j], :] += weighted[..., j, :]
    mass = subtree_mass(skeleton)
    with np.errstate(invalid="ignore", divide="ignore"):
        return weighted / mass[:, None]


def carried_mass(skeleton: Skeleton) -> FloatArray:
    """Mass (kg) each DoF moves: the subtree of its joint (errata Z8b), shape (D,)."""
    return subtree_mass(skeleton)[skeleton.dof_joint]


__all__ = [
    "BALL",
    "PRISMATIC",
    "REVOLUTE",
    "KinematicArrays",
    "canonical_positions",
    "carried_mass",
    "center_of_mass",
    "center_of_mass_jacobian",
    "fk_batch_nb",
    "fk_points_jacobian_pose_nb",
    "fk_pose_nb",
    "forward_kinematics",
    "jacobian",
    "joint_positions",
    "kinematic_arrays",
    "points_and_jacobian",
    "points_jacobian_batch_nb",
    "points_jacobian_pose_nb",
    "points_on_joints",
    "segment_com",
    "subtree_com",
    "subtree_mass",
]
