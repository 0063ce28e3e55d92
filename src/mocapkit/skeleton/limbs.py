"""Limbs, spine and feet of any skeleton, found through its canonical joint names.

Generic code (IK, trackers, balance, refinement, evaluation) never names a preset's own
joints (``l_humerus``, ``l_shoulder``, ...): it asks this module for the joints and DoFs
of an arm, a leg, the spine or the feet, which are derived from `Skeleton.canonical`
and the kinematic tree. So the same code runs on ``zhang21``, ``azad14`` and
``upper_stick``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import UnknownNameError, unknown_name
from mocapkit.skeleton.derived import PerSkeleton, readonly_copy
from mocapkit.skeleton.model import PRISMATIC, REVOLUTE, Skeleton

IntArray = NDArray[np.int64]

SIDES: tuple[str, ...] = ("left", "right")
LIMB_KINDS: tuple[str, ...] = ("arm", "leg")

#: Canonical joints of each limb kind, proximal to distal.
_LIMB_CANONICAL: dict[str, tuple[str, str, str]] = {
    "arm": ("shoulder", "elbow", "wrist"),
    "leg": ("hip", "knee", "ankle"),
}


@dataclass(frozen=True)
class Limb:
    """One arm or leg of a skeleton: joint indices and DoFs, found by canonical names.

    Attributes
    ----------
    name : str
        ``"left_arm"``, ``"right_leg"``, ...
    side : {"left", "right"}
    kind : {"arm", "leg"}
    parent : int
        Joint the limb hangs from (the parent of the ``root`` joint: the thorax or
        clavicle for an arm, the pelvis for a leg).
    root, middle, end : int
        Joints that hold the canonical shoulder/hip, elbow/knee and wrist/ankle.
    tip : int
        The first child of ``end`` (hand or foot end site), or ``-1`` where it has none.
    dofs : ndarray of int, shape (K,)
        Rotational DoFs of the joints from ``root`` to ``end`` inclusive (shoulder and
        elbow for ``zhang21``'s arm; a ball shoulder and the elbow for ``azad14``).
    translation_dofs : ndarray of int, shape (P,)
        Prismatic DoFs on the same joints (``azad14``'s adaptive shoulder offset).
    chain : ndarray of int
        All joints from ``root`` to ``end`` inclusive, in kinematic order.
    """

    name: str
    side: str
    kind: str
    parent: int
    root: int
    middle: int
    end: int
    tip: int
    dofs: IntArray
    translation_dofs: IntArray
    chain: IntArray

    @property
    def joints(self) -> tuple[int, int, int]:
        """``(root, middle, end)`` joint indices."""
        return (self.root, self.middle, self.end)


def _canonical_joint(skeleton: Skeleton, cname: str, what: str) -> int:
    if cname not in skeleton.canonical:
        raise unknown_name(
            "canonical joint", cname, skeleton.canonical, f"skeleton {skeleton.name!r} ({what})"
        )
    return skeleton.joint_index(skeleton.canonical[cname][0])


def _path(parents: IntArray, top: int, bottom: int) -> IntArray:
    """Joints from ``top`` down to ``bottom`` inclusive; empty if ``top`` is no ancestor."""
    out = [bottom]
    j = bottom
    while j != top:
        j = int(parents[j])
        if j < 0:
            return np.zeros(0, dtype=np.int64)
        out.append(j)
    return np.asarray(out[::-1], dtype=np.int64)


#: Limbs found so far, per skeleton; their index arrays are read-only, as every caller
#: shares them.
_LIMBS: PerSkeleton[Limb] = PerSkeleton()


def limb(skeleton: Skeleton, name: str) -> Limb:
    """The arm or leg ``name`` (``"left_arm"``, ``"right_leg"``, ...) of a skeleton.

    Cached per skeleton (immutable): trackers ask for their limbs several times a frame.

    Raises
    ------
    UnknownNameError
        For a name that is not ``{side}_{kind}``, or a skeleton whose canonical joints
        lack this limb (``upper_stick`` has no legs).
    """
    return _LIMBS.get(skeleton, name, _find_limb, name)


def _find_limb(skeleton: Skeleton, name: str) -> Limb:
    valid = [f"{s}_{k}" for s in SIDES for k in LIMB_KINDS]
    if name not in valid:
        raise unknown_name("limb", name, valid)
    side, kind = name.split("_")
    root_c, mid_c, end_c = (f"{side}_{c}" for c in _LIMB_CANONICAL[kind])
    root = _canonical_joint(skeleton, root_c, name)
    middle = _canonical_joint(skeleton, mid_c, name)
    end = _canonical_joint(skeleton, end_c, name)
    chain = _path(skeleton.parents, root, end)
    if chain.size == 0 or middle not in chain:
        raise UnknownNameError(
            f"skeleton {skeleton.name!r}: canonical {root_c}, {mid_c}, {end_c} do not lie on "
            f"one chain (joints {skeleton.joint_names[root]!r}, "
            f"{skeleton.joint_names[middle]!r}, {skeleton.joint_names[end]!r})"
        )
    on_chain = np.isin(skeleton.dof_joint, chain)
    prismatic = skeleton.dof_kind == PRISMATIC
    children = skeleton.children(end)
    return Limb(
        name=name,
        side=side,
        kind=kind,
        parent=int(skeleton.parents[root]),
        root=root,
        middle=middle,
        end=end,
        tip=int(children[0]) if children.size else -1,
        dofs=readonly_copy(np.flatnonzero(on_chain & ~prismatic), np.int64),
        translation_dofs=readonly_copy(np.flatnonzero(on_chain & prismatic), np.int64),
        chain=readonly_copy(chain, np.int64),
    )


def arm(skeleton: Skeleton, side: str) -> Limb:
    """The ``"left"`` or ``"right"`` arm; see `limb`."""
    if side not in SIDES:
        raise unknown_name("side", side, SIDES)
    return limb(skeleton, f"{side}_arm")


def leg(skeleton: Skeleton, side: str) -> Limb:
    """The ``"left"`` or ``"right"`` leg; see `limb`."""
    if side not in SIDES:
        raise unknown_name("side", side, SIDES)
    return limb(skeleton, f"{side}_leg")


def has_limb(skeleton: Skeleton, name: str) -> bool:
    """Whether the skeleton's canonical joints provide the limb ``name``."""
    try:
        limb(skeleton, name)
    except UnknownNameError:
        return False
    return True


def head_joint(skeleton: Skeleton) -> int:
    """Joint holding the canonical head point."""
    return _canonical_joint(skeleton, "head", "head")


def thorax_joint(skeleton: Skeleton) -> int:
    """The chest's joint: the lowest one carrying the canonical neck and both shoulders
    (``spine3`` on ``zhang21``, where the neck and the clavicles hang).

    Raises
    ------
    UnknownNameError
        A skeleton without a canonical neck or shoulder.
    """
    ends = [
        _canonical_joint(skeleton, c, "thorax") for c in ("neck", "left_shoulder", "right_shoulder")
    ]
    above = skeleton.ancestors_mask()
    j = ends[0]
    while not all(above[j, e] for e in ends):
        j = int(skeleton.parents[j])
    return j


def head_dofs(skeleton: Skeleton) -> IntArray:
    """DoFs that turn the head and nothing of the arms: those of the joints from the
    canonical neck down to the head joint, less the joints the arms also hang from.

    For ``zhang21`` these are the neck joint's flexion, lateral bend (and rotation, as an
    option); ``azad14``'s canonical neck is its rigid torso, which carries the arms, and
    its head has no DoF of its own: none. Empty where the skeleton has no canonical neck
    or head.
    """
    if "neck" not in skeleton.canonical or "head" not in skeleton.canonical:
        return np.zeros(0, dtype=np.int64)
    neck = _canonical_joint(skeleton, "neck", "head")
    path = _path(skeleton.parents, neck, head_joint(skeleton))
    carriers: set[int] = set()
    for lmb in limbs_present(skeleton, "arm"):
        j = lmb.root
        while j >= 0:
            carriers.add(j)
            j = int(skeleton.parents[j])
    joints = [j for j in path.tolist() if j not in carriers]
    return np.flatnonzero(np.isin(skeleton.dof_joint, joints)).astype(np.int64)


def part_dofs(skeleton: Skeleton, part: str) -> IntArray:
    """DoFs that pose a body part whose markers or detections went unseen: ``"head"``
    (`head_dofs`), or an arm or leg (``"left_arm"``, ...) with the joints that carry it
    alone above it (a clavicle; a hip joint above a femur) and every joint below it:
    what the part's observations would pose. Empty where the skeleton lacks the part.
    """
    if part == "head":
        return head_dofs(skeleton)
    if not has_limb(skeleton, part):
        return np.zeros(0, dtype=np.int64)
    lmb = limb(skeleton, part)
    parents = skeleton.parents
    n_children = np.bincount(parents[parents >= 0], minlength=skeleton.n_joints)
    top = int(lmb.root)
    while parents[top] > 0 and n_children[parents[top]] == 1:
        top = int(parents[top])
    below = {top}
    for j in range(top + 1, skeleton.n_joints):
        if int(parents[j]) in below:
            below.add(j)
    carried = np.flatnonzero(np.isin(skeleton.dof_joint, sorted(below)))
    return np.union1d(carried, lmb.translation_dofs).astype(np.int64)


def spine_joints(skeleton: Skeleton) -> IntArray:
    """Joints strictly between the canonical pelvis and neck, pelvis to neck order.

    For ``zhang21`` these are ``spine1..spine3``; a model whose trunk is one rigid
    segment without a canonical pelvis (``azad14``) has none.
    """
    if "pelvis" not in skeleton.canonical:
        return np.zeros(0, dtype=np.int64)
    pelvis = _canonical_joint(skeleton, "pelvis", "spine")
    neck = _canonical_joint(skeleton, "neck", "spine")
    path = _path(skeleton.parents, pelvis, neck)
    if path.size == 0:
        raise UnknownNameError(
            f"skeleton {skeleton.name!r}: canonical neck ({skeleton.joint_names[neck]!r}) does "
            f"not hang below the canonical pelvis ({skeleton.joint_names[pelvis]!r})"
        )
    return path[1:-1]


def spine_dofs(skeleton: Skeleton) -> IntArray:
    """Rotational DoFs of the spine joints (see `spine_joints`), pelvis to neck order."""
    joints = spine_joints(skeleton)
    mask = np.isin(skeleton.dof_joint, joints) & (skeleton.dof_kind != PRISMATIC)
    return np.flatnonzero(mask).astype(np.int64)


def foot_joints(skeleton: Skeleton, side: str) -> IntArray:
    """The canonical ankle joint of one side and all joints below it (foot, toe, end sites)."""
    return skeleton.subtree(leg(skeleton, side).end)


def limbs_present(skeleton: Skeleton, kind: str) -> tuple[Limb, ...]:
    """The arms or legs (``kind`` ``"arm"`` or ``"leg"``) the skeleton has, left first.

    Empty for a model without them (``azad14`` and ``upper_stick`` have no legs).
    """
    if kind not in LIMB_KINDS:
        raise unknown_name("limb kind", kind, LIMB_KINDS)
    return tuple(
        limb(skeleton, f"{side}_{kind}") for side in SIDES if has_limb(skeleton, f"{side}_{kind}")
    )


def ankle_joints(skeleton: Skeleton) -> IntArray:
    """Canonical ankle joints of the legs the skeleton has (left first; empty without legs)."""
    return np.asarray([lg.end for lg in limbs_present(skeleton, "leg")], dtype=np.int64)


def limb_length_mm(skeleton: Skeleton, lmb: Limb, *, to_tip: bool = False) -> float:
    """Rest length of a limb along its chain (mm).

    The segments from the root joint to the end joint (shoulder to wrist, hip to
    ankle); with ``to_tip`` also the end joint's own segment (the hand, the foot).
    For ``zhang21``: left arm 300 + 350 (+ 80 hand) mm, left leg 386 + 550 mm.
    """
    lengths = skeleton.bone_length_mm
    joints = lmb.chain if to_tip else lmb.chain[:-1]
    total = 0.0
    for j in joints:
        total += float(lengths[j])
    return total


def flexion_dofs(skeleton: Skeleton, lmb: Limb) -> tuple[IntArray, NDArray[np.float64]]:
    """Flexion hinge(s) of a limb's middle joint (elbow, knee) and the sign of flexion.

    A model may flex its elbow either way round: ``zhang21`` has ``[0, 150] deg`` about
    ``+x``, ``azad14`` has ``theta_4 in [-180, 0] deg`` about ``-x`` (Azad 2008). Both
    bend the forearm forward from the straight pose; what they share is that a flexion
    hinge stops at full extension (0), so its range lies on one side of zero. So the
    flexion DoFs are the revolute DoFs of the middle joint whose range lies on one side
    of zero (a two-sided hinge, such as a pronation axis, is not a flexion), and the
    sign is the side the range lies on (+1 for ``[0, x]``, -1 for ``[x, 0]``). Where a
    range is ``[0, 0]`` the sign is +1. A ball elbow has none.

    Returns
    -------
    dofs : ndarray of int, shape (F,)
    signs : ndarray of float, shape (F,)
        +1 or -1: flexing by ``a`` rad sets the DoF to ``sign * a``.
    """
    on_joint = skeleton.dof_joint == lmb.middle
    hinge = on_joint & (skeleton.dof_kind == REVOLUTE)
    one_sided = (skeleton.lower >= 0.0) | (skeleton.upper <= 0.0)
    dofs = np.flatnonzero(hinge & one_sided).astype(np.int64)
    signs = np.where(skeleton.lower[dofs] >= 0.0, 1.0, -1.0)
    return dofs, signs


def dof_names_of(skeleton: Skeleton, dofs: IntArray) -> tuple[str, ...]:
    """Names of DoF indices, for messages and reports."""
    return tuple(skeleton.dof_names[int(d)] for d in dofs)


def vertical_root_dof(skeleton: Skeleton) -> int:
    """The root joint's prismatic DoF along the world vertical (+z at ``q = 0``).

    The root's frame is parallel to the world at ``q = 0`` and its prismatic DoFs come
    before its rotations, so the DoF whose axis is +z moves the whole body up and down
    (``root_tz`` of ``zhang21``; errata Z13).

    Raises
    ------
    UnknownNameError
        A skeleton whose root has no vertical translation.
    """
    mask = (
        (skeleton.dof_joint == 0)
        & (skeleton.dof_kind == PRISMATIC)
        & np.isclose(skeleton.dof_axis[:, 2], 1.0)
    )
    found = np.flatnonzero(mask)
    if found.size == 0:
        raise UnknownNameError(
            f"skeleton {skeleton.name!r}: its root joint {skeleton.joint_names[0]!r} has no "
            f"prismatic DoF along +z (the vertical root translation)"
        )
    return int(found[0])
