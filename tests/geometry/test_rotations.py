"""Rotations and transforms: known values, round trips, Numba kernels against NumPy."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocapkit.errors import ShapeError
from mocapkit.geometry import (
    invert_transform,
    left_jacobian_so3,
    make_transform,
    matrix_from_axis_angle,
    matrix_from_euler,
    matrix_from_rotvec,
    points_in_frame,
    rotvec_from_matrix,
    skew,
    transform_points,
)
from mocapkit.geometry.rotations import (
    axis_angle_matrix_nb,
    left_jacobian_so3_nb,
    rotvec_matrix_nb,
)


def test_axis_angle_known_value() -> None:
    r = matrix_from_axis_angle([0, 0, 1], np.pi / 2)
    np.testing.assert_allclose(r @ [1, 0, 0], [0, 1, 0], atol=1e-15)


def test_axis_angle_batched_matches_scipy(rng: np.random.Generator) -> None:
    axes = rng.normal(size=(4, 5, 3))
    angles = rng.uniform(-np.pi, np.pi, size=(4, 5))
    unit = axes / np.linalg.norm(axes, axis=-1, keepdims=True)
    expected = Rotation.from_rotvec((unit * angles[..., None]).reshape(-1, 3)).as_matrix()
    np.testing.assert_allclose(
        matrix_from_axis_angle(axes, angles).reshape(-1, 3, 3), expected, atol=1e-12
    )


def test_rotvec_round_trip_near_zero_and_pi(rng: np.random.Generator) -> None:
    axes = rng.normal(size=(50, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    for angle in (1e-9, 0.3, np.pi - 1e-7):
        rv = axes * angle
        back = rotvec_from_matrix(matrix_from_rotvec(rv))
        np.testing.assert_allclose(matrix_from_rotvec(back), matrix_from_rotvec(rv), atol=1e-9)


def test_euler_is_intrinsic_product_in_listed_order() -> None:
    a = np.array([0.3, -0.7, 1.1])
    expected = (
        matrix_from_axis_angle([0, 0, 1], a[0])
        @ matrix_from_axis_angle([0, 1, 0], a[1])
        @ matrix_from_axis_angle([1, 0, 0], a[2])
    )
    np.testing.assert_allclose(matrix_from_euler(a, "ZYX"), expected, atol=1e-12)


def test_left_jacobian_matches_finite_differences(rng: np.random.Generator) -> None:
    # w = J_l(r) dr/dt where [w]x = dR/dt R^T
    for r in (rng.normal(size=3), np.array([1e-8, 0.0, 2e-8])):
        eps = 1e-6
        jl = left_jacobian_so3(r)
        for k in range(3):
            dr = np.zeros(3)
            dr[k] = eps
            d_r = (matrix_from_rotvec(r + dr) - matrix_from_rotvec(r - dr)) / (2 * eps)
            w_hat = d_r @ matrix_from_rotvec(r).T
            w = np.array([w_hat[2, 1], w_hat[0, 2], w_hat[1, 0]])
            np.testing.assert_allclose(w, jl[:, k], atol=1e-7)


def test_numba_kernels_match_numpy(rng: np.random.Generator) -> None:
    out = np.empty((3, 3))
    for _ in range(10):
        r = rng.normal(size=3)
        rotvec_matrix_nb(r, out)
        np.testing.assert_allclose(out, matrix_from_rotvec(r), atol=1e-12)
        left_jacobian_so3_nb(r, out)
        np.testing.assert_allclose(out, left_jacobian_so3(r), atol=1e-12)
        axis = r / np.linalg.norm(r)
        axis_angle_matrix_nb(axis, 0.7, out)
        np.testing.assert_allclose(out, matrix_from_axis_angle(axis, 0.7), atol=1e-12)


def test_skew_is_cross_product(rng: np.random.Generator) -> None:
    v, w = rng.normal(size=(2, 3))
    np.testing.assert_allclose(skew(v) @ w, np.cross(v, w), atol=1e-12)


def test_transform_round_trip(rng: np.random.Generator) -> None:
    r = matrix_from_rotvec(rng.normal(size=(3, 3)))
    t = rng.normal(size=(3, 3)) * 100
    b_from_a = make_transform(r, t)
    pts = rng.normal(size=(3, 7, 3)) * 500
    back = transform_points(invert_transform(b_from_a), transform_points(b_from_a, pts))
    np.testing.assert_allclose(back, pts, atol=1e-9)


def test_points_in_frame_inverts_transform_points(rng: np.random.Generator) -> None:
    world_from_frame = make_transform(
        matrix_from_rotvec(rng.normal(size=(6, 3))), rng.normal(size=(6, 3)) * 100
    )
    pts = rng.normal(size=(6, 3)) * 500
    pts[2] = np.nan
    local = points_in_frame(world_from_frame, pts)
    expected = transform_points(invert_transform(world_from_frame), pts[:, None, :])[:, 0]
    np.testing.assert_allclose(local, expected, atol=1e-9)
    assert np.isnan(local[2]).all()
    back = transform_points(world_from_frame, local[:, None, :])[:, 0]
    np.testing.assert_allclose(back[[0, 1, 3, 4, 5]], pts[[0, 1, 3, 4, 5]], atol=1e-9)
    # known value: a frame turned 90 deg about z and moved to (10, 0, 0)
    turned = make_transform(matrix_from_axis_angle([0, 0, 1], np.pi / 2), [10.0, 0.0, 0.0])
    np.testing.assert_allclose(
        points_in_frame(turned, [10.0, 5.0, 2.0]), [5.0, 0.0, 2.0], atol=1e-12
    )
    with pytest.raises(ShapeError, match=r"points_in_frame: expected \(\.\.\., 4, 4\)"):
        points_in_frame(np.eye(3), pts)


def test_bad_shapes_are_rejected() -> None:
    with pytest.raises(ShapeError, match=r"expected shape \(\.\.\., 3\)"):
        skew([1.0, 2.0])
    with pytest.raises(ShapeError, match="zero length"):
        matrix_from_axis_angle([0, 0, 0], 1.0)
    with pytest.raises(ShapeError, match=r"expected \(\.\.\., 4, 4\)"):
        invert_transform(np.eye(3))
    with pytest.raises(ShapeError, match="axes from 'XYZ'"):
        matrix_from_euler([0.1, 0.2], "ZYX")
