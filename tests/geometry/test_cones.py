"""Contour generators of truncated cones: on the surface, tangent to the viewing rays."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.geometry.cones import cone_contour_generators


def _random_cone(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, float, float]:
    a = rng.uniform(-400, 400, 3) + np.array([0.0, 0.0, 2000.0])
    b = a + rng.normal(0, 1, 3) / 1.0 * rng.uniform(150, 400)
    ra, rb = rng.uniform(20, 60), rng.uniform(10, 60)
    return a, b, ra, rb


@pytest.mark.parametrize("seed", range(5))
def test_generators_are_rulings_tangent_to_the_viewing_rays(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for _ in range(20):
        a, b, ra, rb = _random_cone(rng)
        lines = cone_contour_generators(a, b, ra, rb)
        length = np.linalg.norm(b - a)
        u = (b - a) / length
        k = (rb - ra) / length
        for side in range(2):
            start, end = lines[side]
            # on the surface: radial offsets of the radii's lengths, perpendicular to the axis,
            # the same direction at both ends (a straight ruling)
            e0, e1 = (start - a) / ra, (end - b) / rb
            np.testing.assert_allclose([np.linalg.norm(e0), np.linalg.norm(e1)], 1.0, atol=1e-12)
            assert abs(e0 @ u) < 1e-12
            np.testing.assert_allclose(e0, e1, atol=1e-12)
            # tangency: the surface normal (e - k u, from the cone's parametrisation) is
            # orthogonal to the viewing ray (the point itself: the camera is the origin),
            # at the ruling's ends and midway
            normal = e0 - k * u
            normal /= np.linalg.norm(normal)
            for f in (0.0, 0.5, 1.0):
                p = start + f * (end - start)
                assert abs(p @ normal) / np.linalg.norm(p) < 1e-12
        # two distinct sides, symmetric about the plane of the axis and the camera
        assert np.linalg.norm(lines[0, 0] - lines[1, 0]) > 1e-3
        mid = 0.5 * (lines[0, 0] + lines[1, 0])
        assert abs(np.cross(a, b) @ (mid - a)) / np.linalg.norm(np.cross(a, b)) < 1e-9


def test_generators_bound_the_projected_cone(rng: np.random.Generator) -> None:
    """Projected surface points all lie between the two projected generators."""
    a, b = np.array([100.0, -50.0, 1500.0]), np.array([250.0, 200.0, 1800.0])
    ra, rb = 45.0, 30.0
    lines = cone_contour_generators(a, b, ra, rb)
    u = (b - a) / np.linalg.norm(b - a)
    p = np.cross(u, [0.0, 0.0, 1.0])
    p /= np.linalg.norm(p)
    q = np.cross(u, p)
    t = rng.uniform(0, 1, 2000)
    phi = rng.uniform(0, 2 * np.pi, 2000)
    r = ra + t * (rb - ra)
    radial = np.cos(phi)[:, None] * p + np.sin(phi)[:, None] * q
    pts = a + t[:, None] * (b - a) + r[:, None] * radial

    def signed(line: np.ndarray) -> np.ndarray:
        s, e = line[0, :2] / line[0, 2], line[1, :2] / line[1, 2]
        x = pts[:, :2] / pts[:, 2:]
        d = e - s
        return d[0] * (x[:, 1] - s[1]) - d[1] * (x[:, 0] - s[0])

    s0, s1 = signed(lines[0]), signed(lines[1])
    scale = 1e-9
    assert np.all(s0 * np.sign(np.median(s0)) >= -scale)
    assert np.all(s1 * np.sign(np.median(s1)) >= -scale)


def test_degenerate_cones() -> None:
    a = np.array([0.0, 0.0, 1000.0])
    lines = cone_contour_generators(a, a, 30.0, 30.0)
    np.testing.assert_array_equal(lines[:, 0], [a, a])
    # looking straight down the axis: two opposite rulings of the right radius
    b = np.array([0.0, 0.0, 1300.0])
    lines = cone_contour_generators(a, b, 30.0, 20.0)
    np.testing.assert_allclose(np.linalg.norm(lines[:, 0] - a, axis=1), 30.0)
    np.testing.assert_allclose(lines[0, 0] - a, -(lines[1, 0] - a), atol=1e-12)
