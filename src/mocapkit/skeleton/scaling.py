"""Fitting a body model to a subject: proportional scaling by stature, per-bone overrides."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from mocapkit.errors import ShapeError
from mocapkit.skeleton.kinematics import joint_positions
from mocapkit.skeleton.model import PRISMATIC, Skeleton

#: Height of the lateral malleolus (ankle joint) above the floor as a fraction of stature
#: (Winter, Biomechanics and Motor Control of Human Movement, 4th ed., Fig. 4.1: 0.039 H).
ANKLE_HEIGHT_FRACTION = 0.039


def standing_height_mm(skeleton: Skeleton) -> float:
    """Stature of a skeleton in its rest pose (q = 0), in mm.

    The top of the model (highest joint) minus its lowest joint, divided by
    ``1 - 0.039`` when the lowest joint is an ankle-level foot joint, because the
    models end at the ankle and stature counts the foot below it. Upper-body-only
    models return the span of their joints.
    """
    z = joint_positions(skeleton, skeleton.zero_pose())[:, 2]
    span = float(z.max() - z.min())
    has_feet = "left_ankle" in skeleton.canonical or "right_ankle" in skeleton.canonical
    return span / (1.0 - ANKLE_HEIGHT_FRACTION) if has_feet else span


def scale_skeleton(
    skeleton: Skeleton,
    height_mm: float | None = None,
    mass_kg: float | None = None,
    bone_lengths_mm: Mapping[str, float] | None = None,
) -> Skeleton:
    """Scale a body model to a subject.

    Lengths (offsets, segment ends, radii, prismatic limits, canonical points) scale
    by ``height_mm / standing_height_mm(skeleton)``; masses scale to ``mass_kg`` in
    proportion (de Leva's fractions are kept). Then each override sets the
    length of one joint's segment, moving the joints attached at its end with it.

    Parameters
    ----------
    skeleton : Skeleton
    height_mm : float, optional
        Subject stature; no proportional scaling when omitted.
    mass_kg : float, optional
        Subject body mass; masses unchanged when omitted.
    bone_lengths_mm : mapping of str to float, optional
        Joint name -> length of the segment that joint owns, in mm.
    """
    sk = skeleton
    if height_mm is not None:
        if not np.isfinite(height_mm) or not 500.0 <= height_mm <= 2800.0:
            raise ShapeError(
                f"height_mm: expected a stature between 500 and 2800 mm, found {height_mm}"
            )
        f = float(height_mm) / standing_height_mm(sk)
        lower, upper = sk.lower.copy(), sk.upper.copy()
        pris = sk.dof_kind == PRISMATIC
        lower[pris] *= f
        upper[pris] *= f
        sk = sk.replace(
            offsets_mm=sk.offsets_mm * f,
            bone_end_mm=sk.bone_end_mm * f,
            radii_mm=sk.radii_mm * f,
            lower=lower,
            upper=upper,
            canonical={c: (j, tuple(np.multiply(p, f))) for c, (j, p) in sk.canonical.items()},
        )
    if mass_kg is not None:
        if not np.isfinite(mass_kg) or mass_kg <= 0:
            raise ShapeError(f"mass_kg: expected a positive body mass, found {mass_kg}")
        sk = sk.replace(mass_kg=sk.mass_kg * (float(mass_kg) / sk.total_mass_kg))
    for jname, length in (bone_lengths_mm or {}).items():
        j = sk.joint_index(jname)
        old = float(np.linalg.norm(sk.bone_end_mm[j]))
        if old == 0.0:
            raise ShapeError(f"bone_lengths_mm[{jname!r}]: joint {jname!r} owns no segment")
        if not np.isfinite(length) or length <= 0:
            raise ShapeError(
                f"bone_lengths_mm[{jname!r}]: expected a positive length, found {length}"
            )
        f = float(length) / old
        offsets = sk.offsets_mm.copy()
        ends = sk.bone_end_mm.copy()
        end_before = ends[j].copy()
        ends[j] *= f
        for c in sk.children(j):
            # a child attached at the segment's end moves with it; others keep their offset
            if np.allclose(offsets[c], end_before, atol=1e-6):
                offsets[c] = ends[j]
        sk = sk.replace(offsets_mm=offsets, bone_end_mm=ends)
    return sk
