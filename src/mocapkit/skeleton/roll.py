"""Bone roll: the turn of a bone about its own long axis, which moves no joint.

A bone whose children (and canonical points) all lie on its long axis can turn about
that axis without moving any joint: a stick figure does not show it, a skinned
character does (a twisted arm). `roll_free_bones` finds those bones, `roll_steps`
measures how much each turns about its axis from one frame to the next (the turn left
after the smallest swing that carries last frame's axis onto this frame's), and
`limit_roll` takes world rotations whose roll jumps and returns the same joints with
each roll-free bone's roll changing by at most a given step per frame, catching up with
the input's roll as fast as that step allows. Children keep their world rotations, so
every joint position is unchanged.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ShapeError
from mocapkit.geometry.rotations import matrix_from_axis_angle
from mocapkit.skeleton.model import PRISMATIC, Skeleton

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: A child offset or canonical point counts as on the bone's axis within this angle.
_ON_AXIS_RAD = 1e-6


def roll_free_bones(skeleton: Skeleton) -> IntArray:
    """Joints whose bone may turn about its own axis without moving any joint.

    A joint qualifies when its bone (``bone_end_mm``) has a length, every child's offset
    and every canonical point on it lies on that axis, and no child has prismatic DoFs
    (their axes turn with the parent).
    """
    children: list[list[int]] = [[] for _ in range(skeleton.n_joints)]
    for j, p in enumerate(skeleton.parents):
        if p >= 0:
            children[int(p)].append(j)
    prismatic_joints = set(skeleton.dof_joint[skeleton.dof_kind == PRISMATIC].tolist())
    points: dict[int, list[FloatArray]] = {}
    for joint_name, point in skeleton.canonical.values():
        points.setdefault(skeleton.joint_index(joint_name), []).append(np.asarray(point, float))
    out = []
    for j in range(skeleton.n_joints):
        axis = np.asarray(skeleton.bone_end_mm[j], float)
        length = float(np.linalg.norm(axis))
        if length == 0.0 or any(c in prismatic_joints for c in children[j]):
            continue
        unit = axis / length
        others = [np.asarray(skeleton.offsets_mm[c], float) for c in children[j]]
        others += points.get(j, [])
        if all(
            np.linalg.norm(np.cross(unit, v)) <= _ON_AXIS_RAD * max(1.0, float(np.linalg.norm(v)))
            for v in others
        ):
            out.append(j)
    return np.array(out, dtype=np.int64)


def _axes(skeleton: Skeleton, rot: FloatArray, bones: IntArray) -> FloatArray:
    """Unit long axis of each bone in the world, shape (T, B, 3)."""
    local = skeleton.bone_end_mm[bones]
    local = local / np.linalg.norm(local, axis=1, keepdims=True)
    return np.einsum("tbij,bj->tbi", rot[:, bones], local)


def _swing(a: FloatArray, b: FloatArray) -> FloatArray:
    """Smallest rotations taking unit vectors ``a`` onto ``b`` (..., 3) -> (..., 3, 3)."""
    axis = np.cross(a, b)
    s = np.linalg.norm(axis, axis=-1)
    c = np.clip(np.einsum("...i,...i->...", a, b), -1.0, 1.0)
    angle = np.arctan2(s, c)
    # parallel axes: angle 0 about any axis
    safe = np.where(
        s[..., None] > 1e-12, axis / np.maximum(s, 1e-300)[..., None], np.array([1.0, 0.0, 0.0])
    )
    # antiparallel axes: any perpendicular axis
    flip = (s <= 1e-12) & (c < 0)
    if np.any(flip):
        perp = np.cross(a[flip], np.array([1.0, 0.0, 0.0]))
        bad = np.linalg.norm(perp, axis=-1) < 1e-6
        perp[bad] = np.cross(a[flip][bad], np.array([0.0, 1.0, 0.0]))
        safe[flip] = perp / np.linalg.norm(perp, axis=-1, keepdims=True)
    return matrix_from_axis_angle(safe, angle)


def _check(skeleton: Skeleton, world_rot: ArrayLike) -> FloatArray:
    rot = np.asarray(world_rot, dtype=float)
    if rot.ndim != 4 or rot.shape[1:] != (skeleton.n_joints, 3, 3):
        raise ShapeError(
            f"world rotations: expected shape (T, {skeleton.n_joints}, 3, 3), found {rot.shape}"
        )
    return rot


def roll_steps(skeleton: Skeleton, world_rot: ArrayLike) -> tuple[IntArray, FloatArray]:
    """Signed roll of each roll-free bone from each frame to the next.

    Parameters
    ----------
    skeleton : Skeleton
    world_rot : (T, J, 3, 3) array
        ``world_from_joint`` rotations.

    Returns
    -------
    bones : (B,) int array
        `roll_free_bones`.
    steps_rad : (T - 1, B) array
        Turn about the bone's axis from frame t to t + 1 after the smallest swing of its
        axis, in (-pi, pi].
    """
    rot = _check(skeleton, world_rot)
    bones = roll_free_bones(skeleton)
    if rot.shape[0] < 2 or bones.size == 0:
        return bones, np.zeros((max(rot.shape[0] - 1, 0), bones.size))
    axes = _axes(skeleton, rot, bones)
    swing = _swing(axes[:-1], axes[1:])
    prev = np.einsum("tbij,tbjk->tbik", swing, rot[:-1, bones])
    turn = np.einsum("tbij,tbkj->tbik", rot[1:, bones], prev)  # about axes[1:]
    return bones, _angle_about(turn, axes[1:])


def _angle_about(turn: FloatArray, axis: FloatArray) -> FloatArray:
    """Signed angle of rotations ``turn`` (..., 3, 3) about the unit ``axis`` (..., 3)."""
    vec = np.stack(
        [
            turn[..., 2, 1] - turn[..., 1, 2],
            turn[..., 0, 2] - turn[..., 2, 0],
            turn[..., 1, 0] - turn[..., 0, 1],
        ],
        axis=-1,
    )
    trace = turn[..., 0, 0] + turn[..., 1, 1] + turn[..., 2, 2]
    return np.arctan2(np.einsum("...i,...i->...", vec, axis), trace - 1.0)


def limit_roll(skeleton: Skeleton, world_rot: ArrayLike, max_step_rad: float) -> FloatArray:
    """World rotations with each roll-free bone's roll changing by at most ``max_step_rad``
    per frame.

    The output's roll follows the input's wherever the input turns by less than the
    step; after a larger turn it catches up by ``max_step_rad`` a frame, the shorter
    way round. Only roll-free bones turn (about their own axis), and every other joint
    keeps its world rotation, so no joint moves. NaN frames are passed through and
    restart the follow. `RollLimiter` does the same over a recording in chunks.

    Parameters
    ----------
    skeleton : Skeleton
    world_rot : (T, J, 3, 3) array
    max_step_rad : float
        Positive.
    """
    return RollLimiter(skeleton, max_step_rad)(world_rot)


class RollLimiter:
    """`limit_roll` over a recording given in consecutive chunks of frames: calling it on
    each chunk in turn gives the chunks of ``limit_roll`` on the whole recording (the
    previous chunk's last input frame and roll offsets are carried over).

    Parameters
    ----------
    skeleton : Skeleton
    max_step_rad : float
        Positive.
    """

    def __init__(self, skeleton: Skeleton, max_step_rad: float) -> None:
        if not max_step_rad > 0:
            raise ShapeError(f"max_step_rad: expected a positive angle, found {max_step_rad!r}")
        self.skeleton = skeleton
        self.max_step_rad = float(max_step_rad)
        self._last: FloatArray | None = None  # the previous chunk's last input frame
        self._offset: FloatArray | None = None  # input roll - output roll there

    def __call__(self, world_rot: ArrayLike) -> FloatArray:
        """The next chunk (T, J, 3, 3) of world rotations, limited."""
        skeleton, max_step_rad = self.skeleton, self.max_step_rad
        rot = np.array(_check(skeleton, world_rot), copy=True)
        if rot.shape[0] == 0:
            return rot
        prev = self._last
        self._last = rot[-1].copy()
        full = rot if prev is None else np.concatenate([prev[None], rot])
        bones, steps = roll_steps(skeleton, full)
        if steps.shape[0] == 0 or bones.size == 0:
            return rot
        # output roll = input roll - offset; the output's step from its previous frame to
        # the input is the input's step plus the previous offset (both about the same axis)
        offsets = np.zeros((rot.shape[0], bones.size))
        offset = np.zeros(bones.size) if self._offset is None else self._offset
        two_pi = 2.0 * np.pi
        first = 1 if prev is None else 0  # the chunk's frame that steps[0] leads to
        for t, step in enumerate(steps, start=first):
            wanted = step + offset
            wanted = wanted - two_pi * np.round(wanted / two_pi)
            offset = np.where(
                np.isfinite(wanted), wanted - np.clip(wanted, -max_step_rad, max_step_rad), 0.0
            )
            offsets[t] = offset
        self._offset = offset
        moved = np.flatnonzero(np.any(offsets != 0.0, axis=1))
        if moved.size:
            axes = _axes(skeleton, rot[moved], bones)
            turn = matrix_from_axis_angle(axes, -offsets[moved])
            rot[np.ix_(moved, bones)] = np.einsum(
                "tbij,tbjk->tbik", turn, rot[np.ix_(moved, bones)]
            )
        return rot


__all__ = ["RollLimiter", "limit_roll", "roll_free_bones", "roll_steps"]
