"""Streaming model-based multi-view tracker: a jointed full-body skeleton fitted to every
view's 2-D detections each frame.

``MultiviewTracker.update(sample) -> FrameResult`` per frame:

1. **Detections** of every view (``sample.keypoints_px``: camera -> (K, 2) px, NaN
   where unseen) are undistorted once to normalised coordinates.
2. **Left/right swap test per view.** A detector that takes the subject as seen from
   behind swaps the sides' labels in that view. Each view's detections are compared with
   the previous frame's pose as given and with the labels of every left/right pair
   exchanged; the exchanged labels are taken when their cost is below `swap_ratio` of
   the labels as given and lower by `swap_margin_mm` per joint pair. After the fit the
   test is made again against the fitted pose (which catches the first frame and a
   wrong previous pose), and the frame is fitted again if a view changed.
3. **Robust fit** (`mocapkit.tracking.multiview.fit.fit_pose_nb`): Levenberg-Marquardt
   on the Huber loss of each detection's reprojection (in mm across the ray at the
   subject), a prior towards the previous frame, joint limits; warm-started from the
   previous frame. Detections further than ``reject_mm`` from the fit are dropped per
   joint and view and the frame is fitted again.
4. **Status** per body part (head, arms, legs) by the detections kept: ``seen`` when
   its end joint is kept in two views (or one view with the middle joint in two),
   ``bridged`` over gaps up to ``gap_limit_s``, then ``released``
   (`mocapkit.tracking.base`'s rule: the runner writes their joints as NaN).
5. **Fit figures**: per joint and view the reprojection error (px) against the
   detection used, the views kept per joint, the mean and largest kept error, the
   views whose labels were exchanged, and ``far_joints``: joints further than
   ``warn_px`` from their detections in most views that see them.

The skeleton is the ``zhang21`` full body (`multiview_skeleton`) with the subject's
segment lengths (`mocapkit.tracking.multiview.lengths`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.errors import ConfigError, ShapeError
from mocapkit.skeleton.kinematics import canonical_positions, kinematic_arrays
from mocapkit.skeleton.limbs import has_limb, limb
from mocapkit.skeleton.model import Skeleton
from mocapkit.skeleton.presets import load_preset
from mocapkit.skeleton.scaling import fit_segments, scale_skeleton
from mocapkit.tracking.base import FrameResult, canonical_joints_mm, observation_status
from mocapkit.tracking.multiview.config import MultiviewConfig
from mocapkit.tracking.multiview.fit import FitTargets, fit_pose_nb, points_nb, view_arrays
from mocapkit.tracking.multiview.lengths import column_median, robust_triangulation

FloatArray = NDArray[np.float64]

#: Options of the ``zhang21`` preset the fit uses: a free root, the spine's and neck's
#: twist and sideways bend and the clavicles (the forearm's roll is not seen by joint detections).
MODEL_OPTIONS: tuple[str, ...] = (
    "root_rotation",
    "spine_rotation",
    "spine_lateral",
    "neck_rotation",
    "clavicle",
)

#: DoFs without limits in the fit: the root's place and heading.
FREE_DOFS: tuple[str, ...] = ("root_tx", "root_ty", "root_tz", "root_yaw")

#: Body parts with a status: the part, its end joint and the joint before it.
PARTS: tuple[tuple[str, str, str | None], ...] = (
    ("head", "head", None),
    ("left_arm", "left_wrist", "left_elbow"),
    ("right_arm", "right_wrist", "right_elbow"),
    ("left_leg", "left_ankle", "left_knee"),
    ("right_leg", "right_ankle", "right_knee"),
)


def multiview_skeleton(
    lengths_mm: Mapping[str, float] | None = None,
    height_mm: float | None = None,
    vectors_mm: Mapping[str, FloatArray] | None = None,
) -> Skeleton:
    """The ``zhang21`` full body with `MODEL_OPTIONS`, scaled to ``height_mm`` and then to
    the measured canonical segment lengths and trunk rest vectors
    (`mocapkit.skeleton.scaling.fit_segments`)."""
    sk = load_preset("zhang21", MODEL_OPTIONS)
    if height_mm is not None:
        sk = scale_skeleton(sk, height_mm=height_mm)
    return fit_segments(sk, lengths_mm=dict(lengths_mm or {}), vectors_mm=dict(vectors_mm or {}))


def swap_permutation(joint_names: Sequence[str]) -> NDArray[np.int64]:
    """Index permutation exchanging every ``left_X`` with ``right_X`` (others fixed)."""
    names = list(joint_names)
    perm = np.arange(len(names))
    for i, n in enumerate(names):
        for a, b in (("left_", "right_"), ("right_", "left_")):
            if n.startswith(a) and b + n[len(a) :] in names:
                perm[i] = names.index(b + n[len(a) :])
    return perm


class MultiviewTracker:
    """Streaming full-body fit to the 2-D detections of two or more calibrated views.

    Parameters
    ----------
    skeleton : Skeleton
        A full-body model with a free root (`multiview_skeleton`).
    cameras : sequence of Camera
        The views, in the order of their names in the samples.
    joint_names : sequence of str
        Canonical names of the detections' K joints.
    config : MultiviewConfig, optional
    rebuilt : sequence of str
        Joints the keypoints' reader placed from others (weighted by
        `MultiviewConfig.rebuilt_weight`).
    """

    def __init__(
        self,
        skeleton: Skeleton,
        cameras: Sequence[Camera],
        joint_names: Sequence[str],
        config: MultiviewConfig | None = None,
        rebuilt: Sequence[str] = (),
    ) -> None:
        if len(cameras) < 2:
            raise ConfigError(f"the multi-view fit needs two or more cameras, found {len(cameras)}")
        self.skeleton = skeleton
        self.cameras = list(cameras)
        self.config = config or MultiviewConfig()
        cfg = self.config
        names = tuple(joint_names)
        self.detected_names = names
        self.model_rows = np.array(
            [k for k, n in enumerate(names) if n in skeleton.canonical], dtype=np.int64
        )
        self.names = tuple(names[k] for k in self.model_rows)
        if not {"left_hip", "right_hip", "left_shoulder", "right_shoulder"} <= set(self.names):
            raise ShapeError(
                "the multi-view fit needs detections of both shoulders and both hips, found "
                f"{list(names)}"
            )
        tj, tp = skeleton.canonical_points(self.names)
        self._tj = np.ascontiguousarray(tj, dtype=np.int64)
        self._tp = np.ascontiguousarray(tp, dtype=np.float64)
        self._kin = kinematic_arrays(skeleton)
        self._views = view_arrays([c.camera_from_world for c in self.cameras])
        self._centers = np.stack([np.asarray(c.center_in_world, dtype=float) for c in self.cameras])
        self._perm = swap_permutation(self.names)
        self._err_keys = [f"{n}_{c.name}_px" for n in self.names for c in self.cameras]
        self._views_keys = [f"{n}_views" for n in self.names]
        self._hip_rows = [self.names.index("left_hip"), self.names.index("right_hip")]
        self._pairs = np.flatnonzero(self._perm != np.arange(len(self.names)))
        self._base_w = np.array([cfg.rebuilt_weight if n in rebuilt else 1.0 for n in self.names])
        free = np.array([n in FREE_DOFS for n in skeleton.dof_names])
        lower = np.where(np.isfinite(skeleton.lower) & ~free, skeleton.lower, -1e9)
        upper = np.where(np.isfinite(skeleton.upper) & ~free, skeleton.upper, 1e9)
        self._lower = np.ascontiguousarray(lower, dtype=float)
        self._upper = np.ascontiguousarray(upper, dtype=float)
        root_t = np.array([n in ("root_tx", "root_ty", "root_tz") for n in skeleton.dof_names])
        self._prior = np.where(root_t, cfg.prior_root, cfg.prior_mm_per_rad).astype(float)
        self._prior_first = np.where(root_t, 1e-4, 1e-2).astype(float)
        self._root_t = np.flatnonzero(root_t)
        self._yaw = skeleton.dof_index("root_yaw")
        idx = {n: i for i, n in enumerate(self.names)}
        self._limbs: list[tuple[NDArray[np.int64], list[int]]] = []
        for part, end, mid in PARTS:
            if mid is None or end not in idx or mid not in idx or not has_limb(skeleton, part):
                continue
            side, kind = part.split("_")
            top = f"{side}_{'shoulder' if kind == 'arm' else 'hip'}"
            rows = [idx[n] for n in (top, mid, end) if n in idx]
            self._limbs.append((limb(skeleton, part).dofs, rows))
        self._rng = np.random.default_rng(0)
        self._point_ref = np.full((len(self.names), 3), np.nan)
        self._point_prior = np.zeros(len(self.names))
        self._q: FloatArray | None = None
        self._last_seen: dict[str, float] = {}
        self._ever_seen: set[str] = set()
        self._norm = np.empty((len(self.cameras), len(self.names)))
        self.swapped = np.zeros(len(self.cameras), dtype=bool)

    # ------------------------------------------------------------------ pieces

    def _observed(self, sample: Any) -> tuple[FloatArray, FloatArray]:
        """Pixels (V, K, 2) of the model's joints in every view and their normalised
        undistorted coordinates."""
        v, k = len(self.cameras), len(self.names)
        px = np.full((v, k, 2), np.nan)
        kp = getattr(sample, "keypoints_px", {}) or {}
        for i, cam in enumerate(self.cameras):
            a = kp.get(cam.name)
            if a is None:
                continue
            arr = np.asarray(a, dtype=float)
            if arr.shape != (len(self.detected_names), 2):
                raise ShapeError(
                    f"keypoints of camera {cam.name!r}: expected ({len(self.detected_names)}, 2), "
                    f"found {arr.shape}"
                )
            px[i] = arr[self.model_rows]
        norm = np.full_like(px, np.nan)
        for i, cam in enumerate(self.cameras):
            ok = np.isfinite(px[i]).all(axis=1)
            if ok.any():
                norm[i, ok] = cam.undistort_pixels(px[i, ok])
        return px, norm

    def _initial_pose(self, px: FloatArray) -> FloatArray | None:
        """A start pose from the frame's robust triangulation: the root on the hips'
        midpoint, turned to the hips' and shoulders' left-right line; limbs at rest."""
        pts, _err, _kept = robust_triangulation(self.cameras, px, reject_mm=1e9)
        idx = {n: i for i, n in enumerate(self.names)}
        need = ("left_hip", "right_hip", "left_shoulder", "right_shoulder")
        if not all(np.isfinite(pts[idx[n]]).all() for n in need):
            return None
        sk = self.skeleton
        q = sk.zero_pose()
        across = (pts[idx["right_hip"]] - pts[idx["left_hip"]]) + (
            pts[idx["right_shoulder"]] - pts[idx["left_shoulder"]]
        )
        q[self._yaw] = math.atan2(across[1], across[0])
        mid_hips = 0.5 * (pts[idx["left_hip"]] + pts[idx["right_hip"]])
        model_hips = self._points(q)[self._hip_rows].mean(axis=0)
        q[self._root_t] += mid_hips - model_hips
        return q

    def _scale(self, q: FloatArray) -> FloatArray:
        """Depth (mm) of the model's hips in each view."""
        hips = self._points(q)[self._hip_rows].mean(axis=0)
        z = np.array([float(c.to_camera(hips)[2]) for c in self.cameras])
        return np.maximum(z, 100.0)

    def _points(self, q: FloatArray) -> FloatArray:
        """World places (K, 3) of the model's joints at pose ``q``."""
        return points_nb(np.ascontiguousarray(q, dtype=float), self._kin, self._tj, self._tp)

    def _targets(
        self,
        norm: FloatArray,
        weight: FloatArray,
        scale: FloatArray,
        q_ref: FloatArray,
        prior: FloatArray,
    ) -> FitTargets:
        return FitTargets(
            np.ascontiguousarray(norm),
            np.ascontiguousarray(weight),
            scale,
            q_ref,
            prior,
            self._point_ref,
            self._point_prior,
        )

    def _view_costs(self, q: FloatArray, norm: FloatArray, scale: FloatArray) -> FloatArray:
        """Robust cost (V, 2) of each view's left/right joints at pose ``q``: labels as
        given (column 0) and exchanged (column 1)."""
        cfg = self.config
        out = np.zeros((len(self.cameras), 2))
        w = np.ones((len(self.cameras), len(self.names)))
        for col, obs in enumerate((norm, norm[:, self._perm])):
            tg = self._targets(obs, w, scale, q, self._prior)
            self._cost(q, tg)
            r = self._norm[:, self._pairs]
            out[:, col] = np.nansum(np.minimum(r, cfg.reject_mm), axis=1)
        return out

    def _swap_test(self, q: FloatArray, norm: FloatArray, scale: FloatArray) -> NDArray[np.bool_]:
        """Views whose exchanged labels fit pose ``q`` clearly better."""
        cfg = self.config
        if self._pairs.size == 0:
            return np.zeros(len(self.cameras), dtype=bool)
        costs = self._view_costs(q, norm, scale)
        n_pairs = max(self._pairs.size // 2, 1)
        return (costs[:, 1] < cfg.swap_ratio * costs[:, 0]) & (
            (costs[:, 0] - costs[:, 1]) > cfg.swap_margin_mm * n_pairs
        )

    def _fit(
        self,
        q: FloatArray,
        norm: FloatArray,
        scale: FloatArray,
        q_ref: FloatArray,
        prior: FloatArray,
        iters: int,
    ) -> FloatArray:
        """Fit, drop the detections further than ``reject_mm``, fit again; returns the
        weights (V, K) kept."""
        cfg = self.config
        weight = np.where(np.isfinite(norm).all(axis=-1), self._base_w[None, :], 0.0)
        for _ in range(3):
            tg = self._targets(norm, weight, scale, q_ref, prior)
            fit_pose_nb(
                q,
                self._kin,
                self._tj,
                self._tp,
                self._views,
                tg,
                self._lower,
                self._upper,
                cfg.delta_mm,
                iters,
                self._norm,
            )
            # a detection is dropped when far from the fit and from what the other views
            # say (twice their median residual): when every view is far the fit is wrong,
            # not the detections, and they keep pulling it
            med = column_median(np.where(weight > 0, self._norm, np.nan))
            far = (weight > 0) & ~(self._norm <= cfg.reject_mm) & ~(self._norm <= 2.0 * med)
            if not far.any():
                break
            weight = np.where(far, 0.0, weight)
        return weight

    def _point_weights(self, q: FloatArray, obs: FloatArray) -> FloatArray:
        """Square root of the 3-D point prior's weight per joint (K,): `point_prior` times
        one less the largest |sin| of the angle between the rays to the subject of two
        views that detect the joint. Views far apart (|sin| near 1) fix the joint alone and
        the prior is near 0 (no lag); two facing cameras or a narrow pair leave the depth
        along their rays free and the prior holds it; one view or none: the full weight."""
        hips = self._points(q)[self._hip_rows].mean(axis=0)
        ray = hips[None, :] - self._centers
        ray /= np.maximum(np.linalg.norm(ray, axis=1, keepdims=True), 1e-9)
        sin = np.linalg.norm(np.cross(ray[:, None, :], ray[None, :, :]), axis=2)
        seen = np.isfinite(obs).all(axis=-1) & (self._base_w[None, :] > 0)  # (V, K)
        both = seen[:, None, :] & seen[None, :, :]  # (V, V, K)
        span = np.where(both, sin[:, :, None], 0.0).max(axis=(0, 1))
        return np.ascontiguousarray(self.config.point_prior * (1.0 - span))

    def _restart_limbs(
        self,
        q: FloatArray,
        obs: FloatArray,
        weight: FloatArray,
        scale: FloatArray,
        q_ref: FloatArray,
        prior: FloatArray,
    ) -> bool:
        """Start each limb left far from its detections again from random poses within
        its limits (`MultiviewConfig.restart_mm`); keeps the lowest cost, in place on
        ``q``. The prior of a limb started again no longer holds it to the previous
        frame's pose, which was wrong (``q_ref`` takes the new pose, in place). Returns
        whether a limb was started again."""
        cfg = self.config
        tg = self._targets(obs, weight, scale, q_ref, prior)
        base = self._cost(q, tg)
        norm = self._norm.copy()
        moved = False
        for dofs, rows in self._limbs:
            res = np.where(weight[:, rows] > 0, norm[:, rows], np.nan)
            med = column_median(res)
            if not (np.nanmax(med, initial=0.0) > cfg.restart_mm):
                continue
            lo, hi = self._lower[dofs], self._upper[dofs]
            seeds = self._rng.uniform(lo, hi, (cfg.restart_seeds, dofs.size))
            # the candidates are judged without the limb's prior (its reference pose is
            # the one that went wrong), the current pose with it
            free = prior.copy()
            free[dofs] = 1e-3
            tg_free = self._targets(obs, weight, scale, q_ref, free)
            costs = []
            trial = q.copy()
            for seed in seeds:
                trial[dofs] = seed
                costs.append(self._cost(trial, tg_free))
            # the best seed refined (refining the best two: no better on the tuning set)
            for k in np.argsort(costs)[:1]:
                trial = q.copy()
                trial[dofs] = seeds[k]
                c, _ = fit_pose_nb(
                    trial,
                    self._kin,
                    self._tj,
                    self._tp,
                    self._views,
                    tg_free,
                    self._lower,
                    self._upper,
                    cfg.delta_mm,
                    cfg.max_iter,
                    self._norm,
                )
                if c < base:
                    base = c
                    q[:] = trial
                    q_ref[dofs] = trial[dofs]
                    moved = True
        return moved

    def _cost(self, q: FloatArray, tg: FitTargets) -> float:
        from mocapkit.tracking.multiview.fit import evaluate_nb

        d = q.shape[0]
        return float(
            evaluate_nb(
                q,
                self._kin,
                self._tj,
                self._tp,
                self._views,
                tg,
                self.config.delta_mm,
                False,
                np.empty((d, d)),
                np.empty(d),
                self._norm,
            )
        )

    # ------------------------------------------------------------------ update

    def update(self, sample: Any) -> FrameResult:
        """Fit one frame (``sample.time_s``, ``sample.keypoints_px``)."""
        cfg = self.config
        t = float(sample.time_s)
        px, norm = self._observed(sample)
        first = self._q is None
        if self._q is None:
            self._q = self._initial_pose(px)
        if self._q is None:
            return self._no_pose(t, px)
        q = self._q.copy()
        scale = self._scale(q)
        swapped = np.zeros(len(self.cameras), dtype=bool)
        if not first:
            swapped = self._swap_test(q, norm, scale)
        obs = np.where(swapped[:, None, None], norm[:, self._perm], norm)
        q_ref = q.copy()
        prior = self._prior_first if first else self._prior
        self._point_prior = np.zeros(len(self.names)) if first else self._point_weights(q, obs)
        if not first:
            self._point_ref = np.ascontiguousarray(self._points(q))
        iters = cfg.first_iter if first else cfg.max_iter
        weight = self._fit(q, obs, scale, q_ref, prior, iters)
        if self._restart_limbs(q, obs, weight, scale, q_ref, prior):
            weight = self._fit(q, obs, scale, q_ref, prior, iters)
        again = self._swap_test(q, obs, scale)
        if again.any():
            swapped ^= again
            obs = np.where(swapped[:, None, None], norm[:, self._perm], norm)
            weight = self._fit(q, obs, scale, q_ref, prior, iters)
        n_det = np.isfinite(obs).all(axis=-1)
        if (weight > 0).sum() < 0.5 * max(int((n_det & (self._base_w > 0)).sum()), 1):
            self._q = None  # lost: start again from the next frame's triangulation
        else:
            self._q = q
        self.swapped = swapped
        px_used = np.where(swapped[:, None, None], px[:, self._perm], px)
        return self._result(t, q, px_used, weight)

    def _no_pose(self, t: float, px: FloatArray) -> FrameResult:
        status = {p: self._status(p, t, False) for p, _e, _m in PARTS}
        fit: dict[str, float] = {}
        for n in self.names:
            for c in self.cameras:
                fit[f"{n}_{c.name}_px"] = math.nan
            fit[f"{n}_views"] = 0.0
        for c in self.cameras:
            fit[f"{c.name}_swapped"] = 0.0
        fit.update(
            {"mean_px": math.nan, "max_px": math.nan, "swapped_views": 0.0, "far_joints": 0.0}
        )
        d = self.skeleton.n_dofs
        return FrameResult(t, np.full(d, np.nan), np.full((15, 3), np.nan), status, fit, "")

    def _status(self, part: str, t: float, seen: bool) -> str:
        if seen:
            self._last_seen[part] = t
            self._ever_seen.add(part)
            return "seen"
        if part not in self._ever_seen:
            return "missing"
        # the one rule; 1e-9 s keeps a gap of exactly the limit (in float) bridged
        return observation_status(t - self._last_seen[part], True, self.config.gap_limit_s + 1e-9)

    def _result(self, t: float, q: FloatArray, px: FloatArray, weight: FloatArray) -> FrameResult:
        cfg = self.config
        sk = self.skeleton
        pts = self._points(q)
        err = np.full((len(self.cameras), len(self.names)), np.nan)
        for i, c in enumerate(self.cameras):
            proj = c.project(pts)
            err[i] = np.linalg.norm(proj - px[i], axis=1)
        kept = weight > 0
        views = kept.sum(axis=0)
        fit: dict[str, float] = dict(zip(self._err_keys, err.T.ravel().tolist(), strict=True))
        fit.update(zip(self._views_keys, views.astype(float).tolist(), strict=True))
        kept_err = np.where(kept, err, np.nan)
        finite = np.isfinite(kept_err)
        det = np.isfinite(err)
        with np.errstate(invalid="ignore"):
            far = (det.sum(axis=0) >= 2) & ((err > cfg.warn_px).sum(axis=0) * 2 > det.sum(axis=0))
        worst = ""
        if finite.any():
            per_joint = np.where(
                finite.any(axis=0), np.nanmax(np.where(finite, kept_err, -1), axis=0), -1
            )
            worst = self.names[int(np.argmax(per_joint))]
            mean_px, max_px = float(np.nanmean(kept_err)), float(np.nanmax(kept_err))
        else:
            mean_px = max_px = math.nan
        for i, c in enumerate(self.cameras):
            fit[f"{c.name}_swapped"] = float(self.swapped[i])
        fit.update(
            {
                "mean_px": mean_px,
                "max_px": max_px,
                "swapped_views": float(self.swapped.sum()),
                "far_joints": float(far.sum()),
            }
        )
        idx = {n: i for i, n in enumerate(self.names)}
        status = {}
        for part, end, mid in PARTS:
            if end not in idx:
                continue
            seen = views[idx[end]] >= 2 or (
                views[idx[end]] >= 1 and mid is not None and mid in idx and views[idx[mid]] >= 2
            )
            status[part] = self._status(part, t, bool(seen))
        joints = canonical_joints_mm(sk, canonical_positions(sk, q))
        return FrameResult(t, q.copy(), joints, status, fit, worst)


__all__ = [
    "MODEL_OPTIONS",
    "PARTS",
    "MultiviewTracker",
    "multiview_skeleton",
    "swap_permutation",
]
