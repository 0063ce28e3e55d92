"""Naming tables: how each known motion-file convention names the canonical joints.

A reader detects the convention of a file's joint names (`detect_convention`) and
builds the skeleton's canonical map from it (`canonical_map`); joints a convention
does not name are left out, never guessed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mocapkit.skeleton.model import CANONICAL_JOINTS
from mocapkit.skeleton.presets import load_preset

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class NamingConvention:
    """How one family of files names its joints, and which joint gives each canonical joint.

    ``joints`` maps canonical name -> file joint name; the canonical point is that
    joint's origin, except for ``head``, which is the midpoint of the named joint's
    segment (half its ``bone_end_mm``). ``signature`` lists names that identify the
    convention (all must be present).
    """

    name: str
    signature: frozenset[str]
    joints: Mapping[str, str]


def _sided(
    central: Mapping[str, str], left: Mapping[str, str], right: Mapping[str, str]
) -> dict[str, str]:
    out = dict(central)
    out.update({f"left_{k}": v for k, v in left.items()})
    out.update({f"right_{k}": v for k, v in right.items()})
    return out


#: Limb joints named Left*/Right* + Shoulder (upper arm), Elbow, Wrist, Hip, Knee, Ankle,
#: shared by the CMU 3dsMax-friendly and the Hips/Ab/Chest conventions.
_LEFT_RIGHT_LIMBS: tuple[dict[str, str], dict[str, str]] = tuple(  # type: ignore[assignment]
    {
        "shoulder": f"{side}Shoulder",
        "elbow": f"{side}Elbow",
        "wrist": f"{side}Wrist",
        "hip": f"{side}Hip",
        "knee": f"{side}Knee",
        "ankle": f"{side}Ankle",
    }
    for side in ("Left", "Right")
)

#: mocapkit presets whose BVH exports (`mocapkit.io.bvh.write_bvh`) are read back by name.
_PRESETS_WRITTEN_AS_FILES = ("zhang21", "upper_stick")


def _preset_convention(preset: str) -> NamingConvention:
    """The convention of a file written from a mocapkit preset, taken from the preset itself.

    Its joints are the preset's canonical map (so the preset's own joint names live only
    in its TOML table); its signature is every joint that map names.
    """
    canonical = load_preset(preset).canonical
    joints = {c: canonical[c][0] for c in CANONICAL_JOINTS if c in canonical}
    return NamingConvention(f"mocapkit {preset} preset", frozenset(joints.values()), joints)


#: Naming tables (data). Neck choice per convention: the joint at the base of the
#: neck, where the clavicles start (top of the thorax). In the CMU files that is the
#: start of the ASF bone ``lowerneck`` (MotionBuilder-friendly BVH: ``Neck``;
#: 3dsMax-friendly BVH: ``lowerneck``); in Boxing_Toes-style files ``Neck`` (which
#: sits where the collars start).
NAMING_CONVENTIONS: tuple[NamingConvention, ...] = (
    NamingConvention(
        "CMU MotionBuilder-friendly BVH (cgspeed)",
        frozenset({"Hips", "LHipJoint", "LeftUpLeg", "Spine1", "Neck1", "LeftForeArm"}),
        _sided(
            {"pelvis": "Hips", "neck": "Neck", "head": "Head"},
            {
                "shoulder": "LeftArm",
                "elbow": "LeftForeArm",
                "wrist": "LeftHand",
                "hip": "LeftUpLeg",
                "knee": "LeftLeg",
                "ankle": "LeftFoot",
            },
            {
                "shoulder": "RightArm",
                "elbow": "RightForeArm",
                "wrist": "RightHand",
                "hip": "RightUpLeg",
                "knee": "RightLeg",
                "ankle": "RightFoot",
            },
        ),
    ),
    NamingConvention(
        "CMU 3dsMax-friendly BVH (cgspeed)",
        frozenset({"Hips", "LHipJoint", "LeftHip", "lowerneck", "LeftCollar", "Chest2"}),
        _sided(
            {"pelvis": "Hips", "neck": "lowerneck", "head": "Head"},
            *_LEFT_RIGHT_LIMBS,
        ),
    ),
    NamingConvention(
        "Hips/Ab/Chest BVH (Boxing_Toes style)",
        frozenset({"Hips", "Ab", "Chest", "LeftCollar", "LeftHip"}),
        _sided(
            {"pelvis": "Hips", "neck": "Neck", "head": "Head"},
            *_LEFT_RIGHT_LIMBS,
        ),
    ),
    NamingConvention(
        "CMU ASF/AMC (Acclaim)",
        frozenset({"root", "lfemur", "ltibia", "lhumerus", "lradius", "lowerneck"}),
        _sided(
            {"pelvis": "root", "neck": "lowerneck", "head": "head"},
            {
                "shoulder": "lhumerus",
                "elbow": "lradius",
                "wrist": "lwrist",
                "hip": "lfemur",
                "knee": "ltibia",
                "ankle": "lfoot",
            },
            {
                "shoulder": "rhumerus",
                "elbow": "rradius",
                "wrist": "rwrist",
                "hip": "rfemur",
                "knee": "rtibia",
                "ankle": "rfoot",
            },
        ),
    ),
    *(_preset_convention(name) for name in _PRESETS_WRITTEN_AS_FILES),
)


def detect_convention(joint_names: Sequence[str]) -> tuple[NamingConvention | None, bool]:
    """The naming convention of a set of joint names.

    Returns ``(convention, exact)``: ``exact`` is true when the convention's whole
    signature is present. Otherwise the convention sharing the most canonical joint
    names is returned with ``exact=False`` (``None`` when none shares any), so that
    a reader can fill the canonical joints it recognises and leave out the rest.
    """
    names = set(joint_names)
    for conv in NAMING_CONVENTIONS:
        if conv.signature <= names:
            return conv, True
    scored = [
        (sum(v in names for v in c.joints.values()), i) for i, c in enumerate(NAMING_CONVENTIONS)
    ]
    best, idx = max(scored)
    return (NAMING_CONVENTIONS[idx], False) if best > 0 else (None, False)


def canonical_map(
    joint_names: Sequence[str], bone_end_mm: FloatArray, convention: NamingConvention | None
) -> dict[str, tuple[str, tuple[float, float, float]]]:
    """Canonical map (canonical name -> (joint, point in joint frame mm)) for a skeleton.

    Only joints present by exact name are used; canonical joints whose file joint
    is missing are left out (never guessed).

    Parameters
    ----------
    joint_names : sequence of str, length J
    bone_end_mm : ndarray, shape (J, 3)
        Segment ends (mm, joint frame); the head point is half the head joint's.
    convention : NamingConvention or None
    """
    if convention is None:
        return {}
    index = {n: j for j, n in enumerate(joint_names)}
    out: dict[str, tuple[str, tuple[float, float, float]]] = {}
    for cname in CANONICAL_JOINTS:
        jname = convention.joints.get(cname)
        if jname is None or jname not in index:
            continue
        if cname == "head":
            half = 0.5 * np.asarray(bone_end_mm[index[jname]], dtype=float)
            out[cname] = (jname, (float(half[0]), float(half[1]), float(half[2])))
        else:
            out[cname] = (jname, (0.0, 0.0, 0.0))
    return out


__all__ = ["NAMING_CONVENTIONS", "NamingConvention", "canonical_map", "detect_convention"]
