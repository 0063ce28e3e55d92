"""Drawing the body model's projected limb cones over an image, for inspection and synthetic tests.

Each segment with a length and radii is drawn as its silhouette under the camera:
the quadrilateral between its two contour generators
(`mocapkit.geometry.cones.cone_contour_generators_nb`, exact under
perspective) plus a disc of the projected radius at each end, so limbs look like
tapered capsules. Segments are painted far to near. Corners are projected with the
camera's distortion and joined by straight lines, which is exact for a distortion-free
camera and close otherwise.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.camera.projection import NEAR_PLANE_MM
from mocapkit.errors import ShapeError
from mocapkit.geometry.cones import cone_contour_generators_nb
from mocapkit.skeleton.kinematics import forward_kinematics
from mocapkit.skeleton.model import CANONICAL_SEGMENTS, Skeleton

FloatArray = NDArray[np.float64]
Colour = tuple[int, int, int]


def segment_silhouettes(
    skeleton: Skeleton,
    camera: Camera,
    q: ArrayLike,
    joints: Sequence[str] | None = None,
) -> list[tuple[str, FloatArray, FloatArray, float]]:
    """Projected silhouettes of body segments, sorted far to near.

    Parameters
    ----------
    skeleton, camera : Skeleton, Camera
    q : array_like, shape (D,)
    joints : sequence of str, optional
        Joints whose segments to include (default: every segment with length and radius).

    Returns
    -------
    list of (joint name, quad (4, 2) px, end discs (2, 3) as ``u, v, radius px``, depth mm)
        Segments with an end that is not visible (nearer than 1 mm to the camera plane,
        `mocapkit.camera.projection`) are left out.
    """
    qa = np.asarray(q, dtype=float)
    skeleton.check_q(qa)
    world = forward_kinematics(skeleton, qa)
    if joints is None:
        idx = [
            j
            for j in range(skeleton.n_joints)
            if skeleton.bone_length_mm[j] > 0 and skeleton.radii_mm[j].max() > 0
        ]
    else:
        idx = [skeleton.joint_index(n) for n in joints]
    fx = float(camera.K[0, 0])
    out = []
    lines = np.empty((2, 2, 3))
    for j in idx:
        a_w = world[j, :3, 3]
        b_w = world[j, :3, :3] @ skeleton.bone_end_mm[j] + a_w
        a, b = camera.to_camera(np.stack([a_w, b_w]))
        if a[2] < NEAR_PLANE_MM or b[2] < NEAR_PLANE_MM:
            continue
        ra, rb = (float(r) for r in skeleton.radii_mm[j])
        cone_contour_generators_nb(a, b, ra, rb, lines)
        corners = np.stack([lines[0, 0], lines[0, 1], lines[1, 1], lines[1, 0]])
        quad = camera.project_camera_points(corners)
        ends_px = camera.project_camera_points(np.stack([a, b]))
        discs = np.column_stack([ends_px, [fx * ra / a[2], fx * rb / b[2]]])
        out.append((skeleton.joint_names[j], quad, discs, float(0.5 * (a[2] + b[2]))))
    out.sort(key=lambda item: -item[3])
    return out


def draw_body(
    image: NDArray[np.uint8],
    skeleton: Skeleton,
    camera: Camera,
    q: ArrayLike,
    colours: Mapping[str, Colour] | None = None,
    default_colour: Colour = (150, 150, 150),
    joints: Sequence[str] | None = None,
) -> NDArray[np.uint8]:
    """Paint filled segment silhouettes into ``image`` (in place) and return it.

    Parameters
    ----------
    image : ndarray of uint8, shape (H, W, 3)
        BGR canvas of the camera's size.
    skeleton, camera : Skeleton, Camera
    q : array_like, shape (D,)
    colours : mapping joint name -> BGR, optional
        Colour per segment; others get ``default_colour``.
    joints : sequence of str, optional
        Segments to draw (default all).
    """
    w, h = camera.image_size
    if image.shape[:2] != (h, w) or image.dtype != np.uint8:
        raise ShapeError(
            f"image: expected uint8 of size {h}x{w} for camera {camera.name!r}, found "
            f"{image.shape} {image.dtype}"
        )
    colours = colours or {}
    shift = 4  # sub-pixel precision of OpenCV's drawing
    scale = 1 << shift
    for name, quad, discs, _depth in segment_silhouettes(skeleton, camera, q, joints):
        if not (np.all(np.isfinite(quad)) and np.all(np.isfinite(discs))):
            continue
        colour = tuple(int(c) for c in colours.get(name, default_colour))
        pts = np.round(quad * scale).astype(np.int32)
        cv2.fillConvexPoly(image, pts, colour, cv2.LINE_AA, shift)
        for u, v, r in discs:
            centre = (round(u * scale), round(v * scale))
            cv2.circle(image, centre, max(round(r * scale), 1), colour, -1, cv2.LINE_AA, shift)
    return image


def draw_sticks(
    image: NDArray[np.uint8],
    camera: Camera,
    joint_names: Sequence[str],
    joints_mm: ArrayLike,
    colour: Colour = (0, 165, 255),
    thickness: int = 2,
) -> NDArray[np.uint8]:
    """Draw canonical joints as dots joined by the `CANONICAL_SEGMENTS` sticks, in place.

    Parameters
    ----------
    image : ndarray of uint8, shape (H, W, 3)
        BGR canvas of the camera's size.
    camera : Camera
    joint_names : sequence of str, length K
        Canonical joint names of the rows of ``joints_mm``.
    joints_mm : array_like, shape (K, 3)
        Joint positions in the world frame (mm); joints with NaN, and sticks touching
        them, are left out, as are joints behind the camera.
    colour : BGR
    thickness : int
        Line width (px); dots have this radius plus one.
    """
    pts = np.asarray(joints_mm, dtype=float).reshape(-1, 3)
    if pts.shape[0] != len(joint_names):
        raise ShapeError(
            f"joints_mm: expected {len(joint_names)} joints (one per name), found {pts.shape[0]}"
        )
    in_camera = pts @ camera.camera_from_world[:3, :3].T + camera.camera_from_world[:3, 3]
    ok = np.all(np.isfinite(pts), axis=1) & (in_camera[:, 2] > 1.0)
    px = np.full((pts.shape[0], 2), np.nan)
    if np.any(ok):
        px[ok] = camera.project_camera_points(in_camera[ok])
    px[~ok] = np.nan
    return draw_sticks_px(image, joint_names, px, colour, thickness)


def draw_sticks_px(
    image: NDArray[np.uint8],
    joint_names: Sequence[str],
    pixels: ArrayLike,
    colour: Colour = (0, 165, 255),
    thickness: int = 2,
    left_colour: Colour | None = None,
) -> NDArray[np.uint8]:
    """Draw canonical image points (K, 2) (px; NaN where unseen) as dots joined by the
    `CANONICAL_SEGMENTS` sticks, in place; the left side's segments in ``left_colour``
    when given (so that a left/right swap shows)."""
    px = np.asarray(pixels, dtype=float).reshape(-1, 2)
    if px.shape[0] != len(joint_names):
        raise ShapeError(
            f"pixels: expected {len(joint_names)} points (one per name), found {px.shape[0]}"
        )
    ok = np.all(np.isfinite(px), axis=1)
    index = {n: k for k, n in enumerate(joint_names)}
    shift = 4  # sub-pixel precision of OpenCV's drawing
    scale = 1 << shift
    fixed = np.round(np.where(ok[:, None], px, 0.0) * scale).astype(np.int64)
    for name, (a, b) in CANONICAL_SEGMENTS.items():
        ia, ib = index.get(a), index.get(b)
        if ia is None or ib is None or not (ok[ia] and ok[ib]):
            continue
        pa = (int(fixed[ia, 0]), int(fixed[ia, 1]))
        pb = (int(fixed[ib, 0]), int(fixed[ib, 1]))
        c = left_colour if left_colour is not None and name.startswith("left_") else colour
        cv2.line(image, pa, pb, c, thickness, cv2.LINE_AA, shift)
    for k in np.flatnonzero(ok):
        centre = (int(fixed[k, 0]), int(fixed[k, 1]))
        cv2.circle(image, centre, (thickness + 1) * scale, colour, -1, cv2.LINE_AA, shift)
    return image


def draw_points(
    image: NDArray[np.uint8], points_px: ArrayLike, colour: Colour = (0, 255, 255), radius: int = 1
) -> NDArray[np.uint8]:
    """Draw image points (N, 2) (e.g. `ArmProblem.outline_px`) into ``image`` in place."""
    p = np.asarray(points_px, dtype=float).reshape(-1, 2)
    for u, v in p[np.all(np.isfinite(p), axis=1)]:
        cv2.circle(image, (round(u), round(v)), radius, colour, -1)
    return image


__all__ = ["draw_body", "draw_points", "draw_sticks", "draw_sticks_px", "segment_silhouettes"]
