"""The shared tracker interface: canonical joints, fit summaries, the hybrid's results."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mocapkit.errors import ShapeError
from mocapkit.skeleton import CANONICAL_JOINTS, canonical_positions, load_preset
from mocapkit.tracking.base import STATUSES, FrameResult, Tracker, canonical_joints_mm, fit_summary
from mocapkit.tracking.hybrid import HybridConfig, HybridSample, HybridTracker


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
