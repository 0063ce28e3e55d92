"""What a camera's 2-D keypoints may count as: their age at a frame and their place in the image.

**Age.** Keypoints are detections in video frames, so at a video frame the row nearest in
time is that frame's detection when it is at most `max_age_s` away: one sampling
interval, of the keypoints or of the video, whichever is longer (a detector run on every
third frame still serves the frames between). A row further away is an old (or future)
sample of another pose and no observation, like a marker sample older than the age
limit: keypoints that end at 1 s of a 2 s video give no observation from then on, and the
tracker bridges its own short gaps (`mocapkit.tracking.base.BRIDGE_S`) from its last
observation instead of tracking a held row. Clocks that never overlap the video are
refused when the session loads (`check_keypoint_clock`).

**Place.** A point further outside the image than ``OUTSIDE_IMAGE_MARGIN`` times the
image's width (left, right) or height (top, bottom) is no observation: detectors place
joints just beyond the border when a limb leaves the picture, but not a body length
away, and 1e9 px is a broken file. Such points become NaN and are counted per camera in
an `InputWarning` (`drop_outside_image`).
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import InputWarning, SessionError
from mocapkit.io.session_csv import Keypoints

FloatArray = NDArray[np.float64]

#: How far outside the image a keypoint may lie and still be an observation, as a
#: fraction of the image's width (left and right) and height (top and bottom).
OUTSIDE_IMAGE_MARGIN = 0.25


def _step_s(time_s: FloatArray) -> float:
    return float(np.median(np.diff(time_s))) if time_s.shape[0] > 1 else 0.0


def max_age_s(keypoint_time_s: FloatArray, video_time_s: FloatArray) -> float:
    """Largest time between a video frame and the keypoint row that observes it (s)."""
    return max(_step_s(keypoint_time_s), _step_s(video_time_s))


def keypoints_at(kp: Keypoints, time_s: float, age_s: float) -> FloatArray:
    """The keypoints (K, 2) px observed at ``time_s``: the nearest row when it is at most
    ``age_s`` away, else NaN (no observation)."""
    r = int(np.argmin(np.abs(kp.time_s - time_s)))
    if abs(float(kp.time_s[r]) - time_s) <= age_s + 1e-9:
        return kp.pixels[r]
    return np.full(kp.pixels.shape[1:], np.nan)


def check_keypoint_clock(kp: Keypoints, video_time_s: FloatArray, where: str) -> None:
    """Refuse keypoints whose clock never overlaps the video's; warn when they cover
    only part of it (the frames outside have no keypoint observation)."""
    k0, k1 = float(kp.time_s[0]), float(kp.time_s[-1])
    v0, v1 = float(video_time_s[0]), float(video_time_s[-1])
    age = max_age_s(kp.time_s, video_time_s)
    if k1 < v0 - age or k0 > v1 + age:
        raise SessionError(
            f"{where}: the keypoints span {k0:.3f}-{k1:.3f} s and the video {v0:.3f}-{v1:.3f} s; "
            "expected clocks that overlap (keypoints of another recording, or on another clock)"
        )
    if k0 > v0 + age or k1 < v1 - age:
        warnings.warn(
            f"{where}: the keypoints span {k0:.3f}-{k1:.3f} s of the video's {v0:.3f}-{v1:.3f} s; "
            "frames further than one frame from a keypoint row have no keypoint observation",
            InputWarning,
            stacklevel=2,
        )


def drop_outside_image(kp: Keypoints, image_size: tuple[int, int], where: str) -> Keypoints:
    """``kp`` with the points further outside the image than the margin set to NaN.

    Warns (`InputWarning`) with the count of points and frames dropped, and the first.
    """
    w, h = float(image_size[0]), float(image_size[1])
    m = OUTSIDE_IMAGE_MARGIN
    x, y = kp.pixels[..., 0], kp.pixels[..., 1]
    present = ~np.isnan(x) & ~np.isnan(y)
    with np.errstate(invalid="ignore"):
        inside = (x >= -m * w) & (x <= (1 + m) * w) & (y >= -m * h) & (y <= (1 + m) * h)
    bad = present & ~inside
    if not bad.any():
        return kp
    t, j = (int(i[0]) for i in np.nonzero(bad))
    frames = int(bad.any(axis=1).sum())
    warnings.warn(
        f"{where}: {int(bad.sum())} points in {frames} frames lie more than "
        f"{100 * m:g} % of the image size outside its {image_size[0]}x{image_size[1]} px "
        f"(first: {kp.joint_names[j]} at ({x[t, j]:.6g}, {y[t, j]:.6g}) px, "
        f"{kp.time_s[t]:.3f} s); taken as no observation",
        InputWarning,
        stacklevel=2,
    )
    pixels = kp.pixels.copy()
    pixels[bad] = np.nan
    return dataclasses.replace(kp, pixels=pixels)


__all__ = [
    "OUTSIDE_IMAGE_MARGIN",
    "check_keypoint_clock",
    "drop_outside_image",
    "keypoints_at",
    "max_age_s",
]
