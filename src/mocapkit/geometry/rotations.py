"""Rotation matrices from axis-angle, rotation vectors and Euler angles, batched over leading axes.

Conventions: right-handed, active rotations, column vectors (``x' = R @ x``).
The ``*_nb`` functions are Numba kernels on single values, used inside the
compiled forward kinematics; the public functions take any leading batch shape.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from mocapkit.errors import ShapeError

FloatArray = NDArray[np.float64]


def skew(v: ArrayLike) -> FloatArray:
    """Cross-product matrix ``[v]x`` with ``[v]x @ w == cross(v, w)``.

    Parameters
    ----------
    v : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    v = np.asarray(v, dtype=float)
    if v.shape[-1:] != (3,):
        raise ShapeError(f"skew: expected shape (..., 3), found {v.shape}")
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def matrix_from_axis_angle(axis: ArrayLike, angle_rad: ArrayLike) -> FloatArray:
    """Rodrigues' formula ``R = I + sin(a)[k]x + (1 - cos(a))[k]x^2``.

    Parameters
    ----------
    axis : array_like, shape (..., 3)
        Rotation axis; normalised here.
    angle_rad : array_like, shape (...)
        Angle in radians; broadcast against ``axis[..., 0]``.

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    axis = np.asarray(axis, dtype=float)
    norm = np.linalg.norm(axis, axis=-1, keepdims=True)
    if np.any(norm == 0):
        raise ShapeError("matrix_from_axis_angle: axis has zero length")
    k = skew(axis / norm)
    a = np.asarray(angle_rad, dtype=float)[..., None, None]
    return np.eye(3) + np.sin(a) * k + (1.0 - np.cos(a)) * (k @ k)


def matrix_from_rotvec(rotvec: ArrayLike) -> FloatArray:
    """Rotation matrix of a rotation vector (axis times angle, radians).

    Parameters
    ----------
    rotvec : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    r = np.asarray(rotvec, dtype=float)
    if r.shape[-1:] != (3,):
        raise ShapeError(f"matrix_from_rotvec: expected shape (..., 3), found {r.shape}")
    flat = Rotation.from_rotvec(r.reshape(-1, 3)).as_matrix()
    return flat.reshape(*r.shape[:-1], 3, 3)


def rotvec_from_matrix(matrix: ArrayLike) -> FloatArray:
    """Rotation vector of a rotation matrix, robust near pi (SciPy's quaternion route).

    Parameters
    ----------
    matrix : array_like, shape (..., 3, 3)

    Returns
    -------
    ndarray, shape (..., 3), angle in [0, pi]
    """
    m = np.asarray(matrix, dtype=float)
    if m.shape[-2:] != (3, 3):
        raise ShapeError(f"rotvec_from_matrix: expected shape (..., 3, 3), found {m.shape}")
    flat = Rotation.from_matrix(m.reshape(-1, 3, 3)).as_rotvec()
    return flat.reshape(*m.shape[:-2], 3)


def matrix_from_euler(angles_rad: ArrayLike, axes: str) -> FloatArray:
    """Intrinsic Euler rotation ``R = R_a1(t1) @ R_a2(t2) @ ...`` in the order of ``axes``.

    This is the BVH convention: channels ``Zrotation Yrotation Xrotation`` give
    ``Rz @ Ry @ Rx``.

    Parameters
    ----------
    angles_rad : array_like, shape (..., len(axes))
    axes : str
        Upper-case axis letters, e.g. ``"ZYX"``.

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    a = np.asarray(angles_rad, dtype=float)
    if a.shape[-1:] != (len(axes),) or not set(axes) <= set("XYZ"):
        raise ShapeError(
            f"matrix_from_euler: expected angles (..., {len(axes)}) and axes from 'XYZ', "
            f"found {a.shape} and {axes!r}"
        )
    flat = Rotation.from_euler(axes, a.reshape(-1, len(axes))).as_matrix()
    return flat.reshape(*a.shape[:-1], 3, 3)


def left_jacobian_so3(rotvec: ArrayLike) -> FloatArray:
    """Left Jacobian of SO(3): angular velocity ``w = J_l(r) @ dr/dt`` for ``R = exp([r]x)``.

    ``J_l(r) = I + (1 - cos p)/p^2 [r]x + (p - sin p)/p^3 [r]x^2`` with ``p = |r|``;
    the series is used for small ``p``.

    Parameters
    ----------
    rotvec : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    r = np.asarray(rotvec, dtype=float)
    p = np.linalg.norm(r, axis=-1)[..., None, None]
    small = p < 1e-6
    p_safe = np.where(small, 1.0, p)
    c1 = np.where(small, 0.5 - p**2 / 24.0, (1.0 - np.cos(p_safe)) / p_safe**2)
    c2 = np.where(small, 1.0 / 6.0 - p**2 / 120.0, (p_safe - np.sin(p_safe)) / p_safe**3)
    k = skew(r)
    return np.eye(3) + c1 * k + c2 * (k @ k)


# ---------------------------------------------------------------- Numba kernels


@numba.njit(cache=True, fastmath=False)
def _rodrigues_nb(x: float, y: float, z: float, angle: float, out: FloatArray) -> None:
    """Write the rotation about the unit axis ``(x, y, z)`` by ``angle`` into ``out``."""
    c = np.cos(angle)
    s = np.sin(angle)
    t = 1.0 - c
    out[0, 0] = c + x * x * t
    out[0, 1] = x * y * t - z * s
    out[0, 2] = x * z * t + y * s
    out[1, 0] = y * x * t + z * s
    out[1, 1] = c + y * y * t
    out[1, 2] = y * z * t - x * s
    out[2, 0] = z * x * t - y * s
    out[2, 1] = z * y * t + x * s
    out[2, 2] = c + z * z * t


@numba.njit(cache=True, fastmath=False)
def axis_angle_matrix_nb(axis: FloatArray, angle: float, out: FloatArray) -> None:
    """Write the Rodrigues matrix of a unit ``axis`` (3,) and ``angle`` into ``out`` (3, 3)."""
    _rodrigues_nb(axis[0], axis[1], axis[2], angle, out)


@numba.njit(cache=True, fastmath=False)
def rotvec_matrix_nb(r: FloatArray, out: FloatArray) -> None:
    """Write ``exp([r]x)`` for a rotation vector ``r`` (3,) into ``out`` (3, 3)."""
    p = np.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
    if p < 1e-12:
        # first order: I + [r]x
        out[0, 0], out[0, 1], out[0, 2] = 1.0, -r[2], r[1]
        out[1, 0], out[1, 1], out[1, 2] = r[2], 1.0, -r[0]
        out[2, 0], out[2, 1], out[2, 2] = -r[1], r[0], 1.0
        return
    _rodrigues_nb(r[0] / p, r[1] / p, r[2] / p, p, out)


@numba.njit(cache=True, fastmath=False)
def left_jacobian_so3_nb(r: FloatArray, out: FloatArray) -> None:
    """Write the SO(3) left Jacobian of rotation vector ``r`` (3,) into ``out`` (3, 3)."""
    p2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
    p = np.sqrt(p2)
    if p < 1e-6:
        c1 = 0.5 - p2 / 24.0
        c2 = 1.0 / 6.0 - p2 / 120.0
    else:
        c1 = (1.0 - np.cos(p)) / p2
        c2 = (p - np.sin(p)) / (p2 * p)
    # [r]x and its square written out, so the kernel allocates nothing
    x, y, z = r[0], r[1], r[2]
    k01, k02, k12 = -z, y, -x
    out[0, 0] = 1.0 + c2 * (-(y * y) - z * z)
    out[1, 1] = 1.0 + c2 * (-(x * x) - z * z)
    out[2, 2] = 1.0 + c2 * (-(x * x) - y * y)
    out[0, 1] = c1 * k01 + c2 * x * y
    out[1, 0] = -c1 * k01 + c2 * x * y
    out[0, 2] = c1 * k02 + c2 * x * z
    out[2, 0] = -c1 * k02 + c2 * x * z
    out[1, 2] = c1 * k12 + c2 * y * z
    out[2, 1] = -c1 * k12 + c2 * y * z


@numba.njit(cache=True, fastmath=False)
def matrix_rotvec_nb(m: FloatArray, out: FloatArray) -> None:
    """Write the rotation vector (angle in [0, pi]) of a rotation matrix ``m`` (3, 3) into ``out``.

    Through the unit quaternion by Shepperd's choice of the largest diagonal term, so it
    is well conditioned near pi as well as near 0 (the inverse of `rotvec_matrix_nb`).
    """
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr >= m[0, 0] and tr >= m[1, 1] and tr >= m[2, 2]:
        w = 0.5 * np.sqrt(1.0 + tr)
        f = 0.25 / w
        x, y, z = (m[2, 1] - m[1, 2]) * f, (m[0, 2] - m[2, 0]) * f, (m[1, 0] - m[0, 1]) * f
    elif m[0, 0] >= m[1, 1] and m[0, 0] >= m[2, 2]:
        x = 0.5 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        f = 0.25 / x
        w, y, z = (m[2, 1] - m[1, 2]) * f, (m[0, 1] + m[1, 0]) * f, (m[0, 2] + m[2, 0]) * f
    elif m[1, 1] >= m[2, 2]:
        y = 0.5 * np.sqrt(1.0 - m[0, 0] + m[1, 1] - m[2, 2])
        f = 0.25 / y
        w, x, z = (m[0, 2] - m[2, 0]) * f, (m[0, 1] + m[1, 0]) * f, (m[1, 2] + m[2, 1]) * f
    else:
        z = 0.5 * np.sqrt(1.0 - m[0, 0] - m[1, 1] + m[2, 2])
        f = 0.25 / z
        w, x, y = (m[1, 0] - m[0, 1]) * f, (m[0, 2] + m[2, 0]) * f, (m[1, 2] + m[2, 1]) * f
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    s = np.sqrt(x * x + y * y + z * z)
    scale = 2.0 * np.arctan2(s, w) / s if s > 1e-12 else 2.0 / w
    out[0] = x * scale
    out[1] = y * scale
    out[2] = z * scale


@numba.njit(cache=True, fastmath=False)
def signed_angle_nb(u: FloatArray, v: FloatArray, k: FloatArray) -> float:
    """Signed angle (rad) from ``u`` to ``v`` about axis ``k``, all (3,), after projecting
    both onto the plane perpendicular to ``k``: ``atan2(k_hat . (u' x v'), u' . v')``
    (IVT's three-argument ``Angle``; errata A5). 0 when either projection vanishes."""
    kn = np.sqrt(k[0] * k[0] + k[1] * k[1] + k[2] * k[2])
    if kn == 0.0:
        return 0.0
    kx, ky, kz = k[0] / kn, k[1] / kn, k[2] / kn
    du = u[0] * kx + u[1] * ky + u[2] * kz
    dv = v[0] * kx + v[1] * ky + v[2] * kz
    ux, uy, uz = u[0] - du * kx, u[1] - du * ky, u[2] - du * kz
    vx, vy, vz = v[0] - dv * kx, v[1] - dv * ky, v[2] - dv * kz
    cx = uy * vz - uz * vy
    cy = uz * vx - ux * vz
    cz = ux * vy - uy * vx
    return float(np.arctan2(kx * cx + ky * cy + kz * cz, ux * vx + uy * vy + uz * vz))


@numba.njit(cache=True, fastmath=False)
def rotate_nb(v: FloatArray, k: FloatArray, angle: float, out: FloatArray) -> None:
    """Write ``v`` (3,) rotated right-handedly about axis ``k`` (3,, any length) by
    ``angle`` into ``out`` (Rodrigues' formula; ``out`` may not alias ``v``)."""
    kn = np.sqrt(k[0] * k[0] + k[1] * k[1] + k[2] * k[2])
    if kn == 0.0:
        out[0], out[1], out[2] = v[0], v[1], v[2]
        return
    kx, ky, kz = k[0] / kn, k[1] / kn, k[2] / kn
    c = np.cos(angle)
    s = np.sin(angle)
    d = (kx * v[0] + ky * v[1] + kz * v[2]) * (1.0 - c)
    cx = ky * v[2] - kz * v[1]
    cy = kz * v[0] - kx * v[2]
    cz = kx * v[1] - ky * v[0]
    out[0] = v[0] * c + cx * s + kx * d
    out[1] = v[1] * c + cy * s + ky * d
    out[2] = v[2] * c + cz * s + kz * d
