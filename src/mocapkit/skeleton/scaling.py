"""Fitting a body model to a subject: proportional scaling by stature, per-bone overrides."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike

from mocapkit.errors import ConfigError, ShapeError, unknown_name
from mocapkit.geometry.rotations import matrix_from_axis_angle
from mocapkit.skeleton.kinematics import canonical_positions, joint_positions
from mocapkit.skeleton.model import CANONICAL_SEGMENTS, PRISMATIC, FloatArray, Skeleton

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
            raise ConfigError(
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
            raise ConfigError(f"mass_kg: expected a positive body mass, found {mass_kg}")
        sk = sk.replace(mass_kg=sk.mass_kg * (float(mass_kg) / sk.total_mass_kg))
    for jname, length in (bone_lengths_mm or {}).items():
        j = sk.joint_index(jname)
        old = float(np.linalg.norm(sk.bone_end_mm[j]))
        if old == 0.0:
            raise ConfigError(f"bone_lengths_mm[{jname!r}]: joint {jname!r} owns no segment")
        if not np.isfinite(length) or length <= 0:
            raise ConfigError(
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


def segment_vectors_mm(skeleton: Skeleton) -> dict[str, FloatArray]:
    """Rest-pose vectors (3,) from the proximal to the distal canonical joint of each
    canonical segment (`CANONICAL_SEGMENTS`), in mm, world axes of the rest pose.

    Only segments whose two canonical joints the skeleton provides are listed.
    """
    names = skeleton.canonical_names
    pos = dict(zip(names, canonical_positions(skeleton, skeleton.zero_pose()), strict=True))
    return {
        seg: pos[b] - pos[a] for seg, (a, b) in CANONICAL_SEGMENTS.items() if a in pos and b in pos
    }


def segment_lengths_mm(skeleton: Skeleton) -> dict[str, float]:
    """Lengths of the canonical segments (`CANONICAL_SEGMENTS`) in the rest pose, mm.

    Only segments whose two canonical joints the skeleton provides are listed. The
    trunk of a skeleton with a flexible spine is measured straight (rest pose), as a
    lab measures it on a standing subject.
    """
    return {k: float(np.linalg.norm(v)) for k, v in segment_vectors_mm(skeleton).items()}


def _segment_path(skeleton: Skeleton, ja: int, jb: int, a_mm: FloatArray) -> list[int]:
    """Joints whose rest offsets make up the segment from joint ``ja`` to joint ``jb``.

    The path runs from ``jb`` up to the lowest common ancestor of the two joints; joints
    sitting exactly at A's rest position ``a_mm`` (a clavicle starting where the neck
    does) lie before the segment and are left out.
    """
    up_a = {int(j) for j in np.flatnonzero(skeleton.ancestors_mask()[:, ja])}
    rest = joint_positions(skeleton, skeleton.zero_pose())
    path = []
    j = jb
    while j not in up_a:
        if not np.allclose(rest[j], a_mm, atol=1e-6):
            path.append(j)
        j = int(skeleton.parents[j])
    return path


def _rotation_between(u: FloatArray, v: FloatArray) -> FloatArray:
    """The smallest rotation (3, 3) taking direction ``u`` onto direction ``v``."""
    a = u / np.linalg.norm(u)
    b = v / np.linalg.norm(v)
    axis = np.cross(a, b)
    s = float(np.linalg.norm(axis))
    c = float(np.clip(a @ b, -1.0, 1.0))
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        # opposite directions: half a turn about any axis normal to u
        n = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(n) < 1e-6:
            n = np.cross(a, [0.0, 1.0, 0.0])
        return matrix_from_axis_angle(n, np.pi)
    return matrix_from_axis_angle(axis, float(np.arctan2(s, c)))


def fit_segments(
    skeleton: Skeleton,
    lengths_mm: Mapping[str, float] | None = None,
    vectors_mm: Mapping[str, ArrayLike] | None = None,
) -> Skeleton:
    """Fit a model's canonical segments to a subject's measured lengths or rest vectors.

    For a segment from canonical joint A to canonical joint B, the rest offsets on the
    kinematic path from A's joint down to B's joint (and B's canonical point, and any
    sibling attached at the same place: the clavicles move with the top of the spine)
    are scaled by ``length / current``; with a rest vector they are also turned by the
    smallest rotation taking the current A->B direction onto the measured one. Joint
    frames and DoF axes are not turned. Segments are fitted proximal first (the order of
    `CANONICAL_SEGMENTS`); a segment given both ways follows its vector.

    Parameters
    ----------
    skeleton : Skeleton
    lengths_mm : mapping of str to float, optional
        Segment name (a key of `CANONICAL_SEGMENTS`) -> length (mm).
    vectors_mm : mapping of str to array_like (3,), optional
        Segment name -> vector from A to B (mm) with the subject standing in the
        anatomical position (x to the right, y forward, z up).
    """
    lengths = dict(lengths_mm or {})
    vectors = {k: np.asarray(v, dtype=float) for k, v in (vectors_mm or {}).items()}
    for seg in (*lengths, *vectors):
        if seg not in CANONICAL_SEGMENTS:
            raise unknown_name("body segment", seg, CANONICAL_SEGMENTS, "subject measurements")
    for seg, length in lengths.items():
        if not (np.isfinite(length) and length > 0):
            raise ConfigError(f"bone length of {seg!r}: expected a positive length, found {length}")
    for seg, vec in vectors.items():
        if vec.shape != (3,) or not np.all(np.isfinite(vec)) or np.linalg.norm(vec) == 0:
            raise ShapeError(
                f"rest vector of {seg!r}: expected 3 finite numbers, not all 0, found {vec}"
            )
    sk = skeleton
    for seg, (a, b) in CANONICAL_SEGMENTS.items():
        if (seg not in lengths and seg not in vectors) or a not in sk.canonical:
            continue
        if b not in sk.canonical:
            continue
        current = segment_vectors_mm(sk).get(seg)
        if current is None or np.linalg.norm(current) <= 1e-9:
            continue
        if seg in vectors:
            target = vectors[seg]
            rot = _rotation_between(current, target)
            f = float(np.linalg.norm(target) / np.linalg.norm(current))
        else:
            rot = np.eye(3)
            f = float(lengths[seg]) / float(np.linalg.norm(current))
        m = f * rot
        ja = sk.joint_index(sk.canonical[a][0])
        jb_name, b_point = sk.canonical[b]
        jb = sk.joint_index(jb_name)
        a_mm = canonical_positions(sk, sk.zero_pose(), [a])[0]
        path = _segment_path(sk, ja, jb, a_mm)
        offsets = sk.offsets_mm.copy()
        ends = sk.bone_end_mm.copy()
        for k in path:
            parent = int(sk.parents[k])
            old = offsets[k].copy()
            for c in sk.children(parent):
                if np.allclose(offsets[c], old, atol=1e-6):
                    offsets[c] = m @ old
            if np.allclose(ends[parent], old, atol=1e-6):
                ends[parent] = m @ old
        canonical = dict(sk.canonical)
        if np.any(np.asarray(b_point) != 0):
            # B is a point inside its joint's segment (the head centre): move it and the
            # segment it lies on, so the point keeps its relative place
            bp = m @ np.asarray(b_point, dtype=float)
            canonical[b] = (jb_name, (float(bp[0]), float(bp[1]), float(bp[2])))
            old_end = sk.bone_end_mm[jb].copy()
            ends[jb] = m @ old_end
            for c in sk.children(jb):
                if np.allclose(offsets[c], old_end, atol=1e-6):
                    offsets[c] = ends[jb]
        sk = sk.replace(offsets_mm=offsets, bone_end_mm=ends, canonical=canonical)
    return sk


#: Heights of joint centres above the floor as fractions of stature, standing upright with
#: the arms hanging (Drillis & Contini 1966, as given by Winter, Biomechanics and Motor
#: Control of Human Movement, 4th ed., Fig. 4.1): shoulder (glenohumeral) 0.818, elbow
#: 0.630, wrist 0.485, hip (greater trochanter) 0.530, knee 0.285, ankle 0.039. The
#: segment lengths follow: upper arm 0.188 (Winter: 0.186), forearm 0.145 (0.146), thigh
#: 0.245, shank 0.246.
ANTHROPOMETRIC_HEIGHT_FRACTIONS: dict[str, float] = {
    "shoulder": 0.818,
    "elbow": 0.630,
    "wrist": 0.485,
    "hip": 0.530,
    "knee": 0.285,
    "ankle": ANKLE_HEIGHT_FRACTION,
}


def fit_anthropometric(skeleton: Skeleton, height_mm: float) -> Skeleton:
    """A body model scaled to a stature with a population's proportions.

    For a subject of whom only the stature is known (a raw marker file): the model is
    scaled to ``height_mm`` (`scale_skeleton`), then its canonical segments are fitted
    (`fit_segments`) so that, standing at rest (q = 0, feet on z = 0), its shoulders,
    elbows, wrists, hips, knees and ankles sit at `ANTHROPOMETRIC_HEIGHT_FRACTIONS` of the
    stature, and the top of its head at the stature. The model's own widths and the short
    offsets of the trunk (pelvis to hips, neck base to shoulders) are kept; the trunk
    takes the length that puts the shoulders at their height, the head and neck the rest.

    ``zhang21``'s Table 1 proportions differ from a population's where it matters for an
    elbow: its forearm is 0.207 of the stature (elbow to wrist; a population's 0.146),
    its hips sit at 0.576 (0.530) and its shoulders at 0.860 (0.818), so a model scaled
    by stature alone has a forearm 100 mm too long at 1.73 m and its shoulders 70 mm high.

    Parameters
    ----------
    skeleton : Skeleton
        A standing model with canonical shoulders, elbows, wrists, hips, knees, ankles,
        pelvis, neck and head (``zhang21``).
    height_mm : float
        Stature (mm).

    Returns
    -------
    Skeleton
        With ``standing_height_mm`` equal to ``height_mm``.
    """
    sk = scale_skeleton(skeleton, height_mm=height_mm)
    h = float(height_mm)
    frac = ANTHROPOMETRIC_HEIGHT_FRACTIONS
    names = sk.canonical_names
    missing = [
        c
        for c in (
            "pelvis",
            "neck",
            "head",
            *(f"{s}_{j}" for s in ("left", "right") for j in frac),
        )
        if c not in names
    ]
    if missing:
        raise unknown_name(
            "canonical joint", missing[0], names, f"anthropometric fit of {sk.name!r}"
        )
    rest = dict(zip(names, canonical_positions(sk, sk.zero_pose()), strict=True))

    def mean_z(joint: str) -> float:
        return 0.5 * float(rest[f"left_{joint}"][2] + rest[f"right_{joint}"][2])

    hip_below_pelvis = float(rest["pelvis"][2]) - mean_z("hip")
    shoulder_below_neck = float(rest["neck"][2]) - mean_z("shoulder")
    lengths: dict[str, float] = {
        "trunk": (frac["shoulder"] + shoulder_below_neck / h - frac["hip"]) * h - hip_below_pelvis,
    }
    for side in ("left", "right"):
        lengths[f"{side}_upper_arm"] = (frac["shoulder"] - frac["elbow"]) * h
        lengths[f"{side}_forearm"] = (frac["elbow"] - frac["wrist"]) * h
        lengths[f"{side}_thigh"] = (frac["hip"] - frac["knee"]) * h
        lengths[f"{side}_shank"] = (frac["knee"] - frac["ankle"]) * h
    sk = fit_segments(sk, lengths)
    # stand the model on z = 0 with its ankles at their height
    rest = dict(zip(names, canonical_positions(sk, sk.zero_pose()), strict=True))
    offsets = sk.offsets_mm.copy()
    root = int(np.flatnonzero(sk.parents < 0)[0])
    offsets[root, 2] += frac["ankle"] * h - mean_z("ankle")
    sk = sk.replace(offsets_mm=offsets)
    # the head and neck take what is left up to the stature: scale the head segment so
    # the model's highest joint (the top of the head) lands at ``h``
    z = joint_positions(sk, sk.zero_pose())[:, 2]
    neck_z = float(canonical_positions(sk, sk.zero_pose(), ["neck"])[0, 2])
    above = float(z.max()) - neck_z
    if not above > 0:
        raise ConfigError(
            f"anthropometric fit of {sk.name!r}: expected the head above the neck, "
            f"found the top {above:.0f} mm from it"
        )
    head_now = float(np.linalg.norm(segment_vectors_mm(sk)["head"]))
    return fit_segments(sk, {"head": head_now * (h - neck_z) / above})
