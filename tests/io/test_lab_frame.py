"""Tests of the lab-frame detection (up axis and floor) and its use by the hybrid pipeline."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.io.lab_frame import UP_AXES, LabFrame, detect_lab_frame, parse_up, to_world
from mocapkit.io.marker_sets import evaluate_marker_sets
from mocapkit.io.markers import MarkerData

#: Vicon Z-up to OpenSim Y-up (x kept, file y = Vicon z, file z = -Vicon y).
YUP_FROM_ZUP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])

TENNIS = (
    "kinematics_tennis_serve.c3d",
    ["head=LFHD+RFHD+LBHD+RBHD", "left_hand=LWRA+LWRB", "right_hand=RWRA+RWRB"],
)
BASKET = ("kinematics_basket_sprint.c3d", ["head=Forehead+TempleL+EarL", "left_hand=HandL"])


def _rotated(m: MarkerData, lab_from_orig: np.ndarray, n: int | None = None) -> MarkerData:
    n = m.n_frames if n is None else n
    return MarkerData(
        m.time_s[:n], m.names, m.positions_mm[:n] @ lab_from_orig.T, m.rate_hz, m.source
    )


@pytest.mark.parametrize("up", UP_AXES)
def test_world_from_lab_is_a_rotation_taking_up_to_z(up):
    frame = LabFrame(up, 0.0, "given", True)
    r = frame.world_from_lab
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)
    axis = np.zeros(3)
    axis["xyz".index(up[-1])] = -1.0 if up.startswith("-") else 1.0
    np.testing.assert_allclose(r @ axis, [0.0, 0.0, 1.0], atol=1e-12)


def test_lab_world_round_trip_and_floor(rng):
    frame = LabFrame("-y", 250.0, "given", True)
    p = rng.normal(size=(7, 4, 3)) * 1000.0
    w = frame.world_from_lab_points(p)
    # the height above the floor is the coordinate along -y minus the floor
    np.testing.assert_allclose(w[..., 2], -p[..., 1] - 250.0)
    np.testing.assert_allclose(frame.lab_from_world_points(w), p, atol=1e-9)


def test_parse_up():
    assert parse_up(" +Z") == "z"
    assert parse_up("-Y") == "-y"
    with pytest.raises(ConfigError, match="--up: expected one of x, y, z, -x, -y, -z, found 'up'"):
        parse_up("up")


def _synthetic_standing(rng, up: str, floor_mm: float) -> tuple[MarkerData, np.ndarray]:
    """A 'body' in a Z-up world: feet markers near the floor, head 1.6 m up, hands swinging,
    walking along x; then put in a frame whose up axis is ``up`` with its floor at floor_mm."""
    t = np.arange(200) / 100.0
    walk = np.stack([300.0 * t, 50.0 * np.sin(t), np.zeros_like(t)], axis=1)
    local = np.array(
        [
            [0, -100, 40],
            [0, 100, 40],
            [0, 0, 1000],
            [0, -200, 1400],
            [0, 200, 1400],
            [0, 0, 1650],
            [50, 0, 1620],
        ],
        dtype=float,
    )
    pos = walk[:, None] + local[None] + rng.normal(scale=5.0, size=(t.size, len(local), 3))
    pos[:, 3:5, 0] += 300.0 * np.sin(3 * t)[:, None]
    pos[..., 2] += floor_mm
    frame = LabFrame(up, 0.0, "given", True)
    lab = pos @ frame.world_from_lab  # world_from_lab is orthonormal: its transpose inverts it
    names = ("lt", "rt", "pel", "lh", "rh", "hd1", "hd2")
    return MarkerData(t, names, lab, 100.0), lab[:, 5:7].mean(axis=1)


@pytest.mark.parametrize("up", UP_AXES)
def test_detects_synthetic_up_and_floor(rng, up):
    markers, head = _synthetic_standing(rng, up, 400.0)
    found = detect_lab_frame(markers, head)
    assert (found.up, found.method, found.sure) == (up, "head", True)
    # the lowest markers sit 40 mm above the floor: the floor found is theirs
    assert found.floor_mm == pytest.approx(400.0 + 40.0, abs=20.0)
    by_extent = detect_lab_frame(markers)
    assert (by_extent.up, by_extent.method) == (up, "extent")
    assert detect_lab_frame(markers, head, up="x").method == "given"


@pytest.mark.parametrize(("name", "sets"), [TENNIS, BASKET])
def test_shared_c3d_z_up_and_as_y_up(shared_data, name, sets):
    from mocapkit.io.marker_files import read_markers

    m = read_markers(shared_data / "c3d" / name)
    for lab_from_orig, up in ((np.eye(3), "z"), (YUP_FROM_ZUP, "y")):
        lab = _rotated(m, lab_from_orig)
        head = evaluate_marker_sets(lab, sets[0])[:, 0]
        found = detect_lab_frame(lab, head)
        assert (found.up, found.sure) == (up, True), found.summary()
    # both frames give the same world
    z_frame = detect_lab_frame(m, evaluate_marker_sets(m, sets[0])[:, 0])
    y_lab = _rotated(m, YUP_FROM_ZUP)
    y_frame = detect_lab_frame(y_lab, evaluate_marker_sets(y_lab, sets[0])[:, 0])
    np.testing.assert_allclose(
        to_world(y_lab, y_frame).positions_mm, to_world(m, z_frame).positions_mm, atol=1e-9
    )


def test_tennis_y_up_tracks_like_z_up(shared_data, tmp_path):
    """The same take stored Y-up (as an OpenSim TRC) gives the same elbows, in its frame,
    with the member offsets calibrated on the still start (default) or on the motion."""
    from mocapkit.io.joints_csv import read_joints_csv
    from mocapkit.io.marker_files import read_markers
    from mocapkit.pipelines.hybrid_markers import track_hybrid_marker_file

    m = read_markers(shared_data / "c3d" / TENNIS[0])
    n = 150
    dyn_z = track_hybrid_marker_file(_rotated(m, np.eye(3), n), TENNIS[1], calibration="dynamic")
    dyn_y = track_hybrid_marker_file(_rotated(m, YUP_FROM_ZUP, n), TENNIS[1], calibration="dynamic")
    assert "dynamic: member offsets calibrated on the motion" in dyn_y.calibration_note
    z_run = track_hybrid_marker_file(_rotated(m, np.eye(3), n), TENNIS[1])
    y_run = track_hybrid_marker_file(_rotated(m, YUP_FROM_ZUP, n), TENNIS[1], out_dir=tmp_path)
    assert (z_run.frame.up, y_run.frame.up) == ("z", "y")
    assert "static: member offsets" in y_run.calibration_note
    for z, y in ((z_run, y_run), (dyn_z, dyn_y)):
        for side in ("left", "right"):
            z_elbow = z.motion.joint(f"{side}_elbow")
            y_elbow = y.motion.joint(f"{side}_elbow")
            # outputs are in each file's frame: map the Y-up one back to compare
            np.testing.assert_allclose(y_elbow @ YUP_FROM_ZUP, z_elbow, atol=1.0)
    # joints.csv is written in the file's (Y-up) frame
    _, names, written_mm = read_joints_csv(tmp_path / "joints.csv")
    np.testing.assert_allclose(
        written_mm[:, names.index("left_elbow")], y_run.motion.joint("left_elbow"), atol=1e-3
    )
