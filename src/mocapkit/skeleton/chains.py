"""A joint chain posed below a fixed parent: the kinematics of one limb inside a local search.

A tracker that refines one limb at a time (Zhang et al. 2011 §5.2: each arm on its own)
holds everything above the limb fixed. `LimbChain` keeps the limb's joints as a small
skeleton of their own (`KinematicArrays` with the first joint as root), the pose's
values of their DoFs, where the searched parameters go, and the parent's world
transform; `chain_frames_nb` then runs the shared `fk_pose_nb` on the chain alone and
carries it by the parent's transform. Per evaluation this costs the chain's joints, not
the whole body's.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ShapeError
from mocapkit.skeleton.derived import PerSkeleton, readonly_copy
from mocapkit.skeleton.kinematics import (
    KinematicArrays,
    fk_pose_nb,
    forward_kinematics,
    kinematic_arrays,
)
from mocapkit.skeleton.model import Skeleton

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


class LimbChain(NamedTuple):
    """A chain of joints posed below a fixed parent (build with `limb_chain`).

    Attributes
    ----------
    kin : KinematicArrays
        The chain's joints alone, in chain order; joint 0 is the root.
    q : ndarray, shape (C,)
        The chain's DoF values in the pose the chain was built at.
    x_slots : ndarray of int64, shape (N,)
        Where the searched parameters ``x`` (N,) go in ``q``.
    parent_rotation : ndarray, shape (3, 3)
    parent_origin_mm : ndarray, shape (3,)
        World transform of the first joint's parent.
    """

    kin: KinematicArrays
    q: FloatArray
    x_slots: IntArray
    parent_rotation: FloatArray
    parent_origin_mm: FloatArray


class _ChainLayout(NamedTuple):
    kin: KinematicArrays
    chain_dofs: IntArray
    x_slots: IntArray


#: Per skeleton: the layout of each chain asked for, by joints and DoFs. A tracker builds
#: the same limb's chain every frame; only the pose part changes.
_LAYOUTS: PerSkeleton[_ChainLayout] = PerSkeleton()


def _chain_layout(skeleton: Skeleton, j: IntArray, d: IntArray) -> _ChainLayout:
    key = (j.shape, j.tobytes(), d.shape, d.tobytes())
    return _LAYOUTS.get(skeleton, key, _build_chain_layout, j, d)


def _build_chain_layout(skeleton: Skeleton, j: IntArray, d: IntArray) -> _ChainLayout:
    if j.ndim != 1 or j.size == 0 or np.any(skeleton.parents[j[1:]] != j[:-1]):
        raise ShapeError(
            f"skeleton {skeleton.name!r}: joints {j.tolist()} are not a chain (each the parent "
            "of the next)"
        )
    full = kinematic_arrays(skeleton)
    chain_dofs = np.concatenate(
        [np.arange(full.dof_start[k], full.dof_start[k] + full.dof_count[k]) for k in j]
    ).astype(np.int64)
    if not np.all(np.isin(d, chain_dofs)):
        raise ShapeError(
            f"skeleton {skeleton.name!r}: DoFs {d.tolist()} are not all on joints {j.tolist()}"
        )
    counts = full.dof_count[j]
    n = j.size
    kin = KinematicArrays(
        parents=readonly_copy(np.arange(n) - 1, np.int64),
        offsets=readonly_copy(full.offsets[j], np.float64),
        dof_start=readonly_copy(np.concatenate([[0], np.cumsum(counts)[:-1]]), np.int64),
        dof_count=readonly_copy(counts, np.int64),
        dof_kind=readonly_copy(full.dof_kind[chain_dofs], np.int64),
        dof_axis=readonly_copy(full.dof_axis[chain_dofs], np.float64),
        dof_joint=readonly_copy(np.repeat(np.arange(n), counts), np.int64),
        ancestors=readonly_copy(np.triu(np.ones((n, n), dtype=bool)), np.bool_),
    )
    return _ChainLayout(
        kin,
        readonly_copy(chain_dofs, np.int64),
        readonly_copy(np.searchsorted(chain_dofs, d), np.int64),
    )


def limb_chain(
    skeleton: Skeleton,
    q: ArrayLike,
    joints: ArrayLike,
    dofs: ArrayLike,
    world: FloatArray | None = None,
) -> LimbChain:
    """The chain ``joints`` of ``skeleton`` at pose ``q`` (D,), searched over ``dofs``.

    Parameters
    ----------
    skeleton : Skeleton
    q : array_like, shape (D,)
    joints : array_like of int, shape (K,)
        Each joint the parent of the next.
    dofs : array_like of int, shape (N,)
        Searched DoFs, all on ``joints``.
    world : ndarray, shape (J, 4, 4), optional
        ``forward_kinematics(skeleton, q)`` if already computed.
    """
    j = np.asarray(joints, dtype=np.int64)
    d = np.asarray(dofs, dtype=np.int64)
    kin, chain_dofs, x_slots = _chain_layout(skeleton, j, d)
    qa = np.asarray(q, dtype=np.float64)
    if world is None:
        world = forward_kinematics(skeleton, qa)
    parent = skeleton.parents[j[0]]
    pw = world[parent] if parent >= 0 else np.eye(4)
    return LimbChain(
        kin=kin,
        q=np.ascontiguousarray(qa[chain_dofs]),
        x_slots=x_slots.copy(),  # the caller's own, as the pose's arrays
        parent_rotation=np.ascontiguousarray(pw[:3, :3]),
        parent_origin_mm=np.ascontiguousarray(pw[:3, 3]),
    )


@numba.njit(cache=True)
def chain_frames_nb(x: FloatArray, chain: LimbChain, rots: FloatArray, orig: FloatArray) -> None:
    """World rotations (K, 3, 3) and origins (K, 3) of the chain's joints at parameters ``x``.

    `fk_pose_nb` on the chain with ``x`` in its slots, carried by the parent's transform.
    """
    q = chain.q.copy()
    for i in range(x.shape[0]):
        q[chain.x_slots[i]] = x[i]
    n_joints = chain.kin.parents.shape[0]
    world = np.empty((n_joints, 4, 4))
    axis_world = np.empty((q.shape[0], 3))
    pivot_world = np.empty((q.shape[0], 3))
    fk_pose_nb(q, chain.kin, world, axis_world, pivot_world)
    pr = chain.parent_rotation
    pt = chain.parent_origin_mm
    for s in range(n_joints):
        w = world[s]
        for i in range(3):
            for j in range(3):
                rots[s, i, j] = pr[i, 0] * w[0, j] + pr[i, 1] * w[1, j] + pr[i, 2] * w[2, j]
            orig[s, i] = pr[i, 0] * w[0, 3] + pr[i, 1] * w[1, 3] + pr[i, 2] * w[2, 3] + pt[i]


__all__ = ["LimbChain", "chain_frames_nb", "limb_chain"]
