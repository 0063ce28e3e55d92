"""Chessboard camera calibration: corners, intrinsics, board-defined world pose, stereo pairs.

Follows Zhang's plane-based method (Zhang 1999, as used by the hybrid paper,
Zhang et al. 2011 §3, Fig. 2) through OpenCV: `cv2.findChessboardCorners` +
`cv2.cornerSubPix`, `cv2.calibrateCamera`, `cv2.solvePnP` for a board fixed at a
known world pose, and `cv2.stereoCalibrate` for a rigid pair. Lengths are mm.

Board frame: origin at the first inner corner OpenCV reports, x along a row of
corners (``columns`` of them), y across rows, z = x × y; corners lie at z = 0.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.errors import CalibrationError, ShapeError
from mocapkit.geometry.transforms import make_transform

FloatArray = NDArray[np.float64]

# Sub-pixel refinement: 11x11 search window (OpenCV tutorial default, fits 640x480 boards
# with ~25 px squares), stop at 30 iterations or 0.001 px movement.
_SUBPIX_WINDOW = (11, 11)
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3)
_MIN_VIEWS = 3  # OpenCV needs at least 3 views of a plane for full intrinsics.


@dataclass(frozen=True)
class Board:
    """A chessboard target.

    Parameters
    ----------
    columns, rows : int
        Inner corners per row and per column (``9x6`` -> columns 9, rows 6).
    square_mm : float
        Side of one square in mm.
    """

    columns: int
    rows: int
    square_mm: float

    def __post_init__(self) -> None:
        if self.columns < 2 or self.rows < 2:
            raise CalibrationError(
                f"board: expected at least 2x2 inner corners, found {self.columns}x{self.rows}"
            )
        if not (np.isfinite(self.square_mm) and self.square_mm > 0):
            raise CalibrationError(
                f"board square size: expected a positive number of mm, found {self.square_mm}"
            )

    @property
    def pattern_size(self) -> tuple[int, int]:
        """OpenCV's ``(columns, rows)`` pattern size."""
        return (self.columns, self.rows)

    @property
    def n_corners(self) -> int:
        """Number of inner corners."""
        return self.columns * self.rows

    def points_in_board(self) -> FloatArray:
        """Inner-corner positions (n_corners, 3) in the board frame, mm, OpenCV's order."""
        ix, iy = np.meshgrid(np.arange(self.columns), np.arange(self.rows))
        pts = np.zeros((self.n_corners, 3))
        pts[:, 0] = ix.ravel() * self.square_mm
        pts[:, 1] = iy.ravel() * self.square_mm
        return pts


def parse_board(spec: str, square_mm: float) -> Board:
    """Parse ``"COLSxROWS"`` (inner corners, e.g. ``"9x6"``) into a `Board`."""
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", spec)
    if m is None:
        raise CalibrationError(
            f"--board: expected inner corners as COLUMNSxROWS such as '9x6', found {spec!r}"
        )
    return Board(int(m.group(1)), int(m.group(2)), float(square_mm))


def find_board_corners(image: ArrayLike, board: Board) -> FloatArray | None:
    """Detect and sub-pixel refine the inner corners of ``board`` in one image.

    Parameters
    ----------
    image : ndarray, shape (h, w) or (h, w, 3)
        8-bit grey or BGR image.
    board : Board

    Returns
    -------
    ndarray, shape (n_corners, 2), or None
        Corner pixels in OpenCV's order, or None when the full board is not found.
    """
    img = np.asarray(image, dtype=np.uint8)
    grey = img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(grey, board.pattern_size, flags=flags)
    if not found or corners is None:
        return None
    refined = cv2.cornerSubPix(grey, corners, _SUBPIX_WINDOW, (-1, -1), _SUBPIX_CRITERIA)
    return np.asarray(refined, dtype=float).reshape(board.n_corners, 2)


@dataclass(frozen=True)
class IntrinsicCalibration:
    """Result of `calibrate_intrinsics`.

    Attributes
    ----------
    camera : Camera
        Calibrated camera whose frame is the world (identity extrinsics).
    rms_px : float
        Overall RMS reprojection error (px).
    per_view_rms_px : ndarray, shape (n_views,)
        RMS reprojection error of each board view (px).
    camera_from_board : ndarray, shape (n_views, 4, 4)
        Pose of the board in each view (mm).
    """

    camera: Camera
    rms_px: float
    per_view_rms_px: FloatArray
    camera_from_board: FloatArray


def _as_views(
    corners_px: Sequence[ArrayLike], board: Board, what: str
) -> list[NDArray[np.float32]]:
    views = []
    for i, c in enumerate(corners_px):
        arr = np.asarray(c, dtype=np.float32)
        if arr.shape != (board.n_corners, 2):
            raise ShapeError(
                f"{what} view {i}: expected corners ({board.n_corners}, 2), found {arr.shape}"
            )
        if not np.all(np.isfinite(arr)):
            raise ShapeError(f"{what} view {i}: corners contain NaN or inf")
        views.append(arr.reshape(-1, 1, 2))
    return views


def _rt_to_transform(rvec: ArrayLike, tvec: ArrayLike) -> FloatArray:
    rot, _ = cv2.Rodrigues(np.asarray(rvec, dtype=float).reshape(3, 1))
    return make_transform(rot, np.asarray(tvec, dtype=float).reshape(3))


def calibrate_intrinsics(
    corners_px: Sequence[ArrayLike],
    board: Board,
    image_size: tuple[int, int],
    name: str = "cam0",
    fix_aspect_ratio: bool = False,
) -> IntrinsicCalibration:
    """Intrinsics and 5-coefficient distortion from several board views (`cv2.calibrateCamera`).

    Parameters
    ----------
    corners_px : sequence of array_like, each shape (n_corners, 2)
        Detected corners of each view (px).
    board : Board
    image_size : (int, int)
        Width and height (px).
    name : str
        Name given to the returned camera.
    fix_aspect_ratio : bool
        Force ``fx == fy`` (OpenCV's ``CALIB_FIX_ASPECT_RATIO``).
    """
    views = _as_views(corners_px, board, f"camera {name!r}")
    if len(views) < _MIN_VIEWS:
        raise CalibrationError(
            f"camera {name!r}: intrinsic calibration needs at least {_MIN_VIEWS} board views, "
            f"found {len(views)}"
        )
    obj = [board.points_in_board().astype(np.float32)] * len(views)
    flags = cv2.CALIB_FIX_ASPECT_RATIO if fix_aspect_ratio else 0
    rms, k, dist, rvecs, tvecs, _, _, per_view = cv2.calibrateCameraExtended(
        obj, views, (int(image_size[0]), int(image_size[1])), np.eye(3), np.zeros(5), flags=flags
    )
    if not np.isfinite(rms):
        raise CalibrationError(f"camera {name!r}: calibration diverged (RMS {rms})")
    camera = Camera(name, image_size, np.asarray(k, dtype=float), np.ravel(dist), np.eye(4))
    poses = np.stack([_rt_to_transform(r, t) for r, t in zip(rvecs, tvecs)])
    return IntrinsicCalibration(camera, float(rms), np.ravel(per_view).astype(float), poses)


def world_from_board_pose(
    origin_mm: ArrayLike, x_axis: ArrayLike, y_axis: ArrayLike, tol_deg: float = 2.0
) -> FloatArray:
    """The board's pose in the world (4, 4) from its origin and in-plane axes.

    The hybrid paper's set-up (Zhang et al. 2011 §3): a board fixed with its edges
    along world axes, origin measured in world mm.

    Parameters
    ----------
    origin_mm : array_like, shape (3,)
        World position of the board's first inner corner (mm).
    x_axis, y_axis : array_like, shape (3,)
        World directions of the board's x (along a row of corners) and y axes;
        need not be unit length; must be perpendicular within ``tol_deg``.
    """
    o = np.asarray(origin_mm, dtype=float)
    x = np.asarray(x_axis, dtype=float)
    y = np.asarray(y_axis, dtype=float)
    for what, v in (("origin_mm", o), ("x_axis", x), ("y_axis", y)):
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise CalibrationError(
                f"board pose {what}: expected 3 finite numbers, found {v.tolist()}"
            )
    nx, ny = np.linalg.norm(x), np.linalg.norm(y)
    if nx == 0 or ny == 0:
        raise CalibrationError("board pose: x_axis and y_axis must be non-zero")
    x, y = x / nx, y / ny
    angle = np.degrees(np.arccos(np.clip(x @ y, -1.0, 1.0)))
    if abs(angle - 90.0) > tol_deg:
        raise CalibrationError(
            f"board pose: x_axis and y_axis must be perpendicular, found {angle:.1f} degrees apart"
        )
    # Gram-Schmidt keeps x exact and removes the small measured skew from y.
    y = y - (x @ y) * x
    y /= np.linalg.norm(y)
    rot = np.stack([x, y, np.cross(x, y)], axis=1)  # columns: board axes in world
    return make_transform(rot, o)


def camera_from_board_pnp(camera: Camera, corners_px: ArrayLike, board: Board) -> FloatArray:
    """Board pose in camera coordinates (4, 4), mm, from one view (`cv2.solvePnP`)."""
    views = _as_views([corners_px], board, f"camera {camera.name!r}")
    ok, rvec, tvec = cv2.solvePnP(
        board.points_in_board(),
        views[0].astype(float),
        np.asarray(camera.K),
        np.asarray(camera.dist),
        flags=cv2.SOLVEPNP_ITERATIVE,
    )
    if not ok:
        raise CalibrationError(f"camera {camera.name!r}: solvePnP failed on the board view")
    return _rt_to_transform(rvec, tvec)


def locate_camera(
    camera: Camera, corners_px: ArrayLike, board: Board, world_from_board: ArrayLike
) -> Camera:
    """Return ``camera`` with ``camera_from_world`` set from one view of a board at a known pose.

    Parameters
    ----------
    camera : Camera
        Calibrated intrinsics (its extrinsics are replaced).
    corners_px : array_like, shape (n_corners, 2)
        The board's corners in this camera's image (px).
    board : Board
    world_from_board : array_like, shape (4, 4)
        Board pose in the world (mm), e.g. from `world_from_board_pose`.
    """
    w_from_b = np.asarray(world_from_board, dtype=float)
    if w_from_b.shape != (4, 4):
        raise ShapeError(f"world_from_board: expected (4, 4), found {w_from_b.shape}")
    c_from_b = camera_from_board_pnp(camera, corners_px, board)
    c_from_w = c_from_b @ np.linalg.inv(w_from_b)
    return Camera(camera.name, camera.image_size, camera.K, camera.dist, c_from_w)


@dataclass(frozen=True)
class StereoCalibration:
    """Result of `calibrate_stereo`.

    Attributes
    ----------
    cameras : (Camera, Camera)
        The pair; the first camera's frame is the world (identity extrinsics).
    rms_px : float
        Overall stereo RMS reprojection error (px), both cameras.
    per_view_rms_px : ndarray, shape (n_views, 2)
        RMS error per board view and camera (px).
    second_from_first : ndarray, shape (4, 4)
        Rigid transform from the first camera's frame to the second's (mm).
    """

    cameras: tuple[Camera, Camera]
    rms_px: float
    per_view_rms_px: FloatArray
    second_from_first: FloatArray

    @property
    def baseline_mm(self) -> float:
        """Distance between the two optical centres (mm)."""
        return float(np.linalg.norm(self.second_from_first[:3, 3]))


def calibrate_stereo(
    corners_first_px: Sequence[ArrayLike],
    corners_second_px: Sequence[ArrayLike],
    board: Board,
    first: Camera,
    second: Camera,
    refine_intrinsics: bool = False,
) -> StereoCalibration:
    """Relative pose of a rigid camera pair from simultaneous board views (`cv2.stereoCalibrate`).

    Parameters
    ----------
    corners_first_px, corners_second_px : sequence of array_like, each (n_corners, 2)
        Corners of the same board views in the first and second camera (px).
    board : Board
    first, second : Camera
        Per-camera calibrations (intrinsics used as given, or as a start when refined).
    refine_intrinsics : bool
        Refine K and distortion jointly (``CALIB_USE_INTRINSIC_GUESS``) instead of
        keeping them fixed (``CALIB_FIX_INTRINSIC``).
    """
    va = _as_views(corners_first_px, board, f"camera {first.name!r}")
    vb = _as_views(corners_second_px, board, f"camera {second.name!r}")
    if len(va) != len(vb):
        raise CalibrationError(
            f"stereo calibration: expected the same number of views in both cameras, "
            f"found {len(va)} and {len(vb)}"
        )
    if len(va) < 1:
        raise CalibrationError("stereo calibration: no board view seen by both cameras")
    obj = [board.points_in_board().astype(np.float32)] * len(va)
    flags = cv2.CALIB_USE_INTRINSIC_GUESS if refine_intrinsics else cv2.CALIB_FIX_INTRINSIC
    out = cv2.stereoCalibrateExtended(
        obj,
        va,
        vb,
        np.array(first.K),
        np.array(first.dist),
        np.array(second.K),
        np.array(second.dist),
        # OpenCV takes one image size; it only seeds intrinsics, which are passed in.
        first.image_size,
        np.eye(3),
        np.zeros((3, 1)),
        flags=flags,
    )
    rms, k1, d1, k2, d2, rot, t = out[:7]
    per_view = out[11]
    if not np.isfinite(rms):
        raise CalibrationError(f"stereo calibration diverged (RMS {rms})")
    second_from_first = make_transform(rot, np.ravel(t))
    cam_a = Camera(first.name, first.image_size, np.asarray(k1, float), np.ravel(d1), np.eye(4))
    cam_b = Camera(
        second.name, second.image_size, np.asarray(k2, float), np.ravel(d2), second_from_first
    )
    return StereoCalibration(
        (cam_a, cam_b),
        float(rms),
        np.asarray(per_view, dtype=float).reshape(-1, 2),
        second_from_first,
    )


def reprojection_rms_px(
    camera: Camera, camera_from_board: ArrayLike, corners_px: ArrayLike, board: Board
) -> float:
    """RMS distance (px) between corners (n_corners, 2) and the board at a pose."""
    c_from_b = np.asarray(camera_from_board, dtype=float)
    pts_cam = board.points_in_board() @ c_from_b[:3, :3].T + c_from_b[:3, 3]
    proj = camera.project_camera_points(pts_cam)
    diff = proj - np.asarray(corners_px, dtype=float)
    return float(np.sqrt(np.mean(np.sum(diff**2, axis=-1))))
