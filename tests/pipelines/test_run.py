"""The one runner: any tracker streamed into a result folder with fit.csv."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mocapkit.errors import ShapeError, UnknownNameError
from mocapkit.io.motion_npz import load_motion_npz
from mocapkit.pipelines.run import FIT_FILE, motion_with_held_parts, read_fit_csv, run_tracker
from mocapkit.skeleton import CANONICAL_JOINTS, canonical_positions, load_preset
from mocapkit.skeleton.limbs import arm
from mocapkit.timing import StageTimer
from mocapkit.tracking.base import DelayedTracker, FrameResult, canonical_joints_mm
from mocapkit.tracking.hybrid.tracker import HybridConfig, HybridSample, HybridTracker


class ReplayTracker:
    """A minimal tracker: returns the pose it is given, with a made-up fit figure."""

    def __init__(self, skeleton):
        self.skeleton = skeleton

    def update(self, sample):
        t, q = sample
        joints = canonical_joints_mm(self.skeleton, canonical_positions(self.skeleton, q))
        status = {"left_arm": "seen" if t < 0.05 else "missing"}
        return FrameResult(t, q, joints, status, {"edge_px": 10.0 * t}, "edge_px")


def test_run_tracker_writes_the_result_folder_and_fit(tmp_path) -> None:
    sk = load_preset("upper_stick")
    rng = np.random.default_rng(3)
    q = np.clip(rng.normal(0.0, 0.2, (6, sk.n_dofs)), sk.lower, sk.upper)
    t = np.arange(6) * 0.02
    timer = StageTimer()
    run = run_tracker(
        ReplayTracker(sk), zip(t, q), 6, tmp_path / "res", source="replay", timer=timer
    )
    assert {p.name for p in (tmp_path / "res").iterdir()} == {
        "motion.npz",
        "joints.csv",
        "motion.bvh",
        FIT_FILE,
        "opensim",
    }
    motion = load_motion_npz(tmp_path / "res" / "motion.npz")
    # the left arm missing from the fourth frame: its DoFs held there at the third's
    # (`motion_with_held_parts`, the poses of motion.npz and the BVH alike), the rest as given
    np.testing.assert_allclose(motion.q, motion_with_held_parts(run.motion, run.results).q)
    np.testing.assert_allclose(motion.q[:3], q[:3])
    dofs = arm(sk, "left").dofs
    np.testing.assert_allclose(motion.q[3:, dofs], np.tile(q[2, dofs], (3, 1)))
    right = arm(sk, "right").dofs
    np.testing.assert_allclose(motion.q[:, right], q[:, right])
    np.testing.assert_allclose(motion.time_s, t)
    assert motion.source == "replay" and len(run.results) == 6
    rows, numeric = read_fit_csv(tmp_path / "res" / FIT_FILE)
    assert [r["left_arm_status"] for r in rows] == ["seen"] * 3 + ["missing"] * 3
    np.testing.assert_allclose(numeric["edge_px"], 10.0 * t, atol=1e-6)
    np.testing.assert_allclose(numeric["time_s"], t, atol=1e-9)
    assert {r["worst"] for r in rows} == {"edge_px"}
    assert timer.calls()["track"] == 6 and timer.calls()["write"] == 1
    assert timer.calls()["input"] == 7  # the last draw finds the stream's end


def test_run_tracker_refuses_an_empty_stream() -> None:
    sk = load_preset("upper_stick")
    with pytest.raises(ShapeError, match="replay: no samples to track"):
        run_tracker(ReplayTracker(sk), [], 0, label="replay")


def test_hybrid_through_the_runner_reports_status_and_fit(tmp_path) -> None:
    sk = load_preset("zhang21")
    tracker = HybridTracker(sk, config=HybridConfig(use_video=False))
    q0 = tracker.solver.secondary.omega.copy()
    pos = tracker.solver.effector_positions(q0)[:3]
    samples = [
        HybridSample(
            0.02 * i,
            {"head": pos[0], "left_hand": pos[1] + [0.0, 0.0, 2.0 * i]}
            | ({} if 3 <= i <= 5 else {"right_hand": pos[2]}),
        )
        for i in range(10)
    ]
    timer = StageTimer()
    tracker.timer = timer
    run = run_tracker(tracker, samples, len(samples), tmp_path / "res", timer=timer)
    rows, numeric = read_fit_csv(tmp_path / "res" / FIT_FILE)
    assert [r["right_hand_status"] for r in rows[2:7]] == [
        "seen",
        "bridged",
        "bridged",
        "bridged",
        "seen",
    ]
    assert rows[0]["head_status"] == "seen"
    for key in ("head_mm", "left_hand_mm", "right_hand_mm", "left_foot_mm", "rms_mm", "max_mm"):
        assert key in numeric and numeric[key].shape == (10,)
    assert np.all(numeric["max_mm"] >= numeric["rms_mm"] - 1e-6)
    assert run.results[0].joints_mm.shape == (len(CANONICAL_JOINTS), 3)
    counts = timer.counts()
    assert counts["ik_solves"] >= 10 and counts["ik_iterations"] >= counts["ik_solves"]
    assert {"ik", "balance", "smoothing"} <= set(timer.totals_s())
    assert math.isfinite(numeric["max_mm"][-1])


class ReleasingTracker(ReplayTracker):
    """Replays poses; from 0.05 s the left arm is released and its joints are NaN."""

    def update(self, sample):
        t, q = sample
        joints = canonical_joints_mm(self.skeleton, canonical_positions(self.skeleton, q))
        released = t >= 0.05
        if released:
            joints[CANONICAL_JOINTS.index("left_wrist")] = np.nan
        status = {"left_arm": "released" if released else "seen", "head": "seen"}
        return FrameResult(t, q, joints, status, {}, "")


def test_run_tracker_keeps_nan_joints_and_lists_the_gaps(tmp_path) -> None:
    from mocapkit.io.joints_csv import read_joints_csv

    sk = load_preset("upper_stick")
    q = np.tile(np.clip(np.zeros(sk.n_dofs), sk.lower, sk.upper), (6, 1))
    t = np.arange(6) * 0.02
    run = run_tracker(ReleasingTracker(sk), zip(t, q), 6, tmp_path / "res")
    k = run.motion.joint_names.index("left_wrist")
    assert np.all(np.isfinite(run.motion.joints_mm[:3, k]))
    assert np.all(np.isnan(run.motion.joints_mm[3:, k]))
    assert np.all(np.isfinite(run.motion.q))  # the BVH keeps the pose
    _t, names, joints = read_joints_csv(tmp_path / "res" / "joints.csv")
    assert np.all(np.isnan(joints[3:, names.index("left_wrist")]))
    assert [str(g) for g in run.gaps] == ["left_arm released 0.060-0.100 s (3 frames)"]


class LaggedReplay(ReplayTracker):
    """A `DelayedTracker`: the result of sample k comes with sample k + lag."""

    def __init__(self, skeleton, lag):
        super().__init__(skeleton)
        self.lag = lag
        self.pending = []

    def push(self, sample):
        self.pending.append(self.update(sample))
        return [self.pending.pop(0)] if len(self.pending) > self.lag else []

    def finish(self):
        out, self.pending = self.pending, []
        return out


def test_run_tracker_drains_a_delayed_tracker_and_takes_its_joints(tmp_path) -> None:
    sk = load_preset("upper_stick")
    rng = np.random.default_rng(5)
    q = np.clip(rng.normal(0.0, 0.2, (7, sk.n_dofs)), sk.lower, sk.upper)
    t = np.arange(7) * 0.02
    tracker = LaggedReplay(sk, 3)
    assert isinstance(tracker, DelayedTracker)
    names = ("pelvis", "neck", "left_wrist")
    run = run_tracker(tracker, zip(t, q), 7, tmp_path / "res", joint_names=names)
    np.testing.assert_array_equal(run.motion.time_s, t)
    np.testing.assert_array_equal(run.motion.q, q)
    assert run.motion.joint_names == names
    want = canonical_positions(sk, q, names)
    # ReplayTracker reports left_arm "missing" from 0.05 s: its wrist is NaN there
    want[t >= 0.05, names.index("left_wrist")] = np.nan
    np.testing.assert_allclose(run.motion.joints_mm, want, atol=1e-9)
    _rows, numeric = read_fit_csv(tmp_path / "res" / FIT_FILE)
    np.testing.assert_allclose(numeric["time_s"], t, atol=1e-9)
    with pytest.raises(UnknownNameError, match="elbow_tip"):
        run_tracker(LaggedReplay(sk, 1), zip(t, q), 7, joint_names=("elbow_tip",))


def test_run_tracker_writes_the_plausibility_of_the_motion_against_the_inputs(tmp_path) -> None:
    sk = load_preset("upper_stick")
    q = np.tile(sk.zero_pose(), (6, 1))
    q[4:, arm(sk, "right").dofs[0]] += 0.5  # the right arm swings in one frame
    t = np.arange(6) * 0.02
    still = run_tracker(
        ReplayTracker(sk),
        zip(t, q),
        6,
        tmp_path / "still",
        input_speeds=lambda m: np.zeros(m.joints_mm.shape[:2]),  # the inputs keep still
    )
    rows, numeric = read_fit_csv(tmp_path / "still" / FIT_FILE)
    moved = np.flatnonzero(np.nan_to_num(numeric["implausible_joints"]))
    assert moved.tolist() == [4] and rows[4]["worst_joint"].startswith("right_")
    assert numeric["worst_input_speed_mm_per_s"][4] == 0.0
    assert np.isnan(numeric["implausible_joints"][0])
    run_tracker(ReplayTracker(sk), zip(t, q), 6, tmp_path / "none")  # no evidence
    _, numeric = read_fit_csv(tmp_path / "none" / FIT_FILE)
    assert np.isnan(numeric["implausible_joints"]).all()
    assert len(still.results) == 6
