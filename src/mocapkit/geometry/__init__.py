"""Rotations and rigid transforms: the math every other layer builds on."""

from mocapkit.geometry.rotations import (
    left_jacobian_so3,
    matrix_from_axis_angle,
    matrix_from_euler,
    matrix_from_rotvec,
    rotvec_from_matrix,
    skew,
)
from mocapkit.geometry.transforms import (
    invert_transform,
    make_transform,
    points_in_frame,
    transform_points,
)

__all__ = [
    "invert_transform",
    "left_jacobian_so3",
    "make_transform",
    "matrix_from_axis_angle",
    "matrix_from_euler",
    "matrix_from_rotvec",
    "points_in_frame",
    "rotvec_from_matrix",
    "skew",
    "transform_points",
]
