"""Plausible motion: per frame and joint, is the result's speed one that the inputs show?

A joint's allowed speed on a frame is ``factor`` times the speed its input shows there
plus ``floor_mm_s`` for what no input can show (`SpeedBound`); a joint faster than that
is implausible on that frame (a pop: a re-seed, a branch switch, a depth flip), while a
jump the inputs make too is allowed. Where a joint's input is missing there is no
evidence (NaN) and nothing is flagged. The input speed near a joint comes from markers
(`nearest_input_speeds`) or from 2-D keypoints in calibrated views (one view: the
lateral speed it shows, `view_speeds_mm_s`; two or more: the keypoints triangulated,
`triangulated_speeds_mm_s`). Each bone's roll about its own axis, which no input shows, is held to
one speed limit (`roll_speeds_deg_s`). `check_motion` does both, batched over a run.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.camera.triangulation import triangulate_views
from mocapkit.errors import ConfigError, ShapeError
from mocapkit.eval.continuity import roll_steps_deg, speeds_mm_s
from mocapkit.skeleton.model import Skeleton

FloatArray = NDArray[np.float64]

#: The per-frame columns of `MotionCheck.columns`, in order; those holding names.
FRAME_COLUMNS: tuple[str, ...] = (
    "implausible_joints",
    "worst_joint",
    "worst_speed_ratio",
    "worst_joint_speed_mm_per_s",
    "worst_input_speed_mm_per_s",
    "implausible_rolls",
    "worst_roll_bone",
    "worst_roll_deg_per_s",
)
NAME_COLUMNS: tuple[str, ...] = ("worst_joint", "worst_roll_bone")

#: Frames handled at a time by `roll_speeds_deg_s` (poses turned into world rotations)
#: and `nearest_input_speeds` (joint-to-input distances): memory stays flat as a
#: recording grows.
_FRAME_CHUNK = 2048


@dataclass(frozen=True)
class SpeedBound:
    """The fastest a joint may move given the speed its input shows:
    ``factor * input_mm_s + floor_mm_s``."""

    factor: float
    floor_mm_s: float

    def __post_init__(self) -> None:
        if not (np.isfinite(self.factor) and self.factor >= 0):
            raise ConfigError(f"SpeedBound.factor: expected a number >= 0, found {self.factor}")
        if not (np.isfinite(self.floor_mm_s) and self.floor_mm_s > 0):
            raise ConfigError(
                f"SpeedBound.floor_mm_s: expected a speed > 0 mm/s, found {self.floor_mm_s}"
            )

    def allowed_mm_s(self, input_mm_s: ArrayLike) -> FloatArray:
        """The allowed speed (mm/s) for input speeds ``input_mm_s``; NaN stays NaN."""
        return self.factor * np.asarray(input_mm_s, dtype=float) + self.floor_mm_s


def frame_speeds_mm_s(time_s: ArrayLike, points_mm: ArrayLike) -> FloatArray:
    """Speed of each point from the frame before to this frame, shape (T, K), mm/s: row 0
    and frames where either end lacks the point are NaN
    (`mocapkit.eval.continuity.speeds_mm_s` aligned to the frames)."""
    t = np.asarray(time_s, dtype=float)
    p = np.asarray(points_mm, dtype=float)
    if p.ndim != 3 or p.shape[0] != t.shape[0] or p.shape[2] != 3:
        raise ShapeError(f"points_mm: expected shape ({t.shape[0]}, K, 3), found {p.shape}")
    out = np.full(p.shape[:2], np.nan)
    if t.shape[0] > 1:
        out[1:] = speeds_mm_s(t, p)
    return out


def nearest_input_speeds(
    time_s: ArrayLike,
    joints_mm: ArrayLike,
    inputs_mm: ArrayLike,
    groups: Sequence[int] | None = None,
    candidates: ArrayLike | None = None,
) -> FloatArray:
    """Per frame and joint, the speed (mm/s) of the inputs nearest the joint.

    The nearest input is taken among the joint's ``candidates`` seen on the frame
    before, by distance to the joint there (before any jump of the joint on this frame);
    the speed of its group from that frame to this one (its fastest member seen on both:
    the markers of one set are on one segment, any point of which, the joint it drives
    included, may move as fast as its fastest marker as the segment turns) is the
    joint's evidence, NaN where the nearest input is missing on this frame (no evidence,
    nothing to flag) or the joint has no position on the frame before.

    Parameters
    ----------
    time_s : (T,) array-like
    joints_mm : (T, K, 3) array-like
    inputs_mm : (T, M, 3) array-like
        The input points the tracker used (markers of its sets), NaN where unseen.
    groups : sequence of int, optional
        Per input, its group (its marker set); default: each input its own.
    candidates : (K, M) bool array-like, optional
        Per joint, the inputs that may show its motion (those on its limb,
        `mocapkit.skeleton` chains); default all, and all for a joint with none.

    Returns
    -------
    (T, K) float array; row 0 NaN.
    """
    t = np.asarray(time_s, dtype=float)
    j = np.asarray(joints_mm, dtype=float)
    m = np.asarray(inputs_mm, dtype=float)
    if j.ndim != 3 or j.shape[0] != t.shape[0] or j.shape[2] != 3:
        raise ShapeError(f"joints_mm: expected shape ({t.shape[0]}, K, 3), found {j.shape}")
    if m.ndim != 3 or m.shape[0] != t.shape[0] or m.shape[2] != 3:
        raise ShapeError(f"inputs_mm: expected shape ({t.shape[0]}, M, 3), found {m.shape}")
    out = np.full(j.shape[:2], np.nan)
    if t.shape[0] < 2 or m.shape[1] == 0:
        return out
    cand = np.ones((j.shape[1], m.shape[1]), dtype=bool)
    if candidates is not None:
        cand = np.array(candidates, dtype=bool)
        if cand.shape != (j.shape[1], m.shape[1]):
            raise ShapeError(
                f"candidates: expected shape ({j.shape[1]}, {m.shape[1]}), found {cand.shape}"
            )
        cand[~cand.any(axis=1)] = True
    speed = speeds_mm_s(t, m)  # (T - 1, M)
    if groups is not None:
        g = np.asarray(groups)
        if g.shape != (m.shape[1],):
            raise ShapeError(f"groups: expected {m.shape[1]} group labels, found {g.shape}")
        fastest = speed.copy()
        for label in np.unique(g):
            members = g == label
            top = np.max(np.where(np.isfinite(speed[:, members]), speed[:, members], -1.0), axis=1)
            fastest[:, members] = np.where(top >= 0, top, np.nan)[:, None]
        speed = np.where(np.isfinite(speed), fastest, np.nan)  # the nearest one must be seen
    for a in range(0, t.shape[0] - 1, _FRAME_CHUNK):  # (frames, K, M) at a time: flat memory
        b = min(a + _FRAME_CHUNK, t.shape[0] - 1)
        dist = np.linalg.norm(j[a:b, :, None, :] - m[a:b, None, :, :], axis=3)
        dist = np.where(np.isfinite(dist) & cand, dist, np.inf)
        nearest = np.argmin(dist, axis=2)  # (frames, K)
        has = np.isfinite(np.take_along_axis(dist, nearest[..., None], axis=2)[..., 0])
        picked = np.take_along_axis(speed[a:b], nearest, axis=1)
        out[a + 1 : b + 1] = np.where(has, picked, np.nan)
    return out


def view_speeds_mm_s(
    time_s: ArrayLike, joints_mm: ArrayLike, camera: Camera, pixels: ArrayLike
) -> FloatArray:
    """Per frame and joint, the lateral speed (mm/s) a view's keypoints show: the
    keypoint's image motion (undistorted, in units of the focal length) times the joint's
    depth in that camera (the mean of the two frames'); NaN where the keypoint or the
    joint is missing on either frame.

    ``pixels`` (T, K, 2) are the keypoints of the joints of ``joints_mm`` (T, K, 3), column
    for column (NaN columns for joints the view does not detect).
    """
    t = np.asarray(time_s, dtype=float)
    j = np.asarray(joints_mm, dtype=float)
    px = np.asarray(pixels, dtype=float)
    if j.ndim != 3 or j.shape[0] != t.shape[0] or j.shape[2] != 3:
        raise ShapeError(f"joints_mm: expected shape ({t.shape[0]}, K, 3), found {j.shape}")
    if px.shape != (*j.shape[:2], 2):
        raise ShapeError(f"pixels: expected shape {(*j.shape[:2], 2)}, found {px.shape}")
    out = np.full(j.shape[:2], np.nan)
    if t.shape[0] < 2:
        return out
    seen = np.isfinite(px).all(axis=2)
    normalized = np.full(px.shape, np.nan)
    if seen.any():
        normalized[seen] = camera.undistort_pixels(px[seen])
    depth = camera.to_camera(j)[..., 2]
    step = np.linalg.norm(np.diff(normalized, axis=0), axis=2)
    mean_depth = 0.5 * (depth[1:] + depth[:-1])
    out[1:] = step * mean_depth / np.diff(t)[:, None]
    return out


def triangulated_speeds_mm_s(
    time_s: ArrayLike, cameras: Sequence[Camera], pixels: ArrayLike
) -> FloatArray:
    """Per frame and joint, the speed (mm/s) of the joint's keypoints triangulated from
    the views that see it (`mocapkit.camera.triangulation.triangulate_views`, two or
    more): the depth one view misses, the others see. NaN where fewer than two views see
    the joint on either frame (a component of its motion unobserved: no evidence).

    ``pixels`` (V, T, K, 2): the keypoints of each of the ``cameras``, NaN where unseen.
    """
    t = np.asarray(time_s, dtype=float)
    px = np.asarray(pixels, dtype=float)
    if px.ndim != 4 or px.shape[0] != len(cameras) or px.shape[1] != t.shape[0]:
        raise ShapeError(
            f"pixels: expected shape ({len(cameras)}, {t.shape[0]}, K, 2), found {px.shape}"
        )
    return frame_speeds_mm_s(t, triangulate_views(cameras, px))


@dataclass(frozen=True)
class MotionCheck:
    """A run's motion held against its inputs (`check_motion`).

    Attributes
    ----------
    time_s : (T,) float array
    joint_names : tuple of str
    speed_mm_s, input_mm_s, allowed_mm_s : (T, K) float arrays
        Each joint's speed from the frame before, the speed its input shows, and the
        speed allowed (`SpeedBound`); NaN without evidence (row 0 always).
    bone_names : tuple of str
        The roll-free bones (`mocapkit.skeleton.roll.roll_free_bones`), by joint name.
    roll_deg_s : (T, B) float array
        Each bone's roll speed about its own axis from the frame before (NaN row 0).
    roll_limit_deg_s : float
    """

    time_s: FloatArray
    joint_names: tuple[str, ...]
    speed_mm_s: FloatArray
    input_mm_s: FloatArray
    allowed_mm_s: FloatArray
    bone_names: tuple[str, ...]
    roll_deg_s: FloatArray
    roll_limit_deg_s: float

    @property
    def joint_flags(self) -> NDArray[np.bool_]:
        """(T, K): the joint is faster than allowed on the frame."""
        with np.errstate(invalid="ignore"):
            return np.asarray(self.speed_mm_s > self.allowed_mm_s)

    @property
    def roll_flags(self) -> NDArray[np.bool_]:
        """(T, B): the bone rolls faster than the limit on the frame."""
        with np.errstate(invalid="ignore"):
            return np.asarray(self.roll_deg_s > self.roll_limit_deg_s)

    def columns(self) -> dict[str, list[str] | FloatArray]:
        """Per-frame columns (as fit.csv holds them, `FRAME_COLUMNS`): the count of
        implausible joints and, for the joint nearest its bound (the largest ratio of
        speed to allowed speed), its name, ratio, speed and input speed; the count of
        bones rolling too fast and the fastest one's name and roll speed. Counts and
        figures are NaN, names empty, on frames without evidence."""
        n_frames = self.time_s.shape[0]
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = self.speed_mm_s / self.allowed_mm_s
        has = np.isfinite(ratio)
        any_has: NDArray[np.bool_] = np.asarray(has.any(axis=1))
        worst = (
            np.argmax(np.where(has, ratio, -np.inf), axis=1)
            if ratio.size
            else np.zeros(n_frames, dtype=np.int64)
        )
        rows = np.arange(n_frames)

        def pick(a: FloatArray) -> FloatArray:
            if not a.size:
                return np.full(n_frames, np.nan)
            return np.where(any_has, a[rows, worst], np.nan)

        roll_has = np.isfinite(self.roll_deg_s)
        any_roll: NDArray[np.bool_] = np.asarray(roll_has.any(axis=1))
        fastest = (
            np.argmax(np.where(roll_has, self.roll_deg_s, -np.inf), axis=1)
            if self.roll_deg_s.size
            else np.zeros(n_frames, dtype=np.int64)
        )
        return {
            "implausible_joints": np.where(any_has, self.joint_flags.sum(axis=1), np.nan),
            "worst_joint": [
                self.joint_names[k] if h else "" for k, h in zip(worst.tolist(), list(any_has))
            ],
            "worst_speed_ratio": pick(ratio),
            "worst_joint_speed_mm_per_s": pick(self.speed_mm_s),
            "worst_input_speed_mm_per_s": pick(self.input_mm_s),
            "implausible_rolls": np.where(any_roll, self.roll_flags.sum(axis=1), np.nan),
            "worst_roll_bone": [
                self.bone_names[k] if h else "" for k, h in zip(fastest.tolist(), list(any_roll))
            ],
            "worst_roll_deg_per_s": (
                np.where(any_roll, self.roll_deg_s[rows, fastest], np.nan)
                if self.roll_deg_s.size
                else np.full(n_frames, np.nan)
            ),
        }


def roll_speeds_deg_s(
    skeleton: Skeleton, time_s: ArrayLike, q: ArrayLike
) -> tuple[tuple[str, ...], FloatArray]:
    """Each roll-free bone's roll speed (deg/s) from the frame before, (T, B) with row 0
    NaN (`mocapkit.eval.continuity.roll_steps_deg`), in chunks of frames. A frame without
    a pose (a non-finite ``q``, e.g. the subject out of view) has no roll speed, nor has
    the frame after it."""
    t = np.asarray(time_s, dtype=float)
    qa = np.asarray(q, dtype=float)
    posed = np.isfinite(qa).all(axis=-1)
    qa = np.where(posed[:, None], qa, 0.0)  # a finite stand-in; its steps are dropped below
    names, _ = roll_steps_deg(skeleton, np.zeros((1, qa.shape[-1])))
    out = np.full((t.shape[0], len(names)), np.nan)
    for a in range(0, max(t.shape[0] - 1, 0), _FRAME_CHUNK):
        b = min(a + _FRAME_CHUNK, t.shape[0] - 1)
        _, steps = roll_steps_deg(skeleton, qa[a : b + 1])
        out[a + 1 : b + 1] = steps / np.diff(t[a : b + 1])[:, None]
    out[~posed] = np.nan
    out[1:][~posed[:-1]] = np.nan
    return names, out


def check_motion(
    time_s: ArrayLike,
    joint_names: Sequence[str],
    joints_mm: ArrayLike,
    input_mm_s: ArrayLike | None,
    bound: SpeedBound,
    roll_limit_deg_s: float,
    skeleton: Skeleton | None = None,
    q: ArrayLike | None = None,
) -> MotionCheck:
    """Hold a run's joint speeds against its inputs and its bones' rolls against a limit.

    Parameters
    ----------
    time_s : (T,) array-like
    joint_names : sequence of str
    joints_mm : (T, K, 3) array-like
        The result's joints, NaN where not observed (never flagged).
    input_mm_s : (T, K) array-like or None
        The speed the inputs show near each joint (`nearest_input_speeds`,
        `view_speeds_mm_s`, `triangulated_speeds_mm_s`); None: no evidence anywhere.
    bound : SpeedBound
    roll_limit_deg_s : float
        Fastest roll of a bone about its own axis (deg/s).
    skeleton, q : optional
        The poses (T, D) whose bone rolls are checked; without them no roll is.
    """
    t = np.asarray(time_s, dtype=float)
    speed = frame_speeds_mm_s(t, joints_mm)
    if input_mm_s is None:
        inp = np.full(speed.shape, np.nan)
    else:
        inp = np.asarray(input_mm_s, dtype=float)
        if inp.shape != speed.shape:
            raise ShapeError(f"input_mm_s: expected shape {speed.shape}, found {inp.shape}")
    if skeleton is not None and q is not None:
        bones, roll = roll_speeds_deg_s(skeleton, t, q)
    else:
        bones, roll = (), np.full((t.shape[0], 0), np.nan)
    return MotionCheck(
        t,
        tuple(joint_names),
        speed,
        inp,
        bound.allowed_mm_s(inp),
        bones,
        roll,
        float(roll_limit_deg_s),
    )


__all__ = [
    "FRAME_COLUMNS",
    "NAME_COLUMNS",
    "MotionCheck",
    "SpeedBound",
    "check_motion",
    "frame_speeds_mm_s",
    "nearest_input_speeds",
    "roll_speeds_deg_s",
    "triangulated_speeds_mm_s",
    "view_speeds_mm_s",
]
