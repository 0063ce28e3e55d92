"""Cameras: the pinhole model with OpenCV distortion, calibration and triangulation."""

from mocapkit.camera.pinhole import Camera, distort_normalized, intrinsics_from_fov, look_at

__all__ = ["Camera", "distort_normalized", "intrinsics_from_fov", "look_at"]
