"""The compiled steps of one frame around the solver (`mocapkit.tracking.multiview.fit`):
the left/right swap test per view, the 3-D point prior's weights, the fit with per-joint
per-view outlier rejection, the test for limbs to start again and the start itself, and
the reprojection figures of the result.

`MultiviewTracker.update` calls `begin_frame_nb`, `restart_limb_nb` for each limb
`begin_frame_nb` marks (the random seeds are drawn in Python, so that a seeded tracker
draws the same numbers), `finish_frame_nb` and `frame_figures_nb`: a few calls per frame
instead of a few dozen small numpy steps. Each kernel states the rule it applies; the
rules are the tracker's (`mocapkit.tracking.multiview.tracker` module notes).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
from numpy.typing import NDArray

from mocapkit.camera.projection import CameraArrays, project_world_point_nb
from mocapkit.skeleton.kinematics import KinematicArrays
from mocapkit.tracking.multiview.fit import (
    FitTargets,
    ViewArrays,
    evaluate_nb,
    fit_pose_nb,
    points_nb,
    view_residual_nb,
)

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


class FrameModel(NamedTuple):
    """What stays fixed from frame to frame, in kernel layout.

    Attributes
    ----------
    kin : KinematicArrays
    target_joint : ndarray of int64, shape (K,)
        Joint of each fitted point (the detections' model joints).
    target_point : ndarray, shape (K, 3)
        Each fitted point in its joint's frame.
    views : ViewArrays
    intrinsics : ndarray, shape (V, 3, 3)
    dist : ndarray, shape (V, 8)
        OpenCV distortion per view (`mocapkit.camera.projection.CameraArrays.dist`).
    centers_mm : ndarray, shape (V, 3)
        Optical centres in the world.
    hip_rows : ndarray of int64, shape (2,)
        Rows of the left and right hip among the K points.
    perm : ndarray of int64, shape (K,)
        Row of each point's other side (left <-> right; itself for the others).
    pairs : ndarray of int64, shape (P,)
        Rows with another side.
    base_weight : ndarray, shape (K,)
        Weight of each point's detections.
    lower, upper : ndarray, shape (D,)
        Joint limits of the fit.
    limb_rows : ndarray of int64, shape (L, 3)
        Rows of each limb's joints (top, middle, end; -1 where absent).
    canon_joint : ndarray of int64, shape (C,)
    canon_point : ndarray, shape (C, 3)
        The skeleton's canonical joints (its ``canonical_names`` order), for the output.
    """

    kin: KinematicArrays
    target_joint: IntArray
    target_point: FloatArray
    views: ViewArrays
    intrinsics: FloatArray
    dist: FloatArray
    centers_mm: FloatArray
    hip_rows: IntArray
    perm: IntArray
    pairs: IntArray
    base_weight: FloatArray
    lower: FloatArray
    upper: FloatArray
    limb_rows: IntArray
    canon_joint: IntArray
    canon_point: FloatArray


class FrameSettings(NamedTuple):
    """The thresholds the kernels apply (`MultiviewConfig`'s fields of the same names)."""

    delta_mm: float
    reject_mm: float
    swap_ratio: float
    swap_margin_mm: float
    point_prior: float
    restart_mm: float
    jump_mm: float


@numba.njit(cache=True)
def model_points_nb(m: FrameModel, q: FloatArray) -> FloatArray:
    """World places (K, 3) of the fitted points at pose ``q``."""
    return points_nb(q, m.kin, m.target_joint, m.target_point)


@numba.njit(cache=True)
def residual_norms_nb(
    m: FrameModel, pts: FloatArray, obs: FloatArray, scale: FloatArray, norms: FloatArray
) -> None:
    """Length (mm across the ray) of each detection's residual into ``norms`` (V, K): as
    `mocapkit.tracking.multiview.fit.evaluate_nb` measures it (NaN without a detection or
    behind the camera)."""
    for v in range(obs.shape[0]):
        r = m.views.rotation[v]
        t = m.views.translation_mm[v]
        s = scale[v]
        for k in range(pts.shape[0]):
            norms[v, k] = np.nan
            ox, oy = obs[v, k, 0], obs[v, k, 1]
            if not (np.isfinite(ox) and np.isfinite(oy)):
                continue
            _xc, _yc, zc, rx, ry = view_residual_nb(r, t, s, pts[k], ox, oy)
            if zc < 1.0:
                continue
            norms[v, k] = np.sqrt(rx * rx + ry * ry)


@numba.njit(cache=True)
def swapped_obs_nb(m: FrameModel, norm: FloatArray, swapped: BoolArray) -> FloatArray:
    """The detections (V, K, 2) with the left and right labels of the ``swapped`` views
    exchanged."""
    out = norm.copy()
    for v in range(norm.shape[0]):
        if swapped[v]:
            for k in range(norm.shape[1]):
                out[v, k, 0] = norm[v, m.perm[k], 0]
                out[v, k, 1] = norm[v, m.perm[k], 1]
    return out


@numba.njit(cache=True)
def swap_test_nb(
    m: FrameModel,
    st: FrameSettings,
    pts: FloatArray,
    obs: FloatArray,
    scale: FloatArray,
    norms: FloatArray,
) -> BoolArray:
    """Views whose exchanged labels fit the points ``pts`` clearly better.

    Per view the cost of its left/right joints is the sum of their residuals, each at
    most ``reject_mm``, with the labels as given and exchanged; the exchanged ones are
    taken when their cost is below ``swap_ratio`` of the other and lower by
    ``swap_margin_mm`` per pair.
    """
    n_views = obs.shape[0]
    out = np.zeros(n_views, dtype=np.bool_)
    if m.pairs.shape[0] == 0:
        return out
    costs = np.zeros((n_views, 2))
    for col in range(2):
        o = obs
        if col == 1:
            o = swapped_obs_nb(m, obs, np.ones(n_views, dtype=np.bool_))
        residual_norms_nb(m, pts, o, scale, norms)
        for v in range(n_views):
            c = 0.0
            for i in range(m.pairs.shape[0]):
                r = norms[v, m.pairs[i]]
                if np.isfinite(r):
                    c += min(r, st.reject_mm)
            costs[v, col] = c
    n_pairs = max(m.pairs.shape[0] // 2, 1)
    for v in range(n_views):
        out[v] = (costs[v, 1] < st.swap_ratio * costs[v, 0]) and (
            (costs[v, 0] - costs[v, 1]) > st.swap_margin_mm * n_pairs
        )
    return out


@numba.njit(cache=True)
def point_weights_nb(
    m: FrameModel, st: FrameSettings, pts: FloatArray, obs: FloatArray
) -> FloatArray:
    """Square root of the 3-D point prior's weight per joint (K,): ``point_prior`` times
    one less the largest |sin| of the angle between the rays to the hips of two views
    that detect the joint (`MultiviewConfig.point_prior`)."""
    n_views = obs.shape[0]
    n_pts = obs.shape[1]
    h0, h1 = m.hip_rows[0], m.hip_rows[1]
    ray = np.empty((n_views, 3))
    for v in range(n_views):
        for a in range(3):
            ray[v, a] = (pts[h0, a] + pts[h1, a]) / 2.0 - m.centers_mm[v, a]
        n = np.sqrt(ray[v, 0] ** 2 + ray[v, 1] ** 2 + ray[v, 2] ** 2)
        n = max(n, 1e-9)
        for a in range(3):
            ray[v, a] /= n
    sin = np.zeros((n_views, n_views))
    for v in range(n_views):
        for w in range(n_views):
            cx = ray[v, 1] * ray[w, 2] - ray[v, 2] * ray[w, 1]
            cy = ray[v, 2] * ray[w, 0] - ray[v, 0] * ray[w, 2]
            cz = ray[v, 0] * ray[w, 1] - ray[v, 1] * ray[w, 0]
            sin[v, w] = np.sqrt(cx * cx + cy * cy + cz * cz)
    out = np.empty(n_pts)
    for k in range(n_pts):
        span = 0.0
        if m.base_weight[k] > 0.0:
            for v in range(n_views):
                if not (np.isfinite(obs[v, k, 0]) and np.isfinite(obs[v, k, 1])):
                    continue
                for w in range(n_views):
                    if np.isfinite(obs[w, k, 0]) and np.isfinite(obs[w, k, 1]):
                        span = max(span, sin[v, w])
        out[k] = st.point_prior * (1.0 - span)
    return out


@numba.njit(cache=True)
def column_median_nb(values: FloatArray, keep: BoolArray, out: FloatArray) -> None:
    """Median of each column of ``values`` (N, M) over its finite entries where ``keep``
    (the mean of the two middle ones for an even count; NaN for none), into ``out``."""
    col = np.empty(values.shape[0])
    for j in range(values.shape[1]):
        n = 0
        for i in range(values.shape[0]):
            if keep[i, j] and np.isfinite(values[i, j]):
                col[n] = values[i, j]
                n += 1
        if n == 0:
            out[j] = np.nan
            continue
        srt = np.sort(col[:n])
        out[j] = 0.5 * (srt[(n - 1) // 2] + srt[n // 2])


@numba.njit(cache=True)
def jump_gate_nb(st: FrameSettings, w: FloatArray, jump: FloatArray, k: int) -> bool:
    """Drop (weight 0 in ``w`` (V, K)) joint ``k``'s detections further than ``jump_mm``
    from the previous frame's point (``jump`` (V, K): each detection's distance from it)
    when another of its kept detections is within ``reject_mm`` of it. Returns whether
    one was dropped."""
    agree = False
    for v in range(w.shape[0]):
        if w[v, k] > 0.0 and jump[v, k] <= st.reject_mm:
            agree = True
    if not agree:
        return False
    dropped = False
    for v in range(w.shape[0]):
        if w[v, k] > 0.0 and not (jump[v, k] <= st.jump_mm):
            w[v, k] = 0.0
            dropped = True
    return dropped


@numba.njit(cache=True)
def fit_rejecting_nb(
    m: FrameModel,
    st: FrameSettings,
    q: FloatArray,
    tg: FitTargets,
    iters: int,
    norms: FloatArray,
    gate: bool,
    ref_ok: BoolArray,
) -> None:
    """Fit (in place on ``q``), drop the detections far from the fit, fit again; at most
    three fits. ``tg.weight`` (V, K) is set from the detections and ends with the ones
    kept.

    A detection is dropped when further than ``reject_mm`` from the fit and more than
    twice the median residual of its joint over the views kept: when every view is far,
    the fit is wrong, not the detections, and they keep pulling it. Two views have no
    majority (neither residual can be twice their median), so with ``gate`` (a track
    going on) a joint detected in two views or one drops, before the fit, a detection
    further than ``jump_mm`` from the previous frame's point (``tg.point_ref_mm``) when
    another of its detections is within ``reject_mm`` of it (`jump_gate_nb`). The same
    gate settles a joint whose kept views all stay further than ``reject_mm`` from the
    fit (views in conflict, none outvoted: two views agreeing on a wrong place against a
    third, often when a view is missing), where its previous point was held by two kept
    views (``ref_ok`` (K,), set by `finish_frame_nb`); a previous point the views did
    not confirm is not trusted to outvote them.
    """
    n_views, n_pts = tg.weight.shape
    w = tg.weight
    for v in range(n_views):
        for k in range(n_pts):
            seen = np.isfinite(tg.observed[v, k, 0]) and np.isfinite(tg.observed[v, k, 1])
            w[v, k] = m.base_weight[k] if seen else 0.0
    gate = gate and st.jump_mm > 0.0
    jump = np.full((n_views, n_pts), np.nan)
    if gate:
        residual_norms_nb(m, tg.point_ref_mm, tg.observed, tg.scale_mm, jump)
        for k in range(n_pts):
            n_seen = 0
            for v in range(n_views):
                if w[v, k] > 0.0:
                    n_seen += 1
            if n_seen <= 2:
                jump_gate_nb(st, w, jump, k)
    med = np.empty(n_pts)
    for _ in range(3):
        fit_pose_nb(
            q,
            m.kin,
            m.target_joint,
            m.target_point,
            m.views,
            tg,
            m.lower,
            m.upper,
            st.delta_mm,
            iters,
            norms,
        )
        column_median_nb(norms, w > 0.0, med)
        far = False
        for v in range(n_views):
            for k in range(n_pts):
                r = norms[v, k]
                # NaN residuals count as far (not within either bound)
                if w[v, k] > 0.0 and not (r <= st.reject_mm) and not (r <= 2.0 * med[k]):
                    w[v, k] = 0.0
                    far = True
        if gate:
            for k in range(n_pts):
                near = False
                for v in range(n_views):
                    if w[v, k] > 0.0 and norms[v, k] <= st.reject_mm:
                        near = True
                if not near and ref_ok[k] and jump_gate_nb(st, w, jump, k):
                    far = True
        if not far:
            break


@numba.njit(cache=True)
def cost_nb(
    m: FrameModel, st: FrameSettings, q: FloatArray, tg: FitTargets, norms: FloatArray
) -> float:
    """The fit's robust cost of pose ``q`` (`evaluate_nb` without the normal equations)."""
    d = q.shape[0]
    return evaluate_nb(
        q,
        m.kin,
        m.target_joint,
        m.target_point,
        m.views,
        tg,
        st.delta_mm,
        False,
        np.empty((d, d)),
        np.empty(d),
        norms,
    )


@numba.njit(cache=True)
def begin_frame_nb(
    m: FrameModel,
    st: FrameSettings,
    q: FloatArray,
    norm: FloatArray,
    first: bool,
    prior: FloatArray,
    point_ref: FloatArray,
    iters: int,
    scale: FloatArray,
    ref_ok: BoolArray,
) -> tuple[FitTargets, BoolArray, BoolArray, float]:
    """A frame's first fit from the previous pose ``q`` (in place) and its detections
    ``norm`` (V, K, 2, undistorted normalised); ``scale`` (V,) is the depth of the
    previous pose's hips in each view (`FitTargets.scale_mm`).

    The views' labels are tested against the previous pose (`swap_test_nb`, not on the
    ``first`` frame of a track), the point prior is weighted (`point_weights_nb`) and
    held at the previous pose's points (``point_ref``, updated in place), and the frame
    fitted with outlier rejection (`fit_rejecting_nb`, with the previous frame's
    ``ref_ok``). Returns the fit's targets (their
    ``q_ref`` the previous pose), the views swapped, the limbs to start again (a joint
    of the limb further than ``restart_mm`` from its kept detections, median over the
    views) and the fit's cost.
    """
    n_views, n_pts = norm.shape[0], norm.shape[1]
    norms = np.empty((n_views, n_pts))
    pts = model_points_nb(m, q)
    if first:
        swapped = np.zeros(n_views, dtype=np.bool_)
    else:
        swapped = swap_test_nb(m, st, pts, norm, scale, norms)
    obs = swapped_obs_nb(m, norm, swapped)
    if first:
        point_prior = np.zeros(n_pts)
    else:
        point_prior = point_weights_nb(m, st, pts, obs)
        point_ref[:, :] = pts
    tg = FitTargets(obs, np.zeros((n_views, n_pts)), scale, q.copy(), prior, point_ref, point_prior)
    fit_rejecting_nb(m, st, q, tg, iters, norms, not first, ref_ok)
    base = cost_nb(m, st, q, tg, norms)
    n_limbs = m.limb_rows.shape[0]
    restart = np.zeros(n_limbs, dtype=np.bool_)
    med = np.empty(3)
    for i in range(n_limbs):
        rows = m.limb_rows[i]
        vals = np.full((n_views, 3), np.nan)
        keep = np.zeros((n_views, 3), dtype=np.bool_)
        for j in range(3):
            if rows[j] < 0:
                continue
            for v in range(n_views):
                vals[v, j] = norms[v, rows[j]]
                keep[v, j] = tg.weight[v, rows[j]] > 0.0
        column_median_nb(vals, keep, med)
        worst = 0.0
        for j in range(3):
            if np.isfinite(med[j]):
                worst = max(worst, med[j])
        restart[i] = worst > st.restart_mm
    return tg, swapped, restart, base


@numba.njit(cache=True)
def restart_limb_nb(
    m: FrameModel,
    st: FrameSettings,
    q: FloatArray,
    tg: FitTargets,
    dofs: IntArray,
    seeds: FloatArray,
    base: float,
    max_iter: int,
) -> float:
    """Start one limb again from ``seeds`` (S, len(dofs)) and keep the best if it beats
    the cost ``base``: each seed's cost is taken without the limb's prior (its reference
    pose went wrong), the lowest refined, and kept (in place on ``q``, its pose also
    taken as the prior's reference ``tg.q_ref``) when its cost is below ``base``.
    Returns the cost of the pose kept."""
    n_views, n_pts = tg.weight.shape
    norms = np.empty((n_views, n_pts))
    free = tg.prior.copy()
    for d in dofs:
        free[d] = 1e-3
    tg_free = FitTargets(
        tg.observed, tg.weight, tg.scale_mm, tg.q_ref, free, tg.point_ref_mm, tg.point_prior
    )
    trial = q.copy()
    best = 0
    best_cost = np.inf
    for s in range(seeds.shape[0]):
        for i in range(dofs.shape[0]):
            trial[dofs[i]] = seeds[s, i]
        c = cost_nb(m, st, trial, tg_free, norms)
        if c < best_cost:
            best_cost = c
            best = s
    trial[:] = q
    for i in range(dofs.shape[0]):
        trial[dofs[i]] = seeds[best, i]
    c, _ = fit_pose_nb(
        trial,
        m.kin,
        m.target_joint,
        m.target_point,
        m.views,
        tg_free,
        m.lower,
        m.upper,
        st.delta_mm,
        max_iter,
        norms,
    )
    if c < base:
        q[:] = trial
        for d in dofs:
            tg.q_ref[d] = trial[d]
        return c
    return base


@numba.njit(cache=True)
def finish_frame_nb(
    m: FrameModel,
    st: FrameSettings,
    q: FloatArray,
    norm: FloatArray,
    tg: FitTargets,
    swapped: BoolArray,
    moved: bool,
    iters: int,
    first: bool,
    ref_ok: BoolArray,
) -> tuple[FitTargets, bool]:
    """The rest of a frame's fit after `begin_frame_nb` (and restarts, ``moved``): fitted
    again when a limb was started again; the views' labels tested again against the fit
    (which catches the first frame and a wrong previous pose; ``swapped`` updated in
    place) and the frame fitted again if a view changed. Returns the final targets and
    whether the track is lost (fewer than half the usable detections kept). ``ref_ok``
    (K,) is set in place: the joints two kept views place within ``reject_mm`` of the
    fit (`fit_rejecting_nb` trusts these points in the next frame)."""
    n_views, n_pts = norm.shape[0], norm.shape[1]
    norms = np.empty((n_views, n_pts))
    if moved:
        fit_rejecting_nb(m, st, q, tg, iters, norms, not first, ref_ok)
    again = swap_test_nb(m, st, model_points_nb(m, q), tg.observed, tg.scale_mm, norms)
    if again.any():
        for v in range(n_views):
            swapped[v] = swapped[v] != again[v]
        tg = FitTargets(
            swapped_obs_nb(m, norm, swapped),
            tg.weight,
            tg.scale_mm,
            tg.q_ref,
            tg.prior,
            tg.point_ref_mm,
            tg.point_prior,
        )
        fit_rejecting_nb(m, st, q, tg, iters, norms, not first, ref_ok)
    residual_norms_nb(m, model_points_nb(m, q), tg.observed, tg.scale_mm, norms)
    for k in range(n_pts):
        n_near = 0
        for v in range(n_views):
            if tg.weight[v, k] > 0.0 and norms[v, k] <= st.reject_mm:
                n_near += 1
        ref_ok[k] = n_near >= 2
    usable = 0
    kept = 0
    for v in range(n_views):
        for k in range(n_pts):
            if (
                np.isfinite(tg.observed[v, k, 0])
                and np.isfinite(tg.observed[v, k, 1])
                and m.base_weight[k] > 0.0
            ):
                usable += 1
            if tg.weight[v, k] > 0.0:
                kept += 1
    return tg, kept < 0.5 * max(usable, 1)


@numba.njit(cache=True)
def frame_figures_nb(
    m: FrameModel, q: FloatArray, px: FloatArray, swapped: BoolArray, weight: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Reprojection error (V, K) px of the fitted points against the detections as used
    (``px`` (V, K, 2) with the ``swapped`` views' labels exchanged; NaN without a
    detection or behind the camera), and the canonical joints (C, 3) at ``q``."""
    n_views, n_pts = px.shape[0], px.shape[1]
    pts = model_points_nb(m, q)
    err = np.empty((n_views, n_pts))
    for v in range(n_views):
        cam = CameraArrays(
            m.views.rotation[v], m.views.translation_mm[v], m.intrinsics[v], m.dist[v]
        )
        for k in range(n_pts):
            row = m.perm[k] if swapped[v] else k
            u, w, ok = project_world_point_nb(cam, pts[k, 0], pts[k, 1], pts[k, 2])
            if not ok:
                err[v, k] = np.nan
                continue
            du = u - px[v, row, 0]
            dv = w - px[v, row, 1]
            err[v, k] = np.sqrt(du * du + dv * dv)
    joints = points_nb(q, m.kin, m.canon_joint, m.canon_point)
    return err, joints


__all__ = [
    "FrameModel",
    "FrameSettings",
    "begin_frame_nb",
    "column_median_nb",
    "finish_frame_nb",
    "fit_rejecting_nb",
    "frame_figures_nb",
    "jump_gate_nb",
    "model_points_nb",
    "point_weights_nb",
    "residual_norms_nb",
    "restart_limb_nb",
    "swap_test_nb",
    "swapped_obs_nb",
]
