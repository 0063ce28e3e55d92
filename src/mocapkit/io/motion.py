"""The `Motion` result type: a skeleton, its joint parameters over time and the canonical joints.

A pure data type: files are read and written by the format modules
(`mocapkit.io.bvh`, `mocapkit.io.asf_amc`, `mocapkit.io.motion_npz`,
`mocapkit.io.joints_csv`, `mocapkit.io.trc`) and chosen by suffix in
`mocapkit.io.motion_files`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ShapeError, unknown_name
from mocapkit.skeleton.kinematics import canonical_positions
from mocapkit.skeleton.model import CANONICAL_JOINTS, Skeleton

FloatArray = NDArray[np.float64]


def _readonly(a: ArrayLike, dtype: Any = float) -> NDArray[Any]:
    arr = np.array(a, dtype=dtype, copy=True)
    arr.setflags(write=False)
    return arr


#: Frames whose canonical joints `Motion.from_q` computes at a time.
_FK_CHUNK = 512


@dataclass(frozen=True, eq=False)
class Motion:
    """A motion clip: a skeleton, its joint parameters over time and the canonical joints.

    Parameters
    ----------
    skeleton : Skeleton
    time_s : ndarray, shape (T,)
        Sample times (s), non-decreasing.
    q : ndarray, shape (T, D)
        Joint parameters (rad, mm); a row of NaN marks a frame without a pose.
    joint_names : tuple of str, length K
        Canonical joints provided, in canonical order.
    joints_mm : ndarray, shape (T, K, 3)
        Canonical joint positions in the world frame (mm); NaN where no pose.
    source : str
        Where the motion came from (file path and reader notes).
    """

    skeleton: Skeleton
    time_s: FloatArray
    q: FloatArray
    joint_names: tuple[str, ...]
    joints_mm: FloatArray
    source: str = ""

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "time_s", _readonly(self.time_s))
        set_(self, "q", _readonly(self.q))
        set_(self, "joints_mm", _readonly(self.joints_mm))
        set_(self, "joint_names", tuple(self.joint_names))
        t, d, k = self.time_s.shape, self.skeleton.n_dofs, len(self.joint_names)
        if self.time_s.ndim != 1:
            raise ShapeError(f"Motion.time_s: expected shape (T,), found {self.time_s.shape}")
        n = t[0]
        if self.q.shape != (n, d):
            raise ShapeError(f"Motion.q: expected shape ({n}, {d}), found {self.q.shape}")
        if self.joints_mm.shape != (n, k, 3):
            raise ShapeError(
                f"Motion.joints_mm: expected shape ({n}, {k}, 3), found {self.joints_mm.shape}"
            )
        unknown = [c for c in self.joint_names if c not in CANONICAL_JOINTS]
        if unknown:
            raise ShapeError(f"Motion.joint_names: not canonical joint names: {unknown}")

    @classmethod
    def from_q(
        cls, skeleton: Skeleton, time_s: ArrayLike, q: ArrayLike, source: str = ""
    ) -> Motion:
        """Build a motion from joint parameters; canonical joints come from forward kinematics.

        Parameters
        ----------
        skeleton : Skeleton
        time_s : array_like, shape (T,)
        q : array_like, shape (T, D)
            Rows that contain NaN are frames without a pose (their joints are NaN).
        source : str
        """
        qa = np.asarray(q, dtype=float)
        ta = np.asarray(time_s, dtype=float)
        if qa.ndim != 2 or qa.shape[1] != skeleton.n_dofs or ta.shape != (qa.shape[0],):
            raise ShapeError(
                f"Motion.from_q: expected time_s (T,) and q (T, {skeleton.n_dofs}), "
                f"found {ta.shape} and {qa.shape}"
            )
        names = skeleton.canonical_names
        joints = np.full((qa.shape[0], len(names), 3), np.nan)
        valid = np.flatnonzero(~np.any(np.isnan(qa), axis=1))
        if names:
            # in chunks: forward kinematics holds every joint's transform (J x 128 bytes
            # a frame), the joints are a few of them
            for a in range(0, valid.size, _FK_CHUNK):
                rows = valid[a : a + _FK_CHUNK]
                joints[rows] = canonical_positions(skeleton, qa[rows], names)
        return cls(skeleton, ta, qa, names, joints, source)

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.time_s.shape[0])

    def joint(self, name: str) -> FloatArray:
        """Trajectory (T, 3) of one canonical joint (mm, world)."""
        if name not in self.joint_names:
            raise unknown_name("canonical joint", name, self.joint_names, f"motion {self.source!r}")
        return self.joints_mm[:, self.joint_names.index(name)]


__all__ = ["Motion"]
