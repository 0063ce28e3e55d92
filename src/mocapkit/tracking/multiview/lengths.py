"""The subject's segment lengths, estimated once from a whole take of 2-D detections.

Every frame's joints are triangulated robustly (`robust_triangulation`: all views, then
again without the views whose reprojection is far from the rest), each canonical segment's
length is the median over the frames where both of its joints were seen well by enough
views, and the left and right sides share one length unless they differ by more than
`SIDE_TOLERANCE` (then the data says the subject is not symmetric, or the detector
places one side differently, and each keeps its own).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.camera.triangulation import reprojection_errors_px, triangulate_views
from mocapkit.errors import ShapeError
from mocapkit.skeleton.model import CANONICAL_SEGMENTS, TRUNK_SEGMENTS

FloatArray = NDArray[np.float64]

#: Relative difference of a left and a right segment under which both take their mean.
SIDE_TOLERANCE = 0.08
#: Fewest frames a segment needs for a length (otherwise the model's own is kept).
MIN_FRAMES = 5


def column_median(a: FloatArray) -> FloatArray:
    """Median of each column of ``a`` (N, M) over its finite entries (NaN for a column
    without any). By sorting (NaN last), not `numpy.nanmedian`, which is slow on small
    arrays and warns on empty columns."""
    srt = np.sort(a, axis=0)
    n = np.isfinite(a).sum(axis=0)
    out = np.full(a.shape[1], np.nan)
    ok = n > 0
    cols = np.flatnonzero(ok)
    lo, hi = (n[ok] - 1) // 2, n[ok] // 2
    out[ok] = 0.5 * (srt[lo, cols] + srt[hi, cols])
    return out


def reprojection_errors_mm(
    cameras: Sequence[Camera], points_mm: FloatArray, pixels: FloatArray
) -> FloatArray:
    """Reprojection errors (V, ...) of points (..., 3) against pixels (V, ..., 2) in mm
    across each view's ray at the point (pixels times depth over focal length), so that
    one threshold serves every image size and distance; NaN where a pixel is missing."""
    err = reprojection_errors_px(cameras, points_mm, pixels)
    for v, cam in enumerate(cameras):
        depth = np.asarray(cam.to_camera(points_mm))[..., 2]
        err[v] = err[v] * np.abs(depth) / float(cam.K[0, 0])
    return err


def robust_triangulation(
    cameras: Sequence[Camera], pixels: FloatArray, reject_mm: float, min_views: int = 2
) -> tuple[FloatArray, FloatArray, NDArray[np.int64]]:
    """Triangulate (V, ..., 2) pixels, dropping views that reproject far from the rest.

    The points are triangulated over every view (`triangulate_views`); a view whose
    pixel lies more than ``reject_mm`` from the reprojection (`reprojection_errors_mm`)
    *and* more than twice the median over the views is dropped, and the point is
    triangulated again from the views left. Returns the points (..., 3), the
    reprojection error (mm) per view (V, ...; NaN where the view has no pixel) and the
    count of views kept (...).
    """
    px = np.asarray(pixels, dtype=float)
    if px.ndim < 2 or px.shape[0] != len(cameras) or px.shape[-1] != 2:
        raise ShapeError(
            f"robust_triangulation: expected pixels ({len(cameras)}, ..., 2), found {px.shape}"
        )
    pts = triangulate_views(cameras, px, min_views=min_views)
    err = reprojection_errors_mm(cameras, pts, px)
    flat = err.reshape(err.shape[0], -1)
    med = column_median(flat).reshape(err.shape[1:])
    with np.errstate(invalid="ignore"):
        bad = (err > reject_mm) & (err > 2.0 * med)
    kept_px = np.where(bad[..., None], np.nan, px)
    pts = triangulate_views(cameras, kept_px, min_views=min_views)
    err = reprojection_errors_mm(cameras, pts, px)
    kept = np.sum(np.all(np.isfinite(kept_px), axis=-1), axis=0).astype(np.int64)
    return pts, err, kept


def segment_lengths_from_points(
    joint_names: Sequence[str],
    points_mm: FloatArray,
    good: NDArray[np.bool_],
    side_tolerance: float = SIDE_TOLERANCE,
    min_frames: int = MIN_FRAMES,
) -> dict[str, float]:
    """Median length of each canonical segment (`CANONICAL_SEGMENTS`) over the frames
    where both of its joints are ``good``; points (T, K, 3), good (T, K).

    Left and right segments share the median of both sides' lengths unless their
    medians differ by more than ``side_tolerance`` of their mean and by more than three
    standard errors (robust, from each side's median absolute deviation). Segments with
    fewer than ``min_frames`` good frames are left out.
    """
    names = list(joint_names)
    samples: dict[str, FloatArray] = {}
    for seg, (a, b) in CANONICAL_SEGMENTS.items():
        if a not in names or b not in names:
            continue
        ia, ib = names.index(a), names.index(b)
        ok = good[:, ia] & good[:, ib]
        if int(ok.sum()) < min_frames:
            continue
        samples[seg] = np.linalg.norm(points_mm[ok, ib] - points_mm[ok, ia], axis=1)
    out = {seg: float(np.median(d)) for seg, d in samples.items()}
    for seg in list(out):
        if not seg.startswith("left_"):
            continue
        other = "right_" + seg[len("left_") :]
        if other not in out:
            continue
        left, right = out[seg], out[other]
        # the sides differ when their medians differ by more than the tolerance and by
        # more than three standard errors (from the median absolute deviations)
        se = [
            1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(d.size)
            for d in (samples[seg], samples[other])
        ]
        differ = abs(left - right) > max(
            side_tolerance * 0.5 * (left + right), 3.0 * float(np.hypot(se[0], se[1]))
        )
        if not differ:
            out[seg] = out[other] = float(np.median(np.concatenate([samples[seg], samples[other]])))
    return out


def trunk_vectors_from_points(
    joint_names: Sequence[str],
    points_mm: FloatArray,
    good: NDArray[np.bool_],
    side_tolerance: float = SIDE_TOLERANCE,
    min_frames: int = MIN_FRAMES,
) -> dict[str, FloatArray]:
    """Rest vectors (3,) of the trunk's segments (`TRUNK_SEGMENTS`) in the body's own
    axes (x to the subject's right, y forward, z up), medians over the good frames.

    Each frame's axes come from the points: x along the hips' line, z the pelvis-to-neck
    direction without its x part, y = z x x. Left and right share their mirrored mean
    when their lengths agree within ``side_tolerance``. A detector's pelvis or neck (a midpoint of
    the hips or shoulders) and a motion-capture skeleton's place these joints
    differently; the model takes the subject's own geometry from them.
    """
    names = list(joint_names)
    need = ("pelvis", "neck", "left_hip", "right_hip")
    if not all(n in names for n in need):
        return {}
    ix = {n: names.index(n) for n in names}
    base = np.all([good[:, ix[n]] for n in need], axis=0)
    x = points_mm[:, ix["right_hip"]] - points_mm[:, ix["left_hip"]]
    up = points_mm[:, ix["neck"]] - points_mm[:, ix["pelvis"]]
    with np.errstate(invalid="ignore", divide="ignore"):
        x = x / np.linalg.norm(x, axis=1, keepdims=True)
        z = up - np.sum(up * x, axis=1, keepdims=True) * x
        z = z / np.linalg.norm(z, axis=1, keepdims=True)
    y = np.cross(z, x)
    out: dict[str, FloatArray] = {}
    for seg in TRUNK_SEGMENTS:
        a, b = CANONICAL_SEGMENTS[seg]
        if a not in ix or b not in ix:
            continue
        ok = base & good[:, ix[a]] & good[:, ix[b]]
        if int(ok.sum()) < min_frames:
            continue
        d = points_mm[ok, ix[b]] - points_mm[ok, ix[a]]
        local = np.stack(
            [np.sum(d * x[ok], axis=1), np.sum(d * y[ok], axis=1), np.sum(d * z[ok], axis=1)],
            axis=1,
        )
        out[seg] = np.median(local, axis=0)
    for seg in list(out):
        if seg.startswith("left_") and "right_" + seg[5:] in out:
            left, right = out[seg], out["right_" + seg[5:]]
            nl, nr = float(np.linalg.norm(left)), float(np.linalg.norm(right))
            if abs(nl - nr) > side_tolerance * 0.5 * (nl + nr):
                continue
            # mirror images through the sagittal plane: share their mean
            mean = 0.5 * (left * np.array([-1.0, 1.0, 1.0]) + right)
            out[seg] = mean * np.array([-1.0, 1.0, 1.0])
            out["right_" + seg[5:]] = mean
    return out


def subject_lengths_mm(
    cameras: Sequence[Camera],
    joint_names: Sequence[str],
    pixels: FloatArray,
    reject_mm: float,
    good_mm: float,
    min_views: int = 3,
) -> tuple[dict[str, float], dict[str, FloatArray]]:
    """Segment lengths (mm) of the subject from a take's detections (V, T, K, 2), and
    the rest vectors of its trunk segments (`trunk_vectors_from_points`).

    A joint counts on a frame when, after `robust_triangulation`, at least
    ``min(min_views, V)`` views kept it and its largest kept reprojection error is
    below ``good_mm``.
    """
    pts, err, kept = robust_triangulation(cameras, pixels, reject_mm)
    need = min(min_views, len(cameras))
    with np.errstate(invalid="ignore"):
        kept_err = np.where(err <= reject_mm, err, np.nan)
        worst = np.nanmax(np.where(np.isfinite(kept_err), kept_err, -np.inf), axis=0)
    good = (kept >= need) & np.isfinite(pts).all(axis=-1) & (worst < good_mm)
    return segment_lengths_from_points(joint_names, pts, good), trunk_vectors_from_points(
        joint_names, pts, good
    )


__all__ = [
    "MIN_FRAMES",
    "SIDE_TOLERANCE",
    "column_median",
    "reprojection_errors_mm",
    "robust_triangulation",
    "segment_lengths_from_points",
    "subject_lengths_mm",
    "trunk_vectors_from_points",
]
