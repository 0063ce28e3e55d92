"""Shipped detector offsets of the multi-view fit (generated; do not edit).

Written by ``tools/multiview_detector_offsets.py``
(``--rigs ring --rounds 2 --min-gain-mm 1``):
mm, in the frame of the segment ending at each joint (`offset_points`), from the
fits of the tuning clips' renders
(ring/13_26, ring/01_09, ring/lambada, ring/charleston1, ring/zombie)
with the backend's keypoints against the truth.
"""

OFFSETS_MM: dict[str, dict[str, tuple[float, float, float]]] = {
    "mediapipe": {
        "left_ankle": (11.7, 7.9, 61.6),
        "left_elbow": (2.8, 16.4, 26.0),
        "left_hip": (-15.7, 2.5, 23.6),
        "left_knee": (8.5, -3.0, 15.3),
        "right_ankle": (-11.7, 7.9, 61.6),
        "right_elbow": (-2.8, 16.4, 26.0),
        "right_hip": (15.7, 2.5, 23.6),
        "right_knee": (-8.5, -3.0, 15.3),
    },
}
