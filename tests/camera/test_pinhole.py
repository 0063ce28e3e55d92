"""The pinhole camera: projection against OpenCV, look-at, validation."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from mocapkit.camera import Camera, intrinsics_from_fov, look_at
from mocapkit.errors import ShapeError


@pytest.fixture
def camera() -> Camera:
    k = intrinsics_from_fov((640, 480), 60.0)
    pose = look_at([300, -3000, 1400], [0, 0, 1000])
    return Camera("cam", (640, 480), k, [0.08, -0.05, 0.001, -0.002, 0.01], pose)


def test_projection_matches_opencv(camera: Camera, rng: np.random.Generator) -> None:
    pts = rng.normal(size=(2, 40, 3)) * 300 + [0, 0, 1000]
    r = camera.camera_from_world[:3, :3]
    t = camera.camera_from_world[:3, 3]
    ref, _ = cv2.projectPoints(pts.reshape(-1, 3), cv2.Rodrigues(r)[0], t, camera.K, camera.dist)
    np.testing.assert_allclose(camera.project(pts).reshape(-1, 2), ref[:, 0], atol=1e-9)


def test_look_at_centres_target_and_keeps_up_up(camera: Camera) -> None:
    centre = camera.project([0, 0, 1000])
    np.testing.assert_allclose(centre, [319.5, 239.5], atol=1e-6)
    above = camera.project([0, 0, 1500])
    assert above[1] < centre[1]  # world up is image up


def test_points_behind_camera_are_nan(camera: Camera) -> None:
    assert np.all(np.isnan(camera.project([0, -6000, 1000])))


def test_bad_camera_rejected() -> None:
    k = intrinsics_from_fov((640, 480), 60.0)
    with pytest.raises(ShapeError, match=r"camera 'c' K: expected shape \(3, 3\)"):
        Camera("c", (640, 480), np.eye(2), [], np.eye(4))
    bad = np.eye(4)
    bad[0, 0] = -1
    with pytest.raises(ShapeError, match="not a proper rotation"):
        Camera("c", (640, 480), k, [], bad)
    with pytest.raises(ShapeError, match="found 3"):
        Camera("c", (640, 480), k, [0.1, 0.2, 0.3], np.eye(4))
