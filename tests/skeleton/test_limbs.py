"""Limbs, spine and feet found through canonical names on every preset."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import UnknownNameError
from mocapkit.skeleton import limbs
from mocapkit.skeleton.presets import load_preset


def test_zhang21_arm_and_leg_joints() -> None:
    sk = load_preset("zhang21")
    arm = limbs.arm(sk, "left")
    assert [sk.joint_names[j] for j in arm.joints] == ["l_humerus", "l_radius", "l_hand"]
    assert sk.joint_names[arm.tip] == "l_hand_end"
    assert limbs.dof_names_of(sk, arm.dofs) == tuple(
        sk.dof_names[d] for d in np.flatnonzero(np.isin(sk.dof_joint, arm.chain))
    )
    assert arm.dofs.size == 4  # 3 shoulder + elbow (Table 1)
    assert arm.translation_dofs.size == 0
    leg = limbs.leg(sk, "right")
    assert [sk.joint_names[j] for j in leg.joints] == ["r_femur", "r_tibia", "r_foot"]
    assert leg.dofs.size == 4
    assert sk.joint_names[leg.parent] == sk.joint_names[sk.parents[leg.root]]


def test_azad14_arm_has_ball_shoulder_and_offset() -> None:
    sk = load_preset("azad14", options=("adaptive_shoulder",))
    arm = limbs.arm(sk, "right")
    assert arm.dofs.size == 4  # ball shoulder (3) + elbow
    assert arm.translation_dofs.size == 3  # adaptive shoulder (Azad's 7-DoF arm)
    assert not limbs.has_limb(sk, "left_leg")  # an upper-body model
    assert limbs.spine_dofs(sk).size == 0  # one rigid torso


def test_spine_dofs_and_feet() -> None:
    sk = load_preset("zhang21")
    names = limbs.dof_names_of(sk, limbs.spine_dofs(sk))
    assert names[:3] == ("spine1_flexion", "spine2_flexion", "spine3_flexion")
    feet = [sk.joint_names[j] for j in limbs.foot_joints(sk, "left")]
    assert feet[0] == "l_foot" and "l_foot_end" in feet
    assert sk.joint_names[limbs.head_joint(sk)] == "head"


def test_unknown_limb_names_choices() -> None:
    sk = load_preset("zhang21")
    with pytest.raises(UnknownNameError, match="expected one of: left_arm, left_leg"):
        limbs.limb(sk, "left_wing")
    with pytest.raises(UnknownNameError, match="expected one of: left, right"):
        limbs.arm(sk, "middle")


def test_missing_limb_is_refused_with_the_canonical_name() -> None:
    sk = load_preset("upper_stick")
    if limbs.has_limb(sk, "left_leg"):
        pytest.skip("upper_stick provides legs")
    with pytest.raises(UnknownNameError, match="left_hip"):
        limbs.leg(sk, "left")
