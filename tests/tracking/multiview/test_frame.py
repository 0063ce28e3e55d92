"""The compiled steps of a frame around the solver against their rules written in numpy."""

from __future__ import annotations

from typing import Any

import numpy as np

from mocapkit.skeleton.kinematics import canonical_positions
from mocapkit.skeleton.model import CANONICAL_JOINTS
from mocapkit.synth.rigs import make_rig
from mocapkit.tracking.multiview.fit import FitTargets
from mocapkit.tracking.multiview.frame import (
    column_median_nb,
    fit_rejecting_nb,
    frame_figures_nb,
    model_points_nb,
    point_weights_nb,
    swap_test_nb,
)
from mocapkit.tracking.multiview.lengths import column_median
from mocapkit.tracking.multiview.tracker import MultiviewTracker, multiview_skeleton

NAMES = CANONICAL_JOINTS


def _setup(rng: np.random.Generator) -> tuple[Any, Any, list[Any], np.ndarray]:
    sk = multiview_skeleton()
    cams = make_rig("ring", [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 1300.0)
    tracker = MultiviewTracker(sk, cams, NAMES)
    q = sk.zero_pose()
    q[tracker._root_t] += rng.uniform(-100, 100, 3)
    q[tracker._yaw] = rng.uniform(-np.pi, np.pi)
    for dof, angle in (("r_shoulder_flexion", 0.8), ("r_elbow_flexion", 1.0)):
        i = sk.dof_index(dof)
        q[i] = np.clip(angle, sk.lower[i], sk.upper[i])
    return sk, tracker, cams, q


def _normalised(cams: list[Any], pts: np.ndarray) -> np.ndarray:
    return np.stack([c.undistort_pixels(c.project(pts)) for c in cams])


def _residuals(cams: list[Any], pts: np.ndarray, obs: np.ndarray, scale: np.ndarray) -> Any:
    out = np.full(obs.shape[:2], np.nan)
    for v, c in enumerate(cams):
        pc = c.to_camera(pts)
        out[v] = scale[v] * np.linalg.norm(pc[:, :2] / pc[:, 2:] - obs[v], axis=1)
    return out


def test_swap_test_matches_its_rule(rng: np.random.Generator) -> None:
    _sk, tr, cams, q = _setup(rng)
    pts = tr._points(q)
    obs = _normalised(cams, pts + rng.normal(0, 15, pts.shape))
    obs[1] = obs[1][tr._perm]  # one view takes the subject as seen from behind
    obs[2, 4] = np.nan
    scale = tr._scale(q)
    got = swap_test_nb(tr._model, tr._settings, pts, obs, scale, np.empty(obs.shape[:2]))
    pairs = np.flatnonzero(tr._perm != np.arange(len(tr.names)))
    cfg = tr.config
    costs = [
        np.nansum(np.minimum(_residuals(cams, pts, o, scale)[:, pairs], cfg.reject_mm), axis=1)
        for o in (obs, obs[:, tr._perm])
    ]
    want = (costs[1] < cfg.swap_ratio * costs[0]) & (
        costs[0] - costs[1] > cfg.swap_margin_mm * (pairs.size // 2)
    )
    np.testing.assert_array_equal(got, want)
    assert got.tolist() == [False, True, False, False]


def test_point_weights_match_their_rule(rng: np.random.Generator) -> None:
    _sk, tr, cams, q = _setup(rng)
    pts = tr._points(q)
    obs = _normalised(cams, pts)
    obs[:2, 3] = np.nan  # a joint seen by two views only
    obs[:, 5] = np.nan
    obs[1:, 6] = np.nan
    got = point_weights_nb(tr._model, tr._settings, pts, obs)
    hips = pts[tr._hip_rows].mean(axis=0)
    ray = hips - np.array([c.center_in_world for c in cams])
    ray /= np.linalg.norm(ray, axis=1, keepdims=True)
    sin = np.linalg.norm(np.cross(ray[:, None], ray[None]), axis=2)
    seen = np.isfinite(obs).all(axis=-1)
    span = np.array(
        [sin[np.ix_(seen[:, k], seen[:, k])].max(initial=0.0) for k in range(len(tr.names))]
    )
    np.testing.assert_allclose(got, tr.config.point_prior * (1.0 - span), atol=1e-12)
    assert got[5] == got[6] == tr.config.point_prior  # unseen, or one view: the full prior


def test_column_median_skips_what_is_not_kept(rng: np.random.Generator) -> None:
    a = rng.normal(size=(5, 30))
    a[rng.random(a.shape) < 0.2] = np.nan
    keep = rng.random(a.shape) < 0.7
    keep[:, 0] = False
    out = np.empty(30)
    column_median_nb(a, keep, out)
    assert np.isnan(out[0])
    want = column_median(np.where(keep, a, np.nan))  # numpy's nanmedian (test_multiview)
    np.testing.assert_allclose(out, want, equal_nan=True)


def test_fit_drops_a_wild_detection_and_keeps_the_rest(rng: np.random.Generator) -> None:
    _sk, tr, cams, q = _setup(rng)
    obs = _normalised(cams, tr._points(q))
    wrist = tr.names.index("right_wrist")
    obs[2, wrist] += 0.15  # about 400 mm across the ray at the subject
    start = q.copy()
    start[tr._root_t] += 30.0
    tg = FitTargets(
        obs,
        np.zeros(obs.shape[:2]),
        tr._scale(q),
        start.copy(),
        tr._prior * 1e-3,
        np.full((len(tr.names), 3), np.nan),
        np.zeros(len(tr.names)),
    )
    ok = np.zeros(len(tr.names), dtype=bool)
    fit_rejecting_nb(tr._model, tr._settings, start, tg, 40, np.empty(obs.shape[:2]), False, ok)
    assert tg.weight[2, wrist] == 0.0
    assert (tg.weight > 0).sum() == obs.shape[0] * obs.shape[1] - 1
    err = np.linalg.norm(model_points_nb(tr._model, start) - tr._points(q), axis=1)
    assert err.max() < 1.0


def test_figures_are_the_projections_and_the_canonical_joints(rng: np.random.Generator) -> None:
    sk, tr, cams, q = _setup(rng)
    pts = tr._points(q)
    px = np.stack([c.project(pts) for c in cams]) + rng.normal(0, 2, (len(cams), len(pts), 2))
    px[3, 2] = np.nan
    swapped = np.array([False, True, False, False])
    err, joints = frame_figures_nb(tr._model, q, px, swapped, np.ones(px.shape[:2]))
    used = np.where(swapped[:, None, None], px[:, tr._perm], px)
    want = np.linalg.norm(np.stack([c.project(pts) for c in cams]) - used, axis=-1)
    np.testing.assert_allclose(err, want, atol=1e-9, equal_nan=True)
    assert np.isnan(err[3, 2])
    np.testing.assert_allclose(joints, canonical_positions(sk, q), atol=1e-9)


def _fit_from_previous(
    tr: MultiviewTracker, q: np.ndarray, obs: np.ndarray, gate: bool, ref_ok: np.ndarray
) -> tuple[np.ndarray, FitTargets]:
    """`fit_rejecting_nb` from pose ``q``, the previous frame's pose and points the same."""
    start = q.copy()
    tg = FitTargets(
        obs,
        np.zeros(obs.shape[:2]),
        tr._scale(q),
        q.copy(),
        tr._prior,
        tr._points(q),
        np.zeros(len(tr.names)),
    )
    fit_rejecting_nb(tr._model, tr._settings, start, tg, 40, np.empty(obs.shape[:2]), gate, ref_ok)
    return start, tg


def test_a_wild_detection_of_a_joint_seen_twice_is_dropped_by_its_jump(
    rng: np.random.Generator,
) -> None:
    """Two views of a joint have no majority; the previous frame's place decides."""
    _sk, tr, cams, q = _setup(rng)
    pts = tr._points(q)
    obs = _normalised(cams, pts)
    wrist = tr.names.index("right_wrist")
    obs[2:, wrist] = np.nan  # seen by two views
    obs[1, wrist] += 0.15  # one of them wild, about 400 mm off
    wrist_err = {}
    for gate, kept in ((True, 0.0), (False, 1.0)):
        # the two-view gate needs no confirmation of the previous points
        start, tg = _fit_from_previous(tr, q, obs, gate, np.zeros(len(tr.names), dtype=bool))
        assert tg.weight[1, wrist] == kept
        assert tg.weight[0, wrist] == 1.0
        wrist_err[gate] = np.linalg.norm(model_points_nb(tr._model, start)[wrist] - pts[wrist])
    assert wrist_err[True] < 1.0
    assert wrist_err[False] > 20.0  # without the gate the wild view pulls the wrist


def test_views_in_conflict_are_settled_by_a_confirmed_previous_point(
    rng: np.random.Generator,
) -> None:
    """Three views of a wrist, two agreeing on a place 500 mm off: the fit cannot reach
    it (the forearm holds the wrist), no view is outvoted; the previous frame's point,
    when two views confirmed it, drops the two."""
    _sk, tr, cams, q = _setup(rng)
    pts = tr._points(q)
    obs = _normalised(cams, pts)
    wrist = tr.names.index("right_wrist")
    wrong = pts.copy()
    wrong[wrist] += np.array([0.0, 300.0, 400.0])
    obs[1:3, wrist] = _normalised(cams, wrong)[1:3, wrist]
    obs[3, wrist] = np.nan
    wrist_err = {}
    for confirmed in (True, False):
        start, tg = _fit_from_previous(tr, q, obs, True, np.full(len(tr.names), confirmed))
        want = [1.0, 0.0, 0.0] if confirmed else [1.0, 1.0, 1.0]
        assert tg.weight[:3, wrist].tolist() == want
        wrist_err[confirmed] = np.linalg.norm(model_points_nb(tr._model, start)[wrist] - pts[wrist])
    assert wrist_err[True] < 1.0
    assert wrist_err[False] > 50.0  # unsettled, the two views pull the wrist


def test_cholesky_step_solves_and_refuses_an_indefinite_matrix(rng: np.random.Generator) -> None:
    from mocapkit.tracking.multiview.fit import cholesky_solve_nb

    m = rng.normal(size=(34, 34))
    a = m @ m.T + 0.1 * np.eye(34)
    g = rng.normal(size=34)
    out = np.empty(34)
    assert cholesky_solve_nb(a.copy(), g, out)
    np.testing.assert_allclose(out, np.linalg.solve(a, -g), rtol=1e-8, atol=1e-10)
    a[5, 5] = -1.0
    assert not cholesky_solve_nb(a.copy(), g, out)
