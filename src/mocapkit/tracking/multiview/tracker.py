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
   joint and view and the frame is fitted again; a joint seen by two views (no
   majority), or whose views all stay far from the fit (in conflict, none outvoted),
   drops a detection further than ``jump_mm`` from the joint's place in the previous
   frame when another is near it (in conflict: only where two views confirmed that
   place).
4. **Status** per body part (head, arms, legs) by the detections kept: ``seen`` when
   its end joint is kept in two views (or one view with the middle joint in two),
   ``bridged`` over gaps up to ``gap_limit_s``, then ``released``
   (`mocapkit.tracking.base`'s rule: the runner writes their joints as NaN).
5. **Fit figures**: per joint and view the reprojection error (px) against the
   detection used, the views kept per joint, the mean and largest kept error, the
   views whose labels were exchanged, and ``far_joints``: joints further than
   ``warn_px`` from their detections in most views that see them.

Steps 2, 3 and 5 run as compiled kernels (`mocapkit.tracking.multiview.frame`), a few
calls per frame. The skeleton is the ``zhang21`` full body (`multiview_skeleton`) with
the subject's segment lengths (`mocapkit.tracking.multiview.lengths`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.errors import ConfigError, ShapeError
from mocapkit.geometry.transforms import transform_points
from mocapkit.skeleton.kinematics import kinematic_arrays
from mocapkit.skeleton.limbs import has_limb, limb
from mocapkit.skeleton.model import CANONICAL_JOINTS, Skeleton
from mocapkit.skeleton.presets import load_preset
from mocapkit.skeleton.scaling import fit_segments, scale_skeleton
from mocapkit.tracking.base import FrameResult, observation_status
from mocapkit.tracking.multiview.config import MultiviewConfig
from mocapkit.tracking.multiview.detector_offsets import offset_points
from mocapkit.tracking.multiview.fit import points_nb, view_arrays
from mocapkit.tracking.multiview.frame import (
    FrameModel,
    FrameSettings,
    begin_frame_nb,
    finish_frame_nb,
    frame_figures_nb,
    restart_limb_nb,
)
from mocapkit.tracking.multiview.lengths import robust_triangulation

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


@functools.lru_cache(maxsize=1)
def _model_preset() -> Skeleton:
    """The ``zhang21`` preset with `MODEL_OPTIONS`, read once (a frozen skeleton; the
    scalings return new ones)."""
    return load_preset("zhang21", MODEL_OPTIONS)


def multiview_skeleton(
    lengths_mm: Mapping[str, float] | None = None,
    height_mm: float | None = None,
    vectors_mm: Mapping[str, FloatArray] | None = None,
) -> Skeleton:
    """The ``zhang21`` full body with `MODEL_OPTIONS`, scaled to ``height_mm`` and then to
    the measured canonical segment lengths and trunk rest vectors
    (`mocapkit.skeleton.scaling.fit_segments`)."""
    sk = _model_preset()
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
    point_offsets_mm : mapping of str to (3,) array, optional
        The detector's systematic offset per canonical joint, in that joint's frame of the
        skeleton (`mocapkit.tracking.multiview.detector_offsets.offset_points`): the point
        matched to the detections is the joint plus its offset; the output stays the joint.
    """

    def __init__(
        self,
        skeleton: Skeleton,
        cameras: Sequence[Camera],
        joint_names: Sequence[str],
        config: MultiviewConfig | None = None,
        rebuilt: Sequence[str] = (),
        point_offsets_mm: Mapping[str, Sequence[float]] | None = None,
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
        tj, tp = offset_points(skeleton, self.names, point_offsets_mm or {})
        self._tj = np.ascontiguousarray(tj, dtype=np.int64)
        self._tp = np.ascontiguousarray(tp, dtype=np.float64)
        self._kin = kinematic_arrays(skeleton)
        self._perm = swap_permutation(self.names)
        self._err_keys = [f"{n}_{c.name}_px" for n in self.names for c in self.cameras]
        self._views_keys = [f"{n}_views" for n in self.names]
        self._hip_rows = [self.names.index("left_hip"), self.names.index("right_hip")]
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
        self._rows = idx
        self._limbs: list[tuple[NDArray[np.int64], list[int]]] = []
        for part, end, mid in PARTS:
            if mid is None or end not in idx or mid not in idx or not has_limb(skeleton, part):
                continue
            side, kind = part.split("_")
            top = f"{side}_{'shoulder' if kind == 'arm' else 'hip'}"
            rows = [idx[n] for n in (top, mid, end) if n in idx]
            self._limbs.append((limb(skeleton, part).dofs.astype(np.int64), rows))
        self._camera_from_world = np.stack([c.camera_from_world for c in self.cameras])
        self._swapped_keys = [f"{c.name}_swapped" for c in self.cameras]
        self._rng = np.random.default_rng(0)
        self._point_ref = np.full((len(self.names), 3), np.nan)
        self._ref_ok = np.zeros(len(self.names), dtype=bool)
        self._q: FloatArray | None = None
        self._last_seen: dict[str, float] = {}
        self._ever_seen: set[str] = set()
        self.swapped = np.zeros(len(self.cameras), dtype=bool)
        limb_rows = np.full((len(self._limbs), 3), -1, dtype=np.int64)
        for i, (_dofs, rows) in enumerate(self._limbs):
            limb_rows[i, : len(rows)] = rows
        cj, cp = skeleton.canonical_points()
        self._canon_rows = np.array(
            [CANONICAL_JOINTS.index(n) for n in skeleton.canonical_names], dtype=np.int64
        )
        self._model = FrameModel(
            self._kin,
            self._tj,
            self._tp,
            view_arrays([c.camera_from_world for c in self.cameras]),
            np.stack([c.arrays.K for c in self.cameras]),
            np.stack([c.arrays.dist for c in self.cameras]),
            np.stack([np.asarray(c.center_in_world, dtype=float) for c in self.cameras]),
            np.array(self._hip_rows, dtype=np.int64),
            self._perm,
            np.flatnonzero(self._perm != np.arange(len(self.names))).astype(np.int64),
            self._base_w,
            self._lower,
            self._upper,
            limb_rows,
            np.ascontiguousarray(cj, dtype=np.int64),
            np.ascontiguousarray(cp, dtype=float),
        )
        self._settings = FrameSettings(
            cfg.delta_mm,
            cfg.reject_mm,
            cfg.swap_ratio,
            cfg.swap_margin_mm,
            cfg.point_prior,
            cfg.restart_mm,
            cfg.jump_mm,
        )

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
        # each point on its own: rows without a detection come out NaN, as they go in
        norm = np.stack([cam.undistort_pixels(px[i]) for i, cam in enumerate(self.cameras)])
        norm[~np.isfinite(px).all(axis=-1)] = np.nan
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
        z = transform_points(self._camera_from_world, hips[None, :])[:, 0, 2]
        return np.maximum(z, 100.0)

    def _points(self, q: FloatArray) -> FloatArray:
        """World places (K, 3) of the model's joints at pose ``q``."""
        return points_nb(np.ascontiguousarray(q, dtype=float), self._kin, self._tj, self._tp)

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
        prior = self._prior_first if first else self._prior
        iters = cfg.first_iter if first else cfg.max_iter
        m, st = self._model, self._settings
        tg, swapped, restart, base = begin_frame_nb(
            m, st, q, norm, first, prior, self._point_ref, iters, self._scale(q), self._ref_ok
        )
        moved = False
        for i in np.flatnonzero(restart):
            dofs = self._limbs[i][0]
            seeds = self._rng.uniform(
                self._lower[dofs], self._upper[dofs], (cfg.restart_seeds, dofs.size)
            )
            cost = restart_limb_nb(m, st, q, tg, dofs, seeds, base, cfg.max_iter)
            moved |= cost < base
            base = cost
        tg, lost = finish_frame_nb(m, st, q, norm, tg, swapped, moved, iters, first, self._ref_ok)
        # lost: start again from the next frame's triangulation
        self._q = None if lost else q
        self.swapped = swapped
        return self._result(t, q, px, tg.weight)

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
        err, canon = frame_figures_nb(self._model, q, px, self.swapped, weight)
        kept = weight > 0
        views = kept.sum(axis=0)
        fit: dict[str, float] = dict(zip(self._err_keys, err.T.ravel().tolist(), strict=True))
        fit.update(zip(self._views_keys, views.astype(float).tolist(), strict=True))
        kept_err = np.where(kept, err, np.nan)
        finite = np.isfinite(kept_err)
        det = np.isfinite(err)
        n_det = det.sum(axis=0)
        far = (n_det >= 2) & ((err > cfg.warn_px).sum(axis=0) * 2 > n_det)
        worst = ""
        if finite.any():
            per_joint = np.where(finite, kept_err, -1.0).max(axis=0)
            worst = self.names[int(np.argmax(per_joint))]
            mean_px, max_px = float(kept_err[finite].mean()), float(kept_err[finite].max())
        else:
            mean_px = max_px = math.nan
        fit.update(zip(self._swapped_keys, self.swapped.astype(float).tolist(), strict=True))
        fit.update(
            {
                "mean_px": mean_px,
                "max_px": max_px,
                "swapped_views": float(self.swapped.sum()),
                "far_joints": float(far.sum()),
            }
        )
        status = {}
        for part, end, mid in PARTS:
            if end not in self._rows:
                continue
            e = self._rows[end]
            m = self._rows.get(mid or "", -1)
            seen = views[e] >= 2 or (views[e] >= 1 and m >= 0 and views[m] >= 2)
            status[part] = self._status(part, t, bool(seen))
        joints = np.full((len(CANONICAL_JOINTS), 3), np.nan)
        joints[self._canon_rows] = canon
        return FrameResult(t, q.copy(), joints, status, fit, worst)


__all__ = [
    "MODEL_OPTIONS",
    "PARTS",
    "MultiviewTracker",
    "multiview_skeleton",
    "swap_permutation",
]
