"""The `Motion` type, its exports (npz, CSV, BVH, TRC), naming tables, units and `read_motion`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import FormatError, ShapeError, UnknownNameError
from mocapkit.io.bvh import read_bvh
from mocapkit.io.joints_csv import read_joints_csv, write_joints_csv
from mocapkit.io.motion import Motion
from mocapkit.io.motion_files import read_motion, write_motion, write_result_folder
from mocapkit.io.motion_npz import load_motion_npz, save_motion_npz
from mocapkit.io.naming import NAMING_CONVENTIONS, canonical_map, detect_convention
from mocapkit.io.units import CMU_UNIT_MM, infer_unit_mm
from mocapkit.skeleton import CANONICAL_JOINTS, canonical_positions, load_preset


def _zhang_motion(rng: np.random.Generator, n: int = 12) -> Motion:
    skel = load_preset("zhang21")
    lo = np.where(np.isfinite(skel.lower), skel.lower, -300.0)
    hi = np.where(np.isfinite(skel.upper), skel.upper, 300.0)
    q = rng.uniform(lo, hi, size=(n, skel.n_dofs))
    q[3] = np.nan  # a frame without a pose
    return Motion.from_q(skel, np.arange(n) / 30.0, q, "test")


def test_from_q_computes_canonical_joints_and_skips_nan_rows(rng: np.random.Generator) -> None:
    motion = _zhang_motion(rng)
    assert motion.joint_names == CANONICAL_JOINTS
    assert motion.joints_mm.shape == (12, 15, 3)
    assert np.all(np.isnan(motion.joints_mm[3]))
    ok = [k for k in range(12) if k != 3]
    np.testing.assert_allclose(
        motion.joints_mm[ok], canonical_positions(motion.skeleton, motion.q[ok]), atol=1e-12
    )
    np.testing.assert_array_equal(motion.joint("left_knee"), motion.joints_mm[:, 10])
    with pytest.raises(UnknownNameError, match="unknown canonical joint 'nose'"):
        motion.joint("nose")
    assert not motion.q.flags.writeable


def test_shape_validation(rng: np.random.Generator) -> None:
    skel = load_preset("upper_stick")
    with pytest.raises(ShapeError, match=r"expected time_s \(T,\) and q \(T, 17\)"):
        Motion.from_q(skel, [0.0, 1.0], np.zeros((2, 5)))
    good = Motion.from_q(skel, [0.0], skel.zero_pose()[None])
    with pytest.raises(ShapeError, match=r"Motion.joints_mm: expected shape \(1, 9, 3\)"):
        Motion(skel, good.time_s, good.q, good.joint_names, np.zeros((1, 7, 3)))
    with pytest.raises(ShapeError, match="not canonical joint names"):
        Motion(skel, good.time_s, good.q, ("nose",), np.zeros((1, 1, 3)))


def test_npz_round_trip(rng: np.random.Generator, tmp_path: Path) -> None:
    motion = _zhang_motion(rng)
    save_motion_npz(tmp_path / "m.npz", motion)
    back = load_motion_npz(tmp_path / "m.npz")  # np.load(allow_pickle=False) inside
    np.testing.assert_array_equal(back.q, motion.q)
    np.testing.assert_array_equal(back.time_s, motion.time_s)
    np.testing.assert_array_equal(back.joints_mm, motion.joints_mm)
    assert back.joint_names == motion.joint_names and back.source == "test"
    np.testing.assert_array_equal(back.skeleton.offsets_mm, motion.skeleton.offsets_mm)
    assert back.skeleton.canonical == motion.skeleton.canonical
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    with pytest.raises(FormatError, match=r"other\.npz: not a mocapkit motion file; missing"):
        load_motion_npz(tmp_path / "other.npz")
    (tmp_path / "junk.npz").write_text("junk")
    with pytest.raises(FormatError, match=r"junk\.npz: cannot read as \.npz"):
        load_motion_npz(tmp_path / "junk.npz")


def test_joints_csv_round_trip(rng: np.random.Generator, tmp_path: Path) -> None:
    motion = _zhang_motion(rng)
    path = tmp_path / "joints.csv"
    write_joints_csv(path, motion)
    header = path.read_text().splitlines()[0].split(",")
    assert header[:4] == ["time_s", "head_x_mm", "head_y_mm", "head_z_mm"]
    assert header[-1] == "right_ankle_z_mm" and len(header) == 1 + 45
    time_s, names, joints = read_joints_csv(path)
    assert names == motion.joint_names
    np.testing.assert_allclose(time_s, motion.time_s, atol=1e-9)
    np.testing.assert_allclose(joints, motion.joints_mm, atol=1e-6, rtol=0)
    assert np.all(np.isnan(joints[3]))
    (tmp_path / "bad.csv").write_text("t,head_x_mm\n")
    with pytest.raises(FormatError, match=r"bad\.csv: line 1: expected a header starting with"):
        read_joints_csv(tmp_path / "bad.csv")
    (tmp_path / "bad2.csv").write_text("time_s,head_x_mm,head_y_mm,head_z_mm\n0,1,2\n")
    with pytest.raises(FormatError, match=r"bad2\.csv: line 2: expected 4 values, found 3"):
        read_joints_csv(tmp_path / "bad2.csv")


def test_result_folder(rng: np.random.Generator, tmp_path: Path) -> None:
    motion = _zhang_motion(rng)
    out = write_result_folder(tmp_path / "result", motion)
    assert sorted(p.name for p in out.iterdir()) == ["joints.csv", "motion.bvh", "motion.npz"]
    bvh = read_bvh(out / "motion.bvh")
    ok = [k for k in range(12) if k != 3]
    common = [c for c in CANONICAL_JOINTS if c != "head"]
    ka = [motion.joint_names.index(c) for c in common]
    kb = [bvh.joint_names.index(c) for c in common]
    np.testing.assert_allclose(
        bvh.joints_mm[ok][:, kb], motion.joints_mm[ok][:, ka], atol=1e-6, rtol=0
    )
    # the frame without a pose is written as the previous pose
    np.testing.assert_allclose(bvh.joints_mm[3], bvh.joints_mm[2], atol=1e-9)
    assert read_motion(out / "motion.npz").n_frames == 12


def test_trc_export(rng: np.random.Generator, tmp_path: Path) -> None:
    from mocapkit.io.trc import read_trc

    motion = _zhang_motion(rng)
    write_motion(tmp_path / "joints.trc", motion)
    markers = read_trc(tmp_path / "joints.trc")
    assert markers.names == motion.joint_names
    np.testing.assert_allclose(markers.positions_mm, motion.joints_mm, atol=1e-6, rtol=0)


def test_unit_inference_rule() -> None:
    assert infer_unit_mm(172.0, "f") == 10.0  # cm
    assert infer_unit_mm(1.72, "f") == 1000.0  # m
    assert infer_unit_mm(1720.0, "f") == 1.0  # mm
    assert infer_unit_mm(67.0, "f") == 25.4  # inch
    assert infer_unit_mm(30.0, "f") == CMU_UNIT_MM
    with pytest.raises(FormatError, match=r"toy\.bvh: cannot infer the length unit"):
        infer_unit_mm(5.0, "toy.bvh")
    with pytest.raises(FormatError, match="pass unit_mm explicitly"):
        infer_unit_mm(0.0, "toy.bvh")


def test_naming_tables() -> None:
    for conv in NAMING_CONVENTIONS:
        assert set(conv.joints) <= set(CANONICAL_JOINTS), conv.name
        found, exact = detect_convention(sorted(conv.signature | set(conv.joints.values())))
        assert found is conv and exact, conv.name
    partial, exact = detect_convention(["Hips", "LeftUpLeg", "LeftLeg", "Foo"])
    assert partial is not None and not exact and partial.name.startswith("CMU MotionBuilder")
    ends = np.array([[0, 0, 0.0], [0, 0, 200.0], [0, 0, 0]])
    cmap = canonical_map(["Hips", "Head", "LeftUpLeg"], ends, partial)
    assert cmap == {
        "head": ("Head", (0.0, 0.0, 100.0)),
        "pelvis": ("Hips", (0.0, 0.0, 0.0)),
        "left_hip": ("LeftUpLeg", (0.0, 0.0, 0.0)),
    }
    assert detect_convention(["foo", "bar"]) == (None, False)


def test_read_motion_dispatch(shared_data: Path, tmp_path: Path) -> None:
    mocap = shared_data / "mocap"
    assert read_motion(mocap / "131_01.bvh").n_frames == 994
    amc = read_motion(mocap / "01_09.amc")  # 01.asf found by the subject prefix
    assert "01.asf" in amc.source
    amc2 = read_motion(mocap / "charleston1.amc", asf=mocap / "charleston.asf")
    assert amc2.n_frames == 506
    with pytest.raises(
        FormatError,
        match=r"unsupported motion file extension '\.asf'.*"
        r"read the \.amc",
    ):
        read_motion(mocap / "01.asf")
    with pytest.raises(FormatError, match=r"an ASF skeleton is only used with \.amc files"):
        read_motion(mocap / "131_01.bvh", asf=mocap / "01.asf")
    with pytest.raises(FormatError, match=r"nothing\.bvh: motion file not found"):
        read_motion(tmp_path / "nothing.bvh")
    (tmp_path / "x.txt").write_text("")
    with pytest.raises(FormatError, match=r"unsupported motion file extension '\.txt'"):
        read_motion(tmp_path / "x.txt")
