"""Contour generators of truncated cones under perspective: the exact silhouette sides of a limb.

A limb segment is a truncated cone with axis from ``A`` to ``B`` and radii ``r_A``,
``r_B``. Seen from a centre of projection (the origin: points are in camera
coordinates), its silhouette sides are its *contour generators*, the two rulings along
which the viewing ray is tangent to the surface. For the unit axis ``u``, slope
``k = (r_B - r_A) / L`` and ``w`` the part of ``A`` orthogonal to ``u``, the tangency
condition on the radial unit vector ``e`` reduces to ``e . w = k (u . A) - r_A``: the
same for every point along the axis, so each generator is a straight ruling from
``A + r_A e`` to ``B + r_B e``. This is exact under perspective, unlike offsetting the
projected axis by ``r f / z``; the arm refinement's outline chamfer (Zhang et al. 2011 §5,
errata Z11) and the overlay use it. End caps are not part of the outline.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@numba.njit(cache=True)
def cone_contour_generators_nb(
    a: FloatArray, b: FloatArray, ra: float, rb: float, out: FloatArray
) -> None:
    """The two contour generators of a truncated cone seen from the origin (the camera).

    Parameters
    ----------
    a, b : ndarray, shape (3,)
        Axis start and end in camera coordinates (mm).
    ra, rb : float
        Radii at ``a`` and ``b`` (mm).
    out : ndarray, shape (2, 2, 3)
        Per side, the ruling's start (at ``a``) and end (at ``b``) points (mm).

    Notes
    -----
    A zero-length axis gives ``a`` and ``b`` themselves. Looking straight down the axis,
    any perpendicular serves as the radial direction. When the camera lies inside the
    cone's extension (the limb seen end-on) no tangent ruling exists; the condition is
    clamped to ``|e . w| <= 0.999 |w|``, which gives the nearest-to-tangent rulings.
    """
    # scalar arithmetic throughout: this runs once per limb segment per cost evaluation
    ax, ay, az = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    length = math.sqrt(ax * ax + ay * ay + az * az)
    if length < 1e-9:
        for side in range(2):
            for i in range(3):
                out[side, 0, i] = a[i]
                out[side, 1, i] = b[i]
        return
    ux, uy, uz = ax / length, ay / length, az / length
    slope = (rb - ra) / length
    t0 = ux * a[0] + uy * a[1] + uz * a[2]
    wx, wy, wz = a[0] - t0 * ux, a[1] - t0 * uy, a[2] - t0 * uz
    d = math.sqrt(wx * wx + wy * wy + wz * wz)
    if d < 1e-9:  # looking straight down the axis: any perpendicular will do
        if abs(uz) < 0.9:
            wx, wy, wz = uy, -ux, 0.0
        else:
            wx, wy, wz = 0.0, uz, -uy
        n = math.sqrt(wx * wx + wy * wy + wz * wz)
        wx, wy, wz = wx / n, wy / n, wz / n
        c = 0.0
    else:
        wx, wy, wz = wx / d, wy / d, wz / d
        # tangency e . w = k (u . A) - r_A (module notes); |c| >= 1 means the camera is
        # inside the cone's extension (limb seen end-on): clamp
        c = min(max((slope * t0 - ra) / d, -0.999), 0.999)
    vx, vy, vz = uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx
    sn = math.sqrt(1.0 - c * c)
    for side in range(2):
        sgn = 1.0 if side == 0 else -1.0
        ex, ey, ez = c * wx + sgn * sn * vx, c * wy + sgn * sn * vy, c * wz + sgn * sn * vz
        out[side, 0, 0] = a[0] + ra * ex
        out[side, 0, 1] = a[1] + ra * ey
        out[side, 0, 2] = a[2] + ra * ez
        out[side, 1, 0] = b[0] + rb * ex
        out[side, 1, 1] = b[1] + rb * ey
        out[side, 1, 2] = b[2] + rb * ez


def cone_contour_generators(
    a: FloatArray, b: FloatArray, ra: float, rb: float
) -> FloatArray:
    """`cone_contour_generators_nb` returning a new (2, 2, 3) array (side, start/end, xyz) mm."""
    out = np.empty((2, 2, 3))
    cone_contour_generators_nb(
        np.ascontiguousarray(a, dtype=np.float64),
        np.ascontiguousarray(b, dtype=np.float64),
        float(ra),
        float(rb),
        out,
    )
    return out


__all__ = ["cone_contour_generators", "cone_contour_generators_nb"]
