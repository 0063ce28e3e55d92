"""Triangulation: 3-D points (mm) from pixels seen by two or more calibrated cameras.

Pixels are first undistorted to normalised image coordinates, so the linear
(DLT) systems use ``[R | t]`` only (Hartley & Zisserman, 2nd ed., §12.2); lens
distortion never enters the linear algebra.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.errors import ConfigError, ShapeError

FloatArray = NDArray[np.float64]


def _pixels(pixels: ArrayLike, what: str) -> FloatArray:
    px = np.asarray(pixels, dtype=float)
    if px.ndim < 1 or px.shape[-1] != 2:
        raise ShapeError(f"{what}: expected pixels (..., 2), found shape {px.shape}")
    return px


def _normalised(camera: Camera, pixels: FloatArray) -> FloatArray:
    """Undistorted normalised coordinates (..., 2); NaN stays NaN."""
    flat = pixels.reshape(-1, 2)
    out = np.full_like(flat, np.nan)
    ok = np.all(np.isfinite(flat), axis=1)
    if np.any(ok):
        out[ok] = camera.undistort_pixels(flat[ok])
    return out.reshape(pixels.shape)


def triangulate_pair(
    first: Camera, second: Camera, pixels_first: ArrayLike, pixels_second: ArrayLike
) -> FloatArray:
    """Triangulate matched pixels of a stereo pair (`cv2.triangulatePoints` on undistorted points).

    Parameters
    ----------
    first, second : Camera
    pixels_first, pixels_second : array_like, shape (..., 2)
        Matching pixels in each image; same leading shape. NaN marks a missing point.

    Returns
    -------
    ndarray, shape (..., 3)
        World points (mm); NaN where either pixel is missing.
    """
    a = _pixels(pixels_first, f"camera {first.name!r} pixels")
    b = _pixels(pixels_second, f"camera {second.name!r} pixels")
    if a.shape != b.shape:
        raise ShapeError(
            f"triangulate_pair: expected matching pixel arrays, found {a.shape} and {b.shape}"
        )
    lead = a.shape[:-1]
    na = _normalised(first, a).reshape(-1, 2)
    nb = _normalised(second, b).reshape(-1, 2)
    ok = np.all(np.isfinite(na), axis=1) & np.all(np.isfinite(nb), axis=1)
    out = np.full((na.shape[0], 3), np.nan)
    if np.any(ok):
        p1 = np.asarray(first.camera_from_world)[:3, :]
        p2 = np.asarray(second.camera_from_world)[:3, :]
        hom = cv2.triangulatePoints(p1, p2, na[ok].T.copy(), nb[ok].T.copy())
        with np.errstate(divide="ignore", invalid="ignore"):
            out[ok] = (hom[:3] / hom[3]).T
    return out.reshape((*lead, 3))


def triangulate_views(
    cameras: Sequence[Camera], pixels: ArrayLike, min_views: int = 2
) -> FloatArray:
    """Linear N-view triangulation (homogeneous DLT), batched, with missing views.

    Parameters
    ----------
    cameras : sequence of Camera, length n_views
    pixels : array_like, shape (n_views, ..., 2)
        Pixels of each point in each view; NaN where the view does not see it.
    min_views : int
        Fewest views a point needs (at least 2).

    Returns
    -------
    ndarray, shape (..., 3)
        World points (mm); NaN where fewer than ``min_views`` views see the point.
    """
    n_views = len(cameras)
    px = _pixels(pixels, "triangulate_views pixels")
    if px.ndim < 2 or px.shape[0] != n_views:
        raise ShapeError(
            f"triangulate_views: expected pixels ({n_views}, ..., 2) for {n_views} cameras, "
            f"found {px.shape}"
        )
    if min_views < 2:
        raise ConfigError(f"triangulate_views: min_views must be at least 2, found {min_views}")
    lead = px.shape[1:-1]
    norm = np.stack([_normalised(c, px[i]).reshape(-1, 2) for i, c in enumerate(cameras)])
    seen = np.all(np.isfinite(norm), axis=-1)  # (V, M)
    poses = np.stack([np.asarray(c.camera_from_world)[:3, :] for c in cameras])  # (V, 3, 4)
    # Hartley-style conditioning: express translations in units of the rig size so
    # that the four columns of the DLT matrix have comparable magnitudes.
    scale = float(np.mean(np.linalg.norm(poses[:, :, 3], axis=1))) or 1.0
    poses = poses.copy()
    poses[:, :, 3] /= scale
    x = np.where(seen, norm[..., 0], 0.0)  # (V, M)
    y = np.where(seen, norm[..., 1], 0.0)
    w = seen.astype(float)
    # Rows x*P3 - P1 and y*P3 - P2 of each view; unseen views contribute zero rows.
    rows_x = (x[..., None] * poses[:, None, 2, :] - poses[:, None, 0, :]) * w[..., None]
    rows_y = (y[..., None] * poses[:, None, 2, :] - poses[:, None, 1, :]) * w[..., None]
    a = np.concatenate([rows_x, rows_y], axis=0).transpose(1, 0, 2)  # (M, 2V, 4)
    out = np.full((a.shape[0], 3), np.nan)
    enough = seen.sum(axis=0) >= min_views
    if np.any(enough):
        _, _, vt = np.linalg.svd(a[enough])
        hom = vt[:, -1, :]
        with np.errstate(divide="ignore", invalid="ignore"):
            out[enough] = hom[:, :3] / hom[:, 3:4] * scale
    return out.reshape((*lead, 3))


def reprojection_errors_px(
    cameras: Sequence[Camera], points_in_world: ArrayLike, pixels: ArrayLike
) -> FloatArray:
    """Distance (px) between each view's pixels (n_views, ..., 2) and projected points (..., 3).

    Returns an array (n_views, ...), NaN where a pixel or point is missing.
    """
    pts = np.asarray(points_in_world, dtype=float)
    px = _pixels(pixels, "reprojection_errors_px pixels")
    if px.shape[0] != len(cameras) or px.shape[1:-1] != pts.shape[:-1]:
        raise ShapeError(
            f"reprojection_errors_px: expected pixels ({len(cameras)}, *points.shape[:-1], 2), "
            f"found {px.shape} for points {pts.shape}"
        )
    proj = np.stack([c.project(pts) for c in cameras])
    return np.linalg.norm(proj - px, axis=-1)


def closest_point_to_lines(origins: ArrayLike, directions: ArrayLike) -> FloatArray:
    """Least-squares point (3,) nearest to 3-D lines (e.g. optical axes), mm.

    Parameters
    ----------
    origins : array_like, shape (n, 3)
        A point on each line.
    directions : array_like, shape (n, 3)
        Line directions (any length, non-zero).
    """
    o = np.asarray(origins, dtype=float)
    d = np.asarray(directions, dtype=float)
    if o.ndim != 2 or o.shape[1] != 3 or d.shape != o.shape:
        raise ShapeError(
            f"closest_point_to_lines: expected origins and directions (n, 3), "
            f"found {o.shape} and {d.shape}"
        )
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    proj = (
        np.eye(3)[None] - d[:, :, None] * d[:, None, :]
    )  # projectors onto each line's normal plane
    a = proj.sum(axis=0)
    b = np.einsum("nij,nj->i", proj, o)
    if np.linalg.cond(a) > 1e12:
        raise ShapeError("closest_point_to_lines: lines are parallel; no unique nearest point")
    return np.linalg.solve(a, b)


def widest_view_angle_rad(cameras: Sequence[Camera]) -> float:
    """The largest angle between two cameras' optical axes (rad; 0 for one camera).

    A measure of how well the views fix depth: a narrow stereo pair (axes nearly
    parallel) triangulates along the line of sight poorly, a ring of cameras around the
    subject (axes 90 deg apart and more) well.
    """
    axes = np.array([c.world_from_camera[:3, 2] for c in cameras], dtype=float)
    if len(axes) < 2:
        return 0.0
    cos = np.clip(axes @ axes.T, -1.0, 1.0)
    return float(np.arccos(cos.min()))
