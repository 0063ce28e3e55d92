"""Evaluation metrics: zero on the truth, known figures on known perturbations, time matching."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from mocapkit.cli.main import main
from mocapkit.errors import ConfigError, SessionError, ShapeError
from mocapkit.eval.metrics import (
    evaluate_joints,
    evaluate_result,
    joint_subset,
    match_by_time,
    similarity_align,
)
from mocapkit.geometry.rotations import matrix_from_rotvec
from mocapkit.io.motion import Motion
from mocapkit.io.motion_files import write_result_folder
from mocapkit.io.session import write_session_json
from mocapkit.io.truth import Truth
from mocapkit.skeleton import CANONICAL_JOINTS
from mocapkit.synth.builtin_motions import builtin_motion


@pytest.fixture(scope="module")
def truth() -> tuple[np.ndarray, tuple[str, ...], np.ndarray]:
    m = builtin_motion("table-tennis", duration_s=2.0)
    # truth at 30 Hz like a session's video frames
    keep = np.arange(0, m.n_frames, 4)
    return np.asarray(m.time_s)[keep], m.joint_names, np.asarray(m.joints_mm)[keep]


def test_truth_against_itself_is_zero(truth):
    t, names, j = truth
    r = evaluate_joints(t, names, j, t, names, j)
    assert r.mpjpe_mm == 0.0
    assert r.pa_mpjpe_mm == pytest.approx(0.0, abs=1e-9)
    assert r.elbow_mm == 0.0
    assert r.coverage == 1.0
    assert all(v == 0.0 for v in r.per_joint_mm.values())
    assert r.jitter_mm_s2 == pytest.approx(r.truth_jitter_mm_s2)
    assert r.truth_jitter_mm_s2 > 0
    assert r.joints == tuple(c for c in CANONICAL_JOINTS if c in names)


def test_left_elbow_perturbation_gives_known_figures(truth):
    t, names, j = truth
    est = j.copy()
    k = names.index("left_elbow")
    est[:, k, 1] += 10.0
    r = evaluate_joints(t, names, est, t, names, j)
    assert r.per_joint_mm["left_elbow"] == pytest.approx(10.0)
    assert r.per_joint_mm["right_elbow"] == 0.0
    assert r.elbow_mm == pytest.approx(5.0)
    assert r.mpjpe_mm == pytest.approx(10.0 / len(names))
    # a constant offset adds no acceleration
    assert r.jitter_mm_s2 == pytest.approx(r.truth_jitter_mm_s2)


def test_constant_offset_and_similarity_transform(truth):
    t, names, j = truth
    r = evaluate_joints(t, names, j + np.array([12.0, -16.0, 0.0]), t, names, j)
    assert r.mpjpe_mm == pytest.approx(20.0)
    assert r.pa_mpjpe_mm == pytest.approx(0.0, abs=1e-6)
    rot = matrix_from_rotvec(np.array([0.2, -0.4, 0.9]))
    moved = 1.15 * j @ rot.T + np.array([300.0, -50.0, 20.0])
    r2 = evaluate_joints(t, names, moved, t, names, j)
    assert r2.mpjpe_mm > 100.0
    assert r2.pa_mpjpe_mm == pytest.approx(0.0, abs=1e-6)


def _pa_and_mpjpe(est: np.ndarray, ref: np.ndarray) -> tuple[float, float, float, float]:
    """Per-frame mean and RMS error of one frame, before and after alignment."""
    err = np.linalg.norm(est - ref, axis=-1)
    aligned = np.linalg.norm(similarity_align(est, ref) - ref, axis=-1)
    return (
        float(aligned.mean()),
        float(err.mean()),
        float(np.sqrt((aligned**2).mean())),
        float(np.sqrt((err**2).mean())),
    )


def test_pa_mpjpe_is_the_least_squares_alignment_on_the_same_joints(truth, rng):
    """PA-MPJPE is MPJPE after each frame's least-squares similarity alignment, on the
    same joints and frames: it never exceeds MPJPE in the RMS it minimises, and is below
    MPJPE when the errors are spread over the joints; one joint's large error, spread
    over the others by least squares, can put it above MPJPE (what the report explains)."""
    t, names, j = truth
    for f in range(0, j.shape[0], 5):  # RMS: never above, whatever the errors
        est = j[f] + rng.normal(scale=30.0, size=j[f].shape) * rng.uniform(0, 3, (len(names), 1))
        _, _, pa_rms, rms = _pa_and_mpjpe(est, j[f])
        assert pa_rms <= rms + 1e-9
    noisy = j + rng.normal(scale=15.0, size=j.shape)  # errors spread over the joints
    r = evaluate_joints(t, names, noisy, t, names, j)
    assert r.pa_mpjpe_mm <= r.mpjpe_mm
    per_frame = [_pa_and_mpjpe(noisy[f], j[f])[0] for f in range(j.shape[0])]
    assert r.pa_mpjpe_mm == pytest.approx(float(np.mean(per_frame)))
    upper = evaluate_joints(t, names, noisy, t, names, j, joints=("head", "neck", "pelvis"))
    per_frame = [_pa_and_mpjpe(noisy[f, :3], j[f, :3])[0] for f in range(j.shape[0])]
    assert upper.joints == ("head", "neck", "pelvis") == tuple(names[:3])
    assert upper.pa_mpjpe_mm == pytest.approx(float(np.mean(per_frame)))
    one_off = j.copy()  # a known case: one joint 200 mm off, the others exact
    one_off[:, names.index("pelvis"), 2] += 200.0
    r = evaluate_joints(t, names, one_off, t, names, j)
    assert r.mpjpe_mm == pytest.approx(200.0 / len(names))
    assert r.pa_mpjpe_mm > r.mpjpe_mm


def test_similarity_align_recovers_points(rng):
    pts = rng.normal(size=(10, 3)) * 300
    rot = matrix_from_rotvec(rng.normal(size=3))
    src = 0.8 * pts @ rot.T + 40.0
    np.testing.assert_allclose(similarity_align(src, pts), pts, atol=1e-8)


def test_matching_is_by_time_stamp_not_index(truth):
    t, names, j = truth
    dt = float(np.median(np.diff(t)))
    # every other truth frame, stamped 0.3 frame late: still matched, zero error
    sub = np.arange(0, len(t), 2)
    r = evaluate_joints(t[sub] + 0.3 * dt, names, j[sub], t, names, j)
    assert r.coverage == pytest.approx(len(sub) / len(t))
    assert r.mpjpe_mm == 0.0
    # the same samples shifted by a whole frame are compared with the next truth frame
    shifted = evaluate_joints(t[:-1] + dt, names, j[:-1], t, names, j)
    assert shifted.coverage == pytest.approx((len(t) - 1) / len(t))
    assert shifted.mpjpe_mm > 1.0


def test_match_by_time_tolerance():
    tt = np.array([0.0, 0.1, 0.2, 0.3])
    rt = np.array([0.31, 0.049, 0.24])
    np.testing.assert_array_equal(match_by_time(tt, rt), [1, -1, 2, 0])


def test_nan_result_frames_count_against_coverage(truth):
    t, names, j = truth
    est = j.copy()
    est[:5] = np.nan
    r = evaluate_joints(t, names, est, t, names, j)
    assert r.coverage == pytest.approx((len(t) - 5) / len(t))
    assert r.mpjpe_mm == 0.0


def test_noise_raises_jitter(truth, rng):
    t, names, j = truth
    noisy = j + rng.normal(0, 5.0, j.shape)
    r = evaluate_joints(t, names, noisy, t, names, j)
    assert r.jitter_mm_s2 > 3 * r.truth_jitter_mm_s2


def test_shape_and_vocabulary_errors(truth):
    t, names, j = truth
    with pytest.raises(ShapeError, match="expected joints of shape"):
        evaluate_joints(t, names, j[:, :3], t, names, j)
    with pytest.raises(ShapeError, match="share no joint"):
        evaluate_joints(t, ("head",), j[:, :1], t, names[1:], j[:, 1:])


def test_result_folder_and_cli(tmp_path, truth, capsys):
    m = builtin_motion("squat", duration_s=1.0)
    result = tmp_path / "result"
    write_result_folder(result, m)
    session = tmp_path / "session"
    session.mkdir()
    write_session_json(session / "session.json", {})
    Truth(m.time_s, m.joint_names, m.joints_mm).save(session / "truth.npz")
    r = evaluate_result(result, session)
    assert r.mpjpe_mm == pytest.approx(0.0, abs=1e-9)
    assert r.coverage == 1.0
    # joints.csv alone (no motion.npz) works too; its values are rounded to 1e-6 mm
    (result / "motion.npz").unlink()
    r2 = evaluate_result(result, session / "truth.npz")
    assert r2.mpjpe_mm < 1e-5
    assert main(["eval", str(result), "--truth", str(session), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["coverage"] == 1.0
    assert set(doc["per_joint_mm"]) == set(m.joint_names)
    assert main(["eval", str(result), "--truth", str(session)]) == 0
    assert "mpjpe_mm" in capsys.readouterr().out


def test_missing_result_and_truth(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(SessionError, match="neither motion.npz nor joints.csv"):
        evaluate_result(empty, tmp_path)
    m = builtin_motion("wave", duration_s=0.5)
    write_result_folder(tmp_path / "r", m)
    session = tmp_path / "s"
    session.mkdir()
    write_session_json(session / "session.json", {})
    with pytest.raises(SessionError, match=r"lacks truth\.npz"):
        evaluate_result(tmp_path / "r", session)


def test_motion_result_roundtrip_type():
    m = builtin_motion("wave", duration_s=0.2)
    assert isinstance(m, Motion)


def test_joint_subset_restricts_comparison() -> None:
    from mocapkit.eval.metrics import evaluate_joints, joint_subset
    from mocapkit.skeleton import CANONICAL_JOINTS, UPPER_BODY_JOINTS

    t = np.arange(10) / 30.0
    truth = np.zeros((10, len(CANONICAL_JOINTS), 3))
    result = truth.copy()
    result[:, CANONICAL_JOINTS.index("left_knee"), 0] = 40.0  # a leg error only
    upper = evaluate_joints(
        t, CANONICAL_JOINTS, result, t, CANONICAL_JOINTS, truth, joints=joint_subset("upper")
    )
    assert upper.joints == UPPER_BODY_JOINTS
    assert upper.mpjpe_mm == 0.0
    every = evaluate_joints(t, CANONICAL_JOINTS, result, t, CANONICAL_JOINTS, truth)
    assert every.mpjpe_mm == pytest.approx(40.0 / len(CANONICAL_JOINTS))
    assert joint_subset("left_elbow, right_elbow") == ("left_elbow", "right_elbow")
    with pytest.raises(KeyError, match="unknown canonical joint 'elbows'"):
        joint_subset("elbows")


def test_best_swivel_elbow_known_turn() -> None:
    """An elbow turned by a known angle about the shoulder-wrist axis is turned back onto
    the target: same distances to shoulder and wrist, the turn recovered, floor 0."""
    from mocapkit.eval.metrics import best_swivel_elbow

    rng = np.random.default_rng(15)
    t = 50
    shoulder = rng.normal(0.0, 100.0, (t, 3))
    wrist = shoulder + rng.normal(0.0, 200.0, (t, 3))
    axis = (wrist - shoulder) / np.linalg.norm(wrist - shoulder, axis=1, keepdims=True)
    target = shoulder + rng.normal(0.0, 150.0, (t, 3))
    angle = rng.uniform(-3.0, 3.0, t)
    # the tracked elbow: the target turned by -angle about the shoulder-wrist axis
    elbow = np.array(
        [
            shoulder[i] + matrix_from_rotvec(-angle[i] * axis[i]) @ (target[i] - shoulder[i])
            for i in range(t)
        ]
    )
    best, turn = best_swivel_elbow(shoulder, elbow, wrist, target)
    np.testing.assert_allclose(best, target, atol=1e-6)
    np.testing.assert_allclose(turn, angle, atol=1e-9)
    np.testing.assert_allclose(
        np.linalg.norm(best - shoulder, axis=1), np.linalg.norm(elbow - shoulder, axis=1)
    )
    np.testing.assert_allclose(
        np.linalg.norm(best - wrist, axis=1), np.linalg.norm(elbow - wrist, axis=1)
    )


def test_best_swivel_elbow_floor_and_degenerate() -> None:
    """A target off the elbow's circle leaves a known floor; a straight arm gives NaN;
    shapes must agree."""
    from mocapkit.eval.metrics import best_swivel_elbow

    # shoulder at 0, wrist 400 mm down z, elbow on the circle of radius 100 at z = -200
    s, w, e = np.zeros(3), np.array([0.0, 0.0, -400.0]), np.array([100.0, 0.0, -200.0])
    target = np.array([0.0, 300.0, -250.0])
    best, turn = best_swivel_elbow(s, e, w, target)
    np.testing.assert_allclose(best, [0.0, 100.0, -200.0], atol=1e-9)
    # +x to +y about the shoulder-to-wrist axis -z: a right-handed -90 deg
    assert float(turn) == pytest.approx(-np.pi / 2)
    # floor: 200 mm radially beyond the circle and 50 mm along the axis
    assert float(np.linalg.norm(best - target)) == pytest.approx(np.hypot(200.0, 50.0))
    straight, _ = best_swivel_elbow(s, np.array([0.0, 0.0, -200.0]), w, target)
    assert np.all(np.isnan(straight))
    with pytest.raises(ShapeError, match="expected shoulder, elbow, wrist and target"):
        best_swivel_elbow(np.zeros((2, 3)), np.zeros((3, 3)), np.zeros((2, 3)), np.zeros((2, 3)))


def test_nan_joints_count_against_coverage(truth):
    """`eval` reported coverage 1.000 with the right arm NaN in 79 % of the frames."""
    t, names, j = truth
    est = j.copy()
    arm = [names.index(n) for n in ("right_elbow", "right_wrist")]
    n_nan = round(0.79 * len(t))
    est[:n_nan, arm] = np.nan
    r = evaluate_joints(t, names, est, t, names, j)
    share = n_nan / len(t)
    assert r.per_joint_coverage["right_elbow"] == pytest.approx(1.0 - share)
    assert r.per_joint_coverage["left_elbow"] == 1.0
    assert r.coverage == pytest.approx(1.0 - share * len(arm) / len(names))
    assert r.n_matched_frames == len(t)  # every frame has a pose, not every joint
    assert re.search(r"right_elbow\s+0\.0\s+0\.2\d\d", r.table())


def test_empty_joint_list_is_refused(capsys):
    """`eval --joints ''` was accepted (and compared no joint, or every joint)."""
    with pytest.raises(ConfigError, match=r"--joints: expected 'all', 'upper' or a comma"):
        joint_subset("")
    with pytest.raises(ConfigError, match="found ' , '"):
        joint_subset(" , ")
    with pytest.raises(SystemExit):
        main(["eval", "r", "--truth", "s", "--joints", ""])
    assert "argument --joints: " in capsys.readouterr().err
