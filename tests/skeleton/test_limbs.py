"""Limbs, spine and feet found through canonical names on every preset."""

from __future__ import annotations

import dataclasses

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


def test_thorax_joint_carries_neck_and_clavicles() -> None:
    sk = load_preset("zhang21")
    j = limbs.thorax_joint(sk)
    assert sk.joint_names[j] == "spine3"
    children = {sk.joint_names[c] for c in np.flatnonzero(sk.parents == j)}
    assert children == {"neck", "l_clavicle", "r_clavicle"}
    # a stick whose arms hang from the neck: the neck is the chest's joint
    stick = load_preset("upper_stick")
    assert stick.joint_names[limbs.thorax_joint(stick)] == stick.canonical["neck"][0]
    partial = dataclasses.replace(
        sk, canonical={k: v for k, v in sk.canonical.items() if k != "right_shoulder"}
    )
    with pytest.raises(UnknownNameError, match="canonical joint 'right_shoulder'.*thorax"):
        limbs.thorax_joint(partial)


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


def test_limb_lengths_known_values() -> None:
    sk = load_preset("zhang21")
    # Table 1 segments: upper arm 300, forearm 350, hand 80; thigh 386, shank 550 (mm)
    assert limbs.limb_length_mm(sk, limbs.arm(sk, "left")) == pytest.approx(650.0)
    assert limbs.limb_length_mm(sk, limbs.arm(sk, "left"), to_tip=True) == pytest.approx(730.0)
    assert limbs.limb_length_mm(sk, limbs.leg(sk, "right")) == pytest.approx(936.0)


def test_limbs_present_and_ankles() -> None:
    sk = load_preset("zhang21")
    assert [lb.name for lb in limbs.limbs_present(sk, "leg")] == ["left_leg", "right_leg"]
    assert [sk.joint_names[j] for j in limbs.ankle_joints(sk)] == ["l_foot", "r_foot"]
    az = load_preset("azad14")
    assert [lb.name for lb in limbs.limbs_present(az, "arm")] == ["left_arm", "right_arm"]
    assert limbs.limbs_present(az, "leg") == ()
    assert limbs.ankle_joints(az).size == 0
    with pytest.raises(UnknownNameError, match="expected one of: arm, leg"):
        limbs.limbs_present(sk, "wing")


@pytest.mark.parametrize(
    ("name", "kind", "sign"),
    [("zhang21", "arm", 1.0), ("zhang21", "leg", 1.0), ("azad14", "arm", -1.0)],
)
def test_flexion_dofs_follow_each_models_sign(name: str, kind: str, sign: float) -> None:
    sk = load_preset(name)
    for lb in limbs.limbs_present(sk, kind):
        dofs, signs = limbs.flexion_dofs(sk, lb)
        assert dofs.size == 1 and sk.dof_joint[dofs[0]] == lb.middle
        assert signs.tolist() == [sign]
        # flexing by a small angle in that sign stays inside the joint's range
        d = dofs[0]
        assert sk.lower[d] <= signs[0] * 0.1 <= sk.upper[d]


def test_flexion_dofs_skip_two_sided_hinges() -> None:
    sk = load_preset("zhang21")
    # the shoulder's hinges have two-sided ranges: none of them is a flexion at the middle
    # joint, and asking at the shoulder (as if it were the middle joint) finds none
    arm = limbs.arm(sk, "left")
    fake = dataclasses.replace(arm, middle=arm.root)
    dofs, signs = limbs.flexion_dofs(sk, fake)
    assert dofs.size == 0 and signs.size == 0


def test_vertical_root_dof() -> None:
    sk = load_preset("zhang21")
    assert sk.dof_names[limbs.vertical_root_dof(sk)] == "root_tz"
    sk = load_preset("azad14")
    assert sk.dof_names[limbs.vertical_root_dof(sk)] == "base_tz"
    sk = load_preset("upper_stick")
    assert sk.dof_names[limbs.vertical_root_dof(sk)] == "waist_tz"
    axes = sk.dof_axis.copy()
    axes[limbs.vertical_root_dof(sk)] = (1.0, 0.0, 0.0)  # a root that only slides sideways
    fixed_root = sk.replace(dof_axis=axes)
    with pytest.raises(UnknownNameError, match="no prismatic DoF along"):
        limbs.vertical_root_dof(fixed_root)


def test_part_dofs_are_the_limb_with_its_lone_carrier_and_all_below() -> None:
    """An arm's part is its own DoFs plus the clavicle's where the model has one (the
    clavicle carries that arm alone); the head's is `head_dofs`; none where absent."""
    plain = load_preset("zhang21")
    np.testing.assert_array_equal(limbs.part_dofs(plain, "left_arm"), limbs.arm(plain, "left").dofs)
    sk = load_preset("zhang21", ("clavicle",))
    lmb = limbs.arm(sk, "left")
    clavicle = np.flatnonzero(sk.dof_joint == sk.parents[lmb.chain[0]])
    assert clavicle.size == 2
    np.testing.assert_array_equal(limbs.part_dofs(sk, "left_arm"), np.union1d(clavicle, lmb.dofs))
    np.testing.assert_array_equal(limbs.part_dofs(sk, "head"), limbs.head_dofs(sk))
    leg = limbs.leg(sk, "right")
    assert set(leg.dofs) <= set(limbs.part_dofs(sk, "right_leg").tolist())
    assert limbs.part_dofs(load_preset("upper_stick"), "left_leg").size == 0
