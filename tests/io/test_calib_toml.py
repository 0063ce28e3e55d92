"""Calib.toml (Pose2Sim, anipose, FreeMoCap): reading, units, refusals and the round trip."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.camera import Camera, intrinsics_from_fov, look_at
from mocapkit.errors import FormatError
from mocapkit.io.calib_toml import read_calib_toml, write_calib_toml
from mocapkit.io.cameras import load_cameras, write_cameras

QCA_RELATIVE = Path("video/pose2sim_demo_singleperson/calibration/Calib.qca.txt")

# A Pose2Sim-style camera: the world point (0, 0, 0) sits 3 m in front of it on its axis.
POSE2SIM_TOML = """\
[cam_01]
name = "cam01"
size = [ 1088.0, 1920.0,]
matrix = [ [ 1681.0, 0.0, 543.5,], [ 0.0, 1681.0, 959.5,], [ 0.0, 0.0, 1.0,],]
distortions = [ -0.046, 0.139, 0.0006, 0.0007,]
rotation = [ 0.0, 0.0, 0.0,]
translation = [ 0.1, -0.2, 3.0,]
fisheye = false

[metadata]
adjusted = false
error = 0.0
"""


def _cams() -> list[Camera]:
    k = intrinsics_from_fov((1920, 1080), 60.0)
    return [
        Camera(
            "left",
            (1920, 1080),
            k,
            [-0.1, 0.02, 0.001, -0.002, 0.0003],
            look_at((2000.0, -3000.0, 1600.0), (0.0, 0.0, 1000.0)),
        ),
        Camera("right cam", (1280, 720), k * [[0.5], [0.5], [1]], [0.01, 0.0, 0.0, 0.0],
               look_at((-2500.0, -2800.0, 1400.0), (0.0, 100.0, 900.0))),
    ]  # fmt: skip


def test_reads_pose2sim_metres_as_mm(tmp_path: Path) -> None:
    p = tmp_path / "Calib.toml"
    p.write_text(POSE2SIM_TOML, encoding="utf-8")
    (cam,) = load_cameras(p)
    assert cam.name == "cam01" and cam.image_size == (1088, 1920)
    np.testing.assert_allclose(cam.camera_from_world[:3, 3], [100.0, -200.0, 3000.0])
    np.testing.assert_allclose(cam.dist, [-0.046, 0.139, 0.0006, 0.0007])
    # the world origin lies on the ray through (cx + fx * 0.1 / 3, cy - fx * 0.2 / 3)
    px = cam.project_camera_points(np.array([[0.1, -0.2, 3.0]]) * 1000.0)[0]
    np.testing.assert_allclose(cam.project(np.zeros(3)), px)


def test_mm_translation_read_as_mm_and_unit_can_be_said(tmp_path: Path) -> None:
    p = tmp_path / "calibration.toml"  # anipose / FreeMoCap with the board in mm
    p.write_text(POSE2SIM_TOML.replace("[ 0.1, -0.2, 3.0,]", "[ 100.0, -200.0, 3000.0]"), "utf-8")
    np.testing.assert_allclose(read_calib_toml(p)[0].camera_from_world[:3, 3], [100, -200, 3000])
    np.testing.assert_allclose(
        read_calib_toml(p, unit="m")[0].camera_from_world[:3, 3], [1e5, -2e5, 3e6]
    )


def test_ambiguous_translation_unit_refused(tmp_path: Path) -> None:
    p = tmp_path / "Calib.toml"
    p.write_text(POSE2SIM_TOML.replace("[ 0.1, -0.2, 3.0,]", "[ 0.0, 0.0, 120.0]"), "utf-8")
    with pytest.raises(FormatError, match=r"largest camera translation is 120, between 50"):
        read_calib_toml(p)
    assert read_calib_toml(p, unit="mm")[0].camera_from_world[2, 3] == 120.0


@pytest.mark.parametrize(
    ("old", "new", "match"),
    [
        ("fisheye = false", "fisheye = true", r"\[cam_01\]\.fisheye: expected false"),
        ("rotation = [ 0.0, 0.0, 0.0,]\n", "", r"\[cam_01\]: missing rotation"),
        ("size = [ 1088.0, 1920.0,]", "size = [ 1088.5, 1920.0,]", r"\.size: expected \[width"),
        (
            "[ 0.0, 0.0, 1.0,],]",
            "[ 0.0, 0.0, 2.0,],]",
            r"\[cam_01\] \(matrix as K\) \('cam01'\)\.K: expected \[\[fx",
        ),
        ('"cam01"', "7", r"\[cam_01\]\.name: expected a non-empty string"),
        ("0.0007,", '"x",', r"\.distortions: expected a \(4,\) array of numbers"),
        ("[cam_01]", "[cam_01", r"Calib\.toml: not valid TOML"),
        ("matrix", "matrx", r"expected one table per camera"),
    ],
)
def test_malformed_refused(tmp_path: Path, old: str, new: str, match: str) -> None:
    p = tmp_path / "Calib.toml"
    assert old in POSE2SIM_TOML
    p.write_text(POSE2SIM_TOML.replace(old, new, 1), encoding="utf-8")
    with pytest.raises(FormatError, match=match):
        read_calib_toml(p)


def test_round_trip(tmp_path: Path) -> None:
    cams = _cams()
    path = tmp_path / "out" / "Calib.toml"
    write_calib_toml(path, cams)
    back = load_cameras(path)
    assert [c.name for c in back] == ["left", "right cam"]
    for a, b in zip(cams, back):
        assert a.image_size == b.image_size
        np.testing.assert_array_equal(a.K, b.K)
        np.testing.assert_array_equal(a.dist, b.dist)
        np.testing.assert_allclose(b.camera_from_world, a.camera_from_world, atol=1e-9)
    assert "translation = [" in path.read_text("utf-8")
    assert [p.name for p in path.parent.iterdir()] == ["Calib.toml"]


def test_load_cameras_names_a_folder_and_a_missing_file(tmp_path: Path) -> None:
    with pytest.raises(FormatError, match=r"expected a calibration file, found a folder"):
        load_cameras(tmp_path)
    with pytest.raises(FormatError, match=r"Calib\.toml: calibration file not found"):
        load_cameras(tmp_path / "Calib.toml")
    write_cameras(tmp_path / "c.json", _cams())
    with pytest.raises(FormatError, match=r"c\.json: a translation unit \('m'\) is only read"):
        load_cameras(tmp_path / "c.json", unit="m")


def test_demo_qualisys_through_calib_toml_is_the_same_rig(
    shared_data: Path, tmp_path: Path
) -> None:
    qca = load_cameras(shared_data / QCA_RELATIVE)
    write_calib_toml(tmp_path / "Calib.toml", qca)
    back = load_cameras(tmp_path / "Calib.toml")
    assert [c.name for c in back] == ["cam01", "cam02", "cam03", "cam04"]
    point = np.array([200.0, -300.0, 900.0])
    for a, b in zip(qca, back):
        np.testing.assert_allclose(b.project(point), a.project(point), atol=1e-6)
