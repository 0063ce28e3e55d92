"""The monocular tracker as a `mocapkit.tracking.base.DelayedTracker` of world results.

`MonoStream` wraps `mocapkit.tracking.mono.tracker.MonoTracker` (camera-frame stick poses)
and does the tracker's part every tracker does: each frame it makes final is placed in
the world (`to_world`; with the feet on the floor, `mocapkit.tracking.mono.placement`),
the output skeleton's pose fitted to it and a status given per limb. The runner
(`mocapkit.pipelines.run.run_tracker`) streams it over a recording.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.geometry.transforms import transform_points
from mocapkit.skeleton.model import CANONICAL_JOINTS, Skeleton
from mocapkit.skeleton.presets import load_preset
from mocapkit.skeleton.scaling import fit_segments
from mocapkit.tracking.base import (
    BRIDGE_S,
    FrameResult,
    observation_status,
    unobserved_part,
)
from mocapkit.tracking.mono.depth_fusion import fuse_link_depths
from mocapkit.tracking.mono.placement import DepthRate, FloorDepth
from mocapkit.tracking.mono.pose_fit import fit_stick_pose
from mocapkit.tracking.mono.stick import StickModel
from mocapkit.tracking.mono.tracker import MonoConfig, MonoFrame, MonoTracker

FloatArray = NDArray[np.float64]


def output_skeleton(model: StickModel, lengths_mm: FloatArray) -> Skeleton:
    """``upper_stick`` fitted to the tracked link lengths (mm)."""
    sk = load_preset("upper_stick")
    fitted = {s: float(v) for s, v in zip(model.segments, lengths_mm) if s in _UPPER_SEGMENTS}
    return fit_segments(sk, fitted)


_UPPER_SEGMENTS = (
    "trunk", "head", "left_clavicle", "right_clavicle", "left_upper_arm", "right_upper_arm",
    "left_forearm", "right_forearm",
)  # fmt: skip


def to_world(
    frames: list[MonoFrame],
    model: StickModel,
    camera: Camera | None,
    config: MonoConfig,
    px_per_mm: float,
) -> FloatArray:
    """Tracked joints (T, K, 3) in the world frame (mm).

    Calibrated models are already in the camera frame (mm). The orthographic model's px
    are scaled to mm and, with a camera, placed at the depth where the scale holds
    (``f / px_per_mm``) on the camera's axis; without one, in a frame with x right, y the
    depth and z up.
    """
    cam_pts = np.stack([f.joints_in_camera for f in frames])
    if config.camera_model != "orthographic" and camera is not None:
        return world_points(camera, cam_pts)
    mm = cam_pts / px_per_mm
    if camera is None:
        return np.stack([mm[..., 0], mm[..., 2], -mm[..., 1]], axis=-1)
    k = camera.K
    depth = k[0, 0] / px_per_mm
    pts = np.stack(
        [
            (cam_pts[..., 0] - k[0, 2]) / px_per_mm,
            (cam_pts[..., 1] - k[1, 2]) / px_per_mm,
            depth + mm[..., 2],
        ],
        axis=-1,
    )
    return world_points(camera, pts)


def world_points(camera: Camera, points_in_camera: FloatArray) -> FloatArray:
    """Points (..., 3) in the camera frame -> the world frame (mm)."""
    flat = points_in_camera.reshape(-1, 3)
    return transform_points(camera.world_from_camera, flat).reshape(points_in_camera.shape)


@dataclass
class MonoSample:
    """One frame for `MonoStream`: the stick's joints (K, 2) px, NaN where unseen, and
    the ankles (2, 2) px where the stream places the subject on the floor, and a
    detector's depth order per link (``link_sines``, `MonoTracker.push`) where it has one,
    also blended into the placed pose's depth offsets (`MonoStream`)."""

    time_s: float
    points_px: FloatArray
    ankles_px: FloatArray | None = None
    link_sines: FloatArray | None = None


#: Limbs whose status a `MonoResult` reports, by the stick joint at their end.
MONO_LIMBS: dict[str, str] = {
    "head": "head",
    "left_arm": "left_wrist",
    "right_arm": "right_wrist",
    "left_leg": "left_ankle",
    "right_leg": "right_ankle",
}


@dataclass
class MonoResult(FrameResult):
    """A `FrameResult` of the mono tracker, keeping its `MonoFrame`.

    ``status`` per limb of `MONO_LIMBS` the stick has, from the joints that the limb
    alone places (`mocapkit.tracking.base.unobserved_part`: elbow and wrist of an arm,
    knee and ankle of a leg, the head): ``seen`` (all of them in this frame's 2-D points
    and posed), ``bridged`` (posed, one of them read off the smoother over a gap of at
    most ``bridge_s`` since the limb was last seen whole), ``released`` (no pose for them
    after having one, or unseen for longer than ``bridge_s``), ``missing`` (never posed
    yet). The runner sets the joints of a released or missing limb to NaN, as for every
    tracker (`mocapkit.pipelines.run.unobserved_to_nan`). ``fit``: ``residual_px`` (mean
    2-D distance of the chosen pose's projection to the input points), ``candidates``
    and ``survivors`` (poses before and after pruning), ``all_pruned`` (1 where every
    pose was pruned and the unpruned set kept), ``depth_mm`` (neck depth; NaN
    orthographic), ``flips`` (the chosen flip code, -1 without a pose) and ``on_floor``
    (1 where the depth is the feet's on the floor, `mocapkit.tracking.mono.placement`).
    """

    frame: MonoFrame | None = None


class MonoStream:
    """`MonoTracker` as a `mocapkit.tracking.base.DelayedTracker` of world results.

    Each frame the tracker makes final is placed in the world (`to_world`), its
    ``upper_stick`` pose fitted (`mocapkit.tracking.mono.pose_fit.fit_stick_pose`) and
    returned as a `MonoResult`. Offline (``config.lag`` None) every result comes from
    ``finish``; online, the result of frame k comes with frame k + ``smooth_lag + lag``.
    A released limb's angles in ``q`` are the fit's (no joints to follow: its rest
    pose); the runner holds and blends it back in the result folder, as for every
    tracker (`mocapkit.pipelines.run.motion_with_held_parts`).

    Parameters
    ----------
    tracker : MonoTracker
    skeleton : Skeleton
        `output_skeleton` of the tracker's lengths.
    camera : Camera or None
    px_per_mm : float
        Image scale (orthographic model; NaN otherwise).
    bridge_s : float
        Longest gap (s) in a limb's 2-D points that its status calls ``bridged``
        (`mocapkit.tracking.base.BRIDGE_S`, as the hybrid and stereo trackers).
    floor : FloorDepth or None
        Perspective model: each pose is scaled about the camera's centre (its image
        unchanged) to the neck depth of the feet on the floor where that is found and
        agrees with the tracker's depth (`mocapkit.tracking.mono.placement`), the placed
        depth changing beyond the tracker's own depth motion at most at
        `mocapkit.tracking.base.UNSEEN_SPEED_MM_S` (`DepthRate`); None: the tracker's
        depth. A frame whose sample brings ``link_sines`` then has each link's depth
        offset blended with the detector's (``config.depth_fusion_weight``,
        `mocapkit.tracking.mono.depth_fusion.fuse_link_depths`; perspective model only).
    """

    def __init__(
        self,
        tracker: MonoTracker,
        skeleton: Skeleton,
        camera: Camera | None,
        px_per_mm: float,
        bridge_s: float = BRIDGE_S,
        floor: FloorDepth | None = None,
    ) -> None:
        self.tracker = tracker
        self.floor = floor
        self.skeleton = skeleton
        self.camera = camera
        self.px_per_mm = px_per_mm
        model = tracker.model
        self.joint_names = tuple(n for n in CANONICAL_JOINTS if n in model.joint_names)
        self._order = [model.joint_names.index(n) for n in self.joint_names]
        self._rows = [CANONICAL_JOINTS.index(n) for n in self.joint_names]
        self._limbs: dict[str, list[int]] = {}
        for limb, end in MONO_LIMBS.items():
            part = unobserved_part(limb)
            if end in model.joint_names and part is not None:
                self._limbs[limb] = [
                    model.joint_names.index(j) for j in part[1] if j in model.joint_names
                ]
        self.bridge_s = bridge_s
        # per limb, the time its joints were last all in the 2-D points (the frames
        # pushed so far); per pending frame, each limb's time unseen then
        self._last_seen: dict[str, float] = {}
        self._unseen: dict[int, dict[str, float]] = {}
        self._pushed = 0
        self._posed: set[str] = set()
        self._depth_rate = DepthRate()
        cfg = tracker.config
        # the detector's link sines of the pending frames, where its depth is fused
        self._fuse = (
            cfg.depth_fusion_weight > 0 and cfg.camera_model == "perspective" and camera is not None
        )
        self._sines: dict[int, FloatArray] = {}

    def push(self, sample: MonoSample) -> list[FrameResult]:
        """Track one frame; returns the results it makes final."""
        raw = np.asarray(sample.points_px, dtype=float)
        t = float(sample.time_s)
        unseen = {}
        for limb, js in self._limbs.items():
            if np.all(np.isfinite(raw[js])):
                self._last_seen[limb] = t
            unseen[limb] = t - self._last_seen.get(limb, -math.inf)
        self._unseen[self._pushed] = unseen
        if self._fuse and sample.link_sines is not None:
            self._sines[self._pushed] = np.asarray(sample.link_sines, dtype=float)
        self._pushed += 1
        if self.floor is not None:
            ankles = sample.ankles_px if sample.ankles_px is not None else np.full((2, 2), np.nan)
            self.floor.push(raw[0], ankles)
        return [
            self._result(f)
            for f in self.tracker.push(sample.time_s, sample.points_px, sample.link_sines)
        ]

    def finish(self) -> list[FrameResult]:
        """The results still pending (all of them offline)."""
        return [self._result(f) for f in self.tracker.finish()]

    def _result(self, f: MonoFrame) -> MonoResult:
        t = self.tracker
        unseen = self._unseen.pop(f.index)
        sines = self._sines.pop(f.index, None)
        on_floor = 0.0
        if self.floor is not None and f.code >= 0 and np.isfinite(f.depth_mm) and f.depth_mm > 0:
            z = self.floor.depth(f.index, f.depth_mm)
            on_floor = float(np.isfinite(z))
            z = self._depth_rate.place(f.time_s, z if on_floor else f.depth_mm, f.depth_mm)
            f = replace(f, joints_in_camera=f.joints_in_camera * (z / f.depth_mm), depth_mm=z)
        if sines is not None and f.code >= 0:  # placed: the lengths are the subject's mm
            m, w = t.model, t.config.depth_fusion_weight
            fused = fuse_link_depths(f.joints_in_camera, m.parent, m.child, t.lengths, sines, w)
            f = replace(f, joints_in_camera=fused)
        world = to_world([f], t.model, self.camera, t.config, self.px_per_mm)[0]
        joints = world[self._order]
        q = fit_stick_pose(self.skeleton, self.joint_names, joints[None])[0]
        canonical = np.full((len(CANONICAL_JOINTS), 3), np.nan)
        canonical[self._rows] = joints
        status = {}
        for limb, js in self._limbs.items():
            if f.code >= 0 and np.all(np.isfinite(world[js])):
                self._posed.add(limb)
                status[limb] = observation_status(unseen[limb], True, self.bridge_s)
            else:
                status[limb] = "released" if limb in self._posed else "missing"
        fit = {
            "residual_px": f.residual_px,
            "candidates": float(f.n_candidates),
            "survivors": float(f.n_survivors),
            "all_pruned": float(f.pruned_all),
            "depth_mm": f.depth_mm,
            "flips": float(f.code),
            "on_floor": on_floor,
        }
        return MonoResult(f.time_s, q, canonical, status, fit, "", frame=f)
