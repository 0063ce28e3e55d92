"""The one compiled pinhole projection (OpenCV's distortion model) used by every caller.

``x_px ~ K @ distort([R | t] @ X_world)`` with ``camera_from_world = [[R, t], [0, 1]]``
in mm, as ``cv2.projectPoints`` (radial ``k1 k2 k3`` over ``k4 k5 k6``, tangential
``p1 p2``; thin-prism and tilt terms are not supported). `Camera.project`, the arm
refinement's outline sampling, the overlay and the synthetic renderer all call these
kernels, so they agree on every pixel and on what is visible.

Visibility rule (one for every caller). A point whose camera-frame depth ``z`` lies below
`NEAR_PLANE_MM` (1 mm) is *not visible*: it projects to NaN (the kernels' ``ok`` flag is
False). Points at or behind the optical centre divide by zero or flip through the lens;
points a hair in front of it project millions of pixels away and swamp sums, and nothing
a camera images lies within a millimetre of its centre. The near plane is where those
cases end, not a clipping distance of the scene.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ShapeError

FloatArray = NDArray[np.float64]

#: Depth (mm, camera frame) below which a point is not visible and projects to NaN.
NEAR_PLANE_MM = 1.0


class CameraArrays(NamedTuple):
    """A camera in the layout the compiled kernels take (build with `camera_arrays`).

    Attributes
    ----------
    rotation : ndarray, shape (3, 3)
        Rotation of ``camera_from_world``.
    translation_mm : ndarray, shape (3,)
        Translation of ``camera_from_world`` (mm).
    K : ndarray, shape (3, 3)
        Intrinsic matrix (px); ``K[0, 1]`` is the skew.
    dist : ndarray, shape (8,)
        ``k1 k2 p1 p2 k3 k4 k5 k6`` (zeros where the camera has fewer).
    """

    rotation: FloatArray
    translation_mm: FloatArray
    K: FloatArray
    dist: FloatArray


def camera_arrays(K: ArrayLike, dist: ArrayLike, camera_from_world: ArrayLike) -> CameraArrays:
    """Pack intrinsics, OpenCV distortion (0 to 14 coefficients) and extrinsics for the kernels.

    Raises
    ------
    ShapeError
        For thin-prism or tilt coefficients (the 9th to 14th) that are not zero.
    """
    m = np.asarray(camera_from_world, dtype=np.float64)
    k = np.ascontiguousarray(K, dtype=np.float64)
    if m.shape != (4, 4) or k.shape != (3, 3):
        raise ShapeError(
            f"camera_arrays: expected K (3, 3) and camera_from_world (4, 4), found {k.shape} "
            f"and {m.shape}"
        )
    dd = np.ravel(np.asarray(dist, dtype=np.float64))
    if dd.shape[0] > 8 and np.any(dd[8:] != 0):
        raise ShapeError(
            "distortion: thin-prism/tilt coefficients (s1..s4, tx, ty) are not supported; "
            f"found {dd.tolist()}"
        )
    d8 = np.zeros(8)
    d8[: min(8, dd.shape[0])] = dd[:8]
    return CameraArrays(
        np.ascontiguousarray(m[:3, :3]), np.ascontiguousarray(m[:3, 3]), k, d8
    )


@numba.njit(cache=True, inline="always")
def to_camera_nb(cam: CameraArrays, x: float, y: float, z: float) -> tuple[float, float, float]:
    """World point to camera coordinates (mm)."""
    r = cam.rotation
    t = cam.translation_mm
    xc = r[0, 0] * x + r[0, 1] * y + r[0, 2] * z + t[0]
    yc = r[1, 0] * x + r[1, 1] * y + r[1, 2] * z + t[1]
    zc = r[2, 0] * x + r[2, 1] * y + r[2, 2] * z + t[2]
    return xc, yc, zc


@numba.njit(cache=True, inline="always")
def project_camera_point_nb(
    cam: CameraArrays, xc: float, yc: float, zc: float
) -> tuple[float, float, bool]:
    """Pixel ``(u, v)`` of a camera-frame point and whether it is visible (module notes)."""
    if zc < NEAR_PLANE_MM:
        return 0.0, 0.0, False
    xn = xc / zc
    yn = yc / zc
    d = cam.dist
    r2 = xn * xn + yn * yn
    radial = (1.0 + r2 * (d[0] + r2 * (d[1] + r2 * d[4]))) / (
        1.0 + r2 * (d[5] + r2 * (d[6] + r2 * d[7]))
    )
    xd = xn * radial + 2.0 * d[2] * xn * yn + d[3] * (r2 + 2.0 * xn * xn)
    yd = yn * radial + d[2] * (r2 + 2.0 * yn * yn) + 2.0 * d[3] * xn * yn
    k = cam.K
    u = k[0, 0] * xd + k[0, 1] * yd + k[0, 2]
    v = k[1, 1] * yd + k[1, 2]
    return u, v, True


@numba.njit(cache=True, inline="always")
def project_world_point_nb(
    cam: CameraArrays, x: float, y: float, z: float
) -> tuple[float, float, bool]:
    """Pixel ``(u, v)`` of a world point and whether it is visible."""
    xc, yc, zc = to_camera_nb(cam, x, y, z)
    return project_camera_point_nb(cam, xc, yc, zc)


@numba.njit(cache=True)
def project_points_nb(
    cam: CameraArrays, points: FloatArray, in_world: bool, out: FloatArray
) -> None:
    """Project points (N, 3), world or camera frame, into ``out`` (N, 2) px; NaN if not visible."""
    for i in range(points.shape[0]):
        if in_world:
            u, v, ok = project_world_point_nb(cam, points[i, 0], points[i, 1], points[i, 2])
        else:
            u, v, ok = project_camera_point_nb(cam, points[i, 0], points[i, 1], points[i, 2])
        if ok:
            out[i, 0] = u
            out[i, 1] = v
        else:
            out[i, 0] = np.nan
            out[i, 1] = np.nan


def project(cam: CameraArrays, points: ArrayLike, in_world: bool = True) -> FloatArray:
    """Pixels (..., 2) of points (..., 3) in the world (or camera) frame; NaN where not visible.

    Parameters
    ----------
    cam : CameraArrays
    points : array_like, shape (..., 3)
        Points in mm.
    in_world : bool
        False when ``points`` are already in the camera frame.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.shape[-1:] != (3,):
        raise ShapeError(f"project: expected points (..., 3), found {p.shape}")
    flat = np.ascontiguousarray(p.reshape(-1, 3))
    out = np.empty((flat.shape[0], 2))
    project_points_nb(cam, flat, in_world, out)
    return out.reshape(*p.shape[:-1], 2)


__all__ = [
    "NEAR_PLANE_MM",
    "CameraArrays",
    "camera_arrays",
    "project",
    "project_camera_point_nb",
    "project_points_nb",
    "project_world_point_nb",
    "to_camera_nb",
]
