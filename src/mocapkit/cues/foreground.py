"""Moving foreground of a static camera: the per-pixel median background and its difference.

Mamania et al. (2004) film a dancer before a plain backdrop, where every skin-coloured
pixel belongs to the subject. Real scenes hold skin-coloured things that do not move
(sunlit bark, a pink wall, a wooden floor), so the monocular tracker's skin mask can be
restricted to pixels that differ from the static background. The background is the
per-pixel median of frames spread over the clip (the subject must move away from each
pixel for more than half of them); a pixel is foreground where any colour channel
differs from it by more than ``threshold`` (grey levels), after an opening that drops
isolated pixels (leaves, sensor noise). The subject is followed as the largest connected
foreground region (`largest_region`).
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ConfigError, ShapeError

UInt8Array = NDArray[np.uint8]


def median_background(frames_bgr: Sequence[ArrayLike]) -> UInt8Array:
    """Per-pixel median (H, W, 3) uint8 of frames of one static camera.

    Parameters
    ----------
    frames_bgr : sequence of array_like of uint8, each (H, W, 3)
        At least one frame, all of one size.
    """
    if len(frames_bgr) == 0:
        raise ShapeError("median_background: expected at least one frame, found none")
    stack = np.stack([np.asarray(f) for f in frames_bgr])
    if stack.ndim != 4 or stack.shape[-1] != 3:
        raise ShapeError(
            f"median_background: expected frames of shape (H, W, 3), found {stack.shape[1:]}"
        )
    return np.asarray(np.median(stack, axis=0).round(), dtype=np.uint8)


def foreground_mask(
    image_bgr: ArrayLike, background_bgr: ArrayLike, threshold: float = 30.0, open_px: int = 1
) -> UInt8Array:
    """255 where ``image_bgr`` differs from the background by more than ``threshold``.

    Parameters
    ----------
    image_bgr, background_bgr : array_like of uint8, shape (H, W, 3)
    threshold : float
        Largest channel difference (grey levels) that still counts as background.
    open_px : int
        Radius of the opening that removes isolated foreground pixels (0: none).

    Returns
    -------
    (H, W) uint8
    """
    img = np.asarray(image_bgr)
    bg = np.asarray(background_bgr)
    if img.shape != bg.shape or img.ndim != 3 or img.shape[2] != 3:
        raise ShapeError(
            f"foreground_mask: expected image and background of one (H, W, 3) shape, found "
            f"{img.shape} and {bg.shape}"
        )
    if threshold < 0 or open_px < 0:
        raise ConfigError(
            f"foreground_mask: expected threshold >= 0 and open_px >= 0, found {threshold}, "
            f"{open_px}"
        )
    diff = np.abs(img.astype(np.int16) - bg.astype(np.int16)).max(axis=2)
    m = np.where(diff > threshold, 255, 0).astype(np.uint8)
    if open_px > 0:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * open_px + 1, 2 * open_px + 1))
        m = np.asarray(cv2.morphologyEx(m, cv2.MORPH_OPEN, k), dtype=np.uint8)
    return m


def largest_region(
    mask: ArrayLike, grow_px: int = 0, previous: ArrayLike | None = None
) -> UInt8Array:
    """One connected region of a mask (H, W) dilated by ``grow_px``; 255 on it.

    The mask is dilated first, so pieces of one body less than ``2 grow_px`` apart (a
    forearm beside a dark sleeve) form one region. The region returned is the one that
    overlaps ``previous`` (the last frame's answer) most, so that one person is followed
    while another moves more; the largest when none overlaps or there is no previous. An
    empty mask gives an empty mask.
    """
    m = (np.asarray(mask) != 0).astype(np.uint8)
    if m.ndim != 2:
        raise ShapeError(f"largest_region: expected a (H, W) mask, found {m.shape}")
    if grow_px < 0:
        raise ConfigError(f"largest_region: expected grow_px >= 0, found {grow_px}")
    if grow_px > 0:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * grow_px + 1, 2 * grow_px + 1))
        m = np.asarray(cv2.dilate(m, k), dtype=np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
    out = np.zeros_like(m)
    if n <= 1:
        return out
    best = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    if previous is not None:
        prev = np.asarray(previous) != 0
        if prev.shape != m.shape:
            raise ShapeError(
                f"largest_region: expected previous of shape {m.shape}, found {prev.shape}"
            )
        overlap = np.bincount(labels[prev], minlength=n)[1:]
        if overlap.max() > 0:
            best = 1 + int(np.argmax(overlap))
    out[labels == best] = 255
    return out


__all__ = ["foreground_mask", "largest_region", "median_background"]
