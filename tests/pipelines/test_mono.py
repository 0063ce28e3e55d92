"""The mono runner and CLI on a small session written in the test."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from mocapkit.cli.main import main
from mocapkit.errors import ConfigError, SessionError
from mocapkit.eval.metrics import evaluate_result
from mocapkit.io.cameras import write_cameras
from mocapkit.io.session import write_session_json
from mocapkit.io.session_csv import write_keypoints_csv
from mocapkit.io.truth import Truth
from mocapkit.pipelines.mono import track_mono
from mocapkit.pipelines.mono_accuracy import write_openpose_with_bystander
from mocapkit.pipelines.run import FIT_FILE
from mocapkit.skeleton.model import CANONICAL_JOINTS, UPPER_BODY_JOINTS
from mocapkit.tracking.base import DelayedTracker, FrameResult
from mocapkit.tracking.mono.stick import stick_model
from mocapkit.tracking.mono.stream import (
    MonoResult,
    MonoSample,
    MonoStream,
    output_skeleton,
    to_world,
    world_points,
)
from mocapkit.tracking.mono.tracker import MonoConfig, MonoTracker
from tests.tracking.mono.test_tracker import FPS, camera, stick_motion

N = 30


def _session(folder: Path, lengths: bool = False, n: int = N) -> Path:
    joints, names, _ = stick_motion(n)
    cam = camera()
    folder.mkdir()
    t = np.arange(n) / FPS
    px = cam.project(joints)
    write_cameras(folder / "cameras.json", [cam])
    (folder / "keypoints").mkdir()
    write_keypoints_csv(folder / "keypoints" / "mono.csv", t, names, px)
    Truth(t, names, joints).save(folder / "truth.npz")
    subject: dict[str, object] = {"height_mm": 1700.0}
    if lengths:
        subject["bone_lengths_mm"] = {
            "trunk": 480.0, "head": 110.0, "left_clavicle": 184.4, "right_clavicle": 184.4,
            "left_upper_arm": 300.0, "right_upper_arm": 300.0, "left_forearm": 270.0,
            "right_forearm": 270.0,
        }  # fmt: skip
    write_session_json(folder / "session.json", {"subject": subject, "rates": {"video_hz": FPS}})
    return folder


def test_track_mono_writes_the_result_folder_and_fit(tmp_path: Path) -> None:
    session = _session(tmp_path / "s", lengths=True)
    run = track_mono(session, tmp_path / "r", use_session_lengths=True)
    for f in ("motion.npz", "joints.csv", "motion.bvh", FIT_FILE):
        assert (tmp_path / "r" / f).is_file()
    with open(tmp_path / "r" / FIT_FILE, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == N and {"residual_px", "survivors", "candidates"} <= set(rows[0])
    summary = run.summary()
    assert summary["posed_frames"] == N
    assert 0.0 <= summary["pruned_share_mean"] <= 1.0
    rep = evaluate_result(tmp_path / "r", session, joints=UPPER_BODY_JOINTS)
    assert rep.coverage == 1.0
    assert rep.pa_mpjpe_mm < 40.0
    # measured lengths put the subject at its true depth: MPJPE close to PA-MPJPE
    assert rep.mpjpe_mm < 80.0


def _stick_openpose_folder(folder: Path) -> None:
    """Write the stick motion's projection as OpenPose JSON with a bystander. The detector
    also sees hips a little below the pelvis (the stick has none)."""
    from mocapkit.io.openpose import MAPPED_JOINTS

    joints, jn, _ = stick_motion(N)
    px = camera().project(joints)
    full = np.full((N, len(MAPPED_JOINTS), 2), np.nan)
    for i, n in enumerate(jn):
        full[:, MAPPED_JOINTS.index(n)] = px[:, i]
    pelvis = px[:, jn.index("pelvis")]
    full[:, MAPPED_JOINTS.index("left_hip")] = pelvis + np.array([20.0, 8.0])
    full[:, MAPPED_JOINTS.index("right_hip")] = pelvis + np.array([-20.0, 8.0])
    write_openpose_with_bystander(folder, MAPPED_JOINTS, full, seed=1)


def test_cli_video_lengths_and_openpose_input(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    session = _session(tmp_path / "s")
    assert main(["track", "mono", str(session), "--out", str(tmp_path / "r"), "--json"]) == 0
    assert '"survivors_mean"' in capsys.readouterr().out
    names = UPPER_BODY_JOINTS
    _stick_openpose_folder(tmp_path / "op")
    code = main(
        ["track", "mono", str(session), "--out", str(tmp_path / "r2"), "--keypoints",
         str(tmp_path / "op"), "--lag", "4", "--cost", "rotation"]
    )  # fmt: skip
    assert code == 0
    rep = evaluate_result(tmp_path / "r2", session, joints=names)
    assert rep.coverage == 1.0


def test_session_lengths_must_be_complete(tmp_path: Path) -> None:
    session = _session(tmp_path / "s")
    with pytest.raises(SessionError, match="bone_lengths_mm lacks"):
        track_mono(session, None, use_session_lengths=True)


def test_bench_mono_reports_its_figures() -> None:
    from mocapkit.pipelines.bench import BENCHMARKS

    out = BENCHMARKS["mono"](repeats=1, n_frames=12)
    assert out["fps"] > 0 and out["first_order_fps"] > 0 and out["offline_fps"] > 0
    assert out["image_fps"] > 0 and out["image_2d_fps"] > 0 and out["fps_wall"] > 0
    assert 0.0 <= float(out["pruned_share"]) <= 1.0
    assert float(out["survivors_mean"]) <= float(out["candidates_mean"])
    # the start-up apart, in a fresh process: the import and the session's load take time
    assert float(out["startup_import_s"]) > 0 and float(out["startup_session_s"]) > 0
    assert float(out["startup_total_s"]) == pytest.approx(
        sum(float(out[f"startup_{k}_s"]) for k in ("import", "session", "kernels"))
    )


def test_bench_frames_are_read_back_by_skin_tracking() -> None:
    """The image path of the benchmark: the drawn frames give the head, and each
    forearm's two ends, back within 2 px. Which end is the elbow follows the paper's
    rule (the end nearer the neck), which is wrong while a raised hand is nearer the
    neck than its elbow: frames 0-21 of this sequence for the left arm."""
    from mocapkit.pipelines.mono_bench import _camera, mono_sequence, skin_frames
    from mocapkit.tracking.mono.skin_tracking import SKIN_JOINTS, SkinTracker

    joints, _, model, _ = mono_sequence(20)
    cam = _camera(+1.0)
    px = cam.project(joints)
    tr = SkinTracker(trunk_from_head=True)
    got = np.stack([tr.update(im).joints_px for im in skin_frames(px, model)])

    def col(names: tuple[str, ...], table: tuple[str, ...], pts: np.ndarray) -> np.ndarray:
        return pts[:, [table.index(n) for n in names]]

    head_err = np.linalg.norm(
        col(("head",), SKIN_JOINTS, got) - col(("head",), model.joint_names, px), axis=-1
    )
    assert np.median(head_err) < 2.0
    for side in ("left", "right"):
        ends = (f"{side}_elbow", f"{side}_wrist")
        g, t = col(ends, SKIN_JOINTS, got), col(ends, model.joint_names, px)
        same = np.linalg.norm(g - t, axis=-1).max(axis=1)
        swapped = np.linalg.norm(g - t[:, ::-1], axis=-1).max(axis=1)
        assert np.median(np.minimum(same, swapped)) < 2.0, side
    left = [model.joint_names.index(n) for n in ("neck", "left_elbow", "left_wrist")]
    d_elbow = np.linalg.norm(px[:, left[1]] - px[:, left[0]], axis=-1)
    d_wrist = np.linalg.norm(px[:, left[2]] - px[:, left[0]], axis=-1)
    assert (d_wrist < d_elbow).all()  # the rule's failing case, all 20 frames


def test_mono_scaling_rows() -> None:
    from mocapkit.pipelines.mono_bench import mono_scaling

    rows = mono_scaling(frame_counts=(15,), repeats=1)
    assert [r["links"] for r in rows] == [8.0, 14.0]
    for r in rows:
        assert r["frames"] == 15 and r["online_ms"] > 0 and r["offline_ms"] > 0
        assert 1 <= r["survivors"] <= r["candidates"] <= 2 ** r["links"]


def test_refined_lengths_read_each_link_at_its_own_depth() -> None:
    from mocapkit.pipelines.mono import refined_lengths
    from mocapkit.tracking.mono.stick import stick_model
    from mocapkit.tracking.mono.tracker import MonoFrame
    from tests.tracking.mono.conftest import random_pose

    rng = np.random.default_rng(70)
    model = stick_model()
    frames = []
    true = None
    for k in range(40):
        pos, true = random_pose(rng, model, 0.0 if k % 4 == 0 else 40.0)
        if k % 4 == 0:
            # every link in the plane z = 3000 mm, parallel to the image
            pos[:, 2] = 3000.0
            for i in range(model.n_links):
                d = pos[model.child[i]] - pos[model.parent[i]]
                d[2] = 0.0
                pos[model.child[i]] = pos[model.parent[i]] + true[i] * d / np.linalg.norm(d)
        frames.append(MonoFrame(k, k / 30, pos, 0, 1, 1, False, 0.0, 3000.0))
    assert true is not None
    got = refined_lengths(frames, model, true)
    np.testing.assert_allclose(
        np.linalg.norm(model.link_vectors(frames[0].joints_in_camera), axis=1), true
    )
    # off the optical axis a parallel link is not quite normal to its ray: within 2 %
    np.testing.assert_allclose(got, true, rtol=0.02)


def test_no_trunk_in_any_frame_is_refused(tmp_path: Path) -> None:
    session = _session(tmp_path / "s")
    joints, names, _ = stick_motion(N)
    from mocapkit.tracking.mono.stick import stick_model

    model = stick_model()
    px = camera().project(joints[:, [names.index(n) for n in model.joint_names]])
    px[:, model.joint_names.index("pelvis")] = np.nan
    with pytest.raises(SessionError, match="neck and pelvis are seen together in no frame"):
        track_mono(session, None, pixels=px)
    with pytest.raises(ConfigError, match="either --skin or --keypoints"):
        track_mono(session, None, keypoints=tmp_path, skin=True)


@pytest.mark.parametrize("lag", [None, 4])
def test_mono_stream_answers_with_the_stated_latency(lag: int | None) -> None:
    """Online, frame k's result comes with frame k + smooth_lag + lag; offline, all come
    from ``finish``. Either way one world `FrameResult` per frame, in time order, whose
    joints follow the tracker's frame placed in the world."""
    joints, names, _ = stick_motion(N)
    cam = camera()
    px = cam.project(joints)
    cfg = MonoConfig(lag=lag)
    model = stick_model(cfg.legs, cfg.limits)
    idx = [list(names).index(n) for n in model.joint_names]
    lengths = np.array([300.0] * len(model.segments))
    for k in range(len(model.segments)):
        a, b = model.parent[k], model.child[k]
        lengths[k] = np.median(np.linalg.norm(joints[:, idx[b]] - joints[:, idx[a]], axis=-1))
    sk = output_skeleton(model, lengths)
    stream = MonoStream(MonoTracker(lengths, cam, 1.0 / FPS, cfg, model), sk, cam, float("nan"))
    assert isinstance(stream, DelayedTracker)
    got: list[FrameResult] = []
    for k in range(N):
        out = stream.push(MonoSample(k / FPS, px[k, idx]))
        if lag is None:
            assert out == []
        else:
            latency = cfg.smooth_lag + lag
            assert [r.time_s for r in out] == ([(k - latency) / FPS] if k >= latency else [])
        got += out
    got += stream.finish()
    assert [r.time_s for r in got] == [k / FPS for k in range(N)]
    for r in got:
        assert isinstance(r, MonoResult) and r.frame is not None
        assert r.joints_mm.shape == (len(CANONICAL_JOINTS), 3)
        assert set(r.status) == {"head", "left_arm", "right_arm"}
        assert set(r.status.values()) == {"seen"}  # every joint is in every frame
        assert r.fit["residual_px"] == r.frame.residual_px < 1.0
        assert r.fit["survivors"] == r.frame.n_survivors <= r.fit["candidates"]
        neck = r.joints_mm[CANONICAL_JOINTS.index("neck")]
        np.testing.assert_allclose(
            neck, to_world([r.frame], model, cam, cfg, float("nan"))[0, 0], atol=1e-9
        )


def test_cli_arm_prior_weight_reaches_the_tracker(tmp_path: Path) -> None:
    session = _session(tmp_path / "s")
    for w, out in ((None, "default"), ("0", "off"), ("1e6", "strong")):
        extra = [] if w is None else ["--arm-prior-weight", w]
        assert main(["track", "mono", str(session), "--out", str(tmp_path / out), *extra]) == 0
    for out, cfg in (
        ("default", MonoConfig()),
        ("off", MonoConfig(arm_prior_weight=0.0)),
        ("strong", MonoConfig(arm_prior_weight=1e6)),
    ):
        run = track_mono(session, None, config=cfg)
        got = np.load(tmp_path / out / "motion.npz")["joints_mm"]
        assert np.allclose(got, run.motion.joints_mm, equal_nan=True)
    a = np.load(tmp_path / "off" / "motion.npz")["joints_mm"]
    b = np.load(tmp_path / "strong" / "motion.npz")["joints_mm"]
    assert not np.allclose(a, b, equal_nan=True)  # the weight changed the chosen poses


def _joints_csv(path: Path, names: tuple[str, ...], pose: np.ndarray) -> None:
    cols = [f"{n}_{a}_mm" for n in names for a in "xyz"]
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["time_s", *cols])
        w.writerow([0.0, *pose.ravel().tolist()])


def test_a_known_initial_pose_from_a_joints_csv_gives_the_first_frames_true_flips(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """World-frame start (joints.csv, canonical names, any order) -> the camera frame of
    the tracker: the first frame takes the truth's flips on every link out of the image,
    and each of its surviving candidates, given in the world 300 mm deeper, is chosen."""
    from mocapkit.pipelines.mono import initial_pose_from

    session = _session(tmp_path / "s")
    joints, names, _ = stick_motion(N)
    model = stick_model()
    order = list(reversed(range(len(names))))  # the file's order is not the stick's
    _joints_csv(tmp_path / "start.csv", tuple(names[i] for i in order), joints[0, order])
    code = main(
        ["track", "mono", str(session), "--out", str(tmp_path / "r"), "--initial-pose",
         str(tmp_path / "start.csv"), "--json"]
    )  # fmt: skip
    assert code == 0
    with open(tmp_path / "r" / FIT_FILE, newline="") as fh:
        first = int(float(next(csv.DictReader(fh))["flips"]))
    truth_cam = camera().to_camera(joints[0, [names.index(n) for n in model.joint_names]])
    dz = truth_cam[model.child, 2] - truth_cam[model.parent, 2]
    counted = np.abs(dz) > 0.2 * np.linalg.norm(model.link_vectors(truth_cam), axis=-1)
    assert counted.sum() >= 3
    bits = (first >> np.arange(model.n_links)) & 1
    np.testing.assert_array_equal(bits[counted], (dz[counted] > 0).astype(int))
    # the same start through the API
    start = initial_pose_from(names, joints[0], model)
    run = track_mono(session, None, initial_pose=start)
    assert run.frames[0].code == first
    from mocapkit.tracking.mono.graph import PoseGraph

    firsts = []
    add = PoseGraph.add

    def keeping(self: PoseGraph, *args, **kwargs) -> list:  # type: ignore[no-untyped-def,type-arg]
        out = add(self, *args, **kwargs)
        if self._n == 1:
            firsts.append(self._layers[0])
        return out

    monkeypatch.setattr(PoseGraph, "add", keeping)
    track_mono(session, None)
    layer = firsts[-1]  # the last pass's first frame
    assert layer.codes.shape[0] >= 2
    for i, code in enumerate(layer.codes):
        world = world_points(camera(), layer.positions[i] + np.array([0.0, 0.0, 300.0]))
        assert track_mono(session, None, initial_pose=world).frames[0].code == code
    with pytest.raises(SessionError, match="expected the joint 'neck'"):
        initial_pose_from(("head", "pelvis"), joints[0, :2], model)


def test_a_known_initial_pose_reaches_the_orthographic_model_in_px(tmp_path: Path) -> None:
    """The orthographic model works in px (depth too): the world-frame start is scaled by
    the image's px per mm; among the first frame's 64 survivors it picks the truth's flips."""
    from mocapkit.pipelines.mono import initial_pose_from

    session = _session(tmp_path / "s")
    joints, names, _ = stick_motion(N)
    model = stick_model()
    cfg = MonoConfig(camera_model="orthographic")
    run = track_mono(
        session, None, config=cfg, initial_pose=initial_pose_from(names, joints[0], model)
    )
    assert run.frames[0].n_survivors >= 32
    truth_cam = camera().to_camera(joints[0, [names.index(n) for n in model.joint_names]])
    dz = truth_cam[model.child, 2] - truth_cam[model.parent, 2]
    counted = np.abs(dz) > 0.2 * np.linalg.norm(model.link_vectors(truth_cam), axis=-1)
    bits = (run.frames[0].code >> np.arange(model.n_links)) & 1
    np.testing.assert_array_equal(bits[counted], (dz[counted] > 0).astype(int))


def test_openpose_input_tracks_with_the_rebuilt_neck_settings(tmp_path: Path) -> None:
    """An OpenPose folder's neck and pelvis are rebuilt: `track_mono` tracks it with
    `detector_config` (the clavicles' wider band, the girdle cost), the same as the
    folder's pixels given with that configuration; the session's keypoints keep the
    plain one."""
    from mocapkit.io.openpose import GIRDLE_COSINE, read_openpose_folder
    from mocapkit.pipelines.mono import detector_config, stick_pixels

    session = _session(tmp_path / "s")
    _stick_openpose_folder(tmp_path / "op")
    cfg = detector_config(MonoConfig())
    assert cfg.rebuilt_joints == ("neck", "pelvis") and cfg.girdle_cosine == GIRDLE_COSINE
    assert GIRDLE_COSINE == pytest.approx((0.205**2 - 0.25) / (0.205**2 + 0.25))
    assert MonoConfig().rebuilt_joints == ()
    run = track_mono(session, None, keypoints=tmp_path / "op")
    model = stick_model()
    kp = read_openpose_folder(tmp_path / "op", np.arange(N) / FPS)
    same = track_mono(session, None, config=cfg, pixels=stick_pixels(kp, model))
    np.testing.assert_array_equal(run.motion.joints_mm, same.motion.joints_mm)
    assert np.isfinite(run.motion.joints_mm).any()


def test_girdle_neck_lies_below_the_shoulders_by_the_girdle_rule() -> None:
    """The paper's neck (shoulders' level) moved to the stick's neck base: the fraction
    d W / (T + d W) of the way from the shoulder midpoint to the pelvis, with W the
    shoulder width that the clavicle ratio gives for d = 0.205 (0.178)."""
    from mocapkit.io.openpose import NECK_BELOW_SHOULDERS as d
    from mocapkit.pipelines.mono import girdle_neck_px
    from mocapkit.tracking.mono.lengths import ANTHROPOMETRIC_RATIOS as r
    from mocapkit.tracking.mono.skin_tracking import SKIN_JOINTS

    w = r["left_clavicle"] / np.sqrt(0.25 + d * d)
    frac = d * w / (r["trunk"] + d * w)
    assert frac == pytest.approx(0.178, abs=5e-4)
    px = np.full((2, len(SKIN_JOINTS), 2), np.nan)
    col = SKIN_JOINTS.index
    px[:, col("left_shoulder")] = (160.0, 100.0)
    px[:, col("right_shoulder")] = (100.0, 100.0)
    px[:, col("pelvis")] = (130.0, 200.0)
    px[:, col("neck")] = (131.0, 99.0)
    px[1, col("pelvis")] = np.nan  # no belt: the paper's neck is kept
    neck = girdle_neck_px(px, SKIN_JOINTS)
    np.testing.assert_allclose(neck[0], (130.0, 100.0 + 100.0 * frac))
    np.testing.assert_allclose(neck[1], (131.0, 99.0))


def test_costume_skin_options_are_the_costumes_settings_with_overrides() -> None:
    from mocapkit.pipelines.mono import SKIN_SETTINGS, SkinOptions, costume_skin_options

    paper = costume_skin_options("paper")
    assert paper == SKIN_SETTINGS["paper"]
    assert paper.belt is True and paper.bare_from == "elbow" and paper.girdle_neck is True
    everyday = costume_skin_options("everyday", bare_from=None)
    assert everyday == SkinOptions(bare_from=None, trunk_from_head=True)
    with pytest.raises(ConfigError, match="costume: expected one of paper, everyday, found 'gala'"):
        costume_skin_options("gala")


def test_truth_in_camera_is_the_stick_joints_seen_from_the_camera(tmp_path: Path) -> None:
    from mocapkit.io.session import load_session
    from mocapkit.pipelines.mono_accuracy import truth_in_camera

    folder = _session(tmp_path / "s")
    joints, names, _ = stick_motion(N)
    model = stick_model()
    cam = camera()
    got = truth_in_camera(load_session(folder), cam.name, model)
    idx = [list(names).index(n) for n in model.joint_names]
    np.testing.assert_allclose(got, cam.to_camera(joints[:, idx]))
    assert got.shape == (N, model.n_joints, 3)
    (folder / "truth.npz").unlink()
    with pytest.raises(SessionError, match="expected truth.npz to measure against, found none"):
        truth_in_camera(load_session(folder), cam.name, model)


def test_depth_error_splits_the_placement_from_the_world_error(tmp_path: Path) -> None:
    """An answer that is the truth scaled about the camera by 1.1 (same image) is placed
    0.1 x the neck's depth too far and has no error left at the true depth; an unposed
    frame is left out."""
    from dataclasses import replace

    from mocapkit.io.session import load_session
    from mocapkit.pipelines.mono_accuracy import depth_error, truth_in_camera
    from mocapkit.pipelines.mono_frames import MonoFrames

    folder = _session(tmp_path / "s")
    run = track_mono(folder, None)
    true_cam = truth_in_camera(load_session(folder), camera().name, run.model)
    far = [replace(f, joints_in_camera=1.1 * true_cam[i]) for i, f in enumerate(run.frames)]
    far[0] = replace(far[0], joints_in_camera=np.full_like(true_cam[0], np.nan))
    dz, at_depth = depth_error(replace(run, frames=MonoFrames(far)), true_cam, UPPER_BODY_JOINTS)
    neck = run.model.joint_names.index("neck")
    assert dz == pytest.approx(0.1 * np.median(true_cam[1:, neck, 2]))
    assert at_depth == pytest.approx(0.0, abs=1e-9)


def test_the_feet_on_the_floor_place_the_neck_by_default(tmp_path: Path) -> None:
    """With an ankle seen standing below the neck, the neck lands where the truth has it
    (its depth from the floor, its image from the tracker); with ``on_floor`` False, or
    the weak-perspective model, or no ankles, at the depth from the link lengths."""
    from mocapkit.tracking.mono.placement import ANKLE_SHARE, FloorConfig

    session = _session(tmp_path / "s")
    joints, names, _ = stick_motion(N)
    neck = joints[:, names.index("neck")]
    foot = neck.copy()
    foot[:, 2] = ANKLE_SHARE * 1700.0
    ankles = np.stack([camera().project(foot), np.full((N, 2), np.nan)], axis=1)
    placed = track_mono(session, None, ankles_px=ankles)
    free = track_mono(session, None, ankles_px=ankles, placement=FloorConfig(on_floor=False))
    got = placed.motion.joints_mm[:, placed.motion.joint_names.index("neck")]
    own = free.motion.joints_mm[:, free.motion.joint_names.index("neck")]
    err = np.linalg.norm(got - neck, axis=1)
    assert np.nanmax(err) < 5.0
    assert np.nanmean(err) < 0.5 * np.nanmean(np.linalg.norm(own - neck, axis=1))
    assert placed.summary()["on_floor_share"] == 1.0
    assert free.summary()["on_floor_share"] == 0.0
    weak = track_mono(session, None, ankles_px=ankles, config=MonoConfig(camera_model="weak"))
    assert weak.summary()["on_floor_share"] == 0.0
    assert track_mono(session, None).summary()["on_floor_share"] == 0.0  # no ankles


def test_the_ankle_points_of_a_named_detector_are_lifted_by_its_offsets(tmp_path: Path) -> None:
    """The backend that wrote the keypoints is read from the detection's detect.json (the
    session's own keypoints, or a CSV or OpenPose folder in the detection's layout; none
    elsewhere), and the floor cuts its ankle points' rays at its known ankle offset."""
    import json

    from mocapkit.io.session import load_session
    from mocapkit.pipelines.mono import keypoints_backend, online_mono_stream
    from mocapkit.tracking.mono.placement import detector_ankle_lift_mm
    from mocapkit.tracking.multiview.detector_offsets import detector_offsets

    session = load_session(_session(tmp_path / "s", lengths=True))
    det = tmp_path / "det"
    (det / "keypoints" / "openpose" / "mono").mkdir(parents=True)
    (det / "keypoints" / "mono.csv").write_text("")
    assert keypoints_backend(session, "mono") is None  # no detect.json: unknown origin
    (det / "keypoints" / "detect.json").write_text(json.dumps({"mono": {"backend": "mediapipe"}}))
    assert (
        keypoints_backend(session, "mono", det / "keypoints" / "openpose" / "mono") == "mediapipe"
    )
    assert keypoints_backend(session, "mono", det / "keypoints" / "mono.csv") == "mediapipe"
    assert keypoints_backend(session, "mono", tmp_path / "elsewhere" / "mono") is None
    cfg = MonoConfig(lag=5)
    lift = detector_ankle_lift_mm(detector_offsets("mediapipe"))
    assert lift > 0.0
    stream = online_mono_stream(session, "mono", cfg, 1.0 / FPS, ankles=True, backend="mediapipe")
    assert stream.floor is not None and stream.floor.ankle_lift_mm == lift
    plain = online_mono_stream(session, "mono", cfg, 1.0 / FPS, ankles=True)
    assert plain.floor is not None and plain.floor.ankle_lift_mm == 0.0


def test_a_named_detectors_offsets_are_taken_out_of_the_limbs_video_lengths() -> None:
    """Lengths read between MediaPipe's points (its known offsets added to each joint at
    the body model's rest pose) come back as the joints' lengths on the limbs, to first
    order; the links from the neck keep what the points show; unknown origin: unchanged."""
    from mocapkit.pipelines.mono import detector_corrected_lengths
    from mocapkit.skeleton.kinematics import canonical_positions
    from mocapkit.skeleton.model import CANONICAL_SEGMENTS
    from mocapkit.tracking.multiview.detector_offsets import MIDPOINTS, detector_offsets
    from mocapkit.tracking.multiview.tracker import multiview_skeleton

    sk = multiview_skeleton()
    names = list(sk.canonical_names)
    rest = canonical_positions(sk, sk.zero_pose())
    off = {k: np.asarray(v) for k, v in detector_offsets("mediapipe").items()}
    for mid, (a, b) in MIDPOINTS.items():
        off[mid] = 0.5 * (off[a] + off[b])
    model = stick_model(legs=True)

    def length(seg: str, shifted: bool) -> float:
        a, b = CANONICAL_SEGMENTS[seg]
        oa, ob = (off.get(a, np.zeros(3)), off.get(b, np.zeros(3))) if shifted else (0.0, 0.0)
        return float(np.linalg.norm(rest[names.index(b)] + ob - rest[names.index(a)] - oa))

    true = np.array([length(s, False) for s in model.segments])
    seen = np.array([length(s, True) for s in model.segments])
    i = {s: model.segments.index(s) for s in ("left_upper_arm", "right_forearm", "trunk")}
    assert seen[i["left_upper_arm"]] < true[i["left_upper_arm"]] - 20.0  # its elbow point is up
    assert seen[i["right_forearm"]] > true[i["right_forearm"]] + 20.0
    got = detector_corrected_lengths(seen, model, "mediapipe")
    from_neck = model.parent == 0
    np.testing.assert_array_equal(got[from_neck], seen[from_neck])
    np.testing.assert_allclose(got[~from_neck], true[~from_neck], atol=1.0)
    assert seen[i["trunk"]] < true[i["trunk"]] - 10.0  # kept as seen: the depth's bound
    np.testing.assert_array_equal(detector_corrected_lengths(seen, model, None), seen)


def test_detector_3d_on_canonical_joints_is_measured_like_the_tracker(tmp_path: Path) -> None:
    """A detector's 3-D that is the truth turned, scaled and moved scores 0 mm after the
    per-frame alignment; the neck and pelvis follow the girdle rule in 3-D."""
    from mocapkit.io.openpose import BODY_25, NECK_BELOW_SHOULDERS, PELVIS_ABOVE_HIPS
    from mocapkit.pipelines.mono_accuracy import (
        canonical_from_body25_world,
        detector3d_accuracy,
    )

    rng = np.random.default_rng(3)
    T = 4
    ls, rs = np.array([200.0, 0, 1400]), np.array([-200.0, 0, 1400])
    lh, rh = np.array([100.0, 0, 900]), np.array([-100.0, 0, 900])
    up = np.array([0.0, 0, 1])
    width = 400.0
    neck = 0.5 * (ls + rs) - NECK_BELOW_SHOULDERS * width * up
    pelvis = 0.5 * (lh + rh) + PELVIS_ABOVE_HIPS * width * up
    head = np.array([0.0, 20, 1600])
    truth_pts = {"head": head, "neck": neck, "pelvis": pelvis, "left_shoulder": ls,
                 "right_shoulder": rs, "left_hip": lh, "right_hip": rh}  # fmt: skip
    joints = np.zeros((T, len(CANONICAL_JOINTS), 3))
    for k, n in enumerate(CANONICAL_JOINTS):
        joints[:, k] = truth_pts.get(n, rng.normal(scale=300.0, size=(T, 3)) + up * 1000.0)
    truth = Truth(np.arange(T) / 30.0, CANONICAL_JOINTS, joints, (), np.zeros((T, 0, 3)))
    # the detector's points: the truth's joints turned about z by 30 deg, halved, moved
    c, s = np.cos(np.pi / 6), np.sin(np.pi / 6)
    rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    body = {"LShoulder": "left_shoulder", "RShoulder": "right_shoulder", "LHip": "left_hip",
            "RHip": "right_hip", "LElbow": "left_elbow", "LWrist": "left_wrist",
            "RElbow": "right_elbow", "RWrist": "right_wrist", "LKnee": "left_knee",
            "RKnee": "right_knee", "LAnkle": "left_ankle", "RAnkle": "right_ankle"}  # fmt: skip
    world = np.full((T, len(BODY_25), 3), np.nan)
    for det, can in body.items():
        world[:, BODY_25.index(det)] = joints[:, CANONICAL_JOINTS.index(can)]
    ear = np.array([30.0, 0, 0])
    world[:, BODY_25.index("LEar")] = head + ear
    world[:, BODY_25.index("REar")] = head - ear
    world = 0.5 * world @ rot.T + [5.0, -7.0, 11.0]
    names, mapped = canonical_from_body25_world(world)
    back = (mapped - [5.0, -7.0, 11.0]) @ rot / 0.5
    for n in ("neck", "pelvis", "head"):
        np.testing.assert_allclose(back[:, names.index(n)], np.tile(truth_pts[n], (T, 1)),
                                   atol=1e-9)  # fmt: skip
    path = tmp_path / "cam.npz"
    np.savez(path, time_s=truth.time_s, names=np.array(BODY_25), world_mm=world)
    upper, arms = detector3d_accuracy(path, truth)
    assert upper == pytest.approx(0.0, abs=1e-6)
    assert arms == pytest.approx(0.0, abs=1e-6)
    world[:, BODY_25.index("LWrist")] += [0.0, 0.0, 100.0]
    np.savez(path, time_s=truth.time_s, names=np.array(BODY_25), world_mm=world)
    assert detector3d_accuracy(path, truth)[1] > 1.0
    assert np.isnan(detector3d_accuracy(tmp_path / "none.npz", truth)[0])


def test_arm_swaps_counts_swapped_input_frames_and_those_the_answer_puts_right() -> None:
    """Input arms swapped left for right on frames 2-4, the answer still swapped on frame
    3 alone: 3 swapped, 2 handled; a frame with unknown points counts as not swapped."""
    from mocapkit.pipelines.mono_accuracy import ARM_JOINTS, arm_swaps

    rng = np.random.default_rng(5)
    names = ("neck", *ARM_JOINTS)
    true = np.zeros((8, len(names), 2))
    true[:, 1:4] = [[260.0, 200.0], [250.0, 260.0], [255.0, 320.0]]  # left arm
    true[:, 4:7] = [[380.0, 200.0], [390.0, 260.0], [385.0, 320.0]]  # right arm
    true += rng.normal(scale=2.0, size=true.shape)
    mirror = [0, 4, 5, 6, 1, 2, 3]
    inp = true + rng.normal(scale=3.0, size=true.shape)
    inp[2:5] = inp[2:5][:, mirror]
    inp[6, 2] = np.nan
    out = true.copy()
    out[3] = out[3][mirror]
    assert arm_swaps(inp, out, true, names) == (3, 2)
    assert arm_swaps(true, true, true, names) == (0, 0)
    with pytest.raises(ValueError, match="not in"):
        arm_swaps(inp, out, true, ("neck",))
