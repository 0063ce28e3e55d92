"""Cameras: the pinhole model with OpenCV distortion, calibration and triangulation."""

from mocapkit.camera.calibration import (
    Board,
    IntrinsicCalibration,
    StereoCalibration,
    calibrate_intrinsics,
    calibrate_stereo,
    find_board_corners,
    locate_camera,
    parse_board,
    world_from_board_pose,
)
from mocapkit.camera.pinhole import Camera, distort_normalized, intrinsics_from_fov, look_at
from mocapkit.camera.triangulation import (
    closest_point_to_lines,
    reprojection_errors_px,
    triangulate_pair,
    triangulate_views,
)

__all__ = [
    "Board",
    "Camera",
    "IntrinsicCalibration",
    "StereoCalibration",
    "calibrate_intrinsics",
    "calibrate_stereo",
    "closest_point_to_lines",
    "distort_normalized",
    "find_board_corners",
    "intrinsics_from_fov",
    "locate_camera",
    "look_at",
    "parse_board",
    "reprojection_errors_px",
    "triangulate_pair",
    "triangulate_views",
    "world_from_board_pose",
]
