"""Shipped detector offsets of the multi-view fit (generated; do not edit).

Written by ``tools/multiview_detector_offsets.py``
(``--rigs ring --rounds 2``): mm, in the frame of the segment
ending at each joint (`offset_points`), from the fits of the tuning clips' renders
(ring/13_26, ring/01_09, ring/lambada, ring/charleston1, ring/zombie)
with the backend's keypoints against the truth.
"""

OFFSETS_MM: dict[str, dict[str, tuple[float, float, float]]] = {
    "mediapipe": {
        "head": (0.0, -0.1, -2.9),
        "left_ankle": (11.7, 8.0, 61.8),
        "left_elbow": (3.1, 17.9, 31.5),
        "left_hip": (-15.7, 2.3, 24.1),
        "left_knee": (8.5, -3.1, 15.7),
        "left_shoulder": (-6.2, 12.7, 3.4),
        "left_wrist": (-0.4, 5.8, 0.0),
        "right_ankle": (-11.7, 8.0, 61.8),
        "right_elbow": (-3.1, 17.9, 31.5),
        "right_hip": (15.7, 2.3, 24.1),
        "right_knee": (-8.5, -3.1, 15.7),
        "right_shoulder": (6.2, 12.7, 3.4),
        "right_wrist": (0.4, 5.8, 0.0),
    },
}
