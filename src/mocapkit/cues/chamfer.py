"""Chamfer scoring of projected outlines on truncated edge distance maps (compiled kernels).

Zhang et al. 2011 §5.1-5.2 score a limb pose by the edge distance map under its
projected outline. Per errata Z11 the score here is the *mean truncated distance* over
points sampled every ``step_px`` along the projected outline segments (the literal
eq. 13 sum over the filled silhouette is `filled_outline_sum_nb`). The rules, shared
by every tracker that scores outlines:

- Look-up. Bilinear interpolation on the map's grid; a point counts as inside when all
  four neighbouring cells are inside the map, else it reads the cap
  (`bilinear_lookup_nb`; `mocapkit.cues.edges.DistanceMap.lookup` calls it too).
- Samples. A segment whose ends project to ``p0``, ``p1`` gets
  ``max(2, ceil(|p1 - p0| / step) + 1)`` evenly spaced samples, interpolated in 3-D
  and projected one by one (exact under distortion). A segment with an end that is not
  visible (`mocapkit.camera.projection`: nearer than 1 mm to the camera plane) gets two
  samples at the cap. A segment close to the camera plane projects millions of px long;
  every sample off the map costs the cap anyway, so the count is bounded by twice the
  map's perimeter over ``step``.
- Orientation routing. With K oriented maps (`mocapkit.cues.edges.oriented_distance_maps`)
  a segment reads the map of its own image direction: bin
  ``round(angle(p1 - p0) mod pi * K / pi) mod K``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from numpy.typing import NDArray

from mocapkit.camera.projection import CameraArrays, project_camera_point_nb

FloatArray = NDArray[np.float64]
Float32Array = NDArray[np.float32]


class ChamferMaps(NamedTuple):
    """Distance maps in the layout the compiled kernels take (`DistanceMap.chamfer_maps`).

    Attributes
    ----------
    maps : ndarray of float32, shape (K, h, w)
        One plain map (K = 1) or one per orientation bin (px).
    origin_px : ndarray, shape (2,)
        Image position ``(x0, y0)`` of cell ``[0, 0]``'s corner: cell ``[r, c]`` is centred on
        ``origin + step * (c, r) + (step - 1) / 2``.
    step_px : float
        Grid spacing (1 for a full-resolution map).
    cap_px : float
        Truncation value, read outside the maps.
    """

    maps: Float32Array
    origin_px: FloatArray
    step_px: float
    cap_px: float


@numba.njit(cache=True, inline="always")
def bilinear_lookup_nb(
    dmap: Float32Array, u: float, v: float, x0: float, y0: float, step: float, cap: float
) -> float:
    """Bilinear distance at image point ``(u, v)`` of a map (h, w); ``cap`` outside (see module)."""
    x = (u - x0 - 0.5 * (step - 1.0)) / step
    y = (v - y0 - 0.5 * (step - 1.0)) / step
    h = dmap.shape[0]
    w = dmap.shape[1]
    if not (x >= 0.0 and y >= 0.0 and x < w - 1 and y < h - 1):
        return cap
    c0 = int(x)
    r0 = int(y)
    fx = x - c0
    fy = y - r0
    top = (1.0 - fx) * dmap[r0, c0] + fx * dmap[r0, c0 + 1]
    bot = (1.0 - fx) * dmap[r0 + 1, c0] + fx * dmap[r0 + 1, c0 + 1]
    return (1.0 - fy) * top + fy * bot


@numba.njit(cache=True)
def lookup_points_nb(
    dmap: Float32Array, points_px: FloatArray, x0: float, y0: float, step: float, cap: float,
    out: FloatArray,
) -> None:
    """`bilinear_lookup_nb` at each image point (N, 2) into ``out`` (N,)."""
    for i in range(points_px.shape[0]):
        out[i] = bilinear_lookup_nb(dmap, points_px[i, 0], points_px[i, 1], x0, y0, step, cap)


@numba.njit(cache=True)
def n_samples_nb(p0u: float, p0v: float, p1u: float, p1v: float, step: float) -> int:
    """Samples along a projected segment: ``max(2, ceil(length / step) + 1)``."""
    length = math.sqrt((p1u - p0u) ** 2 + (p1v - p0v) ** 2)
    if not length < 1e9:  # near the camera plane (or NaN): callers cap the count
        length = 1e9
    n = math.ceil(length / step) + 1
    return max(n, 2)


@numba.njit(cache=True)
def outline_chamfer_nb(
    cam: CameraArrays, segments: FloatArray, n_segments: int, maps: ChamferMaps, step_px: float
) -> float:
    """Mean truncated distance over samples of projected 3-D segments (module notes).

    Parameters
    ----------
    cam : CameraArrays
    segments : ndarray, shape (M, 2, 3)
        Segment start and end points in the camera frame (mm); the first ``n_segments``
        are scored.
    n_segments : int
    maps : ChamferMaps
    step_px : float
        Sample spacing along the projected segments.
    """
    dmap = maps.maps
    cap = maps.cap_px
    x0 = maps.origin_px[0]
    y0 = maps.origin_px[1]
    grid = maps.step_px
    n_bins = dmap.shape[0]
    max_n = int(4.0 * (dmap.shape[1] + dmap.shape[2]) * grid / step_px) + 2
    total = 0.0
    count = 0
    for s in range(n_segments):
        p0 = segments[s, 0]
        p1 = segments[s, 1]
        u0, v0, ok0 = project_camera_point_nb(cam, p0[0], p0[1], p0[2])
        u1, v1, ok1 = project_camera_point_nb(cam, p1[0], p1[1], p1[2])
        if not (ok0 and ok1):
            n = 2
            b = 0
        else:
            n = min(n_samples_nb(u0, v0, u1, v1, step_px), max_n)
            b = 0
            if n_bins > 1:
                ang = math.atan2(v1 - v0, u1 - u0) % math.pi
                b = int(ang * n_bins / math.pi + 0.5) % n_bins  # ang >= 0
        d2 = dmap[b]
        for j in range(n):
            f = j / (n - 1)
            px = p0[0] + f * (p1[0] - p0[0])
            py = p0[1] + f * (p1[1] - p0[1])
            pz = p0[2] + f * (p1[2] - p0[2])
            u, v, ok = project_camera_point_nb(cam, px, py, pz)
            total += bilinear_lookup_nb(d2, u, v, x0, y0, grid, cap) if ok else cap
            count += 1
    return total / count


@numba.njit(cache=True)
def outline_points_px_nb(
    cam: CameraArrays, segments: FloatArray, n_segments: int, step_px: float, out: FloatArray
) -> int:
    """The sample points (px) `outline_chamfer_nb` reads, into ``out`` (P, 2).

    Returns how many were written (at most P); points that are not visible are NaN. The
    count per segment is not bounded by a map here.
    """
    m = 0
    for s in range(n_segments):
        p0 = segments[s, 0]
        p1 = segments[s, 1]
        u0, v0, ok0 = project_camera_point_nb(cam, p0[0], p0[1], p0[2])
        u1, v1, ok1 = project_camera_point_nb(cam, p1[0], p1[1], p1[2])
        n = n_samples_nb(u0, v0, u1, v1, step_px) if (ok0 and ok1) else 2
        for j in range(n):
            if m >= out.shape[0]:
                return m
            f = j / (n - 1)
            pp = p0 + f * (p1 - p0)
            u, v, ok = project_camera_point_nb(cam, pp[0], pp[1], pp[2])
            out[m, 0] = u if ok else np.nan
            out[m, 1] = v if ok else np.nan
            m += 1
    return m


@numba.njit(cache=True)
def filled_outline_sum_nb(
    cam: CameraArrays, segments: FloatArray, n_pairs: int, maps: ChamferMaps
) -> float:
    """Eq. 13 literally: sum of the first full-resolution map over its pixels inside the
    projected silhouette, the union of the quadrilaterals between segment pairs
    ``(2 i, 2 i + 1)`` (a cone's two contour generators), ``i < n_pairs``.

    A quadrilateral with a corner that is not visible is left out; with none left the
    sum is 0. Pixel centres are tested inclusively.
    """
    dmap = maps.maps[0]
    quads = np.empty((max(n_pairs, 1), 4, 2))
    valid = np.zeros(max(n_pairs, 1), dtype=np.bool_)
    x0 = maps.origin_px[0]
    y0 = maps.origin_px[1]
    h = dmap.shape[0]
    w = dmap.shape[1]
    lo_u = 1e300
    lo_v = 1e300
    hi_u = -1e300
    hi_v = -1e300
    for s in range(n_pairs):
        ok_all = True
        # quad order: side 0 start -> side 0 end -> side 1 end -> side 1 start
        for k, (side, end) in enumerate(((0, 0), (0, 1), (1, 1), (1, 0))):
            p = segments[2 * s + side, end]
            u, v, ok = project_camera_point_nb(cam, p[0], p[1], p[2])
            ok_all = ok_all and ok
            quads[s, k, 0] = u - x0
            quads[s, k, 1] = v - y0
        valid[s] = ok_all
        if ok_all:
            for k in range(4):
                lo_u = min(lo_u, quads[s, k, 0])
                hi_u = max(hi_u, quads[s, k, 0])
                lo_v = min(lo_v, quads[s, k, 1])
                hi_v = max(hi_v, quads[s, k, 1])
    if not np.any(valid[:n_pairs]):
        return 0.0
    c_lo = max(math.floor(max(lo_u, -1.0)), 0)
    c_hi = min(math.ceil(min(hi_u, w + 1.0)), w - 1)
    r_lo = max(math.floor(max(lo_v, -1.0)), 0)
    r_hi = min(math.ceil(min(hi_v, h + 1.0)), h - 1)
    total = 0.0
    for r in range(r_lo, r_hi + 1):
        for c in range(c_lo, c_hi + 1):
            for s in range(n_pairs):
                if valid[s] and _in_quad(quads[s], c + 0.0, r + 0.0):
                    total += dmap[r, c]
                    break
    return total


@numba.njit(cache=True, inline="always")
def _in_quad(q: FloatArray, px: float, py: float) -> bool:
    """Point in a convex quadrilateral of either orientation (inclusive)."""
    pos = False
    neg = False
    for k in range(4):
        ax, ay = q[k, 0], q[k, 1]
        bx, by = q[(k + 1) % 4, 0], q[(k + 1) % 4, 1]
        cr = (bx - ax) * (py - ay) - (by - ay) * (px - ax)
        if cr > 0:
            pos = True
        elif cr < 0:
            neg = True
    return not (pos and neg)


__all__ = [
    "ChamferMaps",
    "bilinear_lookup_nb",
    "filled_outline_sum_nb",
    "lookup_points_nb",
    "n_samples_nb",
    "outline_chamfer_nb",
    "outline_points_px_nb",
]
