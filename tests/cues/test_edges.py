"""Edge distance transform: brute force, truncation, equalisation table, RoI = full frame,
oriented chamfer maps."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from mocapkit.cues.edges import (
    DistanceMap,
    EdgeConfig,
    distance_to_edges,
    edge_distance_maps,
    edge_distance_transform,
    equalize_lut,
    oriented_distance_maps,
    prepare_frame,
    roi_around_points,
    roi_distance_map,
    to_grey,
)
from mocapkit.errors import ConfigError, ShapeError


def _brute_force(edges: np.ndarray) -> np.ndarray:
    rows, cols = np.nonzero(edges)
    yy, xx = np.mgrid[: edges.shape[0], : edges.shape[1]]
    d2 = (yy[..., None] - rows) ** 2 + (xx[..., None] - cols) ** 2
    return np.sqrt(d2.min(axis=-1))


def _shapes_image(rng: np.random.Generator) -> np.ndarray:
    """Piecewise-constant, high-contrast shapes: every Canny edge is a strong edge, so
    hysteresis is local and RoI processing must match the full frame exactly."""
    img = np.full((240, 320, 3), 40, np.uint8)
    for _ in range(8):
        c = tuple(int(v) for v in rng.integers(120, 255, 3))
        x, y = (int(v) for v in rng.integers(20, 300, 2) % (300, 220))
        w, h = (int(v) for v in rng.integers(15, 60, 2))
        cv2.rectangle(img, (x, y), (x + w, y + h), c, -1)
        cv2.circle(
            img,
            (int(rng.integers(0, 320)), int(rng.integers(0, 240))),
            int(rng.integers(8, 40)),
            c,
            -1,
        )
    return img


def test_precise_distance_equals_brute_force(rng):
    edges = np.where(rng.random((40, 50)) < 0.02, 255, 0).astype(np.uint8)
    got = distance_to_edges(edges, mask="precise")
    np.testing.assert_allclose(got, _brute_force(edges), rtol=1e-6, atol=1e-5)


def test_mask5_distance_within_chamfer_bound_and_cap(rng):
    edges = np.where(rng.random((40, 50)) < 0.02, 255, 0).astype(np.uint8)
    exact = _brute_force(edges)
    got = distance_to_edges(edges, mask="5")
    # the 5x5 chamfer mask (1, 1.4, 2.1969) is within 2 % of the Euclidean distance
    np.testing.assert_array_less(np.abs(got - exact), 0.02 * exact + 1e-6)
    capped = distance_to_edges(edges, cap_px=3.0, mask="precise")
    np.testing.assert_allclose(capped, np.minimum(exact, 3.0), rtol=1e-6, atol=1e-5)
    assert distance_to_edges(edges, cap_px=3.0)[edges > 0].max() == 0.0


def test_equalize_lut_matches_opencv(rng):
    for _ in range(20):
        h, w = (int(v) for v in rng.integers(5, 200, 2))
        grey = rng.normal(rng.uniform(0, 255), rng.uniform(1, 60), (h, w)).clip(0, 255)
        grey = grey.astype(np.uint8)
        np.testing.assert_array_equal(equalize_lut(grey)[grey], cv2.equalizeHist(grey))


def test_roi_result_equals_full_frame_inside_roi(rng):
    img = _shapes_image(rng)
    cfg = EdgeConfig(cap_px=20.0)
    full = edge_distance_transform(img, None, cfg)
    assert full.max() <= 20.0 and full.min() == 0.0
    rois = [(30, 40, 130, 150), (200, 10, 320, 100), (0, 180, 60, 240)]
    maps = edge_distance_maps(img, rois, cfg)
    for roi, dm in zip(rois, maps):
        x0, y0, x1, y1 = roi
        assert dm.roi == roi
        np.testing.assert_array_equal(dm.distance_px, full[y0:y1, x0:x1])
    union = edge_distance_transform(img, rois, cfg)
    np.testing.assert_array_equal(union[40:150, 30:130], full[40:150, 30:130])
    assert np.all(union[160:170, 150:190] == 20.0)  # outside every RoI: the cap


def test_roi_equalisation_uses_the_padded_crop_histogram(rng):
    img = _shapes_image(rng)
    img[:, :160] //= 3  # a darker half, so a local histogram differs from the frame's
    cfg = EdgeConfig(equalize="roi", cap_px=20.0)
    x0, y0, x1, y1 = roi = (60, 40, 130, 150)
    m = cfg.margin_px
    local = edge_distance_maps(img, [roi], cfg)[0].distance_px
    crop_alone = edge_distance_transform(img[y0 - m : y1 + m, x0 - m : x1 + m], None, cfg)
    np.testing.assert_array_equal(local, crop_alone[m:-m, m:-m])
    image_wide = edge_distance_maps(img, [roi], EdgeConfig(cap_px=20.0))[0].distance_px
    assert not np.array_equal(local, image_wide)


def test_lookup_bilinear_and_cap_outside():
    d = np.arange(12, dtype=np.float32).reshape(3, 4)
    dm = DistanceMap(d, (10, 20), 25.0)
    got = dm.lookup([[10.0, 20.0], [11.5, 20.5], [9.0, 20.0], [13.0, 21.0], [np.nan, 0.0]])
    np.testing.assert_allclose(got, [0.0, 0.5 * (1 + 2 + 5 + 6) / 2, 25.0, 25.0, 25.0])


def test_roi_around_points_pads_and_clips():
    roi = roi_around_points([[10.0, 20.0], [50.0, 5.0], [np.nan, np.nan]], (60, 40), 8.0)
    assert roi == (2, 0, 59, 29)
    assert roi_around_points([[np.nan, np.nan]], (60, 40), 8.0) == (0, 0, 0, 0)


def test_bad_inputs_raise():
    with pytest.raises(ShapeError, match="expected dtype uint8, found float64"):
        to_grey(np.zeros((4, 4)))
    with pytest.raises(ShapeError, match=r"found shape \(4, 4, 2\)"):
        to_grey(np.zeros((4, 4, 2), np.uint8))
    with pytest.raises(ConfigError, match="blur_ksize: expected a positive odd"):
        EdgeConfig(blur_ksize=4)
    with pytest.raises(ConfigError, match="cap_px: expected a positive number"):
        EdgeConfig(cap_px=0.0)
    with pytest.raises(ConfigError, match="canny_low <= canny_high"):
        EdgeConfig(canny_low=200, canny_high=100)
    with pytest.raises(ConfigError, match="mask: expected one of"):
        distance_to_edges(np.zeros((3, 3), np.uint8), mask="7")


def _edge_bins(edges: np.ndarray, smoothed: np.ndarray, n_bins: int) -> np.ndarray:
    """Orientation bin of every pixel's edge line, from OpenCV's 3x3 Sobel (reference)."""
    gx = cv2.Sobel(smoothed.astype(np.float32), cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(smoothed.astype(np.float32), cv2.CV_32F, 0, 1, ksize=3)
    line = np.mod(np.arctan2(gy, gx) + 0.5 * np.pi, np.pi)
    return np.floor(line * n_bins / np.pi + 0.5).astype(int) % n_bins


@pytest.mark.parametrize("step", [1, 2])
def test_oriented_maps_equal_brute_force_per_bin(rng, step):
    smoothed = cv2.GaussianBlur(_shapes_image(rng)[:, :, 1], (5, 5), 0)
    edges = cv2.Canny(smoothed, 50, 150)
    n_bins, cap = 6, 18.0
    maps = oriented_distance_maps(edges, smoothed, n_bins, cap, mask="precise", step_px=step)
    h2, w2 = -(-edges.shape[0] // step), -(-edges.shape[1] // step)
    assert maps.shape == (n_bins, h2, w2) and maps.dtype == np.float32
    bins = _edge_bins(edges, smoothed, n_bins)
    for k in range(n_bins):
        near = (edges > 0) & (np.abs((bins - k + 1) % n_bins) <= 2)
        grid = np.zeros((h2, w2), np.uint8)
        ys, xs = np.nonzero(near)
        grid[ys // step, xs // step] = 1
        want = (
            np.minimum(_brute_force(grid) * step, cap) if grid.any() else np.full_like(maps[k], cap)
        )
        np.testing.assert_allclose(maps[k], want, rtol=1e-5, atol=1e-4)


def test_oriented_maps_keep_only_edges_running_the_bins_way():
    # a bright bar at 30 deg: its two long sides are edges at 30 deg (bin 1 of 6)
    img = np.zeros((200, 200), np.uint8)
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    corners = np.array([[-70, -12], [70, -12], [70, 12], [-70, 12]], float)
    rot = corners @ np.array([[c, s], [-s, c]]) + 100.0
    cv2.fillConvexPoly(img, np.round(rot * 16).astype(np.int32), 220, cv2.LINE_AA, 4)
    smoothed = cv2.GaussianBlur(img, (5, 5), 0)
    edges = cv2.Canny(smoothed, 50, 150)
    maps = oriented_distance_maps(edges, smoothed, 6, 25.0, step_px=1)
    # a point on the bar's long side (not near its ends)
    side = np.round(np.array([0.0, 12.0]) @ np.array([[c, s], [-s, c]]) + 100.0).astype(int)
    x, y = side
    assert maps[1][y, x] <= 2.0  # 30 deg: the side's own bin
    assert maps[4][y, x] >= 20.0  # 120 deg: perpendicular, only the far ends' edges
    plain = distance_to_edges(edges, 25.0)
    assert plain[y, x] <= 2.0


def test_roi_map_with_orientation_bins_adds_oriented_maps_of_the_padded_crop(rng):
    img = _shapes_image(rng)
    cfg = EdgeConfig(cap_px=20.0, orientation_bins=8)
    roi = (60, 40, 150, 160)
    dm = roi_distance_map(prepare_frame(img, cfg), roi, cfg)
    plain = roi_distance_map(
        prepare_frame(img, EdgeConfig(cap_px=20.0)), roi, EdgeConfig(cap_px=20.0)
    )
    np.testing.assert_array_equal(dm.distance_px, plain.distance_px)
    assert dm.oriented_px is not None and dm.oriented_px.shape[0] == 8
    m = cfg.margin_px
    assert dm.oriented_origin_px == (roi[0] - m, roi[1] - m) and dm.oriented_step_px == 2
    # every oriented map is at least the plain distance (fewer edges), up to the grid
    ox, oy = dm.oriented_origin_px
    inner = dm.oriented_px[
        :, (roi[1] - oy) // 2 : (roi[3] - oy) // 2, (roi[0] - ox) // 2 : (roi[2] - ox) // 2
    ]
    coarse = plain.distance_px[::2, ::2][: inner.shape[1], : inner.shape[2]]
    assert np.all(inner.min(axis=0) >= coarse - 2.0)
    with pytest.raises(ConfigError, match="orientation_bins: expected 0"):
        EdgeConfig(orientation_bins=1)
