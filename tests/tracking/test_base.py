"""The shared tracker interface: canonical joints, fit summaries, the hybrid's results."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mocapkit.errors import ShapeError
from mocapkit.skeleton import CANONICAL_JOINTS, canonical_positions, load_preset
from mocapkit.tracking.base import STATUSES, FrameResult, Tracker, canonical_joints_mm, fit_summary
from mocapkit.tracking.hybrid.tracker import HybridConfig, HybridSample, HybridTracker


def test_canonical_joints_spread_over_the_canonical_order() -> None:
    sk = load_preset("upper_stick")
    rng = np.random.default_rng(0)
    q = np.clip(rng.normal(0.0, 0.3, sk.n_dofs), sk.lower, sk.upper)
    joints = canonical_positions(sk, q)
    out = canonical_joints_mm(sk, joints)
    assert out.shape == (len(CANONICAL_JOINTS), 3)
    for k, name in enumerate(sk.canonical_names):
        np.testing.assert_array_equal(out[CANONICAL_JOINTS.index(name)], joints[k])
    missing = [CANONICAL_JOINTS.index(n) for n in CANONICAL_JOINTS if n not in sk.canonical_names]
    assert missing and np.all(np.isnan(out[missing]))
    with pytest.raises(ShapeError, match="canonical_joints_mm: expected"):
        canonical_joints_mm(sk, joints[:-1])


def test_fit_summary_known_values() -> None:
    fit, worst = fit_summary({"head": 3.0, "left_hand": 4.0, "right_hand": math.nan})
    assert worst == "left_hand"
    assert fit["head_mm"] == 3.0 and math.isnan(fit["right_hand_mm"])
    assert fit["max_mm"] == 4.0
    assert fit["rms_mm"] == pytest.approx(math.sqrt(12.5))
    fit, worst = fit_summary({"head": math.nan})
    assert worst == "" and math.isnan(fit["rms_mm"]) and math.isnan(fit["max_mm"])


def test_hybrid_tracker_answers_frame_results() -> None:
    sk = load_preset("zhang21")
    tracker = HybridTracker(sk, config=HybridConfig(use_video=False))
    assert isinstance(tracker, Tracker)
    q = tracker.solver.secondary.omega.copy()
    pos = tracker.solver.effector_positions(q)[:3]
    first = tracker.update(HybridSample(0.0, {"head": pos[0], "left_hand": pos[1]}))
    assert isinstance(first, FrameResult)
    assert first.joints_mm.shape == (len(CANONICAL_JOINTS), 3)
    # the right hand was never seen: missing, not released
    assert first.status == {"head": "seen", "left_hand": "seen", "right_hand": "missing"}
    assert set(first.status.values()) <= set(STATUSES)
    marks = {"head": pos[0], "left_hand": pos[1], "right_hand": pos[2]}
    tracker.update(HybridSample(0.02, marks))
    gap = tracker.update(HybridSample(0.04, {"head": pos[0], "left_hand": pos[1]}))
    assert gap.status["right_hand"] == "bridged"
    late = tracker.update(HybridSample(1.0, {"head": pos[0], "left_hand": pos[1]}))
    assert late.status["right_hand"] == "released"
    assert math.isnan(late.fit["right_hand_mm"])
    finite = {k: v for k, v in late.residual_mm.items() if math.isfinite(v)}
    assert late.worst == max(finite, key=lambda k: finite[k])
    assert late.fit["max_mm"] == pytest.approx(max(finite.values()))


def test_observation_status_the_one_rule() -> None:
    from mocapkit.tracking.base import BRIDGE_S, observation_status

    assert observation_status(math.inf, False) == "missing"
    assert observation_status(0.0, True) == "seen"
    assert observation_status(BRIDGE_S, True) == "bridged"
    assert observation_status(BRIDGE_S + 1e-9, True) == "released"
    assert observation_status(0.5, True, bridge_s=1.0) == "bridged"


def test_unobserved_joints_to_nan_the_one_rule() -> None:
    from mocapkit.tracking.base import nan_unobserved, unobserved_joints

    status = {"head": "seen", "left_hand": "released", "right_arm": "missing", "x": "released"}
    assert unobserved_joints(status) == ("left_elbow", "left_wrist", "right_elbow", "right_wrist")
    assert unobserved_joints({"left_leg": "bridged", "right_foot": "released"}) == (
        "right_knee",
        "right_ankle",
    )
    joints = np.arange(45.0).reshape(15, 3)
    out = nan_unobserved(joints, status)
    gone = [CANONICAL_JOINTS.index(j) for j in unobserved_joints(status)]
    assert np.isnan(out[gone]).all()
    kept = [k for k in range(15) if k not in gone]
    np.testing.assert_array_equal(out[kept], joints[kept])
    assert not np.isnan(joints).any()  # the input is left as it was
