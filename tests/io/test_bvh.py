"""BVH reading (both CMU conventions, other files, any channel layout), writing and round trips."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocapkit.errors import FormatError
from mocapkit.io.bvh import parse_bvh, read_bvh, write_bvh
from mocapkit.io.motion import Motion
from mocapkit.io.units import CMU_UNIT_MM, WORLD_FROM_FILE
from mocapkit.skeleton import CANONICAL_JOINTS, joint_positions, load_preset, points_on_joints

# ---------------------------------------------------------------- synthetic files

SMALL_BVH = """HIERARCHY
ROOT Root
{
  OFFSET 1 2 3
  CHANNELS 6 Xposition Yposition Zposition Yrotation Xrotation Zrotation
  JOINT Mid
  {
    OFFSET 0 10 0
    CHANNELS 4 Xrotation Xposition Yposition Zposition
    JOINT Tip
    {
      OFFSET 5 0 0
      CHANNELS 2 Zrotation Xrotation
      End Site
      {
        OFFSET 0 0 4
      }
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.5
0 0 0 0 0 0 0 0 10 0 0 0
4 -3 2.5 30 -20 10 45 1 9 -2 -60 15
"""


def _write(tmp_path: Path, text: str, name: str = "x.bvh") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _rot(order: str, angles_deg: list[float]) -> np.ndarray:
    # intrinsic Euler: the product of the rotations in listed order
    return Rotation.from_euler(order, angles_deg, degrees=True).as_matrix()


def test_channel_order_subsets_and_position_channels_on_any_joint(tmp_path: Path) -> None:
    motion = read_bvh(_write(tmp_path, SMALL_BVH), unit_mm=1.0)
    skel = motion.skeleton
    assert skel.joint_names == ("Root", "Mid", "Tip")
    assert skel.n_dofs == 12
    values = np.loadtxt(SMALL_BVH.splitlines()[-2:])
    for frame, v in enumerate(values):
        # independent FK in the file frame: position channels replace the OFFSET
        r0 = _rot("YXZ", list(v[3:6]))
        p0 = v[0:3]
        r1 = r0 @ _rot("X", [v[6]])
        p1 = p0 + r0 @ v[7:10]
        r2 = r1 @ _rot("ZX", list(v[10:12]))
        p2 = p1 + r1 @ np.array([5.0, 0, 0])
        end = p2 + r2 @ np.array([0, 0, 4.0])
        expected = np.array([p0, p1, p2]) @ WORLD_FROM_FILE.T
        got = joint_positions(skel, motion.q[frame])
        np.testing.assert_allclose(got, expected, atol=1e-9)
        tip_end = points_on_joints(skel, motion.q[frame], ["Tip"], [skel.bone_end_mm[2]])[0]
        np.testing.assert_allclose(tip_end, WORLD_FROM_FILE @ end, atol=1e-9)
    # rest pose (q = 0) reproduces the OFFSETs
    np.testing.assert_allclose(
        joint_positions(skel, skel.zero_pose()),
        np.array([[1, 2, 3], [1, 12, 3], [6, 12, 3]]) @ WORLD_FROM_FILE.T,
        atol=1e-12,
    )
    np.testing.assert_allclose(motion.time_s, [0.0, 0.5])
    assert motion.joint_names == ()  # unknown naming: no canonical joint is guessed


def test_unit_scaling_and_stature_inference(tmp_path: Path) -> None:
    path = _write(tmp_path, SMALL_BVH)
    m1 = read_bvh(path, unit_mm=1.0)
    m10 = read_bvh(path, unit_mm=10.0)
    np.testing.assert_allclose(
        joint_positions(m10.skeleton, m10.q), 10 * joint_positions(m1.skeleton, m1.q), atol=1e-9
    )
    # the toy figure is 14 units tall: no unit makes it a person
    with pytest.raises(FormatError, match="cannot infer the length unit.*pass unit_mm"):
        read_bvh(path)


# ---------------------------------------------------------------- bad input


def test_truncated_motion_block(tmp_path: Path) -> None:
    text = SMALL_BVH.rstrip("\n")
    text = text[: text.rfind(" ")] + "\n"  # drop the last value
    path = _write(tmp_path, text, "short.bvh")
    with pytest.raises(
        FormatError,
        match=r"short\.bvh: MOTION block: expected 2 frames x 12 "
        r"channels = 24 values, found 23 .*line 25 has 11 values",
    ):
        read_bvh(path, unit_mm=1.0)


def test_missing_motion_section(tmp_path: Path) -> None:
    path = _write(tmp_path, SMALL_BVH.split("MOTION")[0], "nomotion.bvh")
    with pytest.raises(FormatError, match=r"nomotion\.bvh: missing 'MOTION' section"):
        read_bvh(path, unit_mm=1.0)


def test_unbalanced_braces(tmp_path: Path) -> None:
    lines = SMALL_BVH.splitlines()
    lines.remove("}")  # the root's closing brace
    path = _write(tmp_path, "\n".join(lines), "braces.bvh")
    with pytest.raises(
        FormatError,
        match=r"braces\.bvh: line \d+: hierarchy ends early "
        r"\(unbalanced braces\?\).*closing joint 'Root'",
    ):
        read_bvh(path, unit_mm=1.0)
    extra = SMALL_BVH.replace("MOTION", "}\nMOTION")
    with pytest.raises(
        FormatError,
        match=r"line 21: expected 'MOTION' after the root joint's "
        r"closing brace.*found '}'",
    ):
        read_bvh(_write(tmp_path, extra, "extra.bvh"), unit_mm=1.0)


def test_non_numeric_value_and_bad_headers(tmp_path: Path) -> None:
    bad = SMALL_BVH.replace("45 1 9", "45 x 9")
    with pytest.raises(FormatError, match=r"bad\.bvh: line 25: expected a number, found 'x'"):
        read_bvh(_write(tmp_path, bad, "bad.bvh"), unit_mm=1.0)
    bad_offset = SMALL_BVH.replace("OFFSET 5 0 0", "OFFSET 5 zero 0")
    with pytest.raises(
        FormatError,
        match=r"line 12: expected a number for OFFSET of joint 'Tip', "
        r"found 'zero'",
    ):
        read_bvh(_write(tmp_path, bad_offset, "off.bvh"), unit_mm=1.0)
    bad_channel = SMALL_BVH.replace("Zrotation Xrotation\n", "Zrotation Wrotation\n")
    with pytest.raises(FormatError, match=r"line 13: joint 'Tip': unknown channel 'Wrotation'"):
        read_bvh(_write(tmp_path, bad_channel, "ch.bvh"), unit_mm=1.0)
    bad_frames = SMALL_BVH.replace("Frames: 2", "Frames: two")
    with pytest.raises(FormatError, match=r"line 22: 'Frames:' expects an integer, found 'two'"):
        read_bvh(_write(tmp_path, bad_frames, "fr.bvh"), unit_mm=1.0)
    with pytest.raises(FormatError, match="drop_rest_frame must be"):
        read_bvh(_write(tmp_path, SMALL_BVH), unit_mm=1.0, drop_rest_frame="yes")
    with pytest.raises(FormatError, match="cannot read BVH file"):
        read_bvh(tmp_path / "absent.bvh")


# ---------------------------------------------------------------- real CMU and other files


def _mocap(shared_data: Path) -> Path:
    return shared_data / "mocap"


def _rest_checks(motion: Motion) -> None:
    """At q = 0 the subject stands up along +Z with its right side towards +X."""
    skel = motion.skeleton
    rest = dict(
        zip(
            skel.canonical_names,
            np.asarray(points_on_joints(skel, skel.zero_pose(), *skel.canonical_points())),
            strict=True,
        )
    )
    assert rest["right_hip"][0] > rest["left_hip"][0]
    assert rest["right_shoulder"][0] > rest["left_shoulder"][0]
    assert rest["head"][2] > rest["neck"][2] > rest["pelvis"][2] > rest["left_knee"][2]
    assert rest["left_knee"][2] > rest["left_ankle"][2]
    height = rest["head"][2] - rest["left_ankle"][2]
    assert 1200 < height < 2000, height


def test_cmu_motionbuilder_friendly_drops_added_rest_frame(shared_data: Path) -> None:
    path = _mocap(shared_data) / "01_01.bvh"
    motion = read_bvh(path)
    raw = parse_bvh(path)
    assert raw.values.shape == (2752, 96)
    assert motion.n_frames == 2751
    assert "rest frame 0 dropped" in motion.source
    assert motion.joint_names == CANONICAL_JOINTS
    kept = read_bvh(path, drop_rest_frame=False)
    assert kept.n_frames == 2752
    np.testing.assert_array_equal(kept.q[1:], motion.q)
    np.testing.assert_allclose(motion.time_s[:3], [0, 0.0083333, 2 * 0.0083333])
    # CMU unit: the root position channel of frame 1 times 56.444 mm
    root = joint_positions(motion.skeleton, motion.q[0])[0]
    np.testing.assert_allclose(root, WORLD_FROM_FILE @ raw.values[1, :3] * CMU_UNIT_MM, atol=1e-9)
    _rest_checks(motion)
    # toes point forward (+Y) at rest
    rest = joint_positions(motion.skeleton, motion.skeleton.zero_pose())
    names = motion.skeleton.joint_names
    assert rest[names.index("LeftToeBase"), 1] > rest[names.index("LeftFoot"), 1]
    # the head segment midpoint is the canonical head
    head_joint, point = motion.skeleton.canonical["head"]
    assert head_joint == "Head"
    np.testing.assert_allclose(point, 0.5 * motion.skeleton.bone_end_mm[names.index("Head")])
    assert read_bvh(path, drop_rest_frame=True).n_frames == 2751


def test_cmu_13_26_and_3dsmax_friendly(shared_data: Path) -> None:
    m13 = read_bvh(_mocap(shared_data) / "13_26.bvh")
    assert m13.n_frames == 3028 and "rest frame 0 dropped" in m13.source
    for name, frames in (("131_01.bvh", 994), ("131_03.bvh", 1102)):
        motion = read_bvh(_mocap(shared_data) / name)
        assert motion.n_frames == frames  # no added rest frame in this release
        assert "3dsMax-friendly" in motion.source and "56.4444 mm" in motion.source
        assert motion.joint_names == CANONICAL_JOINTS
        assert motion.skeleton.canonical["neck"][0] == "lowerneck"
        assert motion.skeleton.canonical["left_shoulder"][0] == "LeftShoulder"
        _rest_checks(motion)
        assert np.all(np.isfinite(motion.joints_mm))


def test_boxing_toes_other_names_100fps_cm(shared_data: Path) -> None:
    motion = read_bvh(_mocap(shared_data) / "extra_unclear_license" / "Boxing_Toes.bvh")
    assert motion.n_frames == 3069
    np.testing.assert_allclose(motion.time_s[1], 0.01)
    assert "unit 10 mm" in motion.source  # centimetres, from the 1.7 m stature rule
    assert "1 frames beyond 'Frames:' ignored" in motion.source
    assert motion.joint_names == CANONICAL_JOINTS
    _rest_checks(motion)


# ---------------------------------------------------------------- writing


def _positions_by_name(motion: Motion) -> dict[str, np.ndarray]:
    pos = joint_positions(motion.skeleton, motion.q)
    return {n: pos[:, j] for j, n in enumerate(motion.skeleton.joint_names)}


def test_round_trip_cmu_excerpt(shared_data: Path, tmp_path: Path) -> None:
    full = read_bvh(_mocap(shared_data) / "01_01.bvh")
    excerpt = Motion.from_q(full.skeleton, full.time_s[:60], full.q[:60], "excerpt")
    out = tmp_path / "excerpt.bvh"
    write_bvh(out, excerpt)
    back = read_bvh(out, unit_mm=1000.0)
    assert back.n_frames == 60  # not mistaken for an added rest frame
    a, b = _positions_by_name(excerpt), _positions_by_name(back)
    assert set(a) == set(b)
    worst = max(np.abs(a[n] - b[n]).max() for n in a)
    assert worst < 1e-6, worst
    np.testing.assert_allclose(back.joints_mm, excerpt.joints_mm, atol=1e-6, rtol=0)
    np.testing.assert_allclose(back.time_s, excerpt.time_s, atol=1e-9)
    # the default unit rule sees a CMU-named skeleton in metres and still reads it right
    again = read_bvh(out)
    np.testing.assert_allclose(again.joints_mm, excerpt.joints_mm, atol=1e-6, rtol=0)


def test_round_trip_zhang21_random_poses(tmp_path: Path, rng: np.random.Generator) -> None:
    skel = load_preset("zhang21", ["root_rotation"])
    n = 25
    lo = np.where(np.isfinite(skel.lower), skel.lower, -500.0)
    hi = np.where(np.isfinite(skel.upper), skel.upper, 500.0)
    q = rng.uniform(lo, hi, size=(n, skel.n_dofs))
    motion = Motion.from_q(skel, np.arange(n) / 60.0, q, "random")
    out = tmp_path / "zhang.bvh"
    write_bvh(out, motion)
    back = read_bvh(out)  # stature rule: metres
    assert "unit 1000 mm" in back.source and "zhang21" in back.source
    a, b = _positions_by_name(motion), _positions_by_name(back)
    assert set(a) == set(b)
    worst = max(np.abs(a[k] - b[k]).max() for k in a)
    assert worst < 1e-6, worst
    np.testing.assert_allclose(back.time_s, motion.time_s, atol=1e-9)
    # canonical joints (all but the head, whose preset point is not the segment midpoint)
    names = [c for c in motion.joint_names if c != "head"]
    ka = [motion.joint_names.index(c) for c in names]
    kb = [back.joint_names.index(c) for c in names]
    np.testing.assert_allclose(back.joints_mm[:, kb], motion.joints_mm[:, ka], atol=1e-6, rtol=0)


def _file_frame_rest_positions(text: str) -> dict[str, np.ndarray]:
    """Joint positions in the BVH file frame from OFFSETs only (all rotations zero)."""
    pos: dict[str, np.ndarray] = {}
    stack: list[np.ndarray] = []
    name = ""
    for line in text.split("MOTION")[0].splitlines():
        s = line.strip()
        m = re.match(r"(ROOT|JOINT)\s+(\S+)", s)
        if m:
            name = m.group(2)
        elif s.startswith("End Site"):
            name = ""
        elif s.startswith("OFFSET"):
            base = stack[-1] if stack else np.zeros(3)
            p = base + np.array([float(v) for v in s.split()[1:4]])
            stack.append(p)
            if name:
                pos[name] = p
        elif s == "}":
            stack.pop()
    return pos


def test_written_standing_pose_has_head_up_along_bvh_y(tmp_path: Path) -> None:
    skel = load_preset("zhang21")
    motion = Motion.from_q(skel, [0.0], skel.zero_pose()[None], "standing")
    out = tmp_path / "standing.bvh"
    write_bvh(out, motion)
    text = out.read_text()
    values = np.array(text.split("Frame Time:")[1].split()[1:], dtype=float)
    rotations = np.delete(values, [0, 1, 2])  # only the root has position channels
    np.testing.assert_allclose(rotations, 0.0, atol=1e-9)
    pos = _file_frame_rest_positions(text)
    np.testing.assert_allclose(values[:3], pos["root"], atol=1e-9)  # root channel = its offset
    head, foot = pos["head"], pos["l_foot"]
    assert head[1] - foot[1] > 1.2  # metres: head well above the feet along +Y
    assert pos["r_humerus"][0] < pos["l_humerus"][0]  # right side towards -X, facing +Z
    assert "CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation" in text


def test_write_rejects_bad_arguments(tmp_path: Path) -> None:
    skel = load_preset("upper_stick")
    motion = Motion.from_q(skel, [0.0], np.full((1, skel.n_dofs), np.nan), "empty")
    with pytest.raises(FormatError, match="no frame with a pose"):
        write_bvh(tmp_path / "a.bvh", motion)
    good = Motion.from_q(skel, [0.0], skel.zero_pose()[None], "one")
    with pytest.raises(FormatError, match="unit_mm must be a positive number"):
        write_bvh(tmp_path / "a.bvh", good, unit_mm=0.0)


# ---------------------------------------------------------------- continuity


def test_continuous_euler_keeps_the_rotations_and_removes_wraps_and_flips() -> None:
    from mocapkit.io.bvh import continuous_euler

    # a body turning round twice while pitching through 90 deg: raw ZYX angles wrap at 180
    t = np.linspace(0.0, 1.0, 200)
    rot = Rotation.from_euler("ZYX", np.stack([4 * np.pi * t, 2.2 * np.sin(3 * t), t], 1))
    raw = rot.as_euler("ZYX")
    assert np.abs(np.diff(raw, axis=0)).max() > np.pi  # the raw channels jump
    smooth = continuous_euler(raw)
    assert np.abs(np.diff(smooth, axis=0)).max() < 0.2
    again = Rotation.from_euler("ZYX", smooth).as_matrix()
    np.testing.assert_allclose(again, rot.as_matrix(), atol=1e-12)


@pytest.mark.parametrize("preset", ["zhang21", "azad14"])
def test_result_bvh_matches_joints_csv_and_its_roll_steps_are_bounded(
    tmp_path: Path, rng: np.random.Generator, preset: str
) -> None:
    """The result folder's BVH (the hybrid's zhang21 and the stereo tracker's azad14):
    its joints equal joints.csv to 1e-6 mm, while each bone's turn about its own axis,
    which the input flips by up to 180 deg in single frames, is at most the roll limit per
    frame and the Euler channels never jump by a whole turn."""
    from mocapkit.io.bvh import MAX_ROLL_SPEED_RAD_S
    from mocapkit.io.joints_csv import read_joints_csv
    from mocapkit.io.motion_files import write_result_folder
    from mocapkit.skeleton import forward_kinematics
    from mocapkit.skeleton.roll import roll_steps

    options = ["root_rotation", "forearm_rotation", "clavicle"] if preset == "zhang21" else []
    sk = load_preset(preset, options)
    n, dt = 120, 1 / 30
    lo = np.where(np.isfinite(sk.lower), sk.lower, -300.0)
    hi = np.where(np.isfinite(sk.upper), sk.upper, 300.0)
    walk = np.cumsum(rng.normal(0.0, 0.02, (n, sk.n_dofs)), axis=0)
    q = np.clip(0.5 * (lo + hi) + walk * (hi - lo), lo, hi)
    revolute = np.flatnonzero(sk.dof_kind != 1)
    flips = rng.random((n, revolute.size)) < 0.03
    q[:, revolute] += np.pi * np.cumsum(flips, axis=0)  # whole half turns of single DoFs
    motion = Motion.from_q(sk, np.arange(n) * dt, q, "walk")
    write_result_folder(tmp_path, motion)
    back = read_bvh(tmp_path / "motion.bvh", unit_mm=1000.0)
    _, names, joints = read_joints_csv(tmp_path / "joints.csv")
    world = forward_kinematics(back.skeleton, back.q)
    for k, name in enumerate(names):
        joint, point = sk.canonical[name]
        j = back.skeleton.joint_index(joint)
        got = world[:, j, :3, :3] @ np.asarray(point, float) + world[:, j, :3, 3]
        np.testing.assert_allclose(got, joints[:, k], atol=1e-6, rtol=0)
    _, before = roll_steps(sk, forward_kinematics(sk, q)[..., :3, :3])
    _, after = roll_steps(back.skeleton, world[..., :3, :3])
    assert np.abs(before).max() > np.deg2rad(150)
    assert np.abs(after).max() <= MAX_ROLL_SPEED_RAD_S * dt + 1e-6
    channels = parse_bvh(tmp_path / "motion.bvh").values
    assert np.abs(np.diff(channels, axis=0)).max() < 300.0  # degrees: no whole-turn wraps


@pytest.mark.parametrize("chunk", [1, 13])
def test_bvh_written_in_chunks_is_byte_identical_to_one_chunk(
    tmp_path: Path, rng: np.random.Generator, monkeypatch: pytest.MonkeyPatch, chunk: int
) -> None:
    """`write_bvh` works through the frames in chunks (bounded memory on long motions):
    the roll limit and the Euler continuity carry over the chunk edges, so the file is the
    one of the whole motion at once, on a motion whose bones flip by half turns and with
    frames without a pose."""
    from mocapkit.io import bvh
    from mocapkit.io.bvh import MAX_ROLL_SPEED_RAD_S, write_bvh

    sk = load_preset("zhang21", ["root_rotation", "forearm_rotation", "clavicle"])
    n = 90
    lo = np.where(np.isfinite(sk.lower), sk.lower, -300.0)
    hi = np.where(np.isfinite(sk.upper), sk.upper, 300.0)
    walk = np.cumsum(rng.normal(0.0, 0.02, (n, sk.n_dofs)), axis=0)
    q = np.clip(0.5 * (lo + hi) + walk * (hi - lo), lo, hi)
    revolute = np.flatnonzero(sk.dof_kind != 1)
    q[:, revolute] += np.pi * np.cumsum(rng.random((n, revolute.size)) < 0.03, axis=0)
    q[[0, 1, 40, 41, 42]] = np.nan
    motion = Motion.from_q(sk, np.arange(n) / 30, q, "walk")
    monkeypatch.setattr(bvh, "_WRITE_CHUNK", n)
    write_bvh(tmp_path / "whole.bvh", motion, max_roll_speed_rad_s=MAX_ROLL_SPEED_RAD_S)
    monkeypatch.setattr(bvh, "_WRITE_CHUNK", chunk)
    write_bvh(tmp_path / "chunks.bvh", motion, max_roll_speed_rad_s=MAX_ROLL_SPEED_RAD_S)
    whole = (tmp_path / "whole.bvh").read_bytes()
    assert (tmp_path / "chunks.bvh").read_bytes() == whole
    assert whole.count(b"\n") > n


def test_continuous_euler_passes_frames_without_a_pose_through() -> None:
    from mocapkit.io.bvh import continuous_euler

    a = np.array([[0.0, 0.0, 3.1], [np.nan, np.nan, np.nan], [0.0, 0.0, -3.1], [0.0, 0.0, 3.1]])
    out = continuous_euler(a)
    assert np.isnan(out[1]).all()
    np.testing.assert_allclose(out[2], [0.0, 0.0, -3.1])  # restarts after the gap
    np.testing.assert_allclose(out[3], [0.0, 0.0, 3.1 - 2 * np.pi])  # nearest: one turn off
