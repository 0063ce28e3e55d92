"""Blobs of a binary mask approximated by ellipses (Mamania et al. 2004, §3.3).

"The output of skin detection is post-processed by morphological operations which
produces the blobs of skin regions ... Each of these blobs can then be approximated as an
ellipse. The endpoints of the major axis of each ellipse gives the endpoints (joints)."

A morphological closing of ``close_px`` joins pieces of one body part that bad image
processing broke apart ("broken blobs can be reunited ... by making use of local
proximity"); connected components smaller than ``min_area_px`` are noise. Each blob's
ellipse comes from its second moments (the ellipse with the same area and inertia, which
is what `cv2.fitEllipse` approximates from the outline; moments use every pixel and need
no 5-point minimum).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ShapeError

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Blob:
    """One blob and its ellipse (pixels).

    Attributes
    ----------
    centre : (2,) float
        Centroid (x, y).
    area : float
        Pixel count.
    major, minor : float
        Semi-axes of the ellipse with the blob's second moments.
    direction : (2,) float
        Unit vector of the major axis.
    ends : (2, 2) float
        The major axis' end points, the upper one (smaller y) first.
    """

    centre: FloatArray
    area: float
    major: float
    minor: float
    direction: FloatArray
    ends: FloatArray


def ellipse_of(points_xy: ArrayLike) -> Blob:
    """The moment ellipse of a set of pixel positions (N, 2)."""
    p = np.asarray(points_xy, dtype=float)
    if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] < 1:
        raise ShapeError(f"ellipse_of: expected (N, 2) pixel positions, found {p.shape}")
    c = p.mean(axis=0)
    # the covariance of a uniform solid ellipse with semi-axes a, b is diag(a^2, b^2) / 4;
    # + 1/12 px^2 per axis for the pixels' own extent
    cov = np.cov((p - c).T, bias=True) + np.eye(2) / 12.0 if p.shape[0] > 1 else np.eye(2) / 12
    vals, vecs = np.linalg.eigh(cov)
    major, minor = 2.0 * np.sqrt(max(vals[1], 0.0)), 2.0 * np.sqrt(max(vals[0], 0.0))
    d = vecs[:, 1]
    ends = np.stack([c + major * d, c - major * d])
    if ends[0, 1] > ends[1, 1]:
        ends = ends[::-1]
    return Blob(c, float(p.shape[0]), float(major), float(minor), d, ends)


def mask_blobs(mask: ArrayLike, min_area_px: int = 30, close_px: int = 2) -> list[Blob]:
    """Blobs of a binary mask (H, W), largest first; see the module docstring."""
    m = np.asarray(mask)
    if m.ndim != 2:
        raise ShapeError(f"mask_blobs: expected a (H, W) mask, found {m.shape}")
    b = (m != 0).astype(np.uint8)
    if close_px > 0:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * close_px + 1, 2 * close_px + 1))
        b = np.asarray(cv2.morphologyEx(b, cv2.MORPH_CLOSE, k), dtype=np.uint8)
    n, labels = cv2.connectedComponents(b, connectivity=8)
    blobs = []
    for i in range(1, n):
        ys, xs = np.nonzero(labels == i)
        if xs.size >= min_area_px:
            blobs.append(ellipse_of(np.stack([xs, ys], axis=1)))
    blobs.sort(key=lambda bl: -bl.area)
    return blobs
