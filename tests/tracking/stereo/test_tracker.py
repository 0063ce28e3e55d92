"""The stereo tracker on small rendered sessions: two and three views, keypoints and skin blobs,
a blackout, the CLI."""

from __future__ import annotations

import time

import numpy as np
import pytest

from mocapkit.cli.main import main
from mocapkit.errors import ConfigError, UnknownNameError
from mocapkit.io.session import load_session
from mocapkit.pipelines.fit_report import SHOWN_SPANS
from mocapkit.pipelines.run import FIT_FILE, read_fit_csv
from mocapkit.pipelines.stereo import (
    ARM_JOINTS,
    ElbowJump,
    arm_errors_per_frame,
    bench_stereo,
    elbow_jump_warnings,
    elbow_jumps,
    elbow_jumps_in_folder,
    evaluate_stereo,
    frames_to_converge,
    parse_cameras,
    track_stereo_session,
)
from mocapkit.skeleton.model import CANONICAL_JOINTS
from mocapkit.synth.realism import RealismOptions
from mocapkit.synth.session_writer import SynthOptions, synthesize_session
from mocapkit.timing import StageTimer
from mocapkit.tracking.base import STATUSES, FrameResult
from mocapkit.tracking.stereo.arm_filter import ArmFilterConfig
from mocapkit.tracking.stereo.hands import keypoint_targets
from mocapkit.tracking.stereo.tracker import (
    KEYPOINT_TORSO_SHOULDER_BOX_MM,
    StereoConfig,
    StereoSample,
    StereoTracker,
    azad_skeleton,
)


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    out = tmp_path_factory.mktemp("stereo") / "wave"
    synthesize_session(
        "builtin:wave",
        out,
        SynthOptions(
            rig="all",
            seconds=0.5,
            image_size=(320, 240),
            sleeve="long",
            video_format="png",
            blackout_s=(0.2, 0.1),
            realism=RealismOptions(blur=0.0),
        ),
    )
    return out


SMALL = StereoConfig(arm=ArmFilterConfig(n_particles=40))


def test_blackout_blanks_every_view_and_its_keypoints(session):
    s = load_session(session)
    t = s.truth.time_s
    blank = (t >= 0.2) & (t < 0.3)
    assert blank.any() and not blank.all()
    for k, smp in enumerate(s.samples()):
        for cam in s.camera_names:
            img = smp.image(cam)
            assert (img.max() == 0) == bool(blank[k])
            kp = s.keypoints[cam].pixels[k]
            assert np.all(np.isnan(kp)) or not blank[k]


@pytest.mark.parametrize(
    ("cams", "torso"),
    [("stereo_left,stereo_right", "shoulders"), (None, "shoulders"), (None, "keypoints")],
)
def test_keypoint_tracking_over_two_and_three_views(session, cams, torso):
    cfg = StereoConfig(arm=SMALL.arm, use_keypoints=True, torso=torso)
    run = track_stereo_session(session, None, cameras=cams, config=cfg)
    m = run.motion
    assert m.n_frames == load_session(session).truth.time_s.shape[0]
    assert np.all(np.isfinite(m.joints_mm))
    ev = evaluate_stereo(run, session)
    assert set(ev["per_joint_mm"]) == set(ARM_JOINTS)
    # wrists are measured directly: they stay close whenever the views see them
    assert ev["per_joint_mm"]["right_wrist"] < 60.0
    # IK samples (60 % of 40) in the first run whenever both hands are measured, none
    # while the views are blank
    t = m.time_s
    blank = (t >= 0.2) & (t < 0.3)
    assert np.all(run.n_ik[blank] == 0)
    assert np.all(run.n_ik[~blank] == 24)
    if torso == "keypoints":  # the torso's yaw is the truth's wherever the views see it
        assert ev["torso_yaw_error_deg"] < 10.0


@pytest.mark.parametrize(("gap_limit_s", "lost"), [(0.25, "bridged"), (0.05, "released")])
def test_blackout_hands_are_bridged_then_released_never_held_as_seen(
    session, tmp_path, gap_limit_s, lost
):
    """The 0.1 s blackout: every measured point is ``bridged`` within the gap limit and
    ``released`` after it; a released arm's elbow and wrist are NaN in the FrameResult
    and its hand distance is NaN; fit.csv carries the same statuses."""
    cfg = StereoConfig(arm=SMALL.arm, use_keypoints=True, gap_limit_s=gap_limit_s)
    run = track_stereo_session(session, tmp_path / "r", config=cfg)
    assert all(isinstance(r, FrameResult) for r in run.results)
    t = run.motion.time_s
    blank = (t >= 0.2) & (t < 0.3)
    names = ("head", "left_hand", "right_hand")
    for r, b in zip(run.results, blank):
        assert r.joints_mm.shape == (len(CANONICAL_JOINTS), 3)
        assert set(r.status) == set(names) and set(r.status.values()) <= set(STATUSES)
        if not b:
            assert all(r.status[n] == "seen" for n in names)
            assert np.isfinite(r.fit["left_hand_mm"]) and np.isfinite(r.fit["rms_mm"])
            continue
        assert np.isnan(r.fit["left_hand_mm"]) and np.isnan(r.fit["right_hand_mm"])
        assert all(r.status[n] in ("bridged", "released") for n in names)
        for side in ("left", "right"):
            arm_rows = [CANONICAL_JOINTS.index(f"{side}_{j}") for j in ("elbow", "wrist")]
            released = r.status[f"{side}_hand"] == "released"
            assert np.all(np.isnan(r.joints_mm[arm_rows])) == released
    statuses = {r.status["left_hand"] for r, b in zip(run.results, blank) if b}
    assert lost in statuses
    rows, _ = read_fit_csv(tmp_path / "r" / FIT_FILE)
    assert [row["left_hand_status"] for row in rows] == [r.status["left_hand"] for r in run.results]


def test_skin_blob_tracking_runs_and_finds_the_head(session):
    run = track_stereo_session(session, None, config=SMALL)
    assert np.all(np.isfinite(run.motion.q))
    s = load_session(session)
    head = s.truth.joints_mm[:, list(s.truth.joint_names).index("head")]
    seen = np.all(np.isfinite(run.measured_mm[:, 0]), axis=1)
    assert seen.sum() >= 0.5 * seen.shape[0]
    assert np.median(np.linalg.norm(run.measured_mm[seen, 0] - head[seen], axis=1)) < 100.0


def test_elbow_jump_limit_is_checked():
    with pytest.raises(ConfigError, match="elbow_jump_mm_per_s: expected > 0 mm/s, found 0"):
        StereoConfig(elbow_jump_mm_per_s=0.0)


def test_keypoint_torso_needs_keypoints():
    with pytest.raises(ConfigError, match="use_keypoints"):
        StereoConfig(torso="keypoints")
    with pytest.raises(ConfigError, match="torso"):
        StereoConfig(torso="pelvis")


def test_camera_choice_is_checked():
    with pytest.raises(UnknownNameError, match="camera"):
        parse_cameras("stereo_left,nope", ["stereo_left", "stereo_right"])
    with pytest.raises(ConfigError, match="two or more"):
        parse_cameras("stereo_left", ["stereo_left", "stereo_right"])


def test_subject_skeleton_takes_the_session_measurements(session):
    s = load_session(session)
    sk = azad_skeleton(s.bone_lengths_mm, s.segment_vectors_mm)
    from mocapkit.skeleton.kinematics import canonical_positions

    names = ("left_shoulder", "left_elbow", "left_wrist", "neck")
    p = canonical_positions(sk, sk.zero_pose(), names)
    assert np.linalg.norm(p[1] - p[0]) == pytest.approx(s.bone_lengths_mm["left_upper_arm"])
    assert np.linalg.norm(p[2] - p[1]) == pytest.approx(s.bone_lengths_mm["left_forearm"])
    np.testing.assert_allclose(p[0] - p[3], s.segment_vectors_mm["left_clavicle"], atol=1e-9)


def test_cli_track_stereo(session, tmp_path, capsys):
    out = tmp_path / "res"
    rc = main(
        [
            "track",
            "stereo",
            str(session),
            "--out",
            str(out),
            "--keypoints",
            "--particles",
            "30",
            "--cameras",
            "stereo_left,stereo_right,mono",
            "--torso",
            "keypoints",
            "--fixed-shoulders",
        ]
    )
    assert rc == 0
    for f in ("motion.npz", "joints.csv", "motion.bvh", FIT_FILE):
        assert (out / f).is_file()
    rows, numeric = read_fit_csv(out / FIT_FILE)
    assert len(rows) == load_session(session).truth.time_s.shape[0]
    assert {"left_hand_mm", "right_hand_mm", "left_arm_edge_error"} <= set(numeric)
    assert {"right_elbow_speed_mm_per_s", "right_elbow_jump"} <= set(numeric)
    # the elbows' speeds: from the second frame on wherever the elbow is reported
    assert np.isnan(numeric["left_elbow_speed_mm_per_s"][0])
    assert np.isfinite(numeric["left_elbow_speed_mm_per_s"][1])
    assert elbow_jumps_in_folder(out) == elbow_jumps(numeric["time_s"], numeric)
    text = capsys.readouterr().out
    assert "arm mean" in text and "torso yaw" in text


def test_elbow_jumps_known_spans():
    """Flagged frames become one span per run of consecutive flags, per side, in time order;
    a fit without the columns (another tracker's) has none."""
    t = np.arange(6) / 30.0
    fit = {
        "left_elbow_jump": [0, 1, 1, 0, 0, 1],
        "left_elbow_speed_mm_per_s": [np.nan, 7000, 9000, 100, 100, 6500],
        "right_elbow_jump": [0, 0, 0, 1, 0, 0],
        "right_elbow_speed_mm_per_s": [np.nan, 100, 100, 12000, 100, 100],
    }
    assert elbow_jumps(t, fit) == [
        ElbowJump("left", t[1], t[2], 2, 9000.0),
        ElbowJump("right", t[3], t[3], 1, 12000.0),
        ElbowJump("left", t[5], t[5], 1, 6500.0),
    ]
    assert str(elbow_jumps(t, fit)[0]) == (
        "the left elbow jumps at 0.03-0.07 s (2 frames), up to 9.0 m/s relative to the shoulder"
    )
    assert str(elbow_jumps(t, fit)[1]).startswith("the right elbow jumps at 0.10 s, up to 12.0")
    assert elbow_jumps(t, {"rms_mm": np.zeros(6)}) == []


def test_elbow_jump_warnings_list_the_fastest_then_count_the_rest():
    """Many jumps: one warning with a count, the fastest few, and how many more (as the
    implausible-motion warning lists its spans), not a line per jump."""
    jumps = [ElbowJump("right", i / 30.0, i / 30.0, 1, 6000.0 + i) for i in range(19)]
    jumps.append(ElbowJump("left", 1.0, 1.1, 4, 5000.0))
    lines = elbow_jump_warnings(jumps, shown=2)
    assert lines[0].startswith("warning: an elbow jumps in 20 spans (23 frames): the arm filter")
    assert lines[1:] == [
        "  the right elbow jumps at 0.60 s, up to 6.0 m/s relative to the shoulder",
        "  the right elbow jumps at 0.57 s, up to 6.0 m/s relative to the shoulder",
        "  ... and 18 more (fit.csv)",
    ]
    assert len(elbow_jump_warnings(jumps)) == 1 + SHOWN_SPANS + 1
    one = elbow_jump_warnings(jumps[-1:])
    assert one[0].startswith("warning: an elbow jumps in 1 span (4 frames)")
    assert one[1:] == [f"  {jumps[-1]}"]
    assert elbow_jump_warnings([]) == []


def test_an_elbow_moving_faster_than_the_limit_is_a_jump(session):
    """The tracker's per-frame check: the elbow's speed relative to its shoulder, flagged
    above `StereoConfig.elbow_jump_mm_per_s`; forgotten when the arms are reset."""
    s = load_session(session)
    names = ["stereo_left", "stereo_right"]
    tracker = StereoTracker(azad_skeleton(), [s.camera(c) for c in names], SMALL)
    joints = np.zeros((len(CANONICAL_JOINTS), 3))

    def ests(elbow_x_mm: float) -> dict:
        pts = np.array([[0.0, 0, 0], [elbow_x_mm, 0, -280], [0, 0, -500], [0, 0, -520]])
        return {side: type("Est", (), {"points_mm": pts})() for side in ("left", "right")}

    first = tracker._elbow_jumps(0.0, ests(0.0), joints)
    assert np.isnan(first["left_elbow_speed_mm_per_s"]) and first["left_elbow_jump"] == 0.0
    limit = SMALL.elbow_jump_mm_per_s
    slow = tracker._elbow_jumps(0.1, ests(0.09 * limit), joints)
    assert slow["right_elbow_speed_mm_per_s"] == pytest.approx(0.9 * limit)
    assert slow["right_elbow_jump"] == 0.0
    fast = tracker._elbow_jumps(0.2, ests(0.09 * limit + 0.11 * limit), joints)
    assert fast["right_elbow_speed_mm_per_s"] == pytest.approx(1.1 * limit)
    assert fast["right_elbow_jump"] == 1.0
    joints[CANONICAL_JOINTS.index("left_elbow")] = np.nan  # not reported: no speed
    hidden = tracker._elbow_jumps(0.3, ests(0.0), joints)
    assert np.isnan(hidden["left_elbow_speed_mm_per_s"]) and hidden["left_elbow_jump"] == 0.0
    tracker.reset_arms()
    assert np.isnan(tracker._elbow_jumps(0.4, ests(5000.0), joints)["right_elbow_speed_mm_per_s"])


def test_arm_rois_hold_every_elbow_on_the_circle(session):
    """The gradient maps are computed only in the arm RoIs: every arm pose that reaches the
    measured hand (any alpha) must project inside them."""
    import math

    from mocapkit.ik.arm_analytic import arm_ik, make_problem
    from mocapkit.tracking.stereo.tracker import StereoTracker, yaw_matrix

    s = load_session(session)
    sk = azad_skeleton(s.bone_lengths_mm, s.segment_vectors_mm)
    cams = [s.camera(c) for c in ("stereo_left", "stereo_right")]
    tracker = StereoTracker(sk, cams)
    rng = np.random.default_rng(0)
    for _ in range(10):
        rb = yaw_matrix(rng.uniform(-0.5, 0.5))
        root = np.array([0.0, 0.0, 1400.0]) + rng.normal(0, 50, 3)
        hands = {}
        for side in ("left", "right"):
            sh = root + rb @ (tracker.shoulder_off[side] + tracker.head_off)
            a, b = tracker.lengths[side]
            d = rng.normal(size=3)
            hands[side] = sh + rng.uniform(0.3, 0.95) * (a + b) * d / np.linalg.norm(d)
        rois = tracker._arm_rois(root, rb, hands)
        for side in ("left", "right"):
            sh = root + rb @ (tracker.shoulder_off[side] + tracker.head_off)
            a, b = tracker.lengths[side]
            prob = make_problem(rb, sh, hands[side], a, b)
            _q, elbows = arm_ik(prob, np.linspace(-math.pi, math.pi, 72))
            for cam, roi in zip(cams, rois):
                assert roi is not None
                px = cam.project(np.vstack([elbows, sh, hands[side]]))
                x0, y0, x1, y1 = roi
                inside = (px[:, 0] >= x0) & (px[:, 0] < x1) & (px[:, 1] >= y0) & (px[:, 1] < y1)
                in_image = cam.in_image(px)
                assert np.all(inside | ~in_image)


def test_cli_refuses_a_keypoint_torso_without_keypoints(session, tmp_path, capsys):
    rc = main(
        ["track", "stereo", str(session), "--out", str(tmp_path / "r"), "--torso", "keypoints"]
    )
    assert rc == 2
    assert "--torso keypoints needs --keypoints" in capsys.readouterr().err


def test_stage_timer_times_every_stage_of_each_frame(session):
    s = load_session(session)
    names = ["stereo_left", "stereo_right"]
    cams = [s.camera(c) for c in names]
    timer = StageTimer(time.process_time)
    tracker = StereoTracker(azad_skeleton(), cams, SMALL, timer=timer)
    n = 4
    for k, smp in enumerate(s.samples(names)):
        if k == n:
            break
        tracker.update(StereoSample(smp.time_s, {c: smp.image(c) for c in names}))
    assert timer.calls() == {"skin": n, "head_hands": n, "gradients": n, "arms": n}
    assert all(v >= 0.0 for v in timer.totals_s().values())


def test_bench_reports_fps_and_per_stage_ms_at_two_particle_counts(session):
    out = bench_stereo(session, n_frames=3, repeats=1, n_particles=20, more_particles=40)
    assert out["fps"] > 0 and out["fps_40_particles"] > 0 and out["particles"] == 20
    assert set(out["stages_ms"]) == {"skin", "head_hands", "gradients", "arms", "other"}
    # the stages and the rest add up to the frame's CPU time (one run: the median is it)
    assert sum(out["stages_ms"].values()) == pytest.approx(1e3 / out["fps"], rel=1e-2)
    assert out["views"] == 2 and out["image_size"] == "320x240"


def test_frames_to_converge_known_values():
    free = np.array([20.0, 20.0, 20.0, 20.0, 20.0, 20.0])
    reset = np.array([20.0, 20.0, 200.0, 90.0, 29.0, 20.0])
    assert frames_to_converge(reset, free, 2, 10.0, 10) == 3  # frames 2, 3, 4: 29 <= 30
    assert frames_to_converge(reset, free, 2, 5.0, 10) == 4
    assert frames_to_converge(reset, free, 0, 10.0, 10) == 1  # on the reset frame already
    assert frames_to_converge(reset, free, 2, 5.0, 2) == 3  # not within the limit
    nan_free = free.copy()
    nan_free[4] = np.nan
    assert frames_to_converge(reset, nan_free, 2, 10.0, 10) == 4  # a NaN frame is not converged


def test_arm_errors_per_frame_leave_nan_joints_out(session):
    truth = load_session(session).truth
    names = list(truth.joint_names)
    joints = truth.joints_mm.copy()
    shift = np.zeros(3)
    shift[0] = 30.0
    joints[:, names.index("left_elbow")] += shift  # one of six joints 30 mm off
    err = arm_errors_per_frame(truth.time_s, names, joints, truth)
    np.testing.assert_allclose(err, 5.0, atol=1e-9)
    joints[:, names.index("left_wrist")] = np.nan  # left out: 30 / 5 joints
    err = arm_errors_per_frame(truth.time_s, names, joints, truth)
    np.testing.assert_allclose(err, 6.0, atol=1e-9)
    for j in ARM_JOINTS:
        joints[:3, names.index(j)] = np.nan
    assert np.all(np.isnan(arm_errors_per_frame(truth.time_s, names, joints, truth)[:3]))


def test_reset_arms_returns_both_filters_to_the_hanging_start(session):
    s = load_session(session)
    names = ["stereo_left", "stereo_right"]
    cfg = StereoConfig(arm=SMALL.arm, use_keypoints=True, torso="keypoints")
    kp_names = s.keypoints["stereo_left"].joint_names
    tracker = StereoTracker(azad_skeleton(), [s.camera(c) for c in names], cfg, kp_names)
    start = {side: f.particles.copy() for side, f in tracker.filters.items()}
    for k, smp in enumerate(s.samples(names)):
        if k == 3:
            break
        tracker.update(StereoSample(smp.time_s, {c: smp.image(c) for c in names}, smp.keypoints_px))
    assert not np.array_equal(tracker.filters["left"].particles, start["left"])
    tracker.reset_arms()
    for side, f in tracker.filters.items():
        np.testing.assert_array_equal(f.particles, start[side])


@pytest.mark.parametrize("anchor", ["neck", "shoulders"])
def test_torso_anchor_places_the_model_on_its_keypoints(session, anchor):
    """With fixed shoulders the model's neck (anchor "neck") or its shoulders' midpoint
    (anchor "shoulders") is the triangulated keypoint's."""
    s = load_session(session)
    names = ["stereo_left", "stereo_right"]
    cams = [s.camera(c) for c in names]
    arm_cfg = ArmFilterConfig(n_particles=20, adaptive_shoulder=False)
    cfg = StereoConfig(arm=arm_cfg, use_keypoints=True, torso="keypoints", torso_anchor=anchor)
    kp_names = s.keypoints["stereo_left"].joint_names
    sk = azad_skeleton(s.bone_lengths_mm, s.segment_vectors_mm)
    tracker = StereoTracker(sk, cams, cfg, kp_names)
    for k, smp in enumerate(s.samples(names)):
        if k == 2:
            break
        pose = tracker.update(StereoSample(smp.time_s, {}, smp.keypoints_px))
        kps = [np.asarray(smp.keypoints_px[c]) for c in names]
        want = ("neck",) if anchor == "neck" else ("left_shoulder", "right_shoulder")
        measured = keypoint_targets(cams, kps, kp_names, want).mean(axis=0)
        model = np.mean([pose.joints_mm[CANONICAL_JOINTS.index(j)] for j in want], axis=0)
        np.testing.assert_allclose(model, measured, atol=1e-6)


def test_torso_anchor_refusals(session, tmp_path, capsys):
    with pytest.raises(ConfigError, match="torso_anchor: expected 'shoulders' or 'neck'"):
        StereoConfig(torso_anchor="hips")
    out = str(tmp_path / "r")
    rc = main(["track", "stereo", str(session), "--out", out, "--torso-anchor", "shoulders"])
    assert rc == 2
    assert "--torso-anchor needs --torso keypoints" in capsys.readouterr().err


def test_a_keypoint_torso_confines_the_shoulder_offsets(session):
    s = load_session(session)
    names = ["stereo_left", "stereo_right"]
    cams = [s.camera(c) for c in names]
    kp_names = s.keypoints["stereo_left"].joint_names

    def tracker(torso, box=None):
        arm_cfg = ArmFilterConfig(n_particles=30, shoulder_box_mm=box)
        cfg = StereoConfig(arm=arm_cfg, use_keypoints=True, torso=torso)
        return StereoTracker(azad_skeleton(), cams, cfg, kp_names)

    assert tracker("shoulders").arm_config.shoulder_box_mm is None  # recipe A's 50 mm
    assert tracker("shoulders", 35.0).arm_config.shoulder_box_mm == 35.0
    assert tracker("keypoints", 35.0).arm_config.shoulder_box_mm == 35.0
    t = tracker("keypoints")
    assert t.arm_config.shoulder_box_mm == KEYPOINT_TORSO_SHOULDER_BOX_MM
    for k, smp in enumerate(s.samples(names)):
        if k == 4:
            break
        t.update(StereoSample(smp.time_s, {c: smp.image(c) for c in names}, smp.keypoints_px))
        for f in t.filters.values():
            assert np.abs(f.particles[:, 4:]).max() <= KEYPOINT_TORSO_SHOULDER_BOX_MM
    t.reset_arms()  # the reset keeps the resolved settings
    for f in t.filters.values():
        assert f.config.shoulder_box_mm == KEYPOINT_TORSO_SHOULDER_BOX_MM
    with pytest.raises(ConfigError, match="shoulder_box_mm: expected >= 0 mm"):
        ArmFilterConfig(shoulder_box_mm=-1.0)


def test_cli_accuracy_stereo_refuses_too_few_particles(capsys):
    rc = main(["accuracy", "stereo", "--particles", "1"])
    assert rc == 2
    assert "--particles: expected at least 2, found 1" in capsys.readouterr().err
