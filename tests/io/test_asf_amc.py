"""ASF/AMC reading: conventions, the BVH cross-check on CMU 01_01, ASF lookup and bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocapkit.errors import FormatError, UnknownNameError
from mocapkit.io.asf_amc import find_asf, read_amc, read_asf
from mocapkit.io.bvh import read_bvh
from mocapkit.io.motion import Motion
from mocapkit.io.units import CMU_UNIT_MM, WORLD_FROM_FILE
from mocapkit.skeleton import CANONICAL_JOINTS, joint_positions, points_on_joints

TINY_ASF = """# a comment line
# Copyright line as in the fairmotion copies
:version 1.10
:name TEST
:units
  mass 1.0
  length 1.0
  angle deg
:root
   order TX TY TZ RX RY RZ
   axis XYZ
   position 0 0 0
   orientation 0 0 0
:bonedata
  begin
     id 1
     name a
     direction 0 1 0
     length 2
     axis 10 20 30 XYZ
    dof rx ry rz
    limits (-90.0 90.0)
           (-80.0 80.0)
           (-70.0 70.0)
  end
  begin
     id 2
     name b
     direction 1 0 0
     length 1
     axis 0 0 0 XYZ
    dof rz
    limits (-170 170)
  end
  begin
     id 3
     name c
     direction 0 0 1
     length 0.5
     axis 0 0 0 XYZ
  end
:hierarchy
  begin
    root a
    a b
    b c
  end
"""

TINY_AMC = """#!OML:ASF tiny.asf
# Copyright line as in the fairmotion copies
:FULLY-SPECIFIED
:DEGREES
1
root 1 2 3 10 20 30
a 5 -15 25
b 40
2
root 0 0 0 0 0 0
b -10
a 0 0 0
"""


def _rx(order: str, angles: list[float]) -> np.ndarray:
    # extrinsic (fixed-axis) Euler, first letter applied first: "xyz" -> Rz @ Ry @ Rx
    return Rotation.from_euler(order, angles, degrees=True).as_matrix()


def _tiny(tmp_path: Path, asf: str = TINY_ASF, amc: str = TINY_AMC, stem: str = "tiny") -> Path:
    tmp_path.mkdir(parents=True, exist_ok=True)
    (tmp_path / f"{stem}.asf").write_text(asf)
    path = tmp_path / f"{stem}.amc"
    path.write_text(amc)
    return path


def test_tiny_skeleton_follows_c_m_cinv(tmp_path: Path) -> None:
    motion = read_amc(_tiny(tmp_path))
    skel = motion.skeleton
    unit = 25.4  # ':units length 1.0' -> one unit is one inch
    assert skel.joint_names == ("root", "a", "b", "c")
    assert skel.dof_names[:3] == ("root_tx", "root_ty", "root_tz")
    np.testing.assert_allclose(motion.time_s, [0.0, 1 / 120])
    # an independent evaluation of the Acclaim convention in the file frame
    r_root = _rx("xyz", [10, 20, 30])
    c_a = _rx("xyz", [10, 20, 30])
    r_a = r_root @ c_a @ _rx("xyz", [5, -15, 25]) @ c_a.T
    p_root = np.array([1.0, 2, 3])
    p_b = p_root + r_a @ np.array([0, 2.0, 0])
    r_b = r_a @ _rx("z", [40])
    p_c = p_b + r_b @ np.array([1.0, 0, 0])
    c_end = p_c + r_b @ np.array([0, 0, 0.5])
    expected = np.array([p_root, p_root, p_b, p_c]) @ WORLD_FROM_FILE.T * unit
    np.testing.assert_allclose(joint_positions(skel, motion.q[0]), expected, atol=1e-9)
    end = points_on_joints(skel, motion.q[0], ["c"], [skel.bone_end_mm[3]])[0]
    np.testing.assert_allclose(end, WORLD_FROM_FILE @ c_end * unit, atol=1e-9)
    # frame 2 lists bones in another order; only b moves
    r_b2 = _rx("z", [-10])
    np.testing.assert_allclose(
        joint_positions(skel, motion.q[1])[3],
        WORLD_FROM_FILE @ (np.array([0, 2.0, 0]) + r_b2 @ [1.0, 0, 0]) * unit,
        atol=1e-9,
    )
    # limits in radians, in DoF order (last listed rotation first)
    ia = skel.dof_index("a_rx")
    assert skel.lower[ia] == pytest.approx(np.deg2rad(-90))
    assert skel.upper[skel.dof_index("a_rz")] == pytest.approx(np.deg2rad(70))
    assert list(skel.dofs_of_joint("a")) == [skel.dof_index(n) for n in ("a_rz", "a_ry", "a_rx")]


def test_real_asf_01(shared_data: Path) -> None:
    skel = read_asf(shared_data / "mocap" / "01.asf")
    assert skel.n_joints == 31 and skel.name == "01"
    assert skel.n_dofs == 6 + 56  # root + every bone's dof list of 01.asf
    np.testing.assert_allclose(
        skel.bone_length_mm[skel.joint_index("lfemur")], 7.1578 * CMU_UNIT_MM, rtol=1e-6
    )
    assert skel.lower[skel.dof_index("lfemur_rx")] == pytest.approx(np.deg2rad(-160))
    assert skel.canonical_names == CANONICAL_JOINTS
    assert skel.canonical["neck"][0] == "lowerneck"


def test_fairmotion_comment_lines_and_fps(shared_data: Path) -> None:
    motion = read_amc(shared_data / "mocap" / "11_01.amc")
    assert motion.n_frames == 597
    assert "11.asf" in motion.source
    assert motion.time_s[-1] == pytest.approx(596 / 120)
    slow = read_amc(shared_data / "mocap" / "11_01.amc", fps=60.0)
    assert slow.time_s[-1] == pytest.approx(596 / 60)
    assert np.all(np.isfinite(motion.joints_mm))


def test_bvh_and_amc_of_cmu_01_01_agree(shared_data: Path) -> None:
    """REQUIRED cross-check: the cgspeed BVH and the original AMC of the same trial.

    BVH frame k >= 1 is AMC frame k (AMC row k - 1); `read_bvh` drops the added BVH
    frame 0, so rows align one to one. Both are in CMU units (56.444 mm).
    The cgspeed skeleton omits the ASF ``thorax`` segment (its Neck and Shoulder joints
    have OFFSET 0 from Spine1), so the upper body sits one thorax length (2.06488 units
    = 116.55 mm) lower in the BVH; with that segment put back every canonical joint
    agrees to a few micrometres, which pins down the ASF rotation convention.
    """
    amc = read_amc(shared_data / "mocap" / "01_01.amc")
    bvh = read_bvh(shared_data / "mocap" / "01_01.bvh")
    assert amc.n_frames == bvh.n_frames == 2751
    assert amc.joint_names == bvh.joint_names == CANONICAL_JOINTS
    err = np.linalg.norm(amc.joints_mm - bvh.joints_mm, axis=-1)  # (T, K)
    lower = [
        amc.joint_names.index(n)
        for n in CANONICAL_JOINTS
        if n == "pelvis" or n.endswith(("hip", "knee", "ankle"))
    ]
    upper = [k for k in range(len(CANONICAL_JOINTS)) if k not in lower]
    assert err[:, lower].max() < 0.01  # mm (BVH values carry 4 decimals)
    thorax_mm = 2.06488 * CMU_UNIT_MM
    np.testing.assert_allclose(err[:, upper], thorax_mm, atol=0.01)

    # put the thorax segment back into the BVH skeleton and compare everything
    skel = bvh.skeleton
    thorax = amc.skeleton.bone_end_mm[amc.skeleton.joint_index("thorax")]
    offsets = np.array(skel.offsets_mm)
    for name in ("Neck", "LeftShoulder", "RightShoulder"):
        offsets[skel.joint_index(name)] = thorax
    fixed = Motion.from_q(skel.replace(offsets_mm=offsets), bvh.time_s, bvh.q, "fixed")
    err_fixed = np.linalg.norm(amc.joints_mm - fixed.joints_mm, axis=-1)
    assert err_fixed.mean() < 0.005 and err_fixed.max() < 0.01


def test_other_real_clips_read(shared_data: Path) -> None:
    mocap = shared_data / "mocap"
    clips = (("01_09.amc", 4242), ("01_12.amc", 4109), ("lambada.amc", 2180), ("zombie.amc", 1558))
    for amc, frames in clips:
        motion = read_amc(mocap / amc)
        assert motion.n_frames == frames
        assert motion.joint_names == CANONICAL_JOINTS
        z = motion.joints_mm[..., 2]
        head, ankle = motion.joint_names.index("head"), motion.joint_names.index("left_ankle")
        assert np.median(z[:, head] - z[:, ankle]) > 1000.0  # mostly upright, in mm
    charleston = read_amc(mocap / "charleston1.amc", mocap / "charleston.asf")
    assert charleston.n_frames == 506
    # the take number is stripped when looking the skeleton up
    assert find_asf(mocap / "charleston1.amc") == mocap / "charleston.asf"


def test_asf_lookup_rules(tmp_path: Path) -> None:
    same = _tiny(tmp_path / "same", stem="07_02")
    assert find_asf(same) == same.with_suffix(".asf")
    pre = tmp_path / "prefix"
    pre.mkdir()
    (pre / "07.asf").write_text(TINY_ASF)
    (pre / "other.asf").write_text(TINY_ASF)
    (pre / "07_05.amc").write_text(TINY_AMC)
    assert find_asf(pre / "07_05.amc") == pre / "07.asf"
    only = tmp_path / "only"
    only.mkdir()
    (only / "skeleton.asf").write_text(TINY_ASF)
    (only / "walk.amc").write_text(TINY_AMC)
    assert find_asf(only / "walk.amc") == only / "skeleton.asf"
    assert read_amc(only / "walk.amc").n_frames == 2
    (pre / "dance.amc").write_text(TINY_AMC)
    with pytest.raises(
        FormatError,
        match=r"dance\.amc: no ASF skeleton found; tried: .*dance\.asf"
        r"; the only \.asf in .*found 2.*Pass asf_path explicitly",
    ):
        read_amc(pre / "dance.amc")
    with pytest.raises(FormatError, match=r"ASF skeleton file .*missing\.asf does not exist"):
        read_amc(only / "walk.amc", tmp_path / "missing.asf")


def test_bad_amc_input(tmp_path: Path) -> None:
    unknown = TINY_AMC.replace("b 40", "zz 40")
    with pytest.raises(
        UnknownNameError,
        match=r"unknown bone 'zz' in .*bad1\.amc line 8 "
        r"\(skeleton bad1\.asf\); expected one of: a, b, root",
    ):
        read_amc(_tiny(tmp_path, amc=unknown, stem="bad1"))
    text = TINY_AMC.replace("a 5 -15 25", "a 5 abc 25")
    with pytest.raises(FormatError, match=r"bad2\.amc: line 7: expected a number, found 'abc'"):
        read_amc(_tiny(tmp_path, amc=text, stem="bad2"))
    missing = TINY_AMC.replace("b -10\n", "")
    with pytest.raises(
        FormatError,
        match=r"bad3\.amc: frame 2 \(line 9\): missing values for "
        r"bone 'b'",
    ):
        read_amc(_tiny(tmp_path, amc=missing, stem="bad3"))
    count = TINY_AMC.replace("b 40", "b 40 50")
    with pytest.raises(FormatError, match=r"line 8: bone 'b' expects 1 values .*found 2"):
        read_amc(_tiny(tmp_path, amc=count, stem="bad4"))
    twice = TINY_AMC.replace("b 40", "b 40\nb 41")
    with pytest.raises(FormatError, match=r"frame 1 \(line 5\): bone 'b' appears 2 times"):
        read_amc(_tiny(tmp_path, amc=twice, stem="bad5"))
    fixed = TINY_AMC.replace("b 40", "b 40\nc 1")
    with pytest.raises(FormatError, match=r"line 9: bone 'c' has no DoFs in bad6\.asf"):
        read_amc(_tiny(tmp_path, amc=fixed, stem="bad6"))


def test_bad_asf_input(tmp_path: Path) -> None:
    bad_dir = TINY_ASF.replace("direction 0 1 0", "direction 0 one 0")
    with pytest.raises(FormatError, match=r"bone 'a' direction: expected 3 numbers"):
        read_amc(_tiny(tmp_path, asf=bad_dir, stem="e1"))
    bad_hier = TINY_ASF.replace("b c\n", "b q\n")
    with pytest.raises(UnknownNameError, match=r"unknown bone 'q' in .*e2\.asf :hierarchy"):
        read_amc(_tiny(tmp_path, asf=bad_hier, stem="e2"))
    bad_limits = TINY_ASF.replace("(-170 170)", "(-170 170)\n           (0 1)")
    with pytest.raises(
        FormatError,
        match=r"bone 'b': expected 1 limit pairs \(one per dof\), "
        r"found 2",
    ):
        read_amc(_tiny(tmp_path, asf=bad_limits, stem="e3"))
    bad_dof = TINY_ASF.replace("dof rz", "dof qz")
    with pytest.raises(FormatError, match=r"bone 'b': unknown dof 'qz'"):
        read_amc(_tiny(tmp_path, asf=bad_dof, stem="e4"))
