"""Tests of the hybrid tracker on one-sided (partial) marker sets."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.cli.main import main
from mocapkit.errors import ConfigError, ShapeError
from mocapkit.io.joints_csv import read_joints_csv
from mocapkit.io.marker_sets import evaluate_marker_sets
from mocapkit.pipelines.hybrid import hybrid_skeleton
from mocapkit.pipelines.hybrid_markers import track_hybrid_marker_arrays, track_hybrid_marker_file
from mocapkit.pipelines.run import read_fit_csv
from mocapkit.skeleton import canonical_positions
from mocapkit.tracking.hybrid.tracker import HybridConfig, default_marker_effectors

#: Vicon Z-up to OpenSim Y-up (x kept, file y = Vicon z, file z = -Vicon y).
YUP_FROM_ZUP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
BASKET_SETS = ["head=Forehead+TempleL+EarL", "left_hand=HandL"]


def test_one_hand_set_leaves_the_other_arm_out(tmp_path):
    sk = hybrid_skeleton(1750.0)
    q = np.zeros((20, sk.n_dofs))
    q[:, sk.dof_index("l_shoulder_flexion")] = np.linspace(0.0, 1.2, 20)
    pts = canonical_positions(sk, q, ["head", "left_wrist"])
    t = np.arange(20) / 50.0
    _, qs, poses = track_hybrid_marker_arrays(
        t,
        {"head": pts[:, 0], "left_hand": pts[:, 1]},
        1750.0,
        HybridConfig(use_video=False, paper=True),
        out_dir=tmp_path,
    )
    assert np.isfinite(qs).all()
    assert max(p.residual_mm["left_hand"] for p in poses) <= 2.0
    assert all("right_hand_mm" not in p.fit for p in poses)
    _, names, joints = read_joints_csv(tmp_path / "joints.csv")
    for j in ("right_elbow", "right_wrist"):
        assert np.isnan(joints[:, names.index(j)]).all()
    for j in ("left_elbow", "left_wrist", "right_shoulder"):
        assert np.isfinite(joints[:, names.index(j)]).all()
    _, fit = read_fit_csv(tmp_path / "fit.csv")
    assert "right_hand_mm" not in fit and "left_hand_mm" in fit


def test_partial_sets_need_head_and_a_hand():
    t = np.arange(3.0)
    with pytest.raises(ShapeError, match="missing marker set 'left_hand/right_hand'"):
        track_hybrid_marker_arrays(t, {"head": np.zeros((3, 3))}, 1700.0)
    with pytest.raises(ShapeError, match="missing marker set 'head'"):
        track_hybrid_marker_arrays(t, {"left_hand": np.zeros((3, 3))}, 1700.0)


def test_basket_sprint_left_side_only(shared_data, tmp_path):
    """The wheelchair sprint (left side instrumented), stored Z-up and Y-up: same left elbow
    within 1 mm, and no right arm."""
    from mocapkit.io.lab_frame import detect_lab_frame
    from mocapkit.io.marker_files import read_markers
    from mocapkit.io.marker_sets import evaluate_marker_sets
    from mocapkit.io.markers import MarkerData

    m = read_markers(shared_data / "c3d" / "kinematics_basket_sprint.c3d")
    part = slice(1650, 1800)  # the hand marker is seen from frame 1622 to 2158
    runs = []
    for lab_from_orig in (np.eye(3), YUP_FROM_ZUP):
        whole = MarkerData(m.time_s, m.names, m.positions_mm @ lab_from_orig.T, m.rate_hz)
        # the up axis is found on the whole take (on these 150 frames of a forward lean
        # the head is as far ahead as above: the detection says it is not sure there)
        head = evaluate_marker_sets(whole, BASKET_SETS[0])[:, 0]
        up = detect_lab_frame(whole, head).up
        lab = MarkerData(m.time_s[part], m.names, whole.positions_mm[part], m.rate_hz, m.source)
        runs.append(track_hybrid_marker_file(lab, BASKET_SETS, height_mm=1750.0, up=up))
    z_run, y_run = runs
    assert (z_run.frame.up, y_run.frame.up) == ("z", "y")
    z_elbow = z_run.motion.joint("left_elbow")
    np.testing.assert_allclose(y_run.motion.joint("left_elbow") @ YUP_FROM_ZUP, z_elbow, atol=1.0)
    assert np.isnan(z_run.motion.joint("right_elbow")).all()
    assert {s for r in z_run.results for s in r.fit} >= {"head_mm", "left_hand_mm"}
    assert not any("right_hand_mm" in r.fit for r in z_run.results)
    # the left arm is reported wherever its hand set is seen
    seen = np.isfinite(m.trajectory("BodyL:HandL")[part]).all(axis=1)
    assert np.isfinite(z_elbow[seen]).all()


def test_one_hand_only_head_refused(shared_data):
    from mocapkit.io.marker_files import read_markers

    m = read_markers(shared_data / "c3d" / "kinematics_basket_sprint.c3d")
    with pytest.raises(ConfigError, match="marker_sets: the hybrid tracker needs marker set"):
        track_hybrid_marker_file(m, ["head=Forehead+TempleL+EarL"])


def test_cli_lab_frame_options(tmp_path, capsys):
    args = ["track", "hybrid", "--markers", str(tmp_path / "none.c3d"), "--out", str(tmp_path)]
    assert main([*args, "--up", "w"]) == 2
    assert "--up: expected one of x, y, z, -x, -y, -z, found 'w'" in capsys.readouterr().err
    assert main([*args, "--warn-fraction", "2"]) == 2
    assert "--warn-fraction: expected a share in [0, 1]" in capsys.readouterr().err
    assert main(["track", "hybrid", str(tmp_path), "--up", "z", "--out", str(tmp_path)]) == 2
    assert "--up apply to --markers" in capsys.readouterr().err


def test_basket_sprint_seated_auto_z_up_and_y_up(shared_data):
    """The wheelchair sprint is taken as seated by ``auto`` (head low for the stature from
    the reach), the same way stored Z-up and Y-up: same seat, same left elbow within
    1 mm, legs NaN, no feet planted."""
    from mocapkit.io.lab_frame import detect_lab_frame
    from mocapkit.io.marker_files import read_markers
    from mocapkit.io.marker_sets import evaluate_marker_sets
    from mocapkit.io.markers import MarkerData

    m = read_markers(shared_data / "c3d" / "kinematics_basket_sprint.c3d")
    part = slice(1650, 1800)
    runs = []
    for lab_from_orig in (np.eye(3), YUP_FROM_ZUP):
        whole = MarkerData(m.time_s, m.names, m.positions_mm @ lab_from_orig.T, m.rate_hz)
        up = detect_lab_frame(whole, evaluate_marker_sets(whole, BASKET_SETS[0])[:, 0]).up
        lab = MarkerData(m.time_s[part], m.names, whole.positions_mm[part], m.rate_hz, m.source)
        runs.append(track_hybrid_marker_file(lab, BASKET_SETS, up=up, posture="auto"))
    z_run, y_run = runs
    for run in runs:
        assert run.posture is not None and run.posture.posture == "seated"
        assert "auto:" in run.posture.reason and "head-to-hand reach" in run.posture.reason
    assert y_run.posture.seat_height_mm == pytest.approx(z_run.posture.seat_height_mm, abs=1.0)
    assert y_run.posture.height_mm == pytest.approx(z_run.posture.height_mm, abs=1.0)
    np.testing.assert_allclose(
        y_run.motion.joint("left_elbow") @ YUP_FROM_ZUP, z_run.motion.joint("left_elbow"), atol=1.0
    )
    for j in ("left_knee", "right_ankle", "left_hip"):
        assert np.isnan(z_run.motion.joint(j)).all()
    assert all(np.isnan(r.fit["left_foot_mm"]) for r in z_run.results)
    assert max(r.fit["head_mm"] for r in z_run.results) < 30.0


def test_seated_as_asked_with_given_stature(shared_data):
    """``seated`` as asked, with the stature given: the seat comes from the head set at
    that stature; an unknown posture is refused."""
    from mocapkit.io.marker_files import read_markers
    from mocapkit.io.markers import MarkerData
    from mocapkit.tracking.hybrid.posture import UPRIGHT_PERCENTILE, pelvis_to_head_mm

    m = read_markers(shared_data / "c3d" / "kinematics_basket_sprint.c3d")
    part = slice(1650, 1700)
    lab = MarkerData(m.time_s[part], m.names, m.positions_mm[part], m.rate_hz, m.source)
    run = track_hybrid_marker_file(lab, BASKET_SETS, height_mm=1600.0, up="z", posture="seated")
    assert run.posture is not None and run.posture.reason.startswith("as asked")
    assert "(given)" in run.posture.reason and run.posture.height_mm == 1600.0
    sk = hybrid_skeleton(1600.0, proportions="anthropometric")  # the raw path's model
    head = evaluate_marker_sets(lab, BASKET_SETS[0])[:, 0, 2]
    point = default_marker_effectors(sk)["head"].point_mm
    want = np.nanpercentile(head, UPRIGHT_PERCENTILE) - pelvis_to_head_mm(sk, point)
    assert run.posture.seat_height_mm == pytest.approx(want, abs=1e-6)
    with pytest.raises(ConfigError, match="--posture: expected one of standing, seated, auto"):
        track_hybrid_marker_file(lab, BASKET_SETS, up="z", posture="lying")


def test_cli_posture_and_static_options(tmp_path, capsys):
    args = ["track", "hybrid", "--markers", str(tmp_path / "none.c3d"), "--out", str(tmp_path)]
    with pytest.raises(SystemExit) as exited:
        main([*args, "--posture", "lying"])
    assert exited.value.code == 2
    assert "invalid choice: 'lying'" in capsys.readouterr().err
    assert (
        main(["track", "hybrid", str(tmp_path), "--static", "x.c3d", "--out", str(tmp_path)]) == 2
    )
    assert "--static apply to --markers" in capsys.readouterr().err
    assert main([*args, "--no-static-calibration", "--calibration", "dynamic"]) == 2
    assert (
        "--no-static-calibration means --calibration none; found --calibration dynamic"
        in capsys.readouterr().err
    )
    session = ["track", "hybrid", str(tmp_path), "--out", str(tmp_path)]
    assert main([*session, "--calibration", "dynamic"]) == 2
    assert "--calibration apply to --markers" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main([*args, "--calibration", "functional"])
    assert "invalid choice: 'functional'" in capsys.readouterr().err
