"""IK effectors: named points on the skeleton that targets pull (Zhang et al. 2011 §4)."""

from __future__ import annotations

from dataclasses import dataclass

from mocapkit.errors import unknown_name
from mocapkit.skeleton import limbs
from mocapkit.skeleton.model import Skeleton

#: Canonical point of each effector name (Zhang et al. 2011 §4: head, hands, feet).
EFFECTOR_CANONICAL: dict[str, str] = {
    "head": "head",
    "left_hand": "left_wrist",
    "right_hand": "right_wrist",
    "left_foot": "left_ankle",
    "right_foot": "right_ankle",
}


@dataclass(frozen=True)
class Effector:
    """A point fixed to a joint that IK drives to a target.

    Parameters
    ----------
    name : str
        Effector name (marker-set name, e.g. ``"left_hand"``).
    joint : str
        Joint carrying the point.
    point_mm : tuple of 3 float
        The point in that joint's frame (mm). For a marker-driven effector this is
        the marker-to-joint offset: the marker set sits at this point.
    """

    name: str
    joint: str
    point_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)


def canonical_effector(skeleton: Skeleton, name: str) -> Effector:
    """The effector ``name`` (one of `EFFECTOR_CANONICAL`) at its canonical point.

    ``head`` is the canonical head point, ``left_hand``/``right_hand`` the wrists,
    ``left_foot``/``right_foot`` the ankles (Zhang et al. 2011 §4: head, hands, feet).

    Raises
    ------
    UnknownNameError
        For another name, or a skeleton without that canonical point (no legs).
    """
    if name not in EFFECTOR_CANONICAL:
        raise unknown_name("effector", name, EFFECTOR_CANONICAL)
    cname = EFFECTOR_CANONICAL[name]
    if cname not in skeleton.canonical:
        raise unknown_name(
            "canonical joint", cname, skeleton.canonical, f"skeleton {skeleton.name!r} ({name})"
        )
    joint, point = skeleton.canonical[cname]
    return Effector(name, joint, (float(point[0]), float(point[1]), float(point[2])))


def default_effectors(skeleton: Skeleton) -> tuple[Effector, ...]:
    """The effectors of the paper: head centre, the wrists and the ankles the skeleton has.

    Five on ``zhang21``; head and both hands on an upper-body model (``azad14``).
    """
    names = ["head"]
    names += [f"{arm.side}_hand" for arm in limbs.limbs_present(skeleton, "arm")]
    names += [f"{lg.side}_foot" for lg in limbs.limbs_present(skeleton, "leg")]
    return tuple(canonical_effector(skeleton, n) for n in names)


__all__ = ["EFFECTOR_CANONICAL", "Effector", "canonical_effector", "default_effectors"]
