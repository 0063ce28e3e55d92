"""The compiled projection kernel: cv2.projectPoints, the near-plane rule, one path for all."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from mocapkit.camera import Camera, intrinsics_from_fov, look_at
from mocapkit.camera.projection import (
    NEAR_PLANE_MM,
    camera_arrays,
    project,
    project_points_nb,
)
from mocapkit.errors import ShapeError

RATIONAL = [-0.21, 0.08, 0.001, -0.0015, -0.01, 0.02, -0.004, 0.001]


@pytest.mark.parametrize("dist", [[], [0.1, -0.05, 0.002, 0.001], RATIONAL])
def test_kernel_matches_cv2_project_points(dist, rng) -> None:
    k = intrinsics_from_fov((640, 480), 60.0)
    pose = look_at([400, -2800, 1500], [0, 0, 1100])
    cam = camera_arrays(k, dist, pose)
    pts = rng.uniform(-700, 700, (300, 3)) + np.array([0.0, 0.0, 1100.0])
    out = np.empty((300, 2))
    project_points_nb(cam, pts, True, out)
    rvec, _ = cv2.Rodrigues(pose[:3, :3])
    ref, _ = cv2.projectPoints(pts, rvec, pose[:3, 3], k, np.asarray(dist, dtype=float))
    np.testing.assert_allclose(out, ref.reshape(-1, 2), atol=1e-8)
    # the camera-frame entry point gives the same pixels
    in_camera = pts @ pose[:3, :3].T + pose[:3, 3]
    np.testing.assert_allclose(project(cam, in_camera, in_world=False), out, atol=1e-9)


def test_points_below_the_near_plane_are_not_visible() -> None:
    cam = camera_arrays(intrinsics_from_fov((640, 480), 60.0), [], np.eye(4))
    z = np.array([-500.0, 0.0, 0.5 * NEAR_PLANE_MM, 0.999 * NEAR_PLANE_MM, NEAR_PLANE_MM, 900.0])
    pts = np.column_stack([np.full(6, 10.0), np.full(6, -20.0), z])
    px = project(cam, pts, in_world=False)
    visible = np.all(np.isfinite(px), axis=1)
    np.testing.assert_array_equal(visible, z >= NEAR_PLANE_MM)


def test_camera_methods_use_the_kernel(rng) -> None:
    pose = look_at([300, -3000, 1400], [0, 0, 1000])
    cam = Camera("c", (640, 480), intrinsics_from_fov((640, 480), 50.0), RATIONAL, pose)
    pts = rng.uniform(-500, 500, (4, 5, 3)) + np.array([0.0, 0.0, 1000.0])
    out = np.empty((20, 2))
    project_points_nb(cam.arrays, pts.reshape(-1, 3), True, out)
    np.testing.assert_array_equal(cam.project(pts), out.reshape(4, 5, 2))
    in_camera = cam.to_camera(pts)
    np.testing.assert_allclose(cam.project_camera_points(in_camera), cam.project(pts), atol=1e-9)
    # a point 0.5 mm in front of the lens is not visible through Camera either
    assert np.all(np.isnan(cam.project_camera_points([1.0, 1.0, 0.5])))


def test_thin_prism_terms_rejected() -> None:
    dist = np.zeros(12)
    dist[9] = 0.01
    with pytest.raises(ShapeError, match="thin-prism/tilt coefficients"):
        camera_arrays(np.eye(3), dist, np.eye(4))
    with pytest.raises(ShapeError, match=r"expected points \(\.\.\., 3\)"):
        project(camera_arrays(np.eye(3), [], np.eye(4)), np.zeros((4, 2)))


def test_distort_normalized_is_the_kernel_with_unit_intrinsics(rng) -> None:
    from mocapkit.camera import distort_normalized

    x, y = rng.uniform(-0.6, 0.6, (2, 7, 3))
    xd, yd = distort_normalized(x, y, RATIONAL)
    pts = np.stack([x, y, np.ones_like(x)], axis=-1).reshape(-1, 3)
    ref, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), np.eye(3), np.array(RATIONAL))
    got = np.stack([xd, yd], -1).reshape(-1, 2)
    np.testing.assert_allclose(got, ref.reshape(-1, 2), atol=1e-12)
