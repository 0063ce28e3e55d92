"""Tests of the seated posture: seat, stature from the reach, the choice, the tracker seated."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.pipelines.hybrid import hybrid_skeleton
from mocapkit.skeleton import canonical_positions, load_preset
from mocapkit.skeleton.model import CANONICAL_JOINTS
from mocapkit.tracking.hybrid.posture import (
    CROUCH_DEAD_BAND_MM,
    SEATED_HEAD_RATIO,
    SEATED_LEFT_OUT,
    SEATED_NECK_FLEXION_RAD,
    STANDING_KNEE_FLEXION_RAD,
    Crouch,
    check_posture,
    choose_posture,
    estimate_seat_height_mm,
    hanging_reach_ratio,
    pelvis_to_head_mm,
    seat_skeleton,
    stature_from_reach_mm,
)
from mocapkit.tracking.hybrid.tracker import (
    HybridConfig,
    HybridSample,
    HybridTracker,
    default_marker_effectors,
)

PELVIS = CANONICAL_JOINTS.index("pelvis")


def _effector_points(sk, q):
    """Head point and both wrists (T, 3, 3) of poses ``q`` (T, D)."""
    from mocapkit.ik.sdls import SDLSSolver

    eff = default_marker_effectors(sk)
    solver = SDLSSolver(sk, [eff["head"], eff["left_hand"], eff["right_hand"]])
    return np.stack([solver.effector_positions(qq) for qq in np.atleast_2d(q)])


def test_seat_skeleton_holds_pelvis_and_legs():
    sk = seat_skeleton(hybrid_skeleton(1600.0), 550.0)
    rng = np.random.default_rng(0)
    q = rng.uniform(-1.0, 1.0, sk.n_dofs)
    q = np.clip(q, sk.lower, sk.upper)
    joints = canonical_positions(sk, q)
    assert joints[PELVIS, 2] == pytest.approx(550.0, abs=1e-6)
    # thighs forward of the hips, shanks straight down (root yaw/pitch/roll of q aside)
    lhip, lknee, lankle = (joints[CANONICAL_JOINTS.index(j)] for j in SEATED_LEFT_OUT[:3])
    assert abs(lknee[2] - lhip[2]) < 1.0
    assert np.linalg.norm(lknee[:2] - lankle[:2]) < 1.0
    assert lankle[2] < lknee[2] - 300.0
    neck = sk.dof_index("neck_flexion")
    assert sk.upper[neck] == pytest.approx(SEATED_NECK_FLEXION_RAD)
    assert sk.lower[neck] == pytest.approx(-SEATED_NECK_FLEXION_RAD)
    with pytest.raises(ConfigError, match="seat height: expected a height > 0 mm"):
        seat_skeleton(hybrid_skeleton(1600.0), -20.0)


def test_stature_from_reach_recovers_known_stature():
    """Hanging-arm reach at 1 % of frames (the rest bent) gives back the model's stature."""
    truth = 1620.0
    sk = hybrid_skeleton(truth)
    q = np.tile(np.clip(sk.zero_pose(), sk.lower, sk.upper), (300, 1))
    rng = np.random.default_rng(1)
    bent = rng.uniform(0.5, 2.0, 300)
    bent[:10] = 0.0  # 10 of 300 frames with the arms hanging straight
    q[:, sk.dof_index("l_elbow_flexion")] = bent
    q[:, sk.dof_index("r_elbow_flexion")] = bent
    pts = _effector_points(sk, q)
    head_point = default_marker_effectors(sk)["head"].point_mm
    # a model at another stature gives the same (scale-free) ratio
    other = hybrid_skeleton(1800.0)
    other_point = default_marker_effectors(other)["head"].point_mm
    assert hanging_reach_ratio(other, other_point) == pytest.approx(
        hanging_reach_ratio(sk, head_point), rel=1e-9
    )
    est = stature_from_reach_mm(other, other_point, pts[:, 0], [pts[:, 1], pts[:, 2]])
    assert est == pytest.approx(truth, abs=2.0)
    few = np.full((300, 3), np.nan)
    few[:5] = pts[:5, 1]
    with pytest.raises(ConfigError, match="cannot estimate the stature of a seated subject"):
        stature_from_reach_mm(other, other_point, pts[:, 0], [few])


def test_seat_height_from_upright_head():
    truth_seat = 600.0
    sk = seat_skeleton(hybrid_skeleton(1700.0), truth_seat)
    n = 200
    q = np.tile(np.clip(sk.zero_pose(), sk.lower, sk.upper), (n, 1))
    lean = np.linspace(0.0, 0.4, n)
    lean[: n // 10] = 0.0  # upright on 10 % of the frames, leaning forward on the rest
    for name in ("spine1_flexion", "spine2_flexion", "spine3_flexion"):
        q[:, sk.dof_index(name)] = lean
    q = np.clip(q, sk.lower, sk.upper)
    head = _effector_points(sk, q)[:, 0]
    point = default_marker_effectors(sk)["head"].point_mm
    assert head[0, 2] == pytest.approx(truth_seat + pelvis_to_head_mm(sk, point), abs=1e-6)
    assert estimate_seat_height_mm(sk, point, head[:, 2]) == pytest.approx(truth_seat, abs=1.0)


def test_choose_posture():
    low = choose_posture("auto", 0.79 * 1500.0, 1500.0, "given")
    assert low.posture == "seated" and "auto:" in low.reason and "0.79" in low.reason
    high = choose_posture("auto", (SEATED_HEAD_RATIO + 0.01) * 1700.0, 1700.0, "given")
    assert high.posture == "standing"
    assert choose_posture("seated", 1600.0, 1700.0, "given").posture == "seated"
    with pytest.raises(ConfigError, match="--posture: expected one of standing, seated, auto"):
        check_posture("kneeling")
    with pytest.raises(ConfigError, match="HybridConfig.posture: expected 'standing' or"):
        HybridConfig(posture="auto")


def test_tracker_seated_fits_upper_body_and_leaves_legs_out():
    """A seated subject leaning and moving the arms: head and hands fitted, pelvis on the
    seat, no feet planted, legs NaN."""
    seat = 580.0
    sk = seat_skeleton(hybrid_skeleton(1650.0, root_rotation=True), seat)
    n = 60
    t = np.arange(n) / 60.0
    q = np.tile(np.clip(sk.zero_pose(), sk.lower, sk.upper), (n, 1))
    q[:, sk.dof_index("root_tx")] = np.linspace(0.0, 300.0, n)  # the chair rolls
    q[:, sk.dof_index("spine2_flexion")] = 0.3 * np.sin(np.pi * t)
    q[:, sk.dof_index("l_shoulder_flexion")] = np.linspace(0.0, 1.0, n)
    q[:, sk.dof_index("r_elbow_flexion")] = np.linspace(0.3, 1.2, n)
    q = np.clip(q, sk.lower, sk.upper)
    pts = _effector_points(sk, q)
    cfg = HybridConfig(use_video=False, start_upright=False, posture="seated")
    tracker = HybridTracker(sk, None, cfg)
    names = ("head", "left_hand", "right_hand")
    poses = [
        tracker.update(HybridSample(float(t[i]), dict(zip(names, pts[i], strict=True))))
        for i in range(n)
    ]
    for p in poses:
        # the smoothing's polish puts effectors back within its tolerance
        assert max(p.residual_mm[k] for k in names) <= cfg.smoothing_polish_tol_mm
        assert np.isnan(p.fit["left_foot_mm"]) and np.isnan(p.fit["right_foot_mm"])
        for j in SEATED_LEFT_OUT:
            assert np.isnan(p.joints_mm[CANONICAL_JOINTS.index(j)]).all()
        assert p.joints_mm[PELVIS, 2] == pytest.approx(seat, abs=1e-6)
        assert np.isfinite(p.joints_mm[CANONICAL_JOINTS.index("left_elbow")]).all()
    assert not any(e[2] == "replanted" for e in tracker.events)


def test_crouch_lowers_the_hip_by_the_drop_over_the_ankle():
    """`Crouch.lowered_rad`: the legs' hip and knee flexions put the hip ``drop`` mm nearer
    the ankle than the straight leg, still over it; the knee never straighter than
    `STANDING_KNEE_FLEXION_RAD`. `Crouch.flexion_rad` takes the highest head it is given as
    standing and leaves the first `CROUCH_DEAD_BAND_MM` of a drop to the trunk."""
    sk = hybrid_skeleton(1750.0)
    crouch = Crouch.of(sk)
    assert crouch is not None and crouch.dofs.size == 4
    rest = np.clip(sk.zero_pose(), sk.lower, sk.upper)
    hip, ankle = (CANONICAL_JOINTS.index(f"left_{j}") for j in ("hip", "ankle"))
    straight = float(crouch.thigh_mm[0] + crouch.shank_mm[0])
    for drop in (0.0, 50.0, 200.0, 400.0):
        q = rest.copy()
        q[crouch.dofs] = crouch.lowered_rad(drop)
        assert np.all(q[crouch.dofs[1::2]] >= STANDING_KNEE_FLEXION_RAD - 1e-12)
        p = canonical_positions(sk, q)
        reach = np.linalg.norm(p[hip] - p[ankle])
        if drop > 0:
            assert reach == pytest.approx(straight - drop, abs=0.5)
        assert abs(p[hip, 1] - p[ankle, 1]) < 0.05 * max(drop, 100.0)  # over the ankle
    head = 1600.0
    standing = crouch.lowered_rad(0.0)
    np.testing.assert_allclose(crouch.flexion_rad(head), standing)
    np.testing.assert_allclose(crouch.flexion_rad(head - 0.5 * CROUCH_DEAD_BAND_MM), standing)
    np.testing.assert_allclose(
        crouch.flexion_rad(head - 200.0 - CROUCH_DEAD_BAND_MM), crouch.lowered_rad(200.0)
    )
    crouch.flexion_rad(head + 30.0)  # a higher head is the standing height from now on
    np.testing.assert_allclose(
        crouch.flexion_rad(head - 200.0 - CROUCH_DEAD_BAND_MM), crouch.lowered_rad(230.0)
    )
    assert Crouch.of(load_preset("azad14")) is None  # no legs


def test_tracker_relaxed_legs_follow_the_head_and_reset_forgets_its_height():
    """The hybrid tracker's relaxed pose (its IK's null-space task) bends the knees when
    the head set drops with the feet planted, straightens them back when it rises, and
    `HybridTracker.reset` forgets the standing height."""
    sk = load_preset("zhang21")
    tracker = HybridTracker(sk, config=HybridConfig(use_video=False))
    knees = [sk.dof_index(n) for n in ("l_knee_flexion", "r_knee_flexion")]
    omega = tracker.solver.secondary.omega
    np.testing.assert_allclose(omega[knees], STANDING_KNEE_FLEXION_RAD)
    pts = _effector_points(sk, omega)[0]
    sets = dict(zip(("head", "left_hand", "right_hand"), pts, strict=True))
    down = {k: v - [0.0, 0.0, 200.0] for k, v in sets.items()}
    tracker.update(HybridSample(0.0, sets))
    tracker.update(HybridSample(0.02, down))
    assert np.all(np.degrees(omega[knees]) > 40.0)  # 200 mm lower: a crouch
    tracker.update(HybridSample(0.04, sets))
    np.testing.assert_allclose(omega[knees], STANDING_KNEE_FLEXION_RAD)
    tracker.update(HybridSample(0.06, down))
    tracker.reset()
    np.testing.assert_allclose(omega[knees], STANDING_KNEE_FLEXION_RAD)
    tracker.update(HybridSample(0.0, down))  # the lower head is the standing height now
    np.testing.assert_allclose(omega[knees], STANDING_KNEE_FLEXION_RAD)
