"""Triangulation: project -> triangulate round trips on synthetic cameras."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.camera import Camera, intrinsics_from_fov, look_at
from mocapkit.camera.triangulation import (
    closest_point_to_lines,
    reprojection_errors_px,
    triangulate_pair,
    triangulate_views,
)
from mocapkit.errors import ConfigError, ShapeError

DIST = [-0.12, 0.03, 0.0008, -0.0004, 0.0]


def _rig() -> list[Camera]:
    """Four distorted cameras around a 2 m tall volume centred on the origin."""
    k = intrinsics_from_fov((1280, 720), 70.0)
    eyes = [(3000, -3000, 1800), (-3000, -3000, 1500), (-3000, 3000, 1700), (3000, 3000, 1200)]
    return [
        Camera(f"c{i}", (1280, 720), k, DIST, look_at(e, (0.0, 0.0, 1000.0)))
        for i, e in enumerate(eyes)
    ]


@pytest.fixture
def points(rng: np.random.Generator) -> np.ndarray:
    """World points (5, 7, 3) in mm, batched over two leading axes."""
    return rng.uniform([-600, -600, 0], [600, 600, 2000], size=(5, 7, 3))


def test_pair_round_trip(points: np.ndarray) -> None:
    a, b = _rig()[:2]
    out = triangulate_pair(a, b, a.project(points), b.project(points))
    assert out.shape == (5, 7, 3)
    np.testing.assert_allclose(out, points, atol=1e-6)


def test_pair_missing_points_are_nan(points: np.ndarray) -> None:
    a, b = _rig()[:2]
    pa = a.project(points)
    pa[1, 2] = np.nan
    out = triangulate_pair(a, b, pa, b.project(points))
    assert np.all(np.isnan(out[1, 2]))
    np.testing.assert_allclose(
        np.delete(out.reshape(-1, 3), 9, axis=0),
        np.delete(points.reshape(-1, 3), 9, axis=0),
        atol=1e-6,
    )
    with pytest.raises(ShapeError, match=r"matching pixel arrays, found \(5, 7, 2\) and \(7, 2\)"):
        triangulate_pair(a, b, pa, pa[0])


def test_n_view_round_trip_with_unseen_views(points: np.ndarray) -> None:
    cams = _rig()
    px = np.stack([c.project(points) for c in cams])  # (4, 5, 7, 2)
    px[0, 0, :] = np.nan  # view 0 misses a whole row
    px[1:, 1, 3] = np.nan  # point (1, 3) seen by view 0 only -> cannot be triangulated
    px[2:, 2, 4] = np.nan  # point (2, 4) seen by exactly 2 views
    out = triangulate_views(cams, px)
    assert out.shape == (5, 7, 3)
    assert np.all(np.isnan(out[1, 3]))
    ok = ~np.isnan(out[..., 0])
    assert ok.sum() == 34
    np.testing.assert_allclose(out[ok], points[ok], atol=1e-6)
    strict = triangulate_views(cams, px, min_views=3)
    assert np.all(np.isnan(strict[2, 4])) and np.all(np.isfinite(strict[3]))


def test_n_view_noise_is_reduced_by_more_views(rng: np.random.Generator) -> None:
    cams = _rig()
    pts = rng.uniform([-500, -500, 200], [500, 500, 1800], size=(400, 3))
    px = np.stack([c.project(pts) for c in cams]) + rng.normal(0.0, 0.5, (4, 400, 2))
    err2 = np.linalg.norm(triangulate_views(cams[:2], px[:2]) - pts, axis=-1)
    err4 = np.linalg.norm(triangulate_views(cams, px) - pts, axis=-1)
    assert np.median(err4) < np.median(err2)
    # 0.5 px at ~4.3 m with f ~ 914 px is ~2.4 mm per ray; 4 rays average it down.
    assert np.median(err4) < 2.5
    res = reprojection_errors_px(cams, triangulate_views(cams, px), px)
    assert res.shape == (4, 400) and np.median(res) < 1.0


def test_n_view_shape_errors() -> None:
    cams = _rig()
    with pytest.raises(
        ShapeError, match=r"expected pixels \(4, \.\.\., 2\) for 4 cameras, found \(3, 5, 2\)"
    ):
        triangulate_views(cams, np.zeros((3, 5, 2)))
    with pytest.raises(ConfigError, match="min_views must be at least 2, found 1"):
        triangulate_views(cams, np.zeros((4, 5, 2)), min_views=1)


def test_closest_point_to_lines() -> None:
    target = np.array([100.0, -50.0, 900.0])
    origins = np.array([[0.0, 0.0, 0.0], [1000.0, 0.0, 0.0], [0.0, 1000.0, 500.0]])
    x = closest_point_to_lines(origins, target - origins)
    np.testing.assert_allclose(x, target, atol=1e-9)
    with pytest.raises(ShapeError, match="parallel"):
        closest_point_to_lines(origins[:2], [[0, 0, 1.0], [0, 0, 2.0]])


def test_widest_view_angle_of_known_rigs() -> None:
    """Axes 90 deg apart give pi/2; a pair turned 3 deg to each other 3 deg; one camera 0."""
    from mocapkit.camera.triangulation import widest_view_angle_rad

    k = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])

    def cam(name: str, eye: tuple[float, float, float], target=(0.0, 0.0, 1000.0)) -> Camera:
        return Camera(name, (640, 480), k, np.zeros(5), look_at(eye, target))

    ring = [cam("a", (4000.0, 0.0, 1000.0)), cam("b", (0.0, 4000.0, 1000.0))]
    assert widest_view_angle_rad(ring) == pytest.approx(np.pi / 2, abs=1e-9)
    half = np.radians(1.5)
    pair = [
        cam("l", (0.0, -4000.0, 1000.0), (4000.0 * np.tan(half), 0.0, 1000.0)),
        cam("r", (0.0, -4000.0, 1000.0), (-4000.0 * np.tan(half), 0.0, 1000.0)),
    ]
    assert widest_view_angle_rad(pair) == pytest.approx(2 * half, abs=1e-9)
    assert widest_view_angle_rad(ring[:1]) == 0.0
