"""Streaming hybrid tracker: warm-started IK, gap bridging/release, smoothing, refiner hook."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from mocapkit.errors import ConfigError, ShapeError, UnknownNameError
from mocapkit.ik.config import IKConfig
from mocapkit.skeleton import canonical_positions, forward_kinematics, load_preset
from mocapkit.skeleton.limbs import arm
from mocapkit.tracking.hybrid.balance import BalanceConfig
from mocapkit.tracking.hybrid.tracker import (
    HybridConfig,
    HybridSample,
    HybridTracker,
    OneEuroFilter,
    calibrate_marker_offsets,
    default_marker_effectors,
)

RATE = 50.0


@pytest.fixture(scope="module")
def truth():
    """A waving sequence of zhang21 poses and its marker-set trajectories."""
    sk = load_preset("zhang21")
    n = 60
    t = np.arange(n) / RATE
    tracker = HybridTracker(sk, config=HybridConfig(use_video=False))
    q = np.tile(tracker.solver.secondary.omega, (n, 1))
    for d, name in enumerate(sk.dof_names):
        if "shoulder" in name or "elbow" in name:
            q[:, d] += 0.4 * np.sin(2 * np.pi * 0.7 * t + d) + 0.4
    q = np.clip(q, sk.lower, sk.upper)
    pos = np.stack([tracker.solver.effector_positions(qq)[:3] for qq in q])
    return sk, t, q, pos


def samples(t, pos, names=("head", "left_hand", "right_hand")):
    return [
        HybridSample(float(t[i]), {n: pos[i, k] for k, n in enumerate(names)})
        for i in range(len(t))
    ]


@pytest.mark.parametrize("paper", [False, True])
def test_tracks_markers(truth, paper):
    sk, t, _q, pos = truth
    cfg = HybridConfig(use_video=False, paper=paper)
    tracker = HybridTracker(sk, config=cfg)
    # contract: the paper pipeline ends on the balance restore (2 x IK tolerance); the
    # default one on the smoothing polish (effectors within its tolerance)
    bound = 2.0 * cfg.ik.tol_mm if paper else cfg.smoothing_polish_tol_mm
    for s in samples(t, pos):
        pose = tracker.update(s)
        assert pose.q.shape == (sk.n_dofs,)
        assert pose.joints_mm.shape == (len(sk.canonical_names), 3)
        assert max(pose.residual_mm[n] for n in ("head", "left_hand", "right_hand")) <= bound
        assert pose.released == () and not pose.refined


def test_gap_bridged_then_released(truth):
    sk, t, _q, pos = truth
    cfg = HybridConfig(use_video=False, gap_limit_s=0.1, rejoin_blend_s=0.2)
    tracker = HybridTracker(sk, config=cfg)
    seq = samples(t, pos)
    gap = range(20, 40)  # 0.4 s gap of the left hand
    for i, s in enumerate(seq):
        if i in gap:
            s = HybridSample(s.time_s, {k: v for k, v in s.markers_mm.items() if k != "left_hand"})
        pose = tracker.update(s)
        if i in gap:
            gap_s = s.time_s - t[19]
            if gap_s <= 0.1:
                assert pose.bridged == ("left_hand",) and pose.released == ()
                # constant-velocity extrapolation stays near the true path over a short gap
                assert pose.residual_mm["left_hand"] < 1e-6 + 40.0
            else:
                assert pose.released == ("left_hand",)
                assert np.isnan(pose.residual_mm["left_hand"])
        elif i > 40:
            assert pose.released == ()
            if s.time_s >= t[40] + cfg.rejoin_blend_s:  # led back to the markers by then
                assert pose.residual_mm["left_hand"] <= cfg.smoothing_polish_tol_mm
    kinds = [e[2] for e in tracker.events if e[1] == "left_hand"]
    assert kinds == ["bridging", "released", "recovered"]


def test_bridge_extrapolates_constant_velocity():
    sk = load_preset("zhang21")
    tracker = HybridTracker(sk, config=HybridConfig(use_video=False, init_iterations=1))
    head = tracker.solver.effector_positions(tracker.solver.secondary.omega)[0]
    lh = np.array([-250.0, 100.0, 900.0])
    rh = np.array([250.0, 100.0, 900.0])
    tracker.update(HybridSample(0.0, {"head": head, "left_hand": lh, "right_hand": rh}))
    tracker.update(
        HybridSample(
            0.02, {"head": head, "left_hand": lh + np.array([0.0, 10.0, 0.0]), "right_hand": rh}
        )
    )
    targets, bridged, released = tracker._targets(
        HybridSample(0.06, {"head": head, "right_hand": rh})
    )
    assert bridged == ["left_hand"] and released == []
    np.testing.assert_allclose(targets[1], lh + np.array([0.0, 30.0, 0.0]))


def test_smoothing_reduces_jitter_without_lag(truth, rng):
    sk, t, q, pos = truth
    noisy = pos + rng.normal(0.0, 4.0, pos.shape)
    elbows = {}
    for smooth in (False, True):
        cfg = HybridConfig(use_video=False, paper=not smooth, balance=BalanceConfig(mode="off"))
        tracker = HybridTracker(sk, config=cfg, initial_q=q[0])
        qs = np.stack([tracker.update(s).q for s in samples(t, noisy)])
        elbows[smooth] = canonical_positions(sk, qs, ["left_elbow", "right_elbow"])
    clean = canonical_positions(sk, q, ["left_elbow", "right_elbow"])

    def jitter(x):  # second difference: high-frequency energy
        return float(np.sqrt(np.mean(np.diff(x, 2, axis=0) ** 2)))

    assert jitter(elbows[True]) < 0.8 * jitter(elbows[False])
    # lag: best alignment with the clean trajectory within 2 frames
    errs = [
        np.mean(np.linalg.norm(elbows[True][10 + k : 50 + k] - clean[10:50], axis=2))
        for k in range(0, 5)
    ]
    assert int(np.argmin(errs)) <= 2


def test_one_euro_passes_constant():
    f = OneEuroFilter(2.0, 0.1)
    for i in range(20):
        out = f(i / 50.0, np.array([3.0, -1.0]))
    np.testing.assert_allclose(out, [3.0, -1.0])


def test_refiner_hook_called_with_hands(truth):
    sk, t, _q, pos = truth
    calls = []

    def refiner(skeleton, camera, q_in, image, hands, config):
        calls.append(sorted(hands))
        return q_in

    tracker = HybridTracker(sk, camera=object(), config=HybridConfig(), refiner=refiner)
    s = samples(t[:2], pos[:2])
    pose = tracker.update(HybridSample(s[0].time_s, s[0].markers_mm, image=np.zeros((4, 4))))
    assert pose.refined and calls == [["left_hand", "right_hand"]]
    pose = tracker.update(s[1])  # no image: no refinement
    assert not pose.refined and len(calls) == 1


def test_marker_offsets(truth):
    sk, _t, q, _pos = truth
    effs = list(default_marker_effectors(sk).values())
    offset = np.array([0.0, 20.0, -30.0])
    shifted = HybridTracker(
        sk, config=HybridConfig(use_video=False, marker_offsets_mm={"right_hand": offset})
    )
    markers = np.stack([shifted.solver.effector_positions(qq)[:3] for qq in q[:5]])
    est = calibrate_marker_offsets(sk, q[:5], markers, effs)
    np.testing.assert_allclose(est[2], offset, atol=1e-9)
    np.testing.assert_allclose(est[0], effs[0].point_mm, atol=1e-9)


def test_bad_inputs(truth):
    sk = truth[0]
    with pytest.raises(UnknownNameError, match="marker set"):
        HybridTracker(sk, config=HybridConfig(marker_offsets_mm={"tail": (0, 0, 0)}))
    with pytest.raises(ConfigError, match="gap_limit_s"):
        HybridConfig(gap_limit_s=-1.0)
    tracker = HybridTracker(sk, config=HybridConfig(ik=IKConfig(), use_video=False))
    with pytest.raises(ShapeError, match="markers_mm\\['head'\\]"):
        tracker.update(HybridSample(0.0, {"head": np.zeros(2)}))


def test_feet_replanted_when_the_subject_steps(truth):
    """A 600 mm side step: planted feet keep the head off its marker unless re-planted."""
    sk, t, _q, pos = truth
    shifted = pos.copy()
    shifted[20:, :, 0] += np.minimum(np.arange(40), 10)[:, None] * 60.0  # 600 mm over 10 frames
    results = {}
    for replant in (0.0, 15.0):
        cfg = HybridConfig(use_video=False, replant_mm=replant, smoothing_polish_tol_mm=1.0)
        tracker = HybridTracker(sk, config=cfg)
        poses = [tracker.update(s) for s in samples(t, shifted)]
        head = [p.residual_mm["head"] for p in poses[-10:]]
        results[replant] = (max(head), [e for e in tracker.events if e[1] == "feet"])
    assert results[0.0][0] > 50.0 and results[0.0][1] == []  # held where they started
    # stepped with the subject: the head ends within the re-plant trigger of its marker
    assert results[15.0][0] <= 15.0 and results[15.0][1]
    assert results[15.0][0] < 0.25 * results[0.0][0]


def _ankle_heights(poses, sk) -> np.ndarray:
    names = list(sk.canonical_names)
    return np.array(
        [[p.joints_mm[names.index(a), 2] for a in ("left_ankle", "right_ankle")] for p in poses]
    )


def test_replanted_feet_step_up_onto_a_box_but_never_below_the_floor(truth):
    """Re-planted feet keep the height the body needs (a step up onto a 300 mm box),
    but not below the floor they started on (a step and a 500 mm drop of every marker,
    more than the legs can crouch)."""
    sk, t, _q, pos = truth
    ramp = np.minimum(np.arange(40), 10)[:, None] / 10.0
    up = pos.copy()
    up[20:, :, 1] += ramp * 400.0
    up[20:, :, 2] += ramp * 300.0
    down = pos.copy()
    down[20:, :, 0] += ramp * 600.0
    down[20:, :, 2] -= ramp * 500.0
    cfg = HybridConfig(use_video=False, smoothing_polish_tol_mm=1.0)
    tracker = HybridTracker(sk, config=cfg)
    poses = [tracker.update(s) for s in samples(t, up)]
    ankles = _ankle_heights(poses, sk)
    assert [e for e in tracker.events if e[1] == "feet"]
    assert np.all(ankles[-5:] > ankles[0] + 250.0)  # standing on the box
    assert max(p.residual_mm["head"] for p in poses[-5:]) <= cfg.replant_mm
    tracker = HybridTracker(sk, config=cfg)
    poses = [tracker.update(s) for s in samples(t, down)]
    ankles = _ankle_heights(poses, sk)
    assert [e for e in tracker.events if e[1] == "feet"]
    # the feet are put down on the floor, not where the stretched legs of the free
    # solve reach (about 500 mm lower); the solve may pull them a little below it when
    # head and hands are out of reach, as here
    assert ankles.min() >= ankles[0].min() - 60.0


#: The canonical joints of the pelvis and legs.
LOWER = ("pelvis", "left_hip", "left_knee", "left_ankle", "right_hip", "right_knee", "right_ankle")


def test_replant_relaxation_is_spread_over_frames_not_a_pop(truth):
    """Head and hands go 500 mm forward and 100 mm down in 0.2 s and stay: the planted
    feet hold the body bent and it is re-planted. The feet-free solve's relaxed-pose pull
    would swing the pelvis and legs under the head in one frame (many times the head's
    speed, while the markers stand still); bounded, they move at most about the head's
    pace, and head and hands still reach their markers."""
    sk, t, _q, pos = truth
    bent = pos.copy()
    ramp = np.minimum(np.arange(40), 10)[:, None] / 10.0
    bent[20:, :, 1] += ramp * 500.0
    bent[20:, :, 2] -= ramp * 100.0
    head_peak_mm_s = float(np.max(np.linalg.norm(np.diff(bent[:, 0], axis=0), axis=1)) * RATE)
    rows = [sk.canonical_names.index(j) for j in LOWER]
    cfg = HybridConfig(use_video=False)
    bound_mm_s = cfg.replant_speed_factor * head_peak_mm_s + cfg.replant_min_speed_mm_s
    peaks, ends = {}, {}
    for min_speed in (cfg.replant_min_speed_mm_s, 1e12):  # 1e12: no bound
        tracker = HybridTracker(sk, config=replace(cfg, replant_min_speed_mm_s=min_speed))
        poses = [tracker.update(s) for s in samples(t, bent)]
        assert [e for e in tracker.events if e[1] == "feet"]
        lower = np.array([p.joints_mm[rows] for p in poses])
        speed = np.linalg.norm(np.diff(lower, axis=0), axis=2).max(axis=1) * RATE
        peaks[min_speed] = float(speed[15:].max())  # after the first pose settles
        ends[min_speed] = max(
            p.residual_mm[n] for p in poses[-5:] for n in ("head", "left_hand", "right_hand")
        )
    assert peaks[1e12] > 2.0 * bound_mm_s  # the pop: 15.6 m/s against a head at 2.5
    # the bound, plus what the balance and smoothing steps add after it
    assert peaks[cfg.replant_min_speed_mm_s] < 1.25 * bound_mm_s
    # spread, not dropped: head and hands end on their markers as well as with the pop
    assert ends[cfg.replant_min_speed_mm_s] <= ends[1e12] + 1.0


def test_a_frame_that_goes_on_with_a_cut_relaxation_skips_the_feet_held_solve(truth):
    """A re-plant whose relaxation is cut by the bound goes on over the next frames, and
    those frames re-plant whatever the solve with the old plants finds: they start with
    the feet-free solve from the previous frame's pose instead (its feet NaN), go on from
    that pose without the bound's head-only solve, and end with the new plants."""
    sk, t, _q, pos = truth
    bent = pos.copy()
    ramp = np.minimum(np.arange(40), 10)[:, None] / 10.0
    bent[20:, :, 1] += ramp * 500.0
    bent[20:, :, 2] -= ramp * 100.0
    tracker = HybridTracker(sk, config=HybridConfig(use_video=False))
    n = len(tracker.marker_sets)
    calls: list[tuple[np.ndarray, bool]] = []
    solve = tracker.solver.solve

    def logged(q0, targets, *args, **kwargs):
        calls.append((np.array(q0, dtype=float), bool(np.isnan(targets[n : n + 2]).all())))
        return solve(q0, targets, *args, **kwargs)

    tracker.solver.solve = logged  # type: ignore[method-assign]
    unpulled: list[int] = []
    solve_unpulled = tracker._unpulled.solve

    def counted(*args, **kwargs):
        unpulled.append(1)
        return solve_unpulled(*args, **kwargs)

    tracker._unpulled.solve = counted  # type: ignore[method-assign]
    carried = 0
    for s in samples(t, bent):
        going_on = tracker._relax_frames > 0
        previous = None if tracker._q is None else tracker._q.copy()
        del calls[:], unpulled[:]
        tracker.update(s)
        if going_on:
            assert not unpulled
            carried += 1
            assert previous is not None
            # first solve: the feet-free one, from the previous frame's pose
            assert calls[0][1]
            np.testing.assert_array_equal(calls[0][0], previous)
            assert not calls[1][1]  # then the solve with the new plants
    assert carried >= 2  # the bound cut the relaxation and it went on


def test_replant_relaxation_is_not_dragged_by_a_hand_its_arm_cannot_reach():
    """The left arm held by its joint limits (within 0.05 rad of the relaxed pose) and its
    hand set 150 mm below where that arm can put it, head and right hand still: freed of
    the feet, a solve with the hand sets drags the pelvis and legs after the unreachable
    hand (many times the 1 m/s a still head allows). The re-plant's relaxation is taken
    from what the head asks for, so it keeps them within the bound."""
    sk0 = load_preset("zhang21")
    relaxed = np.clip(HybridTracker(sk0).solver.secondary.omega, sk0.lower, sk0.upper)
    dofs = arm(sk0, "left").dofs
    lower, upper = sk0.lower.copy(), sk0.upper.copy()
    lower[dofs] = np.maximum(lower[dofs], relaxed[dofs] - 0.05)
    upper[dofs] = np.minimum(upper[dofs], relaxed[dofs] + 0.05)
    sk = replace(sk0, lower=lower, upper=upper)
    tracker = HybridTracker(sk, config=HybridConfig(use_video=False))
    still = tracker.solver.effector_positions(relaxed)[:3]
    for s in samples(np.arange(20) / RATE, np.repeat(still[None], 20, axis=0)):
        tracker.update(s)
    far = still.copy()
    far[1, 2] -= 150.0
    targets, _, _ = tracker._targets(samples([20 / RATE], far[None])[0])
    n = len(tracker.marker_sets)
    targets[n : n + 2] = tracker._feet
    held = tracker.solver.solve(tracker._q, targets)
    assert held.residual_mm[1] > 100.0  # the arm cannot reach its set
    free = targets.copy()
    free[n : n + 2] = np.nan
    pulled = tracker.solver.solve(held.q, free)
    before = tracker._lower_points_mm(tracker._q)
    bound_mm = tracker._lower_bound_mm(1 / RATE)  # the head is still: 1 m/s
    dragged = tracker._unpulled.solve(held.q, free)  # head and hands, no pull
    assert tracker._lower_move_mm(dragged.q, before) > 2.0 * bound_mm
    bounded, _ = tracker._bound_relaxation(held.q, free, pulled.q, 1 / RATE, False)
    limit_mm = max(bound_mm, tracker._lower_move_mm(held.q, before))
    assert tracker._lower_move_mm(bounded, before) <= limit_mm + 1e-6


def test_smoothing_polish_moves_the_pelvis_and_legs_no_further_than_the_bound(truth):
    """Where the polish after the smoothing would carry the pelvis 200 mm in a frame that
    the frame's own solve did not move it (it catches up on a set the solve had left far
    off), the pelvis and legs move at most the bound from the pose last returned, and
    the arms are put back on their hand sets over them; a move within the bound is kept
    as it is."""
    sk, t, _q, pos = truth
    tracker = HybridTracker(sk, config=HybridConfig(use_video=False))
    for s in samples(t[:20], pos[:20]):
        tracker.update(s)
    previous = tracker._out_q.copy()
    targets, _, _ = tracker._targets(samples(t[20:21], pos[20:21])[0])
    n = len(tracker.marker_sets)
    targets[n : n + 2] = tracker._feet
    before = tracker._lower_points_mm(previous)
    bound_mm = tracker._lower_bound_mm(t[20] - t[19])
    far = previous.copy()
    far[sk.dof_names.index("root_ty")] += 200.0
    out, extra = tracker._bound_polish(previous, previous, far, targets, float(t[20]))
    assert extra > 0
    assert tracker._lower_move_mm(far, before) > 4.0 * bound_mm  # the pop
    assert tracker._lower_move_mm(out, before) <= bound_mm + 1e-6
    hands = tracker.solver.effector_positions(out)[1:3] - targets[1:3]
    assert np.linalg.norm(hands, axis=1).max() < 2.0 * tracker.config.smoothing_polish_tol_mm
    near = previous.copy()
    near[sk.dof_names.index("root_ty")] += 0.5 * bound_mm
    kept, extra = tracker._bound_polish(previous, previous, near, targets, float(t[20]))
    assert extra == 0 and np.array_equal(kept, near)


#: Three markers on the glasses and on each hand-held object (mm from the effector point).
MEMBERS = {
    "head": {
        "bridge": (0.0, 100.0, 0.0),
        "temple_l": (-70.0, 60.0, 0.0),
        "temple_r": (70.0, 60.0, 0.0),
    },
    "left_hand": {
        "lh_a": (0.0, 0.0, -80.0),
        "lh_b": (0.0, 0.0, -130.0),
        "lh_c": (40.0, 0.0, -80.0),
    },
    "right_hand": {
        "rh_a": (0.0, 0.0, -80.0),
        "rh_b": (0.0, 0.0, -130.0),
        "rh_c": (-40.0, 0.0, -80.0),
    },
}


@pytest.fixture(scope="module")
def turned():
    """The waving sequence on a model with a free root yaw, turned 150 deg from the
    default facing, with its marker-set centres and member markers."""
    sk = load_preset("zhang21", ["root_rotation"])
    tracker = HybridTracker(sk, config=HybridConfig(use_video=False, member_offsets_mm=MEMBERS))
    n = 40
    t = np.arange(n) / RATE
    q = np.tile(tracker.solver.secondary.omega, (n, 1))
    for d, name in enumerate(sk.dof_names):
        if "shoulder" in name or "elbow" in name:
            q[:, d] += 0.4 * np.sin(2 * np.pi * 0.7 * t + d) + 0.4
    q[:, sk.dof_index("root_yaw")] = np.radians(150.0)
    q = np.clip(q, sk.lower, sk.upper)
    eff = np.stack([tracker.solver.effector_positions(qq) for qq in q])
    member_names = [m for _, m in tracker.members]
    seq = [
        HybridSample(
            float(t[i]),
            {s: eff[i, k] for k, s in enumerate(tracker.marker_sets)},
            members_mm={m: eff[i, 5 + k] for k, m in enumerate(member_names)},
        )
        for i in range(n)
    ]
    return sk, q, seq


def test_member_markers_show_the_turn(turned):
    """Set centres alone leave the body's turn free; the glasses' members fix it."""
    sk, q, seq = turned
    truth = canonical_positions(sk, q)
    errors = {}
    for members in (False, True):
        cfg = HybridConfig(use_video=False, member_offsets_mm=MEMBERS if members else {})
        tracker = HybridTracker(sk, config=cfg)
        poses = [tracker.update(s) for s in seq]
        est = np.stack([p.joints_mm for p in poses])
        errors[members] = float(np.linalg.norm(est - truth, axis=-1).mean())
        if members:
            yaw = np.array([p.q[sk.dof_index("root_yaw")] for p in poses])
            turn = np.angle(np.exp(1j * (yaw - q[:, sk.dof_index("root_yaw")])))
            assert np.abs(np.degrees(turn)).max() < 2.0
            assert pose_members_close(poses[-1], tracker)
    assert errors[True] < 10.0
    assert errors[False] > 5.0 * errors[True]


def pose_members_close(pose, tracker) -> bool:
    return all(pose.residual_mm[m] < 10.0 for _, m in tracker.members)


def test_oriented_arms_are_not_refined(turned):
    """An arm whose hand set's orientation is seen is fixed by the markers; only the
    other arm goes to the video refinement."""
    sk, q, seq = turned
    calls = []

    def refiner(skeleton, camera, q_in, image, hands, config):
        calls.append(sorted(hands))
        return q_in

    members = {k: v for k, v in MEMBERS.items() if k != "right_hand"}
    cfg = HybridConfig(member_offsets_mm=members)
    tracker = HybridTracker(sk, camera=object(), config=cfg, refiner=refiner, initial_q=q[0])
    s = seq[0]
    tracker.update(
        HybridSample(s.time_s, s.markers_mm, image=np.zeros((4, 4)), members_mm=s.members_mm)
    )
    assert calls == [["right_hand"]]
    # the left hand's members lost: that arm is refined again
    gone = {m: v for m, v in s.members_mm.items() if not m.startswith("lh_")}
    tracker.update(
        HybridSample(s.time_s + 0.02, s.markers_mm, image=np.zeros((4, 4)), members_mm=gone)
    )
    assert calls[-1] == ["left_hand", "right_hand"]


def test_lazy_image_is_decoded_only_for_frames_whose_arms_are_refined(turned):
    """A callable image is called (the frame decoded) only where an arm is refined, and
    the refiner gets the image it returns."""
    sk, q, seq = turned
    got, decoded = [], []

    def refiner(skeleton, camera, q_in, image, hands, config):
        got.append(image)
        return q_in

    frame = np.zeros((4, 4))

    def load():
        decoded.append(True)
        return frame

    cfg = HybridConfig(member_offsets_mm=MEMBERS)  # every set oriented: nothing refined
    tracker = HybridTracker(sk, camera=object(), config=cfg, refiner=refiner, initial_q=q[0])
    s = seq[0]
    tracker.update(HybridSample(s.time_s, s.markers_mm, image=load, members_mm=s.members_mm))
    assert decoded == [] and got == []
    # the right hand's members lost: that arm is refined, so the frame is decoded once
    gone = {m: v for m, v in s.members_mm.items() if not m.startswith("rh_")}
    pose = tracker.update(HybridSample(s.time_s + 0.02, s.markers_mm, image=load, members_mm=gone))
    assert decoded == [True] and len(got) == 1 and got[0] is frame and pose.refined


def test_bad_member_inputs(turned):
    sk, _q, seq = turned
    with pytest.raises(UnknownNameError, match="marker set 'tail'.*member_offsets_mm"):
        HybridTracker(sk, config=HybridConfig(member_offsets_mm={"tail": {"a": (0, 0, 0)}}))
    with pytest.raises(ConfigError, match=r"member_offsets_mm\['head'\]\['a'\]: expected 3 finite"):
        HybridTracker(sk, config=HybridConfig(member_offsets_mm={"head": {"a": (0, np.nan, 0)}}))
    tracker = HybridTracker(sk, config=HybridConfig(use_video=False, member_offsets_mm=MEMBERS))
    with pytest.raises(ShapeError, match=r"members_mm\['bridge'\]: expected 3 coordinates"):
        tracker.update(HybridSample(0.0, seq[0].markers_mm, members_mm={"bridge": np.zeros(4)}))


@pytest.mark.parametrize("paper", [False, True])
def test_refiner_gets_the_previous_elbows_carried_by_the_trunk(truth, paper):
    """The elbow-jump penalty's input: the last frame's elbows, in the frame of each
    shoulder's parent, carried to the world by the current pose (none in paper mode)."""
    sk, t, _q, pos = truth
    calls = []

    def refiner(skeleton, camera, q_in, image, hands, config, **kw):
        calls.append((q_in.copy(), kw))
        return q_in

    tracker = HybridTracker(sk, camera=object(), config=HybridConfig(paper=paper), refiner=refiner)
    image = np.zeros((4, 4))
    outputs = []
    for s in samples(t[:3], pos[:3]):
        pose = tracker.update(HybridSample(s.time_s, s.markers_mm, image=image))
        outputs.append(pose)
    assert len(calls) == 3 and calls[0][1] == {}
    if paper:
        assert all(kw == {} for _q_in, kw in calls)
        return
    for k in (1, 2):
        q_in, kw = calls[k]
        assert kw["elapsed_s"] == pytest.approx(t[k] - t[k - 1])
        prev_world = forward_kinematics(sk, outputs[k - 1].q)
        now_world = forward_kinematics(sk, q_in)
        for side, (humerus, radius) in {
            "left": ("l_humerus", "l_radius"),
            "right": ("r_humerus", "r_radius"),
        }.items():
            parent = sk.parents[sk.joint_index(humerus)]
            elbow_prev = prev_world[sk.joint_index(radius), :3, 3]
            local = prev_world[parent, :3, :3].T @ (elbow_prev - prev_world[parent, :3, 3])
            expected = now_world[parent, :3, :3] @ local + now_world[parent, :3, 3]
            np.testing.assert_allclose(kw["previous_elbows_mm"][side], expected, atol=1e-9)


def test_stale_marker_sample_is_no_observation(truth):
    """Markers that end before the video: the last sample, older than the bridge, is not
    used as live; the sets are released and their joints are NaN (issue 14)."""
    sk, t, _q, pos = truth
    cfg = HybridConfig(use_video=False, gap_limit_s=0.1)
    tracker = HybridTracker(sk, config=cfg)
    names = ("head", "left_hand", "right_hand")
    last = 29
    for i in range(len(t)):
        k = min(i, last)  # the marker stream stops at frame 29; the video goes on
        s = HybridSample(float(t[i]), {n: pos[k, j] for j, n in enumerate(names)}, float(t[k]))
        pose = tracker.update(s)
        age = t[i] - t[last]
        if age <= 0.1:
            assert set(pose.status.values()) <= {"seen"}
            assert np.all(np.isfinite(pose.joints_mm[:3]))
        else:
            assert pose.status == dict.fromkeys(names, "released")
            assert np.all(np.isnan(pose.joints_mm))
            assert np.all(np.isfinite(pose.q))  # the pose is kept for BVH
    assert [e[2] for e in tracker.events if e[1] == "head"] == ["released"]


def test_no_pose_before_the_markers_start(truth):
    sk, t, _q, pos = truth
    tracker = HybridTracker(sk, config=HybridConfig(use_video=False))
    names = ("head", "left_hand", "right_hand")
    first = tracker.update(HybridSample(0.0, {}))
    assert first.status == dict.fromkeys(names, "missing")
    assert np.all(np.isnan(first.q)) and np.all(np.isnan(first.joints_mm))
    # the first pose is placed when the markers come, on them
    pose = tracker.update(HybridSample(float(t[1]), {n: pos[1, j] for j, n in enumerate(names)}))
    assert set(pose.status.values()) == {"seen"}
    assert max(pose.residual_mm[n] for n in names) <= HybridConfig().smoothing_polish_tol_mm


def test_released_hand_has_nan_arm_joints(truth):
    from mocapkit.skeleton import CANONICAL_JOINTS

    sk, t, _q, pos = truth
    tracker = HybridTracker(sk, config=HybridConfig(use_video=False, gap_limit_s=0.05))
    for i in range(len(t)):
        marks = {"head": pos[i, 0], "right_hand": pos[i, 2]}
        if i < 10:
            marks["left_hand"] = pos[i, 1]
        pose = tracker.update(HybridSample(float(t[i]), marks))
    assert pose.status["left_hand"] == "released"
    nan = [n for n in CANONICAL_JOINTS if np.isnan(pose.joints_mm[CANONICAL_JOINTS.index(n)]).any()]
    assert {"left_elbow", "left_wrist"} <= set(nan)
    assert "right_wrist" not in nan and "head" not in nan


def test_lost_arm_is_started_again_from_the_relaxed_pose():
    """``reseed_arm_mm``: an arm folded into its limits (a racket drop beyond the
    shoulder's range) with its hand set far off is solved again from the relaxed pose,
    which reaches the set; a hand set nearer than the trigger is left as it is."""
    from mocapkit.pipelines.hybrid import hybrid_skeleton

    sk = hybrid_skeleton(1750.0, forearm_rotation=True)
    tracker = HybridTracker(sk, config=HybridConfig(use_video=False, reseed_arm_mm=50.0))
    omega = tracker.solver.secondary.omega
    folded = omega.copy()
    for name, deg in (
        ("r_shoulder_flexion", -60.0),
        ("r_shoulder_abduction", -30.0),
        ("r_shoulder_rotation", -90.0),
        ("r_elbow_flexion", 150.0),
        ("r_forearm_rotation", -80.0),
    ):
        folded[sk.dof_index(name)] = np.radians(deg)
    goal = omega.copy()
    goal[sk.dof_index("r_shoulder_flexion")] = np.radians(90.0)
    goal[sk.dof_index("r_elbow_flexion")] = np.radians(30.0)
    targets = tracker.solver.effector_positions(goal)
    targets[3:5] = np.nan  # no planted feet
    hand = tracker.marker_sets.index("right_hand")
    before = np.linalg.norm(tracker.solver.effector_positions(folded)[hand] - targets[hand])
    assert before > 300.0
    q, iterations = tracker._reseed_lost_arms(folded, targets)
    assert iterations > 0
    assert np.linalg.norm(tracker.solver.effector_positions(q)[hand] - targets[hand]) < 5.0
    # the frame is solved whole: head and the other hand stay on their sets
    off = np.linalg.norm(tracker.solver.effector_positions(q)[:3] - targets[:3], axis=1)
    assert off.max() < 5.0
    near = tracker.solver.effector_positions(folded)
    near[hand] += [0.0, 0.0, 40.0]
    near[3:5] = np.nan
    same, none = tracker._reseed_lost_arms(folded, near)
    assert none == 0
    np.testing.assert_array_equal(same, folded)
    with pytest.raises(ConfigError, match="reseed_arm_mm: expected >= 0 mm"):
        HybridConfig(reseed_arm_mm=-1.0)


def test_reseed_moves_the_arm_and_its_clavicle_only():
    """The re-seed holds the trunk, the pelvis and the legs (a whole-body solve swung the
    shoulder 250-360 mm in a frame on a real take): only the lost arms' and their
    clavicles' DoFs change, also where head and hands ask the body 150 mm aside, and the
    hand set still comes closer."""
    from mocapkit.pipelines.hybrid import hybrid_skeleton

    sk = hybrid_skeleton(1750.0, forearm_rotation=True, clavicle=True, twist=True)
    tracker = HybridTracker(sk, config=HybridConfig(use_video=False, reseed_arm_mm=50.0))
    omega = tracker.solver.secondary.omega
    folded = omega.copy()
    for name, deg in (
        ("r_shoulder_flexion", -60.0),
        ("r_shoulder_rotation", -90.0),
        ("r_elbow_flexion", 150.0),
    ):
        folded[sk.dof_index(name)] = np.radians(deg)
    goal = omega.copy()
    goal[sk.dof_index("r_shoulder_flexion")] = np.radians(90.0)
    goal[sk.dof_index("root_tx")] += 150.0
    targets = tracker.solver.effector_positions(goal)
    targets[3:5] = np.nan
    hand = tracker.marker_sets.index("right_hand")
    before = np.linalg.norm(tracker.solver.effector_positions(folded)[hand] - targets[hand])
    q, iterations = tracker._reseed_lost_arms(folded, targets)
    assert iterations > 0
    free = {
        d
        for side in ("left", "right")
        for d in (*arm(sk, side).dofs, *sk.dofs_of_joint(arm(sk, side).parent))
    }
    assert {sk.dof_names[d] for d in free} >= {"l_clavicle_elevation", "r_clavicle_elevation"}
    moved = set(np.flatnonzero(q != folded).tolist())
    assert moved and moved <= free
    after = np.linalg.norm(tracker.solver.effector_positions(q)[hand] - targets[hand])
    assert after < 0.5 * before


def _raised_and_turned_right_arm(
    tracker: HybridTracker, turn_deg: float
) -> tuple[np.ndarray, np.ndarray]:
    """The relaxed pose with the right arm raised and bent (the goal), and that arm turned
    ``turn_deg`` about its shoulder-wrist axis and clipped to its limits (stuck there)."""
    from mocapkit.ik.swivel import swivel_arm

    sk = tracker.skeleton
    goal = tracker.solver.secondary.omega.copy()
    for name, deg in (
        ("r_shoulder_flexion", 70.0),
        ("r_shoulder_abduction", 20.0),
        ("r_elbow_flexion", 90.0),
    ):
        goal[sk.dof_index(name)] = np.radians(deg)
    stuck = np.clip(swivel_arm(sk, goal, "right", np.radians(turn_deg)), sk.lower, sk.upper)
    return goal, stuck


def test_reseed_keeps_the_branch_nearest_the_elbow():
    """A right arm turned 90 deg about its shoulder-wrist axis into its joint limits, its
    hand set 79 mm off on the other branch. The re-seed puts the wrist back on
    its set, on the branch whose elbow is nearest the stuck one (the swivel seeds), where
    the relaxed seed alone takes the elbow more than twice as far in one frame."""
    from mocapkit.pipelines.hybrid import hybrid_skeleton
    from mocapkit.tracking.hybrid.reseed import arm_seeds

    sk = hybrid_skeleton(1750.0, forearm_rotation=True)
    tracker = HybridTracker(sk, config=HybridConfig(use_video=False, reseed_arm_mm=50.0))
    omega = tracker.solver.secondary.omega
    goal, stuck = _raised_and_turned_right_arm(tracker, 90.0)
    assert (
        stuck[sk.dof_index("r_shoulder_abduction")]
        == sk.lower[sk.dof_index("r_shoulder_abduction")]
    )
    targets = tracker.solver.effector_positions(goal)
    targets[3:5] = np.nan
    hand = tracker.marker_sets.index("right_hand")
    targets[hand] += [0.0, 60.0, 0.0]  # the set moved on while the arm was held
    assert np.linalg.norm(tracker.solver.effector_positions(stuck)[hand] - targets[hand]) > 50.0
    elbow = arm(sk, "right").middle

    def elbow_move_mm(q: np.ndarray) -> float:
        return float(
            np.linalg.norm(
                forward_kinematics(sk, q)[elbow, :3, 3]
                - forward_kinematics(sk, stuck)[elbow, :3, 3]
            )
        )

    q, _ = tracker._reseed_lost_arms(stuck, targets)
    assert np.linalg.norm(tracker.solver.effector_positions(q)[hand] - targets[hand]) < 5.0
    relaxed_seed = arm_seeds(sk, stuck, "right", omega)[0]
    relaxed = tracker.solver.solve(relaxed_seed, targets, frozen=tracker._reseed_frozen["right"]).q
    assert np.linalg.norm(tracker.solver.effector_positions(relaxed)[hand] - targets[hand]) < 5.0
    assert elbow_move_mm(q) < 0.5 * elbow_move_mm(relaxed)


def test_reseed_fits_the_members_of_the_set():
    """A hand set with a member marker tells the branches apart: an arm turned 150 deg
    about its shoulder-wrist axis into its limits is re-seeded onto the pose the set and
    its member were taken from (elbow within 10 mm), however far its elbow goes; with the
    set's centre alone the branch nearest the stuck elbow is kept, elsewhere."""
    from mocapkit.pipelines.hybrid import hybrid_skeleton

    sk = hybrid_skeleton(1750.0)
    elbow = arm(sk, "right").middle
    members = {"right_hand": {"RFRM": (0.0, 80.0, 0.0)}}
    elbows = {}
    for with_member in (True, False):
        cfg = HybridConfig(
            use_video=False, reseed_arm_mm=50.0, member_offsets_mm=members if with_member else {}
        )
        tracker = HybridTracker(sk, config=cfg)
        goal, stuck = _raised_and_turned_right_arm(tracker, 150.0)
        targets = tracker.solver.effector_positions(goal)
        targets[3:5] = np.nan
        q, _ = tracker._reseed_lost_arms(stuck, targets)
        fit = np.linalg.norm(tracker.solver.effector_positions(q) - targets, axis=1)
        assert np.nanmax(fit) < 5.0  # the set, and its member where there is one
        elbows[with_member] = np.linalg.norm(
            forward_kinematics(sk, q)[elbow, :3, 3] - forward_kinematics(sk, goal)[elbow, :3, 3]
        )
    assert elbows[True] < 10.0 < 100.0 < elbows[False]


def test_pelvis_and_foot_sets_drive_the_legs():
    """A squat (hips and knees bent 0.2 -> 1.2 rad): with the pelvis and foot sets as further
    IK tasks the knees follow the markers, closer than from head and hands alone. The
    foot sets take the plants' place (their residual is the fit's ``left_foot``) and the
    balance step stays out of the way (no spine lean)."""
    from mocapkit.tracking.hybrid.tracker import LEG_SETS, MARKER_SETS, marker_set_effectors

    sk = load_preset("zhang21")
    n = 40
    t = np.arange(n) / RATE
    probe = HybridTracker(sk, config=HybridConfig(use_video=False))
    q = np.tile(probe.solver.secondary.omega, (n, 1))
    bend = 0.2 + 1.0 * np.minimum(t / 0.5, 1.0)
    for d, name in enumerate(sk.dof_names):
        if "hip_flexion" in name:
            q[:, d] += bend * np.sign(sk.upper[d])
        elif "knee" in name:
            q[:, d] += bend * np.sign(sk.upper[d] + sk.lower[d])
    q = np.clip(q, sk.lower, sk.upper)
    effs = marker_set_effectors(sk)
    names = MARKER_SETS + LEG_SETS
    leg_solver = type(probe.solver)(sk, [effs[k] for k in names])
    # the feet stay on the floor: the pelvis drops by what the bent legs take
    pos = np.stack([leg_solver.effector_positions(qq) for qq in q])
    pos -= (pos[:, 4:6, 2].mean(axis=1) - pos[0, 4:6, 2].mean())[:, None, None] * [0, 0, 1]
    knees = [sk.canonical_names.index(f"{s}_knee") for s in ("left", "right")]
    hips = [sk.canonical_names.index(f"{s}_hip") for s in ("left", "right")]
    ankles = [sk.canonical_names.index(f"{s}_ankle") for s in ("left", "right")]

    def knee_deg(j):
        u, v = j[hips] - j[knees], j[ankles] - j[knees]
        c = np.sum(u * v, axis=1) / np.linalg.norm(u, axis=1) / np.linalg.norm(v, axis=1)
        return 180.0 - np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))

    truth = knee_deg(canonical_positions(sk, q[-1]))
    got = {}
    for given in (MARKER_SETS, names):
        # started from the first pose: from the relaxed one the knees sit at their
        # straight limit, where the solver locks them (its round-off release rule,
        # `mocapkit.ik.solve`) and the legs stay straight whatever the markers say
        tracker = HybridTracker(
            sk,
            config=HybridConfig(use_video=False),
            initial_q=q[0],
            marker_effectors={k: effs[k] for k in given},
        )
        poses = [
            tracker.update(HybridSample(float(t[i]), {k: pos[i, names.index(k)] for k in given}))
            for i in range(n)
        ]
        got[len(given)] = (knee_deg(poses[-1].joints_mm), poses[-1])
    assert np.all(truth > 60.0)
    legs, last = got[6]
    np.testing.assert_allclose(legs, truth, atol=2.0)  # head and hands alone: 5.6 deg off
    assert np.all(np.abs(legs - truth) < np.abs(got[3][0] - truth))
    assert last.residual_mm["left_foot"] < 15.0 and last.residual_mm["pelvis"] < 15.0
    assert last.spine_lean_rad is None or not np.any(last.spine_lean_rad)


def test_rejoining_hand_set_is_blended_back_over_rejoin_blend_s():
    """A hand set released (unseen past the bridge) while the hand moves on: the arm holds
    its last observed pose, and when the set is seen again its IK target goes from where
    the held arm puts it to the marker linearly over `HybridConfig.rejoin_blend_s`: the fit
    (against the marker) falls in equal shares and the hand moves in small steps; with 0
    the arm snaps there."""
    from mocapkit.skeleton.limbs import arm

    sk = load_preset("zhang21")
    probe = HybridTracker(sk, config=HybridConfig(use_video=False))
    pos = probe.solver.effector_positions(probe.solver.secondary.omega)[:3]
    dt, n, back = 0.02, 110, 60
    gone = range(10, back)

    def left(i):
        return pos[1] + np.array([0.0, -250.0, 350.0]) * min(i / 40.0, 1.0)

    samples = [
        HybridSample(
            dt * i,
            {"head": pos[0], "right_hand": pos[2]} | ({} if i in gone else {"left_hand": left(i)}),
        )
        for i in range(n)
    ]
    hand = sk.joint_index("l_hand")
    runs = {}
    for blend_s in (HybridConfig().rejoin_blend_s, 0.0):
        tracker = HybridTracker(sk, config=HybridConfig(use_video=False, rejoin_blend_s=blend_s))
        poses = [tracker.update(s) for s in samples]
        q = np.array([p.q for p in poses])
        released = [i for i, p in enumerate(poses) if "left_hand" in p.released]
        assert released and released[-1] == back - 1
        dofs = arm(sk, "left").dofs
        held = np.tile(q[released[0] - 1, dofs], (len(released), 1))
        np.testing.assert_allclose(q[released][:, dofs], held)  # the arm holds its pose
        fit = np.array([p.residual_mm["left_hand"] for p in poses])
        steps = np.linalg.norm(np.diff(forward_kinematics(sk, q)[:, hand, :3, 3], axis=0), axis=1)
        runs[blend_s] = fit, steps
    blend_s = HybridConfig().rejoin_blend_s
    fit, steps = runs[blend_s]
    k = round(blend_s / dt)
    jump = fit[back]  # the held arm's hand from the marker when the set is seen again
    assert jump > 200.0
    # the fit falls in equal shares (within the polish's tolerance of its moving target)
    share = (1.0 - np.arange(k + 5) * dt / blend_s).clip(0.0)
    np.testing.assert_allclose(
        fit[back : back + k + 5], jump * share, atol=HybridConfig().smoothing_polish_tol_mm
    )
    assert steps[back - 1 : back + k].max() < 1.5 * jump * dt / blend_s  # no snap
    fit0, steps0 = runs[0.0]
    assert steps0[back - 1] > 0.8 * jump and fit0[back] < 5.0  # snapped
    for bad in (-0.1, math.inf, math.nan):
        with pytest.raises(ConfigError, match="rejoin_blend_s: expected a finite time >= 0 s"):
            HybridConfig(rejoin_blend_s=bad)
