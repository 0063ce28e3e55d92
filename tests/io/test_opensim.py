"""OpenSim export: TRC in OpenSim's frame, a model with a marker at each joint centre, an
IK setup; with the `opensim` package, OpenSim's own IK reproduces the markers."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.io.motion import Motion
from mocapkit.io.openpose import DIRECT
from mocapkit.io.opensim import (
    IK_SETUP_FILE,
    MARKER_FILE,
    MODEL_FILE,
    write_opensim_folder,
)
from mocapkit.io.trc import read_trc, write_trc
from mocapkit.io.units import OPENSIM_FROM_WORLD
from mocapkit.skeleton import load_preset


def _walk(preset: str, options: list[str], n: int, rng: np.random.Generator) -> Motion:
    sk = load_preset(preset, options)
    lo = np.where(np.isfinite(sk.lower), sk.lower, -200.0)
    hi = np.where(np.isfinite(sk.upper), sk.upper, 200.0)
    walk = np.cumsum(rng.normal(0.0, 0.02, (n, sk.n_dofs)), axis=0)
    q = np.clip(0.5 * (lo + hi) + walk * (hi - lo), lo, hi)
    return Motion.from_q(sk, np.arange(n) / 50.0, q, "walk")


def test_trc_is_y_up_in_mm_and_the_model_has_a_marker_per_joint(
    tmp_path: Path, rng: np.random.Generator
) -> None:
    sk = load_preset("zhang21")
    motion = Motion.from_q(sk, [0.0, 0.02], np.tile(sk.zero_pose(), (2, 1)), "standing")
    # the left arm not observed in the second frame: an empty field there
    joints = np.array(motion.joints_mm, copy=True)
    joints[1, motion.joint_names.index("left_wrist")] = np.nan
    motion = Motion(sk, motion.time_s, motion.q, motion.joint_names, joints)
    write_opensim_folder(tmp_path, motion)
    trc = read_trc(tmp_path / MARKER_FILE)
    assert trc.names == motion.joint_names
    np.testing.assert_allclose(trc.positions_mm, joints @ OPENSIM_FROM_WORLD.T, atol=1e-6)
    head, ankle = trc.names.index("head"), trc.names.index("left_ankle")
    assert trc.positions_mm[0, head, 1] - trc.positions_mm[0, ankle, 1] > 1400  # Y up, mm
    right, left = trc.names.index("right_shoulder"), trc.names.index("left_shoulder")
    assert trc.positions_mm[0, right, 2] > trc.positions_mm[0, left, 2]  # Z to the right
    model = ET.parse(tmp_path / MODEL_FILE).getroot()
    markers = {m.get("name"): m for m in model.iter("Marker")}
    assert set(markers) == set(motion.joint_names)
    assert markers["left_elbow"].findtext("socket_parent_frame") == "/bodyset/l_radius"
    coords = {c.get("name") for c in model.iter("Coordinate")}
    assert {"l_elbow_flexion", "r_shoulder_rotation", "root_tilt", "root_ty"} <= coords
    setup = ET.parse(tmp_path / IK_SETUP_FILE).getroot()
    assert setup.findtext(".//marker_file") == MARKER_FILE
    assert {t.get("name") for t in setup.iter("IKMarkerTask")} == set(motion.joint_names)


def test_joints_the_skeleton_lacks_are_left_out_of_the_export(tmp_path: Path) -> None:
    """A mono result with legs: its skeleton is the upper-body stick, its joints go on to
    the ankles; the export holds the skeleton's joints (it raised ValueError before)."""
    sk = load_preset("upper_stick")
    motion = Motion.from_q(sk, [0.0, 0.02], np.tile(sk.zero_pose(), (2, 1)), "standing")
    legs = np.full((2, 1, 3), 100.0)
    names = (*motion.joint_names, "left_ankle")
    joints = np.concatenate([motion.joints_mm, legs], axis=1)
    write_opensim_folder(tmp_path, Motion(sk, motion.time_s, motion.q, names, joints))
    trc = read_trc(tmp_path / MARKER_FILE)
    assert trc.names == motion.joint_names
    np.testing.assert_allclose(trc.positions_mm, motion.joints_mm @ OPENSIM_FROM_WORLD.T, atol=1e-6)


def test_trc_writer_renames_markers_and_turns_them_in_one_call(tmp_path: Path) -> None:
    names = ["head", "left_elbow", "right_knee"]
    pos = np.arange(2 * 3 * 3, dtype=float).reshape(2, 3, 3)
    out = tmp_path / "body25.trc"
    write_trc(out, [0.0, 0.1], names, pos, rename=DIRECT, file_from_world=OPENSIM_FROM_WORLD)
    back = read_trc(out)
    assert back.names == ("LElbow", "RKnee")  # the head has no BODY_25 point of its own
    np.testing.assert_allclose(back.positions_mm, pos[:, 1:] @ OPENSIM_FROM_WORLD.T)
    with pytest.raises(ConfigError, match="rename: expected a map naming some"):
        write_trc(out, [0.0, 0.1], names, pos, rename={"nose": "Nose"})
    with pytest.raises(ConfigError, match="file_from_world: expected a 3x3 rotation"):
        write_trc(out, [0.0, 0.1], names, pos, file_from_world=2 * np.eye(3))


@pytest.mark.parametrize(
    ("preset", "options"),
    [("zhang21", ["root_rotation", "forearm_rotation", "clavicle"]), ("azad14", [])],
)
def test_opensim_inverse_kinematics_runs_on_the_export_and_fits_every_marker(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, rng: np.random.Generator, preset, options
) -> None:
    osim = pytest.importorskip(
        "opensim", reason="the OpenSim check needs the opensim package (pip install opensim)"
    )
    motion = _walk(preset, options, 15, rng)
    write_opensim_folder(tmp_path, motion)
    monkeypatch.chdir(tmp_path)  # the setup names its files relative to itself
    assert osim.InverseKinematicsTool(IK_SETUP_FILE).run()
    errors = np.loadtxt(next(tmp_path.glob("*_ik_marker_errors.sto")), skiprows=7)
    assert errors.shape[0] == 15
    assert errors[:, 3].max() < 1e-3  # metres: every marker within 1 mm on every frame
