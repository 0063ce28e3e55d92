"""The elbow's swivel about the shoulder-hand axis, bounded from one frame to the next.

Every arm pose that puts the hand on a point has its elbow on a circle about the
shoulder-hand line (`mocapkit.ik.arm_analytic`); the swivel is the elbow's angle on that
circle. A real swivel change passes through the angles between at the arm's speed, while
the arm filter's cues at times favour the other side of the circle for a few frames. The
filter's estimate therefore keeps its swivel within a window about the last estimate's
(`mocapkit.tracking.stereo.arm_filter.ArmParticleFilter.step`): `swivel_window_rad` turns
the elbow's plausible move in a frame (mm, along its circle) into that window, and
`bound_swivel_nb` brings poses into it.

Angles are measured with IVT's signed ``Angle`` (`mocapkit.geometry.rotations.signed_angle_nb`):
about the shoulder-hand axis, after projecting both elbows onto the plane across it.
Bringing a pose into the window turns its whole arm about its own shoulder-hand axis:
the hand point and the elbow angle stay where they are.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from mocapkit.geometry.rotations import (
    axis_angle_matrix_nb,
    matrix_rotvec_nb,
    rotvec_matrix_nb,
    signed_angle_nb,
)

FloatArray = NDArray[np.float64]

#: Elbows nearer than this to the shoulder-hand axis (mm) have no swivel to bound: the arm
#: is straight, and even half a turn about the axis moves the elbow under 20 mm.
MIN_SWIVEL_RADIUS_MM = 10.0


def swivel_window_rad(max_move_mm: float, radius_mm: float) -> float:
    """Half-width (rad) of the swivel window: the angle an elbow at ``radius_mm`` from the
    shoulder-hand axis covers moving ``max_move_mm`` along its circle; ``inf`` where that
    reaches half the circle or the radius is under `MIN_SWIVEL_RADIUS_MM` (no bound)."""
    if not (math.isfinite(max_move_mm) and radius_mm >= MIN_SWIVEL_RADIUS_MM):
        return math.inf
    window = max_move_mm / radius_mm
    return window if window < math.pi else math.inf


def swivel_radius_mm(elbow_mm: FloatArray, hand_mm: FloatArray) -> float:
    """Distance (mm) of an elbow from the shoulder-hand axis, both relative to the shoulder."""
    h = np.asarray(hand_mm, dtype=float)
    e = np.asarray(elbow_mm, dtype=float)
    n = float(np.linalg.norm(h))
    if n < 1e-9:
        return float(np.linalg.norm(e))
    return float(np.linalg.norm(e - (e @ h) / (n * n) * h))


@numba.njit(cache=True)
def bound_swivel_nb(
    particles: FloatArray,
    upper_mm: float,
    reach_mm: float,
    ref_elbow_mm: FloatArray,
    window_rad: float,
) -> int:
    """Turn each particle whose swivel lies more than ``window_rad`` from the reference's
    back to the window's edge, in place; returns how many were turned.

    ``particles`` (N, >= 4): the shoulder's rotation vector and the elbow angle of
    `mocapkit.tracking.stereo.arm_filter` (torso frame); ``upper_mm`` the upper arm,
    ``reach_mm`` elbow to hand point; ``ref_elbow_mm`` (3,) the reference elbow relative
    to its shoulder, torso frame. Each particle's swivel is measured about its own
    shoulder-hand axis (module notes).
    """
    r = np.empty((3, 3))
    turn = np.empty((3, 3))
    out = np.empty((3, 3))
    e = np.empty(3)
    h = np.empty(3)
    u = np.empty(3)
    rv = np.empty(3)
    n_turned = 0
    for i in range(particles.shape[0]):
        rotvec_matrix_nb(particles[i, :3], r)
        st = math.sin(particles[i, 3])
        ct = math.cos(particles[i, 3])
        for k in range(3):
            e[k] = -upper_mm * r[k, 2]
            h[k] = e[k] + reach_mm * (-st * r[k, 1] - ct * r[k, 2])
        hn = math.sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2])
        if hn < 1e-9:
            continue
        for k in range(3):
            u[k] = h[k] / hn
        eu = e[0] * u[0] + e[1] * u[1] + e[2] * u[2]
        ru = ref_elbow_mm[0] * u[0] + ref_elbow_mm[1] * u[1] + ref_elbow_mm[2] * u[2]
        e_off = math.sqrt(max(e[0] ** 2 + e[1] ** 2 + e[2] ** 2 - eu * eu, 0.0))
        r_off = math.sqrt(
            max(ref_elbow_mm[0] ** 2 + ref_elbow_mm[1] ** 2 + ref_elbow_mm[2] ** 2 - ru * ru, 0.0)
        )
        if e_off < MIN_SWIVEL_RADIUS_MM or r_off < MIN_SWIVEL_RADIUS_MM:
            continue
        delta = signed_angle_nb(ref_elbow_mm, e, u)
        if abs(delta) <= window_rad:
            continue
        edge = window_rad if delta > 0 else -window_rad
        axis_angle_matrix_nb(u, edge - delta, turn)
        for a in range(3):
            for b in range(3):
                out[a, b] = turn[a, 0] * r[0, b] + turn[a, 1] * r[1, b] + turn[a, 2] * r[2, b]
        matrix_rotvec_nb(out, rv)
        particles[i, 0] = rv[0]
        particles[i, 1] = rv[1]
        particles[i, 2] = rv[2]
        n_turned += 1
    return n_turned


__all__ = [
    "MIN_SWIVEL_RADIUS_MM",
    "bound_swivel_nb",
    "swivel_radius_mm",
    "swivel_window_rad",
]
