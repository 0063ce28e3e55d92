"""What the inputs of a run show: per frame and joint of its motion, the speed (mm/s) the
tracker's inputs show near that joint (`mocapkit.pipelines.run.InputSpeeds`), from which
the runner judges whether the result's motion is plausible
(`mocapkit.eval.plausibility`).

- Markers (the hybrid): the speed of the set of the marker nearest the joint among those
  the tracker used on the joint's limb (its sets' members; `limb_candidates`): the
  marker on the joint's own segment where there is one, and the closest observed motion
  elsewhere (`marker_input_speeds`).
- 2-D keypoints in calibrated views (stereo, multi-view, mono): two or more views, the
  speed of the joint's keypoints triangulated; one view (mono), the keypoint's image
  speed times the joint's depth over the focal length (a lateral speed): a single view
  does not see depth, which is left to the bound's allowance for what no input shows
  (`keypoint_input_speeds`, `pixel_input_speeds`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.errors import MocapError
from mocapkit.eval.plausibility import (
    nearest_input_speeds,
    triangulated_speeds_mm_s,
    view_speeds_mm_s,
)
from mocapkit.io.keypoint_checks import max_age_s
from mocapkit.io.motion import Motion
from mocapkit.io.session import Session
from mocapkit.io.session_csv import Keypoints
from mocapkit.pipelines.run import InputSpeeds
from mocapkit.skeleton.model import Skeleton

FloatArray = NDArray[np.float64]


def limb_candidates(
    skeleton: Skeleton, joint_names: Sequence[str], sets: Sequence[str]
) -> NDArray[np.bool_]:
    """(K, M): which markers may show each canonical joint's motion: those whose set's
    effector (`mocapkit.tracking.hybrid.tracker.marker_set_effectors`) hangs below the
    joint or carries it (on the chain from the root through the joint and below it), so
    a hand held near the other arm's elbow is not that elbow's evidence. A marker of no
    known set (or of a set the model has no effector for) is a candidate of every
    joint."""
    from mocapkit.tracking.hybrid.tracker import (
        default_marker_effectors,
        marker_set_effectors,
    )

    try:
        effectors = marker_set_effectors(skeleton)
    except MocapError:  # a model without legs: the head and hand sets only
        try:
            effectors = default_marker_effectors(skeleton)
        except MocapError:
            effectors = {}
    carries = skeleton.ancestors_mask()  # [a, j]: a is j or above it
    set_joint = {
        n: skeleton.joint_index(effectors[n].joint) for n in dict.fromkeys(sets) if n in effectors
    }
    cand = np.ones((len(joint_names), len(sets)), dtype=bool)
    for k, name in enumerate(joint_names):
        if name not in skeleton.canonical:
            continue
        j = skeleton.joint_index(skeleton.canonical[name][0])
        for i, s in enumerate(sets):
            if s in set_joint:
                e = set_joint[s]
                cand[k, i] = carries[e, j] or carries[j, e]
    return cand


def marker_input_speeds(
    marker_time_s: ArrayLike, markers_mm: ArrayLike, sets: Sequence[str]
) -> InputSpeeds:
    """`InputSpeeds` from the markers a tracker used, (Tm, M, 3) at ``marker_time_s``, in
    the motion's frame, with each marker's set (M names): each frame sees the newest
    marker sample at or before it (as a session's samples do), and each joint the speed
    of the set of its nearest marker on its limb (`limb_candidates`;
    `mocapkit.eval.plausibility.nearest_input_speeds`)."""
    labels = {n: k for k, n in enumerate(dict.fromkeys(sets))}
    groups = [labels[n] for n in sets]
    mt = np.asarray(marker_time_s, dtype=float)
    m = np.asarray(markers_mm, dtype=float)

    def speeds(motion: Motion) -> FloatArray:
        rows = np.searchsorted(mt, motion.time_s + 1e-9, side="right") - 1
        at = m[np.clip(rows, 0, max(mt.shape[0] - 1, 0))].copy()
        at[rows < 0] = np.nan
        candidates = limb_candidates(motion.skeleton, motion.joint_names, sets)
        return nearest_input_speeds(motion.time_s, motion.joints_mm, at, groups, candidates)

    return speeds


def pixel_input_speeds(
    cameras: Sequence[Camera],
    pixels: Sequence[ArrayLike],
    names: Sequence[str],
    motion: Motion,
) -> FloatArray:
    """The speeds (mm/s) the keypoints ``pixels`` (per camera (T, N, 2), of the joints
    ``names``) show for ``motion``'s joints (T, K): one camera, the lateral speed
    (`mocapkit.eval.plausibility.view_speeds_mm_s`); two or more, the speed of the
    keypoints triangulated (`mocapkit.eval.plausibility.triangulated_speeds_mm_s`). NaN
    for joints the views lack."""
    cols = {n: k for k, n in enumerate(names)}
    aligned = np.full((len(cameras), *motion.joints_mm.shape[:2], 2), np.nan)
    for v, px in enumerate(pixels):
        p = np.asarray(px, dtype=float)
        for k, n in enumerate(motion.joint_names):
            if n in cols:
                aligned[v, :, k] = p[:, cols[n]]
    if len(cameras) == 1:
        return view_speeds_mm_s(motion.time_s, motion.joints_mm, cameras[0], aligned[0])
    return triangulated_speeds_mm_s(motion.time_s, cameras, aligned)


def _keypoints_at_frames(kp: Keypoints, time_s: FloatArray, names: Sequence[str]) -> FloatArray:
    """`mocapkit.io.keypoint_checks.keypoints_at` for every frame at once, for the joints
    ``names``: (T, N, 2), the nearest row within the age rule (`max_age_s`), else NaN
    (and for joints the keypoints lack)."""
    age = max_age_s(kp.time_s, time_s)
    after = np.clip(np.searchsorted(kp.time_s, time_s), 0, kp.time_s.shape[0] - 1)
    before = np.clip(after - 1, 0, kp.time_s.shape[0] - 1)
    d_after, d_before = np.abs(kp.time_s[after] - time_s), np.abs(kp.time_s[before] - time_s)
    rows = np.where(d_before <= d_after, before, after)
    out = np.full((time_s.shape[0], len(names), 2), np.nan)
    for k, n in enumerate(names):
        if n in kp.joint_names:
            out[:, k] = kp.pixels[rows, kp.joint_names.index(n)]
    out[np.minimum(d_before, d_after) > age + 1e-9] = np.nan
    return out


def keypoint_input_speeds(session: Session, cameras: Sequence[str]) -> InputSpeeds | None:
    """`InputSpeeds` from a session's 2-D keypoints of ``cameras`` (those that have them),
    each frame seeing the row the session's samples give it (`pixel_input_speeds`). None
    when no camera has keypoints."""
    views: Mapping[str, Keypoints] = {
        c: session.keypoints[c] for c in cameras if c in session.keypoints
    }
    if not views:
        return None

    names = sorted({n for kp in views.values() for n in kp.joint_names})
    calibrated = [session.camera(c) for c in views]

    def speeds(motion: Motion) -> FloatArray:
        pixels = [_keypoints_at_frames(kp, motion.time_s, names) for kp in views.values()]
        return pixel_input_speeds(calibrated, pixels, names, motion)

    return speeds


__all__ = ["keypoint_input_speeds", "marker_input_speeds", "pixel_input_speeds"]
