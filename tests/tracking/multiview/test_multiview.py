"""The model-based multi-view fit: Jacobian, pose recovery, swaps, outliers, gaps, lengths."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from mocapkit.errors import ConfigError, ShapeError, UnknownNameError
from mocapkit.skeleton.kinematics import canonical_positions, kinematic_arrays
from mocapkit.skeleton.model import CANONICAL_JOINTS
from mocapkit.synth.rigs import RING_CAMERAS, RING_DISTANCE_MM, make_rig
from mocapkit.tracking.base import BRIDGE_S
from mocapkit.tracking.multiview.config import MultiviewConfig, MultiviewRunConfig
from mocapkit.tracking.multiview.fit import FitTargets, evaluate_nb, fit_pose_nb, view_arrays
from mocapkit.tracking.multiview.lengths import (
    robust_triangulation,
    segment_lengths_from_points,
    subject_lengths_mm,
)
from mocapkit.tracking.multiview.tracker import (
    MultiviewTracker,
    multiview_skeleton,
    swap_permutation,
)

NAMES = CANONICAL_JOINTS


@dataclass
class Sample:
    time_s: float
    keypoints_px: dict[str, Any]


def _rig() -> list[Any]:
    return make_rig("ring", [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 1300.0)


def _pose(sk: Any, rng: np.random.Generator, spread: float = 0.4) -> np.ndarray:
    q = sk.zero_pose()
    lo = np.where(np.isfinite(sk.lower), sk.lower, -1.0)
    hi = np.where(np.isfinite(sk.upper), sk.upper, 1.0)
    mid = 0.5 * (lo + hi)
    rot = sk.dof_kind == 0
    q[rot] = np.clip(
        mid[rot] + spread * rng.uniform(-1, 1, rot.sum()) * (hi - lo)[rot] / 2, lo[rot], hi[rot]
    )
    q[sk.dof_index("root_yaw")] = rng.uniform(-np.pi, np.pi)
    q[sk.dof_index("root_pitch")] *= 0.2
    q[sk.dof_index("root_roll")] *= 0.2
    q[sk.dof_index("root_tx")] = rng.uniform(-200, 200)
    q[sk.dof_index("root_ty")] = rng.uniform(-200, 200)
    return q


def _pixels(sk: Any, cams: list[Any], q: np.ndarray) -> dict[str, np.ndarray]:
    pts = canonical_positions(sk, q, NAMES)
    return {c.name: c.project(pts) for c in cams}


def test_ring_rig_surrounds_the_subject() -> None:
    cams = _rig()
    assert [c.name for c in cams] == [f"ring{i + 1}" for i in range(RING_CAMERAS)]
    centres = np.array([c.center_in_world for c in cams])
    dist = np.linalg.norm(centres[:, :2], axis=1)
    np.testing.assert_allclose(dist, RING_DISTANCE_MM, rtol=1e-9)
    az = np.sort(np.degrees(np.arctan2(centres[:, 1], centres[:, 0])) % 360)
    np.testing.assert_allclose(np.diff(az), 360.0 / RING_CAMERAS, atol=1e-6)
    for c in cams:  # the pelvis is in every image
        u, v = c.project(np.array([[0.0, 0.0, 1000.0]]))[0]
        assert 0 < u < c.image_size[0] and 0 < v < c.image_size[1]


def test_gradient_matches_finite_differences(rng: np.random.Generator) -> None:
    sk = multiview_skeleton()
    cams = _rig()
    q = _pose(sk, rng)
    tj, tp = sk.canonical_points(NAMES)
    views = view_arrays([c.camera_from_world for c in cams])
    px = _pixels(sk, cams, q + rng.normal(0, 0.01, q.shape))
    obs = np.stack([c.undistort_pixels(px[c.name]) for c in cams])
    obs += rng.normal(0, 1e-3, obs.shape)
    weight = rng.uniform(0.5, 1.0, obs.shape[:2])
    # the 3-D point prior: references off the points, one of them absent
    ref = canonical_positions(sk, q + 0.03, NAMES) + rng.normal(0, 20.0, (len(NAMES), 3))
    ref[0] = np.nan
    tg = FitTargets(
        obs,
        weight,
        np.full(len(cams), 4000.0),
        q + 0.05,
        np.full(q.shape, 3.0),
        ref,
        rng.uniform(0.0, 0.5, len(NAMES)),
    )
    d = q.shape[0]
    hess, grad = np.empty((d, d)), np.empty(d)
    norms = np.empty(obs.shape[:2])
    kin = kinematic_arrays(sk)

    def cost(qq: np.ndarray, delta: float) -> float:
        return evaluate_nb(qq, kin, tj, tp, views, tg, delta, False, hess, grad, norms)

    for delta in (1e6, 5.0):  # quadratic, and Huber with most residuals past delta
        evaluate_nb(q, kin, tj, tp, views, tg, delta, True, hess, grad, norms)
        g = grad.copy()
        fd = np.empty(d)
        for k in range(d):
            h = 1e-6 if sk.dof_kind[k] != 1 else 1e-4
            e = np.zeros(d)
            e[k] = h
            fd[k] = (cost(q + e, delta) - cost(q - e, delta)) / (2 * h)
        np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-5 * np.abs(fd).max())
    # the Gauss-Newton matrix of the quadratic problem is J^T W J: symmetric, PSD
    evaluate_nb(q, kin, tj, tp, views, tg, 1e6, True, hess, grad, norms)
    np.testing.assert_allclose(hess, hess.T)
    assert np.linalg.eigvalsh(hess).min() > 0


def test_fit_recovers_a_pose_from_exact_detections(rng: np.random.Generator) -> None:
    sk = multiview_skeleton()
    cams = _rig()
    tj, tp = sk.canonical_points(NAMES)
    views = view_arrays([c.camera_from_world for c in cams])
    kin = kinematic_arrays(sk)
    for _ in range(3):
        q_true = _pose(sk, rng, 0.3)
        px = _pixels(sk, cams, q_true)
        obs = np.stack([c.undistort_pixels(px[c.name]) for c in cams])
        q = q_true + rng.normal(0, 0.08, q_true.shape) * (sk.dof_kind == 0)
        tg = FitTargets(
            obs,
            np.ones(obs.shape[:2]),
            np.full(len(cams), 4000.0),
            q.copy(),
            np.full(q.shape, 1e-6),
            np.full((len(NAMES), 3), np.nan),
            np.zeros(len(NAMES)),
        )
        norms = np.empty(obs.shape[:2])
        lo = np.where(np.isfinite(sk.lower), sk.lower, -1e9)
        hi = np.where(np.isfinite(sk.upper), sk.upper, 1e9)
        fit_pose_nb(q, kin, tj, tp, views, tg, lo, hi, 25.0, 200, norms)
        err = np.linalg.norm(
            canonical_positions(sk, q, NAMES) - canonical_positions(sk, q_true, NAMES), axis=1
        )
        assert err.max() < 1.0
        assert np.nanmax(norms) < 0.5


def _track(frames: list[dict[str, np.ndarray]]) -> list[Any]:
    tracker = MultiviewTracker(multiview_skeleton(), _rig(), NAMES)
    return [tracker.update(Sample(i / 30.0, f)) for i, f in enumerate(frames)]


def _walk(sk: Any, rng: np.random.Generator, n: int) -> list[np.ndarray]:
    q0, q1 = _pose(sk, rng, 0.25), _pose(sk, rng, 0.25)
    q1[sk.dof_index("root_yaw")] = q0[sk.dof_index("root_yaw")] + 0.3
    return [q0 + (q1 - q0) * k / max(n - 1, 1) for k in range(n)]


def test_tracker_follows_motion_and_reports_fit(rng: np.random.Generator) -> None:
    sk = multiview_skeleton()
    cams = _rig()
    qs = _walk(sk, rng, 10)
    res = _track([_pixels(sk, cams, q) for q in qs])
    for q, r in zip(qs, res, strict=True):
        truth = canonical_positions(sk, q)
        assert np.nanmax(np.linalg.norm(r.joints_mm - truth, axis=1)) < 5.0
        assert r.fit["mean_px"] < 1.0
        assert r.fit["left_wrist_views"] == len(cams)
        assert r.fit["swapped_views"] == 0 and r.fit["far_joints"] == 0
        assert set(r.status.values()) == {"seen"}


def test_swapped_view_and_wild_point_are_handled(rng: np.random.Generator) -> None:
    sk = multiview_skeleton()
    cams = _rig()
    qs = _walk(sk, rng, 8)
    perm = swap_permutation(NAMES)
    assert NAMES[perm[NAMES.index("left_knee")]] == "right_knee"
    assert perm[NAMES.index("head")] == NAMES.index("head")
    frames = [_pixels(sk, cams, q) for q in qs]
    for f in frames[3:6]:
        f["ring2"] = f["ring2"][perm]  # the detector took the subject as seen from behind
    frames[6]["ring3"][NAMES.index("right_elbow")] += (120.0, -90.0)  # a wild point
    res = _track(frames)
    for k in (3, 4, 5):
        assert res[k].fit["swapped_views"] == 1
    assert res[6].fit["right_elbow_views"] == len(cams) - 1
    assert res[6].fit["right_elbow_ring3_px"] > 100
    for q, r in zip(qs, res, strict=True):
        truth = canonical_positions(sk, q)
        assert np.nanmax(np.linalg.norm(r.joints_mm - truth, axis=1)) < 5.0


def test_gaps_are_bridged_then_released(rng: np.random.Generator) -> None:
    sk = multiview_skeleton()
    cams = _rig()
    qs = _walk(sk, rng, 20)
    frames = [_pixels(sk, cams, q) for q in qs]
    short, long_ = range(3, 5), range(8, 20)
    for k in (*short, *long_):
        for c in cams:
            frames[k][c.name][[NAMES.index("left_elbow"), NAMES.index("left_wrist")]] = np.nan
    res = _track(frames)
    assert [res[k].status["left_arm"] for k in short] == ["bridged"] * 2
    states = [res[k].status["left_arm"] for k in long_]
    n_bridge = int(BRIDGE_S * 30 + 1e-9)
    assert states[:n_bridge] == ["bridged"] * n_bridge
    assert set(states[n_bridge + 1 :]) == {"released"}
    assert res[0].status["left_arm"] == "seen" and res[10].status["right_arm"] == "seen"


def test_no_pose_before_the_body_is_seen(rng: np.random.Generator) -> None:
    sk = multiview_skeleton()
    cams = _rig()
    q = _pose(sk, rng, 0.2)
    empty = {c.name: np.full((len(NAMES), 2), np.nan) for c in cams}
    res = _track([empty, _pixels(sk, cams, q)])
    assert np.isnan(res[0].q).all() and res[0].status["left_arm"] == "missing"
    assert np.linalg.norm(res[1].joints_mm - canonical_positions(sk, q), axis=1).max() < 5.0


def test_lengths_from_a_take(rng: np.random.Generator) -> None:
    sk = multiview_skeleton(
        {"left_forearm": 240.0, "right_forearm": 250.0, "left_thigh": 400.0, "right_thigh": 470.0}
    )
    cams = _rig()
    qs = [_pose(sk, rng, 0.3) for _ in range(12)]
    px = np.stack([np.stack([_pixels(sk, cams, q)[c.name] for q in qs]) for c in cams])
    px[1, 2, NAMES.index("left_wrist")] += 200.0  # one wild detection
    pts, err, kept = robust_triangulation(cams, px, reject_mm=150.0)
    truth = np.stack([canonical_positions(sk, q, NAMES) for q in qs])
    assert np.abs(pts - truth).max() < 0.5
    assert kept[2, NAMES.index("left_wrist")] == len(cams) - 1
    assert np.nanmax(np.where(np.isfinite(err) & (err < 150), err, 0)) < 0.5
    lengths, vectors = subject_lengths_mm(cams, NAMES, px, reject_mm=150.0, good_mm=30.0)
    # the forearms agree within the side tolerance and share their mean; the thighs do not
    assert lengths["left_forearm"] == pytest.approx(245.0, abs=0.5)
    assert lengths["right_forearm"] == lengths["left_forearm"]
    assert lengths["left_thigh"] == pytest.approx(400.0, abs=0.5)
    assert lengths["right_thigh"] == pytest.approx(470.0, abs=0.5)
    assert vectors["left_pelvis"][0] == pytest.approx(-vectors["right_pelvis"][0])
    assert vectors["trunk"][2] > 0
    good = np.ones((3, 2), dtype=bool)
    assert segment_lengths_from_points(("left_hip", "left_knee"), np.zeros((3, 2, 3)), good) == {}


def test_config_and_inputs_are_checked() -> None:
    assert MultiviewConfig().gap_limit_s == BRIDGE_S
    with pytest.raises(ConfigError, match="reject_mm"):
        MultiviewConfig(reject_mm=0.0)
    with pytest.raises(ConfigError, match="swap_ratio"):
        MultiviewConfig(swap_ratio=1.5)
    with pytest.raises(UnknownNameError, match="smoothing"):
        MultiviewRunConfig(smoothing="kalman")
    sk = multiview_skeleton()
    with pytest.raises(ConfigError, match="two or more cameras"):
        MultiviewTracker(sk, _rig()[:1], NAMES)
    with pytest.raises(ShapeError, match="both shoulders and both hips"):
        MultiviewTracker(sk, _rig(), ("head", "left_wrist"))
    tracker = MultiviewTracker(sk, _rig(), NAMES)
    with pytest.raises(ShapeError, match="ring1"):
        tracker.update(Sample(0.0, {"ring1": np.zeros((3, 2))}))


def test_a_limb_stuck_in_a_wrong_pose_is_started_again(rng: np.random.Generator) -> None:
    from mocapkit.skeleton.limbs import limb

    sk = multiview_skeleton()
    cams = _rig()
    q = _pose(sk, rng, 0.2)
    # a weak temporal prior: the test is of the restart, not of the prior's pull towards
    # the wrong previous pose (which a strong prior turns into a few mm at the shoulder)
    tracker = MultiviewTracker(sk, cams, NAMES, MultiviewConfig(prior_mm_per_rad=20.0))
    tracker.update(Sample(0.0, _pixels(sk, cams, q)))
    dofs = limb(sk, "right_arm").dofs
    assert tracker._q is not None
    tracker._q[dofs] = sk.lower[dofs]  # the previous frame left the arm at its limits
    r = tracker.update(Sample(1 / 30, _pixels(sk, cams, q)))
    err = np.linalg.norm(r.joints_mm - canonical_positions(sk, q), axis=1)
    arm_rows = [NAMES.index("right_elbow"), NAMES.index("right_wrist")]
    assert err[arm_rows].max() < 5.0
    # the temporal prior still pulls the trunk a little towards the wrong previous pose
    assert np.nanmax(err) < 15.0


def test_column_median_matches_numpy(rng: np.random.Generator) -> None:
    from mocapkit.tracking.multiview.lengths import column_median

    a = rng.normal(size=(7, 40))
    a[rng.random(a.shape) < 0.3] = np.nan
    a[:, 0] = np.nan
    got = column_median(a)
    assert np.isnan(got[0])
    np.testing.assert_allclose(got[1:], np.nanmedian(a[:, 1:], axis=0))
