"""Outline chamfer kernels: bilinear look-up, sampling, the cap, orientation routing."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.ndimage import map_coordinates

from mocapkit.camera.projection import camera_arrays
from mocapkit.cues.chamfer import (
    ChamferMaps,
    filled_outline_sum_nb,
    lookup_points_nb,
    outline_chamfer_nb,
    outline_points_px_nb,
)
from mocapkit.cues.edges import DistanceMap

K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
CAM = camera_arrays(K, [], np.eye(4))  # camera at the world origin, looking along +z


def _segments(*pairs_px: tuple[tuple[float, float], tuple[float, float]], z: float = 2000.0):
    """Camera-frame segments at depth z whose ends project to the given pixels."""
    out = np.empty((len(pairs_px), 2, 3))
    for i, pair in enumerate(pairs_px):
        for j, (u, v) in enumerate(pair):
            out[i, j] = [(u - 320.0) * z / 500.0, (v - 240.0) * z / 500.0, z]
    return out


@pytest.mark.parametrize("step", [1, 2])
def test_lookup_is_bilinear_on_the_grid_and_cap_outside(step: int, rng) -> None:
    d = rng.uniform(0, 20, (30, 40)).astype(np.float32)
    x0, y0 = 100.0, 50.0
    uv = np.column_stack(
        [rng.uniform(95, 100 + 40 * step + 5, 500), rng.uniform(45, 50 + 30 * step + 5, 500)]
    )
    out = np.empty(500)
    lookup_points_nb(d, uv, x0, y0, float(step), 25.0, out)
    col = (uv[:, 0] - x0 - 0.5 * (step - 1)) / step
    row = (uv[:, 1] - y0 - 0.5 * (step - 1)) / step
    inside = (col >= 0) & (row >= 0) & (col < 39) & (row < 29)
    ref = map_coordinates(d.astype(np.float64), [row[inside], col[inside]], order=1)
    np.testing.assert_allclose(out[inside], ref, atol=1e-9)
    assert np.all(out[~inside] == 25.0) and (~inside).sum() > 10


def test_distance_map_lookup_uses_the_kernel(rng) -> None:
    d = rng.uniform(0, 20, (12, 9)).astype(np.float32)
    dm = DistanceMap(d, (3, 4), 20.0)
    pts = rng.uniform(0, 15, (6, 7, 2))
    out = np.empty(42)
    lookup_points_nb(d, pts.reshape(-1, 2), 3.0, 4.0, 1.0, 20.0, out)
    np.testing.assert_array_equal(dm.lookup(pts), out.reshape(6, 7))
    maps = dm.chamfer_maps()
    assert maps.maps.shape == (1, 12, 9) and maps.step_px == 1.0 and maps.cap_px == 20.0


def test_outline_chamfer_samples_every_step_and_averages_the_look_ups(rng) -> None:
    d = rng.uniform(0, 20, (200, 300)).astype(np.float32)
    maps = ChamferMaps(d[None], np.array([150.0, 100.0]), 1.0, 25.0)
    segs = _segments(((200.0, 150.0), (260.0, 230.0)), ((180.0, 120.0), (182.0, 121.0)))
    pts = np.empty((1000, 2))
    m = outline_points_px_nb(CAM, segs, 2, 3.0, pts)
    # 100 px long: ceil(100 / 3) + 1 = 35 samples; 2.2 px long: 2 samples
    assert m == 35 + 2
    np.testing.assert_allclose(pts[0], [200.0, 150.0], atol=1e-9)
    np.testing.assert_allclose(pts[34], [260.0, 230.0], atol=1e-9)
    np.testing.assert_allclose(np.diff(pts[:35], axis=0), [[60 / 34, 80 / 34]] * 34, atol=1e-9)
    dm = DistanceMap(d, (150, 100), 25.0)
    mean = outline_chamfer_nb(CAM, segs, 2, maps, 3.0)
    assert mean == pytest.approx(float(np.mean(dm.lookup(pts[:m]))), rel=1e-12)


def test_off_map_and_invisible_segments_cost_the_cap() -> None:
    maps = ChamferMaps(np.zeros((1, 50, 50), np.float32), np.array([0.0, 0.0]), 1.0, 25.0)
    far = _segments(((400.0, 300.0), (450.0, 300.0)))
    assert outline_chamfer_nb(CAM, far, 1, maps, 3.0) == 25.0
    behind = np.array([[[0.0, 0.0, 1000.0], [10.0, 0.0, -5.0]]])
    assert outline_chamfer_nb(CAM, behind, 1, maps, 3.0) == 25.0
    # half on the map, half off: the mean of zeros and caps
    on = _segments(((10.0, 10.0), (30.0, 10.0)))
    both = np.concatenate([on, behind])
    assert outline_chamfer_nb(CAM, both, 2, maps, 2.0) == pytest.approx(25.0 * 2 / 13)


@pytest.mark.parametrize("n_bins", [4, 8])
def test_each_segment_reads_the_map_of_its_image_direction(n_bins: int) -> None:
    maps = ChamferMaps(
        np.ascontiguousarray(
            np.broadcast_to(np.arange(n_bins, dtype=np.float32)[:, None, None], (n_bins, 100, 100))
        ),
        np.array([0.0, 0.0]),
        2.0,
        25.0,
    )
    for deg in range(0, 360, 15):
        a = math.radians(deg)
        seg = _segments(((100.0, 100.0), (100.0 + 40 * math.cos(a), 100.0 + 40 * math.sin(a))))
        expected = round((deg % 180) * n_bins / 180.0) % n_bins
        assert outline_chamfer_nb(CAM, seg, 1, maps, 3.0) == pytest.approx(expected), deg


def test_filled_outline_sum_counts_pixels_inside_the_quad() -> None:
    maps = ChamferMaps(np.ones((1, 100, 100), np.float32), np.array([0.0, 0.0]), 1.0, 25.0)
    # generators of a 20 x 40 px rectangle, pixel centres on its border count
    segs = _segments(((10.0, 10.0), (10.0, 50.0)), ((30.0, 10.0), (30.0, 50.0)))
    assert filled_outline_sum_nb(CAM, segs, 1, maps) == pytest.approx(21 * 41)
