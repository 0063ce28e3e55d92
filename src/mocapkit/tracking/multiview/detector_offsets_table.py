"""Shipped detector offsets of the multi-view fit (generated; do not edit).

Written by ``tools/multiview_detector_offsets.py``
(``--rigs ring --rounds 2``): mm, each shrunk by its
held-out factor (`held_out_shrinkage`), in the frame of the segment ending at
each joint (`offset_points`), from the fits of the tuning clips' renders
(ring/13_26, ring/01_09, ring/lambada, ring/charleston1, ring/zombie)
with the backend's keypoints against the truth.
"""

OFFSETS_MM: dict[str, dict[str, tuple[float, float, float]]] = {
    "mediapipe": {
        "head": (0.0, -0.1, -2.1),
        "left_ankle": (11.6, 7.9, 61.1),
        "left_elbow": (2.5, 14.6, 25.8),
        "left_hip": (-10.1, 1.5, 15.5),
        "left_knee": (5.9, -2.2, 11.0),
        "left_shoulder": (-1.6, 3.3, 0.9),
        "left_wrist": (-0.2, 2.8, 0.0),
        "right_ankle": (-11.6, 7.9, 61.1),
        "right_elbow": (-2.5, 14.6, 25.8),
        "right_hip": (10.1, 1.5, 15.5),
        "right_knee": (-5.9, -2.2, 11.0),
        "right_shoulder": (1.6, 3.3, 0.9),
        "right_wrist": (0.2, 2.8, 0.0),
    },
}
