"""The Skeleton model and its presets: Table 1 figures, validation, scaling."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ConfigError, ShapeError, UnknownNameError
from mocapkit.skeleton import (
    CANONICAL_JOINTS,
    PRISMATIC,
    REVOLUTE,
    canonical_positions,
    forward_kinematics,
    load_preset,
    preset_names,
    preset_options,
    scale_skeleton,
    standing_height_mm,
)
from mocapkit.skeleton.scaling import (
    ANTHROPOMETRIC_HEIGHT_FRACTIONS,
    fit_anthropometric,
    segment_lengths_mm,
    segment_vectors_mm,
)

TABLE1 = {  # Zhang et al. 2011 Table 1: bone -> (length mm, mass g, DoFs)
    "spine1": (156, 5790, 1),
    "spine2": (171, 5790, 1),
    "spine3": (142, 4130, 1),
    "neck": (90, 3520, 2),
    "head": (100, 4390, 0),
    "clavicle": (190, 4130, 0),
    "humerus": (300, 2180, 3),
    "radius": (350, 1310, 1),
    "hand": (80, 520, 0),
    "hip": (85, 5715, 0),
    "femur": (386, 10050, 3),
    "tibia": (550, 3510, 1),
    "foot": (128, 1110, 0),
}


def test_presets_listed() -> None:
    assert set(preset_names()) == {"zhang21", "azad14", "upper_stick"}


def test_zhang21_matches_table1() -> None:
    sk = load_preset("zhang21")
    rot = sk.dof_kind == REVOLUTE
    assert int(rot.sum()) == 21
    assert int((sk.dof_kind == PRISMATIC).sum()) == 3  # errata Z13 root translation
    assert sk.total_mass_kg == pytest.approx(80.67, abs=1e-9)
    lengths = sk.bone_length_mm
    for bone, (length, mass_g, n_dof) in TABLE1.items():
        names = [bone] if bone in sk.joint_names else [f"l_{bone}", f"r_{bone}"]
        for name in names:
            j = sk.joint_index(name)
            assert lengths[j] == pytest.approx(length, abs=0.1), name
            assert sk.mass_kg[j] * 1000 == pytest.approx(mass_g), name
            assert len(sk.dofs_of_joint(j)) == n_dof, name


def test_zhang21_limits_in_radians_and_aaos_elbow() -> None:
    sk = load_preset("zhang21")
    d = sk.dof_index("r_elbow_flexion")
    assert sk.lower[d] == 0.0
    assert sk.upper[d] == pytest.approx(np.radians(150))
    d = sk.dof_index("l_shoulder_flexion")
    assert sk.upper[d] == pytest.approx(np.pi)


def test_presets_cover_canonical_vocabulary() -> None:
    assert load_preset("zhang21").canonical_names == CANONICAL_JOINTS
    upper = set(CANONICAL_JOINTS[:9])
    assert set(load_preset("upper_stick").canonical_names) == upper
    assert set(load_preset("azad14").canonical_names) == upper - {"pelvis"}


def test_azad14_has_14_dofs_and_optional_shoulder_offsets() -> None:
    assert load_preset("azad14").n_dofs == 14
    assert preset_options("azad14") == ("adaptive_shoulder",)
    sk = load_preset("azad14", ["adaptive_shoulder"])
    assert sk.n_dofs == 20
    d = sk.dof_index("l_shoulder_dx")
    assert (sk.lower[d], sk.upper[d]) == (-50.0, 50.0)


def test_rest_pose_is_upright_and_symmetric() -> None:
    sk = load_preset("zhang21")
    p = dict(zip(sk.canonical_names, canonical_positions(sk, sk.zero_pose()), strict=True))
    assert p["head"][2] > p["neck"][2] > p["pelvis"][2] > p["left_knee"][2] > p["left_ankle"][2]
    assert p["right_wrist"][0] > 0 > p["left_wrist"][0]  # right side towards +X
    np.testing.assert_allclose(p["left_elbow"] * [-1, 1, 1], p["right_elbow"], atol=1e-9)


def test_positive_flexion_moves_limbs_forward_on_both_sides() -> None:
    sk = load_preset("zhang21")
    for side in ("l", "r"):
        q = sk.zero_pose()
        q[sk.dof_index(f"{side}_shoulder_flexion")] = np.pi / 2
        name = "left_wrist" if side == "l" else "right_wrist"
        wrist = canonical_positions(sk, q, [name])[0]
        shoulder = canonical_positions(sk, q, [name.replace("wrist", "shoulder")])[0]
        assert wrist[1] - shoulder[1] == pytest.approx(650, abs=1e-6)  # arm points forward (+Y)
        q = sk.zero_pose()
        q[sk.dof_index(f"{side}_shoulder_abduction")] = np.pi / 2
        wrist = canonical_positions(sk, q, [name])[0]
        assert abs(wrist[0]) > abs(shoulder[0]) + 600  # abduction moves the arm outwards


def test_scaling_by_height_and_bone_override() -> None:
    sk = load_preset("zhang21")
    assert standing_height_mm(sk) == pytest.approx(1690, abs=1)
    tall = scale_skeleton(sk, height_mm=1850.0, mass_kg=90.0)
    assert standing_height_mm(tall) == pytest.approx(1850.0, rel=1e-9)
    assert tall.total_mass_kg == pytest.approx(90.0)
    f = 1850.0 / standing_height_mm(sk)
    j = sk.joint_index("l_radius")
    assert tall.bone_length_mm[j] == pytest.approx(350 * f)
    custom = scale_skeleton(sk, bone_lengths_mm={"l_radius": 300.0})
    assert custom.bone_length_mm[j] == pytest.approx(300.0)
    hand = custom.joint_index("l_hand")
    np.testing.assert_allclose(custom.offsets_mm[hand], [0, 0, -300.0])


def test_bad_input_is_rejected() -> None:
    with pytest.raises(UnknownNameError, match="unknown skeleton preset 'nope'.*zhang21"):
        load_preset("nope")
    with pytest.raises(UnknownNameError, match="preset option"):
        load_preset("zhang21", ["wings"])
    sk = load_preset("zhang21")
    with pytest.raises(UnknownNameError, match="unknown joint 'elbow'"):
        sk.joint_index("elbow")
    with pytest.raises(ShapeError, match="topologically ordered"):
        sk.replace(parents=np.r_[-1, 2, np.asarray(sk.parents[2:])])
    with pytest.raises(ShapeError, match="unit vectors"):
        sk.replace(dof_axis=sk.dof_axis * 2)
    with pytest.raises(ShapeError, match=r"expected shape \(27, 3\)"):
        sk.replace(offsets_mm=np.zeros((3, 3)))
    with pytest.raises(ConfigError, match="stature between 500 and 2800 mm"):
        scale_skeleton(sk, height_mm=17.5)
    with pytest.raises(ConfigError, match="owns no segment"):
        scale_skeleton(sk, bone_lengths_mm={"head_end": 10.0})


def test_skeleton_is_immutable() -> None:
    sk = load_preset("zhang21")
    with pytest.raises(ValueError, match="read-only"):
        sk.offsets_mm[0, 0] = 1.0
    with pytest.raises(AttributeError):
        sk.name = "other"  # type: ignore[misc]


def test_segment_lengths_and_vectors_of_zhang21() -> None:
    from mocapkit.skeleton import segment_lengths_mm, segment_vectors_mm

    sk = load_preset("zhang21")
    lengths = segment_lengths_mm(sk)
    assert lengths["left_upper_arm"] == pytest.approx(300.0)
    assert lengths["trunk"] == pytest.approx(156 + 171 + 142)
    assert lengths["head"] == pytest.approx(90 + 50)  # neck base to the head centre
    np.testing.assert_allclose(segment_vectors_mm(sk)["right_clavicle"], [184.6, 0, -45])


def test_fit_segments_sets_lengths_and_trunk_directions() -> None:
    from mocapkit.skeleton import fit_segments, segment_lengths_mm, segment_vectors_mm

    sk = load_preset("zhang21")
    target = {"left_upper_arm": 280.0, "right_forearm": 210.0, "trunk": 400.0, "head": 250.0}
    vectors = {"left_clavicle": [-180.0, -18.0, 77.0], "right_pelvis": [90.0, 10.0, -60.0]}
    fit = fit_segments(sk, target, vectors)
    got = segment_lengths_mm(fit)
    for seg, length in target.items():
        assert got[seg] == pytest.approx(length, abs=1e-9), seg
    vec = segment_vectors_mm(fit)
    for seg, v in vectors.items():
        np.testing.assert_allclose(vec[seg], v, atol=1e-9)
    # untouched segments keep their length; the clavicles ride on the top of the trunk
    assert got["left_thigh"] == pytest.approx(386.0)
    assert got["right_clavicle"] == pytest.approx(segment_lengths_mm(sk)["right_clavicle"])
    # joint frames are not turned: the rest pose still has every frame parallel to the world
    from mocapkit.skeleton import forward_kinematics

    rot = forward_kinematics(fit, fit.zero_pose())[:, :3, :3]
    np.testing.assert_allclose(rot, np.broadcast_to(np.eye(3), rot.shape), atol=1e-12)


def test_fit_segments_rejects_bad_input() -> None:
    from mocapkit.skeleton import fit_segments

    sk = load_preset("zhang21")
    with pytest.raises(UnknownNameError, match="unknown body segment 'arm'"):
        fit_segments(sk, {"arm": 300.0})
    with pytest.raises(ConfigError, match="expected a positive length"):
        fit_segments(sk, {"left_forearm": -1.0})
    with pytest.raises(ShapeError, match="rest vector of 'trunk'"):
        fit_segments(sk, vectors_mm={"trunk": [0.0, 0.0, 0.0]})


def test_clavicle_option_lifts_and_protracts_the_shoulders() -> None:
    sk = load_preset("zhang21", ["clavicle"])
    assert sk.n_dofs == load_preset("zhang21").n_dofs + 4
    for side, prefix in (("left", "l"), ("right", "r")):
        rest = canonical_positions(sk, sk.zero_pose(), [f"{side}_shoulder"])[0]
        q = sk.zero_pose()
        q[sk.dof_index(f"{prefix}_clavicle_elevation")] = 0.3
        assert canonical_positions(sk, q, [f"{side}_shoulder"])[0][2] > rest[2] + 50
        q = sk.zero_pose()
        q[sk.dof_index(f"{prefix}_clavicle_protraction")] = 0.3
        assert canonical_positions(sk, q, [f"{side}_shoulder"])[0][1] > rest[1] + 50


def test_forearm_rotation_option_turns_the_hand_about_the_forearm() -> None:
    """Pronation turns the hand's frame about the forearm's axis: elbow and wrist stay,
    a point in front of the wrist (the thumb side, arm hanging) turns medially."""
    sk = load_preset("zhang21", ["forearm_rotation"])
    assert sk.n_dofs == load_preset("zhang21").n_dofs + 2
    for side, prefix, medial in (("left", "l", 1.0), ("right", "r", -1.0)):
        d = sk.dof_index(f"{prefix}_forearm_rotation")
        assert np.degrees(sk.lower[d]) == pytest.approx(-80.0)
        assert np.degrees(sk.upper[d]) == pytest.approx(80.0)
        hand = sk.joint_index(sk.canonical[f"{side}_wrist"][0])
        q = sk.zero_pose()
        q[sk.dof_index(f"{prefix}_elbow_flexion")] = 0.5
        turned = q.copy()
        turned[d] = np.pi / 2
        names = [f"{side}_elbow", f"{side}_wrist"]
        np.testing.assert_allclose(
            canonical_positions(sk, turned, names), canonical_positions(sk, q, names), atol=1e-9
        )
        thumb = np.array([0.0, 30.0, 0.0])  # in front of the wrist, in the hand's frame
        before = forward_kinematics(sk, q)[hand]
        after = forward_kinematics(sk, turned)[hand]
        p0 = before[:3, :3] @ thumb + before[:3, 3]
        p1 = after[:3, :3] @ thumb + after[:3, 3]
        # a quarter turn of pronation takes the thumb side from the front to the middle
        assert medial * (p1[0] - p0[0]) == pytest.approx(30.0, abs=1e-6)


def test_fit_anthropometric_puts_the_joints_at_their_heights() -> None:
    """Known values: at 1731 mm the joints sit at Winter's fractions of the stature, the
    forearm is 0.145 of it (Table 1's scaled: 359 mm), and the stature is kept."""
    sk0 = load_preset("zhang21", ["root_rotation"])
    assert segment_lengths_mm(scale_skeleton(sk0, height_mm=1731.0))[
        "left_forearm"
    ] == pytest.approx(358.6, abs=0.5)
    sk = fit_anthropometric(sk0, 1731.0)
    assert standing_height_mm(sk) == pytest.approx(1731.0, abs=1e-6)
    rest = dict(zip(sk.canonical_names, canonical_positions(sk, sk.zero_pose()), strict=True))
    for joint, frac in ANTHROPOMETRIC_HEIGHT_FRACTIONS.items():
        for side in ("left", "right"):
            assert rest[f"{side}_{joint}"][2] == pytest.approx(frac * 1731.0, abs=1e-6)
    lengths = segment_lengths_mm(sk)
    assert lengths["left_forearm"] == pytest.approx(0.145 * 1731.0, abs=1e-6)
    assert lengths["right_upper_arm"] == pytest.approx(0.188 * 1731.0, abs=1e-6)
    # widths and the short trunk offsets are the scaled model's
    scaled = scale_skeleton(sk0, height_mm=1731.0)
    for seg in ("left_clavicle", "right_pelvis"):
        np.testing.assert_allclose(
            segment_vectors_mm(sk)[seg], segment_vectors_mm(scaled)[seg], atol=1e-6
        )
    with pytest.raises(UnknownNameError, match="anthropometric fit of 'upper_stick'"):
        fit_anthropometric(load_preset("upper_stick"), 1731.0)
