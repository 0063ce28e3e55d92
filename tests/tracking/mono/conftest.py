"""Stick-figure poses for the monocular tests."""

from __future__ import annotations

import numpy as np

from mocapkit.tracking.mono.stick import StickModel

#: Rest link directions in the camera frame (x right, y down, z away): facing the camera.
REST = {
    "trunk": (0.0, 1.0, 0.0),
    "head": (0.0, -1.0, 0.0),
    "left_clavicle": (1.0, 0.15, 0.0),  # the subject's left is the image's right
    "right_clavicle": (-1.0, 0.15, 0.0),
    "left_upper_arm": (0.2, 1.0, 0.0),
    "left_forearm": (0.1, 1.0, -0.4),
    "right_upper_arm": (-0.2, 1.0, 0.0),
    "right_forearm": (-0.1, 1.0, -0.4),
    "left_pelvis": (1.0, 0.0, 0.0),
    "right_pelvis": (-1.0, 0.0, 0.0),
    "left_thigh": (0.0, 1.0, 0.0),
    "left_shank": (0.0, 1.0, 0.2),
    "right_thigh": (0.0, 1.0, 0.0),
    "right_shank": (0.0, 1.0, 0.2),
}
LENGTHS = {
    "trunk": 480.0,
    "head": 200.0,
    "left_clavicle": 180.0,
    "right_clavicle": 180.0,
    "left_upper_arm": 300.0,
    "right_upper_arm": 300.0,
    "left_forearm": 260.0,
    "right_forearm": 260.0,
    "left_pelvis": 90.0,
    "right_pelvis": 90.0,
    "left_thigh": 420.0,
    "right_thigh": 420.0,
    "left_shank": 410.0,
    "right_shank": 410.0,
}


def _rotate(v: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    return (
        v * np.cos(angle)
        + np.cross(axis, v) * np.sin(angle)
        + axis * (axis @ v) * (1 - np.cos(angle))
    )


def random_pose(
    rng: np.random.Generator, model: StickModel, spread_deg: float, depth_mm: float = 3000.0
) -> tuple[np.ndarray, np.ndarray]:
    """Joint positions (K, 3) in the camera frame and link lengths (L,).

    Each link turns from its rest direction by a random angle up to ``spread_deg``; the
    limbs' turns are larger (x 2) than the trunk's.
    """
    pos = np.zeros((model.n_joints, 3))
    pos[0] = (rng.uniform(-200, 200), rng.uniform(-200, 200), depth_mm)
    lengths = np.array([LENGTHS[s] for s in model.segments])
    for i, (_, _, seg) in enumerate(model.links):
        d = np.asarray(REST[seg], dtype=float)
        d /= np.linalg.norm(d)
        limb = "arm" in seg or "fore" in seg or "thigh" in seg or "shank" in seg
        ang = np.radians(rng.uniform(0, spread_deg * (2.0 if limb else 1.0)))
        d = _rotate(d, rng.normal(size=3), ang)
        pos[model.child[i]] = pos[model.parent[i]] + lengths[i] * d
    return pos, lengths
