"""Per-DoF cost weights of the weighted Jacobian (recipe Z, errata Z3, Z8b)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import ShapeError
from mocapkit.ik.secondary import carried_mass_planted, planted_feet
from mocapkit.skeleton import limbs
from mocapkit.skeleton.model import PRISMATIC, Skeleton

FloatArray = NDArray[np.float64]


def arm_length_mm(skeleton: Skeleton) -> float:
    """Rest length of the left arm, shoulder to the end of the hand segment (mm).

    Upper arm + forearm + hand segments of `mocapkit.skeleton.limbs.arm` (730 mm for
    Table 1); 0.1 of it is the default target clamp ``D_max``.
    """
    if not limbs.has_limb(skeleton, "left_arm"):
        raise ShapeError(
            f"skeleton {skeleton.name!r} has no canonical left arm "
            "(left_shoulder, left_elbow, left_wrist); set IKConfig.dmax_mm explicitly"
        )
    total = limbs.limb_length_mm(skeleton, limbs.arm(skeleton, "left"), to_tip=True)
    if total <= 0:
        raise ShapeError(
            f"skeleton {skeleton.name!r}: the left arm has zero length; "
            "set IKConfig.dmax_mm explicitly"
        )
    return total


def leg_length_mm(skeleton: Skeleton) -> float:
    """Rest length of the left leg, hip joint to ankle (mm); arm length if there are no legs.

    The reference length ``L`` of the prismatic root DoFs (module doc). An upper-body
    model (``azad14``) has no legs; its arm length is the nearest stand-in for the
    scale of the body's motion.
    """
    if limbs.has_limb(skeleton, "left_leg"):
        return limbs.limb_length_mm(skeleton, limbs.leg(skeleton, "left"))
    return arm_length_mm(skeleton)


def dof_weights(
    skeleton: Skeleton,
    planted_joints: Sequence[str] | None = None,
) -> FloatArray:
    """Cost weights ``mu`` (D,) of the weighted Jacobian (recipe Z, errata Z3; see module doc).

    ``mu_j = sqrt(m_j / m_min)`` over revolute and ball DoFs (min 1); prismatic DoFs
    get ``sqrt(m_j / m_min) / L`` (per mm) with ``L`` the leg length (`leg_length_mm`).
    ``planted_joints`` defaults to the ankles (`mocapkit.ik.secondary.planted_feet`).
    """
    if planted_joints is None:
        planted_joints = planted_feet(skeleton)
    m = carried_mass_planted(skeleton, planted_joints)
    rot = skeleton.dof_kind != PRISMATIC
    positive = m[rot & (m > 0)]
    if positive.size == 0:
        raise ShapeError(
            f"skeleton {skeleton.name!r}: no rotational DoF carries mass; "
            "cannot weight the Jacobian"
        )
    m_min = float(positive.min())
    mu = np.sqrt(np.maximum(m, m_min) / m_min)
    length = leg_length_mm(skeleton)
    if not length > 0:
        raise ShapeError(f"skeleton {skeleton.name!r}: the leg has zero length")
    mu = np.where(rot, mu, mu / length)
    return mu


__all__ = ["arm_length_mm", "dof_weights", "leg_length_mm"]
