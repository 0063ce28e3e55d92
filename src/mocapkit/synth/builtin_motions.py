"""Procedural motions on the ``zhang21`` body model for demos and tests: no data files needed.

Each motion is a list of key poses (joint angles in degrees, named by the preset's DoFs)
interpolated with a shape-preserving cubic (PCHIP, so no overshoot beyond the keys) and
sampled at 120 Hz, then clipped into the preset's joint limits (AAOS ranges). The root
translation (3 prismatic DoFs) is solved so that the feet stay planted: the mean ankle
position is held where it is in the upright rest pose, which makes a squat lower (and move
back) the pelvis as in a real squat.

Motions
-------
``table-tennis``
    A right-handed rally in a ready stance (knees and hips flexed, trunk leaning forward),
    alternating forehand and backhand strokes: the racket arm swings across the body,
    the trunk leans into each stroke and the stance dips on the backswing.
``squat``
    Slow squats to about 100 degrees of knee flexion with the arms raised forwards for
    balance.
``wave``
    Standing; the right arm rises to the side and the hand waves (elbow flexion
    oscillating with the forearm up) while the left arm hangs.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import PchipInterpolator

from mocapkit.errors import ConfigError, unknown_name
from mocapkit.io.motion import Motion
from mocapkit.skeleton.kinematics import canonical_positions
from mocapkit.skeleton.model import Skeleton
from mocapkit.skeleton.presets import load_preset

FloatArray = NDArray[np.float64]
RATE_HZ = 120.0
BUILTIN_NAMES: tuple[str, ...] = ("table-tennis", "squat", "wave")

Key = tuple[float, Mapping[str, float]]


def _interpolate(skel: Skeleton, keys: Sequence[Key], t: FloatArray) -> FloatArray:
    """Joint angles (T, D) in radians from key poses (time, {dof: degrees})."""
    q = np.zeros((t.shape[0], skel.n_dofs))
    dofs = sorted({d for _, pose in keys for d in pose})
    times = np.array([k[0] for k in keys])
    for d in dofs:
        values = np.array([pose.get(d, 0.0) for _, pose in keys])
        q[:, skel.dof_index(d)] = np.radians(PchipInterpolator(times, values)(t))
    return q


def _cycle(keys: Sequence[Key], period: float, n: int) -> list[Key]:
    """Repeat a cycle of keys (times in [0, period]) n times."""
    out: list[Key] = []
    for c in range(n):
        for k, (tk, pose) in enumerate(keys):
            if c > 0 and k == 0:
                continue  # the first key of a cycle equals the last of the previous one
            out.append((c * period + tk, pose))
    return out


def _plant_feet(skel: Skeleton, q: FloatArray) -> FloatArray:
    """Set the root translation so that the mean ankle stays where it is at rest."""
    q = q.copy()
    root = [skel.dof_index(n) for n in ("root_tx", "root_ty", "root_tz")]
    q[:, root] = 0.0
    ankles = ["left_ankle", "right_ankle"]
    rest = canonical_positions(skel, skel.zero_pose(), ankles).mean(axis=0)
    now = canonical_positions(skel, q, ankles).mean(axis=1)
    q[:, root] = rest - now
    return q


def _stance(knee: float, hip: float, spine: float, spread: float = 6.0) -> dict[str, float]:
    return {
        "l_hip_flexion": hip,
        "r_hip_flexion": hip,
        "l_knee_flexion": knee,
        "r_knee_flexion": knee,
        "l_hip_abduction": spread,
        "r_hip_abduction": spread,
        "spine1_flexion": spine / 3,
        "spine2_flexion": spine / 3,
        "spine3_flexion": spine / 3,
    }


def _table_tennis(duration_s: float) -> list[Key]:
    ready = {
        "r_shoulder_flexion": 35.0,
        "r_shoulder_abduction": 15.0,
        "r_shoulder_rotation": 20.0,
        "r_elbow_flexion": 95.0,
    }
    free = {
        "l_shoulder_flexion": 30.0,
        "l_shoulder_abduction": 15.0,
        "l_shoulder_rotation": 25.0,
        "l_elbow_flexion": 85.0,
        "neck_flexion": -12.0,
    }

    def pose(
        arm: Mapping[str, float], knee: float, hip: float, spine: float, neck_lat: float = 0.0
    ) -> dict[str, float]:
        return {**free, **_stance(knee, hip, spine), **arm, "neck_lateral": neck_lat}

    rdy = pose(ready, 25, 22, 18)
    forehand = [
        (0.0, rdy),
        (
            0.35,
            pose(
                {
                    "r_shoulder_flexion": -15.0,
                    "r_shoulder_abduction": 45.0,
                    "r_shoulder_rotation": -20.0,
                    "r_elbow_flexion": 80.0,
                },
                35,
                28,
                12,
                5,
            ),
        ),
        (
            0.62,
            pose(
                {
                    "r_shoulder_flexion": 95.0,
                    "r_shoulder_abduction": -25.0,
                    "r_shoulder_rotation": 35.0,
                    "r_elbow_flexion": 65.0,
                },
                22,
                20,
                26,
                -5,
            ),
        ),
        (1.0, rdy),
    ]
    backhand = [
        (0.0, rdy),
        (
            0.33,
            pose(
                {
                    "r_shoulder_flexion": 40.0,
                    "r_shoulder_abduction": -25.0,
                    "r_shoulder_rotation": 55.0,
                    "r_elbow_flexion": 120.0,
                },
                32,
                26,
                22,
                -4,
            ),
        ),
        (
            0.6,
            pose(
                {
                    "r_shoulder_flexion": 75.0,
                    "r_shoulder_abduction": 30.0,
                    "r_shoulder_rotation": -10.0,
                    "r_elbow_flexion": 45.0,
                },
                24,
                21,
                20,
                4,
            ),
        ),
        (1.0, rdy),
    ]
    rally = [(t, p) for t, p in forehand] + [(1.0 + t, p) for t, p in backhand[1:]]
    n = int(np.ceil(duration_s / 2.0)) + 1
    return _cycle(rally, 2.0, n)


def _squat(duration_s: float) -> list[Key]:
    stand = {
        **_stance(3, 2, 0, 0),
        "l_shoulder_flexion": 5.0,
        "r_shoulder_flexion": 5.0,
        "l_elbow_flexion": 15.0,
        "r_elbow_flexion": 15.0,
    }
    down = {
        **_stance(100, 85, 36, 0),
        "l_shoulder_flexion": 80.0,
        "r_shoulder_flexion": 80.0,
        "l_elbow_flexion": 10.0,
        "r_elbow_flexion": 10.0,
        "neck_flexion": -20.0,
    }
    keys = [(0.0, stand), (0.6, stand), (1.9, down), (2.4, down), (3.6, stand), (4.0, stand)]
    n = int(np.ceil(duration_s / 4.0)) + 1
    return _cycle(keys, 4.0, n)


def _wave(duration_s: float) -> list[Key]:
    hang = {
        "l_shoulder_abduction": 8.0,
        "l_elbow_flexion": 15.0,
        "r_shoulder_abduction": 8.0,
        "r_elbow_flexion": 15.0,
    }
    keys: list[Key] = [(0.0, hang), (0.5, hang)]
    t = 1.4
    up = {
        "l_shoulder_abduction": 8.0,
        "l_elbow_flexion": 15.0,
        "r_shoulder_abduction": 105.0,
        "r_shoulder_flexion": 15.0,
        "r_shoulder_rotation": -80.0,
        "neck_lateral": 5.0,
    }
    keys.append((t, {**up, "r_elbow_flexion": 80.0}))
    while t < duration_s + 0.5:
        keys.append((t + 0.25, {**up, "r_elbow_flexion": 55.0}))
        keys.append((t + 0.5, {**up, "r_elbow_flexion": 105.0}))
        t += 0.5
    return keys


#: Length of a built-in motion unless a longer one is asked for (s).
DEFAULT_DURATION_S = 20.0


def builtin_motion(name: str, duration_s: float = DEFAULT_DURATION_S) -> Motion:
    """A procedural motion on the ``zhang21`` preset, sampled at 120 Hz.

    Parameters
    ----------
    name : {"table-tennis", "squat", "wave"}
    duration_s : float
        Length of the motion (s).

    Returns
    -------
    Motion
        ``skeleton`` is ``load_preset("zhang21")`` (24 DoFs: 3 root translations and 21
        joint angles); ``source`` is ``"builtin:<name>"``.
    """
    makers = {"table-tennis": _table_tennis, "squat": _squat, "wave": _wave}
    if name not in makers:
        raise unknown_name("built-in motion", name, BUILTIN_NAMES, "builtin:")
    if not (np.isfinite(duration_s) and 0.1 <= duration_s <= 3600.0):
        raise ConfigError(f"duration_s: expected 0.1-3600 s, found {duration_s}")
    skel = load_preset("zhang21")
    n = round(duration_s * RATE_HZ) + 1
    t = np.arange(n) / RATE_HZ
    q = skel.clip_to_limits(_interpolate(skel, makers[name](duration_s), t))
    q = _plant_feet(skel, q)
    return Motion.from_q(skel, t, q, f"builtin:{name}")
