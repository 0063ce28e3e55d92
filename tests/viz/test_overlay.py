"""Canonical sticks drawn over an image at the camera's projections."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.camera.pinhole import Camera
from mocapkit.errors import ShapeError
from mocapkit.viz.overlay import draw_sticks


def _camera() -> Camera:
    # at the origin looking along world +Y, image x along world +X, image y along world -Z
    pose = np.eye(4)
    pose[:3, :3] = [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]
    k = np.array([[100.0, 0.0, 80.0], [0.0, 100.0, 60.0], [0.0, 0.0, 1.0]])
    return Camera("c", (160, 120), k, np.zeros(5), pose)


def test_sticks_drawn_at_projections_and_gaps_left_out():
    cam = _camera()
    names = ("pelvis", "neck", "head", "left_hip")
    joints = np.array(
        [[0.0, 2000.0, 0.0], [0.0, 2000.0, 600.0], [np.nan, 2000.0, 800.0], [0.0, -500.0, 0.0]]
    )
    img = draw_sticks(np.zeros((120, 160, 3), np.uint8), cam, names, joints, (0, 0, 255), 1)
    u_p, v_p = cam.project(joints[0])
    u_n, v_n = cam.project(joints[1])
    assert (u_p, v_p) == pytest.approx((80.0, 60.0))
    assert (u_n, v_n) == pytest.approx((80.0, 30.0))
    # the trunk stick pelvis-neck: red along the column between the two projections
    assert np.all(img[33:58, 80, 2] > 100)
    assert np.all(img[33:58, 80, :2] == 0)
    # the head is missing (NaN) and the hip behind the camera: nothing above the neck, and
    # nothing else drawn than the trunk with its two dots
    assert not img[:25].any()
    red = np.argwhere(img[..., 2] > 0)
    assert red[:, 1].min() >= 76 and red[:, 1].max() <= 84


def test_sticks_shape_checked():
    with pytest.raises(ShapeError, match="expected 2 joints"):
        draw_sticks(
            np.zeros((120, 160, 3), np.uint8), _camera(), ("neck", "head"), np.zeros((3, 3))
        )
