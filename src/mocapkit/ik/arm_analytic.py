"""Analytic redundant arm IK of Azad et al. 2008 §VII (Algorithm 2, corrected by errata A1-A9).

Given the base (torso) rotation ``R_b``, a shoulder position ``s``, a hand position
``h`` and the segment lengths ``a`` (upper arm) and ``b`` (forearm), every arm pose
that puts the hand on ``h`` has its elbow on a circle about the shoulder-hand line;
the angle ``alpha`` picks a point on it. `arm_ik_nb` returns, for many alphas in one
compiled call, the axis-angle shoulder rotation ``(theta1, theta2, theta3)`` and the
elbow angle ``theta4 = gamma - pi`` in [-pi, 0].

Frames
------
The paper computes in a frame where the zero pose points the arm along +y and the
elbow bends about x (errata A6, A7). The ``azad14`` preset hangs the arm along -z
with the elbow axis -x (torso frame: x to the subject's right, y forward, z up). The
fixed proper rotation ``P`` (`PAPER_TO_TORSO`) with ``P e_x = -e_x``, ``P e_y = -e_z``,
``P e_z = -e_y`` maps one to the other: the paper's x is the subject's left, y is
down, z is backwards, and ``P R_x(t) P^T = R_{-x}(t)``, so the paper's elbow
``R_x(theta4)`` is the preset's. A paper rotation ``R`` is the preset's ``P R P^T``,
whose rotation vector is ``P theta``; the paper's ``c = R_b^T (h - s)`` becomes
``P^T R_b^T (h - s)``. Forward kinematics (errata A7) in the preset's frame:
``elbow = s + R_b R (0, 0, -a)``, ``hand = elbow + R_b R R_{-x}(theta4) (0, 0, -b)``.

Corrections (errata)
--------------------
- A1/A2: ``cos beta = (a^2 + c^2 - b^2) / (2 a c)``, ``cos gamma = (a^2 + b^2 - c^2) / (2 a b)``.
- A3: separate names for the vector ``c_vec`` and the length ``c_len``; ``a_vec``,
  ``b_vec`` for the segment vectors, the scalar ``b`` in step 18's ``(0, b, 0)``.
- A4: ``sign(0) := +1`` in step 8.
- A5: ``Angle(u, v, k)`` is signed about ``k`` after projecting onto the plane
  perpendicular to ``k`` (`mocapkit.geometry.rotations.signed_angle_nb`).
- A6: n0 flips sign when ``c_z`` changes sign with ``c_x != 0`` (inherent to the
  two-rotation construction; kept, so the alpha range switches halves of the circle
  there).
- A7: steps 15-17 are singular for ``a_vec`` parallel to +-y: identity for +y, a
  pi rotation about x for -y; the rotation vector is taken through the quaternion
  (`matrix_rotvec_nb`), accurate near pi.
- A8: ``|c|`` is clamped to ``[max(|a - b|, 1e-3 (a + b)), 0.95 (a + b)]``; a zero
  ``c`` takes the direction +y (hand straight down).
- A9: the alpha bounds. With these frames alpha = +pi/2 puts the elbow at the
  paper's -x for a hand hanging straight down, which is the subject's right, i.e.
  medial for the left arm: the paper's bounds ([-0.2, pi] left, [-pi, 0.2] right)
  would send the left elbow through the torso. `ALPHA_RANGE_RAD` therefore mirrors
  them (left [-pi, 0.2], right [-0.2, pi]); a test checks that no alpha in range puts
  an elbow medial of its shoulder for hands below or in front of the shoulder.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ConfigError, ShapeError
from mocapkit.geometry.rotations import (
    axis_angle_matrix_nb,
    matrix_from_axis_angle,
    matrix_from_rotvec,
    matrix_rotvec_nb,
    rotate_nb,
    signed_angle_nb,
)

FloatArray = NDArray[np.float64]

#: ``P``: torso-frame vector = P @ paper-frame vector (module notes). P = P^T = P^-1.
PAPER_TO_TORSO = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, -1.0, 0.0]])

#: Upper clamp of ``|c|`` relative to ``a + b`` (Algorithm 2, step 2).
REACH_CLAMP = 0.95
#: Lower clamp floor relative to ``a + b`` (errata A8).
MIN_REACH_FRACTION = 1e-3

#: Elbow-circle angle bounds per side (errata A9: the paper's, mirrored; module notes).
ALPHA_RANGE_RAD = {"left": (-math.pi, 0.2), "right": (-0.2, math.pi)}


class ArmIKProblem(NamedTuple):
    """One IK problem: the arm's base, shoulder, hand and segment lengths.

    Attributes
    ----------
    base_rotation : ndarray, shape (3, 3)
        ``R_b``: world-from-torso rotation.
    shoulder_mm : ndarray, shape (3,)
        Shoulder joint centre, world.
    hand_mm : ndarray, shape (3,)
        Target hand (wrist) position, world.
    lengths_mm : ndarray, shape (2,)
        ``(a, b)``: upper arm and forearm length.
    """

    base_rotation: FloatArray
    shoulder_mm: FloatArray
    hand_mm: FloatArray
    lengths_mm: FloatArray


@numba.njit(cache=True, fastmath=False)
def _clamped_c_nb(problem: ArmIKProblem, c_vec: FloatArray) -> float:
    """Write the clamped ``c`` in the paper's frame into ``c_vec`` (3,); return ``|c|``."""
    rb = problem.base_rotation
    a = problem.lengths_mm[0]
    b = problem.lengths_mm[1]
    d0 = problem.hand_mm[0] - problem.shoulder_mm[0]
    d1 = problem.hand_mm[1] - problem.shoulder_mm[1]
    d2 = problem.hand_mm[2] - problem.shoulder_mm[2]
    # torso frame: R_b^T d
    t0 = rb[0, 0] * d0 + rb[1, 0] * d1 + rb[2, 0] * d2
    t1 = rb[0, 1] * d0 + rb[1, 1] * d1 + rb[2, 1] * d2
    t2 = rb[0, 2] * d0 + rb[1, 2] * d1 + rb[2, 2] * d2
    # paper frame: P^T t = (-t0, -t2, -t1)
    c_vec[0], c_vec[1], c_vec[2] = -t0, -t2, -t1
    n = np.sqrt(c_vec[0] ** 2 + c_vec[1] ** 2 + c_vec[2] ** 2)
    hi = REACH_CLAMP * (a + b)
    lo = max(abs(a - b), MIN_REACH_FRACTION * (a + b))  # errata A8
    if n < 1e-12:
        c_vec[0], c_vec[1], c_vec[2] = 0.0, lo, 0.0  # no direction: straight down
        return lo
    target = min(max(n, lo), hi)
    f = target / n
    c_vec[0] *= f
    c_vec[1] *= f
    c_vec[2] *= f
    return target


@numba.njit(cache=True, fastmath=False)
def _circle_nb(problem: ArmIKProblem, c_vec: FloatArray, n0: FloatArray) -> tuple[float, float]:
    """Steps 1-10: clamped ``c_vec`` and the reference ``n0`` (paper frame); returns
    ``(c_len, gamma)`` and leaves ``a cos(beta)`` to the caller via ``c_vec``."""
    a = problem.lengths_mm[0]
    b = problem.lengths_mm[1]
    c_len = _clamped_c_nb(problem, c_vec)
    cos_beta = min(max((a * a + c_len * c_len - b * b) / (2.0 * a * c_len), -1.0), 1.0)  # A1
    cos_gamma = min(max((a * a + b * b - c_len * c_len) / (2.0 * a * b), -1.0), 1.0)  # A2
    sin_beta = np.sqrt(max(1.0 - cos_beta * cos_beta, 0.0))
    gamma = np.arccos(cos_gamma)
    u1 = np.array([0.0, c_len, 0.0])
    sgn = 1.0 if c_vec[2] >= 0.0 else -1.0  # errata A4: sign(0) = +1
    u2 = np.array([0.0, c_vec[1], sgn * np.sqrt(c_vec[0] ** 2 + c_vec[2] ** 2)])
    ex = np.array([1.0, 0.0, 0.0])
    ey = np.array([0.0, 1.0, 0.0])
    canon = np.array([0.0, 0.0, -a * sin_beta])
    tmp = np.empty(3)
    rotate_nb(canon, ex, signed_angle_nb(u1, u2, ex), tmp)  # step 9
    rotate_nb(tmp, ey, signed_angle_nb(u2, c_vec, ey), n0)  # step 10
    return c_len, gamma


@numba.njit(cache=True, fastmath=False)
def arm_ik_nb(
    problem: ArmIKProblem, alphas_rad: FloatArray, out_q: FloatArray, out_elbow_mm: FloatArray
) -> None:
    """Algorithm 2 (errata A1-A9) for every alpha.

    Parameters
    ----------
    problem : ArmIKProblem
    alphas_rad : ndarray, shape (N,)
    out_q : ndarray, shape (N, 4)
        Written: the preset's shoulder rotation vector (torso frame) and theta4.
    out_elbow_mm : ndarray, shape (N, 3)
        Written: elbow positions, world.
    """
    a = problem.lengths_mm[0]
    b = problem.lengths_mm[1]
    rb = problem.base_rotation
    c_vec = np.empty(3)
    n0 = np.empty(3)
    c_len, gamma = _circle_nb(problem, c_vec, n0)
    cos_beta = min(max((a * a + c_len * c_len - b * b) / (2.0 * a * c_len), -1.0), 1.0)
    m = c_vec * (a * cos_beta / c_len)  # step 12
    n = np.empty(3)
    a_vec = np.empty(3)
    b_vec = np.empty(3)
    re = np.empty((3, 3))
    rx = np.empty((3, 3))
    ry = np.empty((3, 3))
    r = np.empty((3, 3))
    ex = np.array([1.0, 0.0, 0.0])
    ey = np.array([0.0, 1.0, 0.0])
    axis = np.empty(3)
    fb = np.empty(3)
    tmp = np.empty(3)
    rv = np.empty(3)
    axis_angle_matrix_nb(ex, gamma - np.pi, rx)
    for i in range(alphas_rad.shape[0]):
        rotate_nb(n0, c_vec, alphas_rad[i], n)  # step 11
        for k in range(3):
            a_vec[k] = m[k] + n[k]  # step 13
            b_vec[k] = c_vec[k] - a_vec[k]  # step 14
        an = np.sqrt(a_vec[0] ** 2 + a_vec[1] ** 2 + a_vec[2] ** 2)
        # steps 15-17: the rotation taking +y onto a_vec / |a_vec|; u1 x u2 = (z, 0, -x)/|a|
        axis[0], axis[1], axis[2] = a_vec[2] / an, 0.0, -a_vec[0] / an
        sin_t = np.sqrt(axis[0] ** 2 + axis[2] ** 2)
        if sin_t < 1e-12:  # errata A7: a_vec parallel to +-y
            if a_vec[1] > 0.0:
                re[:, :] = 0.0
                re[0, 0] = re[1, 1] = re[2, 2] = 1.0
            else:
                axis_angle_matrix_nb(ex, np.pi, re)
        else:
            ang = np.arctan2(sin_t, a_vec[1] / an)  # unsigned angle; the axis carries the sign
            axis[0] /= sin_t
            axis[2] /= sin_t
            axis_angle_matrix_nb(axis, ang, re)
        # step 18: phi about a_vec taking R_e R_x(gamma - pi) (0, b, 0) onto b_vec
        for k in range(3):
            fb[k] = rx[k, 1] * b
        for k in range(3):
            tmp[k] = re[k, 0] * fb[0] + re[k, 1] * fb[1] + re[k, 2] * fb[2]
        phi = signed_angle_nb(tmp, b_vec, a_vec)
        axis_angle_matrix_nb(ey, phi, ry)
        for j in range(3):  # step 19: R = R_e R_y(phi)
            for k in range(3):
                r[j, k] = re[j, 0] * ry[0, k] + re[j, 1] * ry[1, k] + re[j, 2] * ry[2, k]
        matrix_rotvec_nb(r, rv)  # step 20
        # torso frame: P theta = (-t0, -t2, -t1)
        out_q[i, 0], out_q[i, 1], out_q[i, 2] = -rv[0], -rv[2], -rv[1]
        out_q[i, 3] = gamma - np.pi  # step 21
        # elbow in the world: s + R_b P a_vec
        p0, p1, p2 = -a_vec[0], -a_vec[2], -a_vec[1]
        for k in range(3):
            out_elbow_mm[i, k] = (
                problem.shoulder_mm[k] + rb[k, 0] * p0 + rb[k, 1] * p1 + rb[k, 2] * p2
            )


def make_problem(
    base_rotation: ArrayLike,
    shoulder_mm: ArrayLike,
    hand_mm: ArrayLike,
    upper_mm: float,
    fore_mm: float,
) -> ArmIKProblem:
    """Validated `ArmIKProblem` (contiguous float64 arrays)."""
    rb = np.ascontiguousarray(base_rotation, dtype=float)
    s = np.ascontiguousarray(shoulder_mm, dtype=float)
    h = np.ascontiguousarray(hand_mm, dtype=float)
    if rb.shape != (3, 3) or s.shape != (3,) or h.shape != (3,):
        raise ShapeError(
            f"arm IK: expected base_rotation (3, 3), shoulder (3,), hand (3,), found "
            f"{rb.shape}, {s.shape}, {h.shape}"
        )
    if not (np.all(np.isfinite(rb)) and np.all(np.isfinite(s)) and np.all(np.isfinite(h))):
        raise ShapeError("arm IK: base rotation, shoulder and hand must be finite")
    if not (upper_mm > 0 and fore_mm > 0 and math.isfinite(upper_mm + fore_mm)):
        raise ConfigError(
            f"arm IK: expected positive segment lengths, found a={upper_mm}, b={fore_mm}"
        )
    return ArmIKProblem(rb, s, h, np.array([float(upper_mm), float(fore_mm)]))


def arm_ik(problem: ArmIKProblem, alphas_rad: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Algorithm 2 for an array of alphas.

    Parameters
    ----------
    problem : ArmIKProblem
        From `make_problem`.
    alphas_rad : array_like, shape (N,)

    Returns
    -------
    q : ndarray, shape (N, 4)
        Shoulder rotation vector (torso frame, the preset's convention) and theta4 (rad).
    elbow_mm : ndarray, shape (N, 3)
        Elbow positions, world.
    """
    al = np.ascontiguousarray(alphas_rad, dtype=float).reshape(-1)
    q = np.empty((al.shape[0], 4))
    e = np.empty((al.shape[0], 3))
    arm_ik_nb(problem, al, q, e)
    return q, e


def elbow_circle(problem: ArmIKProblem) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The elbow circle: ``(clamped hand, centre, n0)``, world frame (mm).

    The clamped hand is ``s + R_b P c_vec`` (on the clamp sphere when the target is out of
    range), the centre ``s + R_b P m``, and ``n0`` the alpha = 0 offset from the centre.
    """
    c_vec = np.empty(3)
    n0 = np.empty(3)
    c_len, _gamma = _circle_nb(problem, c_vec, n0)
    a, b = problem.lengths_mm
    cos_beta = np.clip((a * a + c_len * c_len - b * b) / (2.0 * a * c_len), -1.0, 1.0)
    to_world = problem.base_rotation @ PAPER_TO_TORSO
    hand = problem.shoulder_mm + to_world @ c_vec
    centre = problem.shoulder_mm + to_world @ (c_vec * (a * cos_beta / c_len))
    return hand, centre, to_world @ n0


def arm_fk(
    base_rotation: ArrayLike, shoulder_mm: ArrayLike, q: ArrayLike, upper_mm: float, fore_mm: float
) -> tuple[FloatArray, FloatArray]:
    """Forward kinematics implied by Algorithm 2 (errata A7) in the preset's frames.

    Parameters
    ----------
    base_rotation : (3, 3)
    shoulder_mm : (..., 3)
    q : (..., 4)
        Shoulder rotation vector (torso frame) and theta4.

    Returns
    -------
    elbow_mm, hand_mm : ndarray, shape (..., 3)
    """
    qq = np.asarray(q, dtype=float)
    rb = np.asarray(base_rotation, dtype=float)
    r = rb @ matrix_from_rotvec(qq[..., :3])
    elbow = np.asarray(shoulder_mm, dtype=float) + r @ np.array([0.0, 0.0, -upper_mm])
    rel = matrix_from_axis_angle(np.array([-1.0, 0.0, 0.0]), qq[..., 3])
    hand = elbow + (r @ rel) @ np.array([0.0, 0.0, -fore_mm])
    return elbow, hand


__all__ = [
    "ALPHA_RANGE_RAD",
    "PAPER_TO_TORSO",
    "REACH_CLAMP",
    "ArmIKProblem",
    "arm_fk",
    "arm_ik",
    "arm_ik_nb",
    "elbow_circle",
    "make_problem",
]
