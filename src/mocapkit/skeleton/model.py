"""The body model: a frozen `Skeleton` describing joints, degrees of freedom and body segments.

The model holds no pose. A pose is a plain array of joint parameters ``q`` with
shape ``(..., D)`` (radians for rotations, mm for translations), so that a whole
sequence or a cloud of particles goes through kinematics in one call
(see :mod:`mocapkit.skeleton.kinematics`).

Kinematic convention
--------------------
Joint ``j`` has a frame whose origin sits at ``offsets_mm[j]`` in its parent's frame.
Its transform relative to the parent is::

    parent_from_joint = T(offset_j) @ T(sum of prismatic DoFs) @ R_1(q_1) @ R_2(q_2) @ ...

where the rotations are taken in the order the DoFs are listed: a revolute DoF is a
rotation about its ``dof_axis`` (a unit vector in the joint frame); a ball joint is
three consecutive ``BALL`` DoFs holding a rotation vector (axis times angle)
expressed in the joint frame. With ``q = 0`` every frame is parallel to the world.

Each joint owns the body segment (bone) that starts at it and ends at
``bone_end_mm[j]`` in its frame; mass, centre of mass and cone radii belong to
that segment. Joints without DoFs model fixed bones and end sites.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import ShapeError, unknown_name

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

REVOLUTE = 0
PRISMATIC = 1
BALL = 2
DOF_KINDS = {"revolute": REVOLUTE, "prismatic": PRISMATIC, "ball": BALL}

#: Canonical joint vocabulary used by every output and by evaluation.
CANONICAL_JOINTS: tuple[str, ...] = (
    "head",
    "neck",
    "pelvis",
    "left_shoulder",
    "left_elbow",
    "left_wrist",
    "right_shoulder",
    "right_elbow",
    "right_wrist",
    "left_hip",
    "left_knee",
    "left_ankle",
    "right_hip",
    "right_knee",
    "right_ankle",
)

#: The upper-body subset (what the hybrid and stereo trackers estimate from arms and head).
UPPER_BODY_JOINTS: tuple[str, ...] = CANONICAL_JOINTS[:9]

#: Body segments a lab measures on a subject, as (proximal, distal) canonical joints.
#: ``session.json`` gives subject bone lengths under these names.
CANONICAL_SEGMENTS: dict[str, tuple[str, str]] = {
    "trunk": ("pelvis", "neck"),
    "head": ("neck", "head"),
    "left_clavicle": ("neck", "left_shoulder"),
    "right_clavicle": ("neck", "right_shoulder"),
    "left_upper_arm": ("left_shoulder", "left_elbow"),
    "right_upper_arm": ("right_shoulder", "right_elbow"),
    "left_forearm": ("left_elbow", "left_wrist"),
    "right_forearm": ("right_elbow", "right_wrist"),
    "left_pelvis": ("pelvis", "left_hip"),
    "right_pelvis": ("pelvis", "right_hip"),
    "left_thigh": ("left_hip", "left_knee"),
    "right_thigh": ("right_hip", "right_knee"),
    "left_shank": ("left_knee", "left_ankle"),
    "right_shank": ("right_knee", "right_ankle"),
}

#: Segments whose rest direction is the same in any standing rest pose (a T-pose and the
#: anatomical position differ only in the limbs), so their rest vectors can be given.
TRUNK_SEGMENTS: tuple[str, ...] = (
    "trunk",
    "head",
    "left_clavicle",
    "right_clavicle",
    "left_pelvis",
    "right_pelvis",
)


def _frozen(a: Any, dtype: Any, shape: tuple[int, ...] | None, what: str) -> NDArray[Any]:
    arr = np.array(a, dtype=dtype, copy=True)
    if shape is not None and arr.shape != shape:
        raise ShapeError(f"Skeleton.{what}: expected shape {shape}, found {arr.shape}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Skeleton:
    """An articulated body model (immutable).

    Parameters
    ----------
    name : str
        Preset or source name.
    joint_names : sequence of str, length J
    parents : array_like of int, shape (J,)
        Parent index of each joint, ``-1`` for the root; topological order
        (``parents[j] < j``), exactly one root at index 0.
    offsets_mm : array_like, shape (J, 3)
        Joint origin in the parent frame at ``q = 0``.
    dof_joint : array_like of int, shape (D,)
        Joint each DoF belongs to; non-decreasing; within a joint the prismatic
        DoFs come first, then the rotations in product order.
    dof_kind : array_like of int, shape (D,)
        ``REVOLUTE``, ``PRISMATIC`` or ``BALL``.
    dof_axis : array_like, shape (D, 3)
        Unit axis in the joint frame (for ``BALL``: the three basis vectors).
    dof_names : sequence of str, length D
    lower, upper : array_like, shape (D,)
        Limits in radians (revolute, ball components) or mm (prismatic); ``inf`` for none.
    bone_end_mm : array_like, shape (J, 3)
        End of the segment owned by each joint, in the joint frame.
    mass_kg : array_like, shape (J,)
        Segment masses.
    com_fraction : array_like, shape (J,)
        Centre of mass of each segment as a fraction of the way to ``bone_end_mm``.
    radii_mm : array_like, shape (J, 2)
        Proximal and distal radius of the cone that fleshes out each segment.
    canonical : mapping
        Canonical joint name -> ``(joint name, point in that joint's frame, mm)``.
    """

    name: str
    joint_names: tuple[str, ...]
    parents: IntArray
    offsets_mm: FloatArray
    dof_joint: IntArray
    dof_kind: IntArray
    dof_axis: FloatArray
    dof_names: tuple[str, ...]
    lower: FloatArray
    upper: FloatArray
    bone_end_mm: FloatArray
    mass_kg: FloatArray
    com_fraction: FloatArray
    radii_mm: FloatArray
    canonical: Mapping[str, tuple[str, tuple[float, float, float]]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        names = tuple(self.joint_names)
        n = len(names)
        if len(set(names)) != n:
            dup = sorted({x for x in names if names.count(x) > 1})
            raise ShapeError(f"Skeleton {self.name!r}: duplicate joint names {dup}")
        set_ = object.__setattr__
        set_(self, "joint_names", names)
        set_(self, "parents", _frozen(self.parents, np.int64, (n,), "parents"))
        set_(self, "offsets_mm", _frozen(self.offsets_mm, float, (n, 3), "offsets_mm"))
        d = len(self.dof_names)
        set_(self, "dof_names", tuple(self.dof_names))
        set_(self, "dof_joint", _frozen(self.dof_joint, np.int64, (d,), "dof_joint"))
        set_(self, "dof_kind", _frozen(self.dof_kind, np.int64, (d,), "dof_kind"))
        set_(
            self, "dof_axis", _frozen(np.reshape(self.dof_axis, (d, 3)), float, (d, 3), "dof_axis")
        )
        set_(self, "lower", _frozen(self.lower, float, (d,), "lower"))
        set_(self, "upper", _frozen(self.upper, float, (d,), "upper"))
        set_(self, "bone_end_mm", _frozen(self.bone_end_mm, float, (n, 3), "bone_end_mm"))
        set_(self, "mass_kg", _frozen(self.mass_kg, float, (n,), "mass_kg"))
        set_(self, "com_fraction", _frozen(self.com_fraction, float, (n,), "com_fraction"))
        set_(self, "radii_mm", _frozen(self.radii_mm, float, (n, 2), "radii_mm"))
        set_(self, "canonical", dict(self.canonical))
        self._validate()

    def _validate(self) -> None:
        p = self.parents
        if p[0] != -1 or np.any(p[1:] < 0) or np.any(p[1:] >= np.arange(1, len(p))):
            raise ShapeError(
                f"Skeleton {self.name!r}: parents must be topologically ordered with a single "
                f"root at index 0 (parents[0] == -1, 0 <= parents[j] < j); found {p.tolist()}"
            )
        if np.any(np.diff(self.dof_joint) < 0):
            raise ShapeError(f"Skeleton {self.name!r}: dof_joint must be non-decreasing")
        if self.n_dofs and (self.dof_joint.min() < 0 or self.dof_joint.max() >= self.n_joints):
            raise ShapeError(f"Skeleton {self.name!r}: dof_joint out of range")
        if not np.all(np.isin(self.dof_kind, (REVOLUTE, PRISMATIC, BALL))):
            raise ShapeError(f"Skeleton {self.name!r}: unknown dof_kind in {self.dof_kind}")
        norms = np.linalg.norm(self.dof_axis, axis=1)
        if not np.allclose(norms, 1.0, atol=1e-9):
            raise ShapeError(f"Skeleton {self.name!r}: DoF axes must be unit vectors")
        if np.any(self.lower > self.upper):
            bad = [self.dof_names[i] for i in np.flatnonzero(self.lower > self.upper)]
            raise ShapeError(f"Skeleton {self.name!r}: lower > upper for DoFs {bad}")
        for j in range(self.n_joints):
            kinds = self.dof_kind[self.dof_joint == j]
            n_ball = int(np.sum(kinds == BALL))
            if n_ball not in (0, 3):
                raise ShapeError(
                    f"Skeleton {self.name!r}: joint {self.joint_names[j]!r} has {n_ball} ball "
                    f"DoFs; a ball joint needs exactly 3"
                )
            if n_ball and np.any(kinds == REVOLUTE):
                raise ShapeError(
                    f"Skeleton {self.name!r}: joint {self.joint_names[j]!r} mixes ball and "
                    f"revolute DoFs"
                )
            rot_seen = False
            for k in kinds:
                if k == PRISMATIC and rot_seen:
                    raise ShapeError(
                        f"Skeleton {self.name!r}: joint {self.joint_names[j]!r} lists a "
                        f"prismatic DoF after a rotation; prismatic DoFs come first"
                    )
                rot_seen = rot_seen or k != PRISMATIC
        for cname, (jname, _point) in self.canonical.items():
            if jname not in self.joint_names:
                raise unknown_name("joint", jname, self.joint_names, f"canonical[{cname!r}]")

    # ------------------------------------------------------------ sizes and lookups

    @property
    def n_joints(self) -> int:
        """Number of joints J (including fixed joints and end sites)."""
        return len(self.joint_names)

    @property
    def n_dofs(self) -> int:
        """Number of joint parameters D."""
        return len(self.dof_names)

    @property
    def total_mass_kg(self) -> float:
        """Sum of segment masses."""
        return float(self.mass_kg.sum())

    def joint_index(self, name: str) -> int:
        """Index of a joint by name; raises `UnknownNameError` listing valid names."""
        try:
            return self.joint_names.index(name)
        except ValueError:
            raise unknown_name("joint", name, self.joint_names, f"skeleton {self.name!r}") from None

    def dof_index(self, name: str) -> int:
        """Index of a DoF by name; raises `UnknownNameError` listing valid names."""
        try:
            return self.dof_names.index(name)
        except ValueError:
            raise unknown_name("DoF", name, self.dof_names, f"skeleton {self.name!r}") from None

    def dofs_of_joint(self, joint: int | str) -> IntArray:
        """Indices of the DoFs of one joint."""
        j = self.joint_index(joint) if isinstance(joint, str) else int(joint)
        return np.flatnonzero(self.dof_joint == j)

    def children(self, joint: int) -> IntArray:
        """Indices of the direct children of a joint."""
        return np.flatnonzero(self.parents == joint)

    def subtree(self, joint: int) -> IntArray:
        """Indices of the joint and all its descendants (topological order)."""
        inside = np.zeros(self.n_joints, dtype=bool)
        inside[joint] = True
        for j in range(joint + 1, self.n_joints):
            inside[j] = inside[self.parents[j]]
        return np.flatnonzero(inside)

    def ancestors_mask(self) -> NDArray[np.bool_]:
        """``A[a, j]`` is true when joint ``a`` is ``j`` or one of its ancestors. Shape (J, J)."""
        a = np.eye(self.n_joints, dtype=bool)
        for j in range(1, self.n_joints):
            a[:, j] |= a[:, self.parents[j]]
        return a

    @property
    def bone_length_mm(self) -> FloatArray:
        """Length of each joint's segment, shape (J,)."""
        return np.linalg.norm(self.bone_end_mm, axis=1)

    @property
    def canonical_names(self) -> tuple[str, ...]:
        """Canonical joints this skeleton provides, in canonical order."""
        return tuple(c for c in CANONICAL_JOINTS if c in self.canonical)

    def canonical_points(self, names: Sequence[str] | None = None) -> tuple[IntArray, FloatArray]:
        """Joint indices (K,) and points in those joints' frames (K, 3) for canonical names.

        Parameters
        ----------
        names : sequence of str, optional
            Canonical names; defaults to all this skeleton provides.
        """
        names = self.canonical_names if names is None else tuple(names)
        idx = np.empty(len(names), dtype=np.int64)
        pts = np.empty((len(names), 3))
        for k, cname in enumerate(names):
            if cname not in self.canonical:
                raise unknown_name(
                    "canonical joint", cname, self.canonical, f"skeleton {self.name!r}"
                )
            jname, point = self.canonical[cname]
            idx[k] = self.joint_index(jname)
            pts[k] = point
        return idx, pts

    def zero_pose(self) -> FloatArray:
        """``q = 0`` clipped into the limits, shape (D,)."""
        return np.clip(np.zeros(self.n_dofs), self.lower, self.upper)

    def clip_to_limits(self, q: NDArray[Any]) -> FloatArray:
        """Clip joint parameters (..., D) into ``[lower, upper]``."""
        q = np.asarray(q, dtype=float)
        self.check_q(q)
        return np.clip(q, self.lower, self.upper)

    def check_q(self, q: NDArray[Any], what: str = "q") -> None:
        """Raise `ShapeError` unless ``q`` has shape (..., D) and is finite."""
        if q.ndim < 1 or q.shape[-1] != self.n_dofs:
            raise ShapeError(
                f"{what}: expected joint parameters of shape (..., {self.n_dofs}) for skeleton "
                f"{self.name!r}, found {q.shape}"
            )
        if not np.isfinite(q).all():  # the method: every FK and solve checks its pose
            raise ShapeError(f"{what}: joint parameters contain NaN or inf")

    def replace(self, **changes: Any) -> Skeleton:
        """A copy with some fields replaced (the model itself is immutable)."""
        fields = {f: getattr(self, f) for f in self.__dataclass_fields__}
        fields.update(changes)
        return Skeleton(**fields)
