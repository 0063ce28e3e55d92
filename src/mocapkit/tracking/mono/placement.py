"""The subject's depth from the feet on the floor, with a calibrated camera.

The tracker's own depth (`mocapkit.tracking.mono.tracker`) comes from the link lengths
alone: an upper bound per frame, of which a low percentile is taken, so it errs by one
or two hundred mm either way and the pose lands off the person in the other cameras.
A calibrated camera also knows its height and tilt above the floor (the world's z = 0,
z up). Where an ankle is seen and stands on the floor, its viewing ray meets the plane
``z = ankle_height`` at the foot; the neck lies on its own ray above the foot
(upright trunk): the ray's point nearest the foot in the floor's plan gives the neck's
depth. Of the two ankles the nearer intersection is taken (a raised foot's ray meets the
plane beyond the foot). A frame counts only where the neck so placed stands a plausible
height above the foot (``neck_share`` of the stature, a band); the depth of a frame is
a low percentile (`FloorConfig.percentile`) over a window of such frames around it (a
foot lifted in a step meets the floor beyond itself: its depths lie on the far side).

Where the subject does not stand on the floor (a step, a box, a treadmill) the floor
places it too far. So the floor's depth is tested against the tracker's (the stature's)
depth of the same frame: at the tracker's depth the foot would stand
``(camera height - ankle height) (1 - tracker depth / floor depth)`` above the floor;
where that exceeds `FloorConfig.gap_mm` the floor is not trusted and the tracker's depth
stays. One-sided: a floor depth nearer than the tracker's (the foot would be below the
floor) is kept. Where no floor depth is found the tracker's depth stays too.

A detector marks the ankle where its training labels put it, not at the joint:
MediaPipe's sits some 60 mm above it. Where the keypoints name their detector, its known
offset (`mocapkit.tracking.multiview.detector_offsets`, read by the pipeline) raises the
plane the ankle's ray is cut with (``ankle_lift_mm``, `detector_ankle_lift_mm`); without
it MediaPipe's floor depths land 50-250 mm beyond the subject.

The depth placed is the floor's on some frames and the tracker's on others, and the
floor's window changes as frames enter and leave it: each switch moved the whole body
along the camera's rays by 100-300 mm in one frame. `DepthRate` passes the tracker's own
depth motion whole and lets the rest of a change (a change of estimate, not of the
subject's motion) through at `mocapkit.tracking.base.UNSEEN_SPEED_MM_S` at most.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.tracking.base import UNSEEN_SPEED_MM_S

FloatArray = NDArray[np.float64]

#: Height of the ankle joint above the floor when the foot is down, as a share of the
#: stature (the lowest ankle of the tuning clips' truth: 0.052-0.072).
ANKLE_SHARE = 0.055
#: Band of the neck's height above the standing ankle, as shares of the stature:
#: upright about 0.78; lower when bent or squatting; above it the foot is off the floor.
NECK_SHARE = (0.45, 0.85)


@dataclass(frozen=True)
class FloorConfig:
    """How `FloorDepth` places the subject (module docstring).

    Attributes
    ----------
    on_floor : bool
        Place the subject by its feet where they stand on the floor (with a calibrated
        perspective camera and the ankles seen); False: the tracker's depth throughout.
    half_window : int
        Frames on each side of a frame whose floor depths its depth takes.
    percentile : float
        Percentile of the window's floor depths (a lifted foot's lie beyond).
    gap_mm : float
        Largest height (mm) the foot may stand above the floor at the tracker's depth
        for the floor's depth to be taken.
    """

    on_floor: bool = True
    half_window: int = 15
    percentile: float = 25.0
    gap_mm: float = 200.0


#: The joints whose image points stand on the floor.
ANKLE_JOINTS = ("left_ankle", "right_ankle")


def detector_ankle_lift_mm(offsets_mm: Mapping[str, Sequence[float]]) -> float:
    """Height (mm) of a detector's ankle point above the ankle joint of a foot standing on
    the floor, from its per-joint offsets (`mocapkit.tracking.multiview.detector_offsets`:
    mm in the shank's frame, whose z is up at the rest pose, standing): the mean z of the
    ankles' offsets; 0 where it has none. The offsets' small sideways and forward parts
    are left out (the foot's point is only cut with a horizontal plane)."""
    ups = [float(offsets_mm[n][2]) for n in ANKLE_JOINTS if n in offsets_mm]
    return float(np.mean(ups)) if ups else 0.0


def floor_points(
    camera: Camera, normalised: ArrayLike, height_mm: float
) -> tuple[FloatArray, FloatArray]:
    """Where viewing rays meet the horizontal plane ``z = height_mm`` of the world.

    Parameters
    ----------
    camera : Camera
        Calibrated, in a world frame whose floor is z = 0 (z up).
    normalised : (A, 2) float
        Undistorted normalised image points (x_n, y_n).
    height_mm : float

    Returns
    -------
    depth : (A,) float
        Camera depth (z, mm) of each meeting point; NaN where the ray does not meet the
        plane in front of the camera or the point is NaN.
    world : (A, 3) float
        The meeting points in the world frame (mm; NaN where ``depth`` is).
    """
    n = np.asarray(normalised, dtype=float).reshape(-1, 2)
    world_from_camera = np.linalg.inv(camera.camera_from_world)
    rot, centre = world_from_camera[:3, :3], world_from_camera[:3, 3]
    rays = np.c_[n, np.ones(n.shape[0])] @ rot.T
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (height_mm - centre[2]) / rays[:, 2]
    t = np.where(np.isfinite(t) & (t > 0), t, np.nan)  # a ray's camera z is 1: t is the depth
    return t, centre + t[:, None] * rays


def floor_neck_depth(
    camera: Camera,
    stature_mm: float,
    neck_px: ArrayLike,
    ankles_px: ArrayLike,
    ankle_lift_mm: float = 0.0,
) -> float:
    """Depth (camera z, mm) of the neck above the foot standing on the floor; NaN where
    no ankle is seen, none meets the floor in front of the camera, or the neck so placed
    is not a plausible height above it (module docstring).

    Parameters
    ----------
    camera : Camera
        Calibrated, in a world frame whose floor is z = 0 (z up).
    stature_mm : float
    neck_px : (2,) float
    ankles_px : (A, 2) float
        NaN where not seen.
    ankle_lift_mm : float
        Height of the ankle points above the ankle joint (a detector's offset,
        `detector_ankle_lift_mm`; 0: the joint itself).
    """
    neck = np.asarray(neck_px, dtype=float).reshape(1, 2)
    ankles = np.asarray(ankles_px, dtype=float).reshape(-1, 2)
    seen = np.isfinite(ankles).all(axis=1)
    if not np.isfinite(neck).all() or not seen.any():
        return float("nan")
    world_from_camera = np.linalg.inv(camera.camera_from_world)
    rot, centre = world_from_camera[:3, :3], world_from_camera[:3, 3]
    height = ANKLE_SHARE * stature_mm + ankle_lift_mm
    t, feet = floor_points(camera, camera.undistort_pixels(ankles[seen]), height)
    t = np.where(np.isfinite(t), t, np.inf)
    if not np.isfinite(t).any():
        return float("nan")
    i = int(np.argmin(t))  # the nearer foot: a raised one meets the plane beyond itself
    foot = feet[i]
    d = np.r_[camera.undistort_pixels(neck)[0], 1.0] @ rot.T
    plan = float(d[:2] @ d[:2])
    if plan <= 1e-12:
        return float("nan")
    s = float((foot - centre)[:2] @ d[:2]) / plan
    neck_w = centre + s * d
    rise = (neck_w[2] - foot[2]) / stature_mm
    if s <= 0 or not NECK_SHARE[0] <= rise <= NECK_SHARE[1]:
        return float("nan")
    return float(s)  # the ray's z in the camera frame is 1: s is the depth


class FloorDepth:
    """`floor_neck_depth` per frame, a percentile of it over a window of frames around
    one, and the test against the tracker's depth (module docstring).

    Parameters
    ----------
    camera : Camera
    stature_mm : float
    config : FloorConfig, optional
    ankle_lift_mm : float
        Height of the ankle points above the ankle joint (`floor_neck_depth`).
    """

    def __init__(
        self,
        camera: Camera,
        stature_mm: float,
        config: FloorConfig | None = None,
        ankle_lift_mm: float = 0.0,
    ) -> None:
        self.camera = camera
        self.stature_mm = float(stature_mm)
        self.config = config or FloorConfig()
        self.ankle_lift_mm = float(ankle_lift_mm)
        #: height (mm) above the floor of the ankle points of a foot standing on it
        self.ankle_height_mm = ANKLE_SHARE * self.stature_mm + self.ankle_lift_mm
        self._lift = float(np.linalg.inv(camera.camera_from_world)[2, 3]) - self.ankle_height_mm
        self._depth: dict[int, float] = {}
        self._n = 0
        self.trusted = 0
        self.rejected = 0

    def push(self, neck_px: ArrayLike, ankles_px: ArrayLike) -> None:
        """The next frame's neck and ankles (px, NaN where unseen)."""
        self._depth[self._n] = floor_neck_depth(
            self.camera, self.stature_mm, neck_px, ankles_px, self.ankle_lift_mm
        )
        self._n += 1

    def window_depth(self, frame: int) -> float:
        """The ``percentile`` of the floor depths of the window around ``frame`` among the
        frames pushed (NaN if it has none); frames older than the window are forgotten
        (call in frame order)."""
        hw = self.config.half_window
        for k in [k for k in self._depth if k < frame - hw]:
            del self._depth[k]
        w = [v for k, v in self._depth.items() if abs(k - frame) <= hw and np.isfinite(v)]
        return float(np.percentile(w, self.config.percentile)) if w else float("nan")

    def depth(self, frame: int, own_depth_mm: float) -> float:
        """The floor's depth of ``frame`` where it passes the test against the tracker's
        depth ``own_depth_mm`` (NaN: keep the tracker's; module docstring)."""
        z = self.window_depth(frame)
        if not np.isfinite(z):
            return z
        if np.isfinite(own_depth_mm) and self._lift > 0:
            if self._lift * (1.0 - own_depth_mm / z) > self.config.gap_mm:
                self.rejected += 1
                return float("nan")
        self.trusted += 1
        return z


class DepthRate:
    """The placed depth, moving with the tracker's own depth and otherwise at most
    ``speed_mm_s`` (module docstring).

    Parameters
    ----------
    speed_mm_s : float
        Fastest change of the estimate beyond the tracker's own depth motion.
    """

    def __init__(self, speed_mm_s: float = UNSEEN_SPEED_MM_S) -> None:
        self.speed_mm_s = speed_mm_s
        self._last: tuple[float, float, float] | None = None  # time, placed, own depth

    def place(self, time_s: float, target_mm: float, own_depth_mm: float) -> float:
        """The depth to place a frame at: ``target_mm`` (the floor's or the tracker's
        depth) where the previous frame's placed depth plus the tracker's own change
        since lies within the bound of it, else the bound's edge towards it."""
        z = target_mm
        if self._last is not None:
            t0, z0, own0 = self._last
            base = z0 + (own_depth_mm - own0)
            step = self.speed_mm_s * max(time_s - t0, 0.0)
            z = min(max(target_mm, base - step), base + step)
        self._last = (time_s, z, own_depth_mm)
        return z
