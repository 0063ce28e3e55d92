"""The pinhole camera with OpenCV's lens-distortion model, and batched projection.

``x_px ~ K @ distort([R | t] @ X_world)`` with ``camera_from_world = [[R, t], [0, 1]]``
in mm (Zhang et al. 2011 eq. 11, corrected per errata Z10: OpenCV's extrinsics are
already world -> camera, so no inverse is taken). Distortion coefficients follow
OpenCV's order ``k1, k2, p1, p2[, k3[, k4, k5, k6]]``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.camera.projection import CameraArrays, camera_arrays, project
from mocapkit.errors import ShapeError
from mocapkit.geometry.transforms import invert_transform, transform_points

FloatArray = NDArray[np.float64]


def _frozen(a: Any, shape: tuple[int, ...] | None, what: str, name: str) -> FloatArray:
    arr = np.array(a, dtype=float, copy=True)
    if shape is not None and arr.shape != shape:
        raise ShapeError(f"camera {name!r} {what}: expected shape {shape}, found {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ShapeError(f"camera {name!r} {what}: contains NaN or inf")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Camera:
    """A calibrated camera (immutable).

    Parameters
    ----------
    name : str
    image_size : (int, int)
        Width and height in pixels.
    K : array_like, shape (3, 3)
        Intrinsic matrix (px).
    dist : array_like, shape (n,), n in {0, 4, 5, 8}
        OpenCV distortion coefficients.
    camera_from_world : array_like, shape (4, 4)
        Rigid transform from world to camera coordinates (mm).
    """

    name: str
    image_size: tuple[int, int]
    K: FloatArray
    dist: FloatArray
    camera_from_world: FloatArray

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        w, h = (int(v) for v in self.image_size)
        if w <= 0 or h <= 0:
            raise ShapeError(
                f"camera {self.name!r} image_size: expected positive [w, h], "
                f"found {self.image_size}"
            )
        set_(self, "image_size", (w, h))
        set_(self, "K", _frozen(self.K, (3, 3), "K", self.name))
        dist = _frozen(np.ravel(self.dist), None, "dist", self.name)
        if dist.shape[0] not in (0, 4, 5, 8, 12, 14):
            raise ShapeError(
                f"camera {self.name!r} dist: expected 0, 4, 5, 8, 12 or 14 OpenCV coefficients, "
                f"found {dist.shape[0]}"
            )
        set_(self, "dist", dist)
        m = _frozen(self.camera_from_world, (4, 4), "camera_from_world", self.name)
        r = m[:3, :3]
        if not np.allclose(r @ r.T, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
            raise ShapeError(
                f"camera {self.name!r} camera_from_world: rotation part is not a proper rotation"
            )
        set_(self, "camera_from_world", m)

    @property
    def world_from_camera(self) -> FloatArray:
        """Camera pose in the world (4, 4)."""
        return invert_transform(self.camera_from_world)

    @property
    def center_in_world(self) -> FloatArray:
        """Optical centre in world coordinates (3,), mm."""
        return self.world_from_camera[:3, 3]

    def to_camera(self, points_in_world: ArrayLike) -> FloatArray:
        """World points (..., 3) to camera coordinates (..., 3), mm."""
        p = np.asarray(points_in_world, dtype=float)
        if p.shape[-1:] != (3,):
            raise ShapeError(f"camera {self.name!r}: expected points (..., 3), found {p.shape}")
        flat = p.reshape(-1, 3)
        return transform_points(self.camera_from_world, flat).reshape(p.shape)

    @cached_property
    def arrays(self) -> CameraArrays:
        """This camera in the layout of the compiled kernels (`mocapkit.camera.projection`).

        Raises `ShapeError` (on first use) for non-zero thin-prism/tilt coefficients.
        """
        return camera_arrays(self.K, self.dist, self.camera_from_world)

    def project(self, points_in_world: ArrayLike) -> FloatArray:
        """Project world points (..., 3) to pixels (..., 2), with distortion.

        Points closer to the camera plane than `NEAR_PLANE_MM` (1 mm), behind the camera
        included, are not visible and project to NaN (`mocapkit.camera.projection`).
        """
        p = np.asarray(points_in_world, dtype=float)
        if p.shape[-1:] != (3,):
            raise ShapeError(f"camera {self.name!r}: expected points (..., 3), found {p.shape}")
        return project(self.arrays, p, in_world=True)

    def project_camera_points(self, points_in_camera: ArrayLike) -> FloatArray:
        """Project camera-frame points (..., 3) to pixels (..., 2); NaN where z < 1 mm."""
        p = np.asarray(points_in_camera, dtype=float)
        if p.shape[-1:] != (3,):
            raise ShapeError(f"camera {self.name!r}: expected points (..., 3), found {p.shape}")
        return project(self.arrays, p, in_world=False)

    def undistort_pixels(self, pixels: ArrayLike) -> FloatArray:
        """Pixels (..., 2) to undistorted normalised image coordinates (..., 2)."""
        import cv2

        px = np.asarray(pixels, dtype=float)
        flat = px.reshape(-1, 1, 2)
        out = cv2.undistortPoints(flat, np.asarray(self.K), np.asarray(self.dist))
        return np.asarray(out, dtype=float).reshape(px.shape)

    def in_image(self, pixels: ArrayLike, margin_px: float = 0.0) -> NDArray[np.bool_]:
        """Whether pixels (..., 2) lie inside the image (minus a margin)."""
        px = np.asarray(pixels, dtype=float)
        w, h = self.image_size
        with np.errstate(invalid="ignore"):
            return (
                (px[..., 0] >= margin_px)
                & (px[..., 0] <= w - 1 - margin_px)
                & (px[..., 1] >= margin_px)
                & (px[..., 1] <= h - 1 - margin_px)
            )

    def projection_matrix(self) -> FloatArray:
        """``P = K [R | t]`` (3, 4), ignoring distortion."""
        return np.asarray(self.K) @ np.asarray(self.camera_from_world)[:3, :]


def distort_normalized(
    x: ArrayLike, y: ArrayLike, dist: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Apply OpenCV's radial/tangential (and rational) distortion to normalised coordinates.

    The projection kernel (`mocapkit.camera.projection`) with ``K = I`` at depth 1.

    Parameters
    ----------
    x, y : array_like, shape (...)
        Undistorted normalised coordinates ``X/Z``, ``Y/Z``.
    dist : array_like, shape (n,)
        ``k1, k2, p1, p2[, k3[, k4, k5, k6]]``; thin-prism and tilt terms (n = 12, 14)
        are not supported here and raise `ShapeError` when non-zero.
    """
    xa, ya = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    unit = camera_arrays(np.eye(3), dist, np.eye(4))
    px = project(unit, np.stack([xa, ya, np.ones_like(xa)], axis=-1), in_world=False)
    return px[..., 0], px[..., 1]


def look_at(eye_mm: ArrayLike, target_mm: ArrayLike, up: ArrayLike = (0.0, 0.0, 1.0)) -> FloatArray:
    """``camera_from_world`` (4, 4) of a camera at ``eye_mm`` looking at ``target_mm``.

    OpenCV camera axes: x right, y down, z forward. ``up`` is the world direction
    that appears upwards in the image.
    """
    eye = np.asarray(eye_mm, dtype=float)
    fwd = np.asarray(target_mm, dtype=float) - eye
    n = np.linalg.norm(fwd)
    if n == 0:
        raise ShapeError("look_at: eye and target coincide")
    z = fwd / n
    x = np.cross(z, np.asarray(up, dtype=float))
    if np.linalg.norm(x) < 1e-9:
        raise ShapeError("look_at: viewing direction is parallel to 'up'")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    r = np.stack([x, y, z])  # rows: camera axes in world coordinates
    out = np.eye(4)
    out[:3, :3] = r
    out[:3, 3] = -r @ eye
    return out


def intrinsics_from_fov(image_size: tuple[int, int], horizontal_fov_deg: float) -> FloatArray:
    """A distortion-free K (3, 3) with square pixels and a centred principal point."""
    w, h = image_size
    f = 0.5 * w / np.tan(np.radians(horizontal_fov_deg) / 2)
    return np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1.0]])
