"""Moving foreground of a static camera (`mocapkit.cues.foreground`)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from mocapkit.cues.foreground import foreground_mask, largest_region, median_background
from mocapkit.errors import ConfigError, ShapeError


def _frames(n: int = 9) -> tuple[list[np.ndarray], np.ndarray]:
    rng = np.random.default_rng(0)
    bg = rng.integers(0, 256, size=(120, 160, 3), dtype=np.uint8)
    frames = []
    for k in range(n):
        f = bg.copy()
        cv2.rectangle(f, (10 + 15 * k, 40), (30 + 15 * k, 80), (200, 50, 50), -1)
        frames.append(f)
    return frames, bg


def test_the_median_background_is_the_scene_without_the_mover() -> None:
    frames, bg = _frames()
    np.testing.assert_array_equal(median_background(frames), bg)
    with pytest.raises(ShapeError, match="at least one frame"):
        median_background([])


def test_the_foreground_is_the_moving_square() -> None:
    frames, bg = _frames()
    f = frames[4]
    m = foreground_mask(f, bg, threshold=0, open_px=0)
    truth = np.any(f != bg, axis=2)
    np.testing.assert_array_equal(m != 0, truth)
    assert (m != 0).sum() == 21 * 41 - np.all(f[40:81, 70:91] == bg[40:81, 70:91], axis=2).sum()
    with pytest.raises(ShapeError, match="one \\(H, W, 3\\) shape"):
        foreground_mask(f, bg[:10])
    with pytest.raises(ConfigError, match="threshold >= 0"):
        foreground_mask(f, bg, threshold=-1)


def test_largest_region_and_following_the_previous_one() -> None:
    m = np.zeros((50, 80), dtype=np.uint8)
    m[5:25, 5:25] = 1  # 400 px
    m[30:40, 50:60] = 1  # 100 px
    big = largest_region(m)
    assert (big != 0).sum() == 400 and big[10, 10] == 255
    prev = np.zeros_like(m)
    prev[32:36, 52:56] = 255
    small = largest_region(m, previous=prev)
    assert (small != 0).sum() == 100 and small[35, 55] == 255
    grown = largest_region(m, grow_px=2, previous=prev)
    # OpenCV's 5x5 ellipse kernel lacks the 2 outer pixels of each corner row: a 10x10
    # square grows to 14x14 less 2 px per corner
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
    assert kernel.sum() == 25 - 8
    assert (grown != 0).sum() == 14 * 14 - 4 * 2
    assert not largest_region(np.zeros_like(m)).any()
