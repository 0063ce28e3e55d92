"""Calibration from chessboard image sets: one set -> one camera, two sets -> a stereo pair.

The world frame is the first camera's frame, unless a board pose is given: then a
board fixed at a measured world pose (edges along world axes, origin in world mm,
the hybrid paper's set-up, Zhang et al. 2011 §3 and Fig. 2) defines it.

Board-pose file (JSON)::

    {"origin_mm": [x, y, z],      # world position of the board's first inner corner
     "x_axis": [1, 0, 0],         # world direction of the board's rows of corners
     "y_axis": [0, 1, 0],         # world direction across rows
     "image": "left01.jpg"}       # optional: the image (of the first set) showing the
                                  # board at that pose; default: the first usable one

"First inner corner" is the corner OpenCV reports first; the report prints its
pixel position so that it can be checked against the measured origin.
"""

from __future__ import annotations

import glob
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from mocapkit.camera.calibration import (
    Board,
    calibrate_intrinsics,
    calibrate_stereo,
    find_board_corners,
    locate_camera,
    world_from_board_pose,
)
from mocapkit.camera.pinhole import Camera
from mocapkit.errors import CalibrationError, FormatError
from mocapkit.pipelines.calibrate_config import DEFAULT_MAX_RMS_PX, DEFAULT_MIN_BOARDS

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff")
#: Smallest plausible board square (mm). Smaller values are nearly always metres typed
#: where millimetres are expected (0.025 for 25 mm).
MIN_SQUARE_MM = 2.0
#: Smallest plausible stereo baseline (mm); below it the two sets are the same view.
MIN_BASELINE_MM = 1.0
#: Found images checked for a larger board than the one given (each check is a detection).
_BOARD_SIZE_CHECKS = 3

PathLike = str | os.PathLike[str]


@dataclass(frozen=True)
class BoardPose:
    """World pose of a fixed board (mm); see the module docstring for the file format."""

    origin_mm: tuple[float, float, float]
    x_axis: tuple[float, float, float]
    y_axis: tuple[float, float, float]
    image: str | None = None

    def world_from_board(self) -> NDArray[np.float64]:
        """The board's pose in the world (4, 4), mm."""
        return world_from_board_pose(self.origin_mm, self.x_axis, self.y_axis)


def read_board_pose(path: PathLike) -> BoardPose:
    """Read a board-pose JSON file (keys origin_mm, x_axis, y_axis, optional image)."""
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise FormatError(f"{p}: board-pose file not found") from exc
    except json.JSONDecodeError as exc:
        raise FormatError(
            f"{p}: not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})"
        ) from exc
    if not isinstance(doc, dict):
        raise FormatError(f"{p}: expected a JSON object, found {type(doc).__name__}")
    allowed = {"origin_mm", "x_axis", "y_axis", "image"}
    missing = sorted({"origin_mm", "x_axis", "y_axis"} - set(doc))
    if missing:
        raise FormatError(
            f"{p}: missing key(s) {', '.join(missing)}; expected origin_mm, x_axis, y_axis"
        )
    extra = sorted(set(doc) - allowed)
    if extra:
        raise FormatError(
            f"{p}: unknown key(s) {', '.join(extra)}; expected {', '.join(sorted(allowed))}"
        )
    vecs = []
    for key in ("origin_mm", "x_axis", "y_axis"):
        v = doc[key]
        if (
            not isinstance(v, list)
            or len(v) != 3
            or not all(isinstance(x, int | float) and not isinstance(x, bool) for x in v)
            or not all(np.isfinite(v))
        ):
            raise FormatError(f"{p}: {key}: expected 3 finite numbers, found {v!r}")
        vecs.append((float(v[0]), float(v[1]), float(v[2])))
    image = doc.get("image")
    if image is not None and not isinstance(image, str):
        raise FormatError(f"{p}: image: expected a file name, found {image!r}")
    pose = BoardPose(vecs[0], vecs[1], vecs[2], image)
    try:
        pose.world_from_board()
    except CalibrationError as exc:
        raise FormatError(f"{p}: {exc}") from exc
    return pose


def resolve_images(spec: PathLike) -> list[Path]:
    """Image files of one set: a folder (its image files) or a glob pattern, sorted by name."""
    s = str(spec)
    p = Path(s)
    if p.is_dir():
        files = [f for f in p.iterdir() if f.is_file() and f.suffix.lower() in IMAGE_SUFFIXES]
    else:
        files = [Path(f) for f in glob.glob(s) if Path(f).is_file()]
    if not files:
        what = "folder" if p.is_dir() else "pattern"
        raise CalibrationError(
            f"image set {s!r}: {what} matches no image files (expected {', '.join(IMAGE_SUFFIXES)})"
        )
    return sorted(files, key=lambda f: f.name)


@dataclass(frozen=True)
class ImageResult:
    """Board detection and fit for one image.

    Attributes
    ----------
    path : Path
    found : bool
        Whether the full board was detected.
    error_px : float or None
        RMS reprojection error of this view after intrinsic calibration (px).
    stereo_error_px : float or None
        RMS error of this view in the stereo fit (px), when its pair was used.
    first_corner_px : tuple of float or None
        Pixel of the board's first inner corner (its origin).
    note : str
        Why it was not found or not used.
    """

    path: Path
    found: bool
    error_px: float | None = None
    stereo_error_px: float | None = None
    first_corner_px: tuple[float, float] | None = None
    note: str = ""


@dataclass(frozen=True)
class CameraReport:
    """Per-camera part of a calibration report."""

    camera: Camera
    source: str
    images: list[ImageResult]
    rms_px: float

    @property
    def n_found(self) -> int:
        """Images where the board was found."""
        return sum(r.found for r in self.images)


@dataclass(frozen=True)
class CalibrationReport:
    """What `calibrate_from_images` did and what it found.

    Attributes
    ----------
    cameras : list of Camera
        Final cameras (world frame as described by ``world_frame``).
    per_camera : list of CameraReport
    world_frame : str
        How the world frame was defined.
    stereo_rms_px, baseline_mm : float or None
        Stereo RMS reprojection error (px) and distance between optical centres (mm).
    n_pairs_used : int
    """

    cameras: list[Camera]
    per_camera: list[CameraReport]
    world_frame: str
    stereo_rms_px: float | None = None
    baseline_mm: float | None = None
    n_pairs_used: int = 0
    notes: list[str] = field(default_factory=list)

    def lines(self) -> list[str]:
        """Human-readable report, one line per string."""
        out: list[str] = []
        for rep in self.per_camera:
            out.append(
                f"camera {rep.camera.name!r} ({rep.source}): board found in "
                f"{rep.n_found} of {len(rep.images)} images"
            )
            for r in rep.images:
                if not r.found:
                    out.append(
                        f"  {r.path.name:<28} not found{(' (' + r.note + ')') if r.note else ''}"
                    )
                    continue
                parts = [f"  {r.path.name:<28} found"]
                if r.error_px is not None:
                    parts.append(f"reprojection {r.error_px:.3f} px")
                if r.stereo_error_px is not None:
                    parts.append(f"stereo {r.stereo_error_px:.3f} px")
                if r.note:
                    parts.append(f"({r.note})")
                out.append("  ".join(parts))
            k = rep.camera.K
            out.append(
                f"  intrinsic RMS {rep.rms_px:.3f} px; fx {k[0, 0]:.2f} fy {k[1, 1]:.2f} "
                f"cx {k[0, 2]:.2f} cy {k[1, 2]:.2f} px"
            )
        if self.stereo_rms_px is not None:
            out.append(
                f"stereo: {self.n_pairs_used} pairs, RMS {self.stereo_rms_px:.3f} px, "
                f"baseline {self.baseline_mm:.1f} mm"
            )
        out.append(f"world frame: {self.world_frame}")
        out.extend(self.notes)
        return out


def _detect(
    files: Sequence[Path], board: Board, source: str
) -> tuple[list[NDArray[np.float64] | None], tuple[int, int], list[str]]:
    corners: list[NDArray[np.float64] | None] = []
    notes: list[str] = []
    size: tuple[int, int] | None = None
    size_from = ""
    for f in files:
        img = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        if img is None:
            corners.append(None)
            notes.append("unreadable image")
            continue
        this = (int(img.shape[1]), int(img.shape[0]))
        if size is None:
            size, size_from = this, f.name
        elif this != size:
            raise CalibrationError(
                f"image set {source!r}: {f.name} is {this[0]}x{this[1]} px, expected "
                f"{size[0]}x{size[1]} like {size_from}; one camera's images must share a size"
            )
        c = find_board_corners(img, board)
        corners.append(c)
        notes.append("" if c is not None else f"no {board.columns}x{board.rows} board")
    if size is None:
        raise CalibrationError(
            f"image set {source!r}: none of its {len(files)} images could be read"
        )
    return corners, size, notes


def _too_few(
    source: str,
    name: str,
    found: int,
    need: int,
    failed: Sequence[Path],
    board: Board,
    what: str = "images",
) -> CalibrationError:
    names = ", ".join(f.name for f in failed[:20]) + (" ..." if len(failed) > 20 else "")
    return CalibrationError(
        f"camera {name!r} ({source}): board {board.columns}x{board.rows} found in {found} {what}, "
        f"need at least {need}; not found in: {names or 'none'}"
    )


def _check_square(board: Board) -> None:
    if board.square_mm < MIN_SQUARE_MM:
        raise CalibrationError(
            f"--square-mm: expected the square side in millimetres (at least {MIN_SQUARE_MM:g}), "
            f"found {board.square_mm:g}; a board square is typically 10-100 mm. Was it given in "
            f"metres ({board.square_mm:g} m = {board.square_mm * 1000:g} mm)?"
        )


def _check_same_images(files: Sequence[Sequence[Path]], sources: Sequence[str]) -> None:
    """Refuse a stereo pair whose two image sets hold the same pictures."""
    if len(files) != 2 or not files[0]:
        return
    same = sum(
        a.resolve() == b.resolve() or a.read_bytes() == b.read_bytes()
        for a, b in zip(files[0], files[1])
    )
    if same == len(files[0]):
        raise CalibrationError(
            f"stereo image sets {sources[0]!r} and {sources[1]!r}: expected two cameras' "
            f"views, found the same {same} images in both"
        )


def _check_board_size(
    files: Sequence[Path], corners: Sequence[NDArray[np.float64] | None], board: Board, source: str
) -> None:
    """Refuse a board size smaller than the board in the images (OpenCV finds a sub-board).

    A 9x6 board detected as 8x6 calibrates with a low RMS, but its corners may be the left
    or the right eight columns, so the board frame jumps by a square between views. The
    first few images with a detected board are searched for one more column or row.
    """
    checked = 0
    for f, c in zip(files, corners):
        if c is None:
            continue
        grey = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        if grey is None:  # read once already by `_detect`; gone since
            continue
        for cols, rows in ((board.columns + 1, board.rows), (board.columns, board.rows + 1)):
            bigger = Board(cols, rows, board.square_mm)
            if find_board_corners(grey, bigger) is not None:
                raise CalibrationError(
                    f"--board: {board.columns}x{board.rows} inner corners given, but {f.name} "
                    f"({source}) shows a board of at least {cols}x{rows}; give the board's full "
                    f"inner-corner count (OpenCV would otherwise pick a different part of the "
                    f"board in different views)"
                )
        checked += 1
        if checked >= _BOARD_SIZE_CHECKS:
            return


def _check_rms(what: str, rms_px: float, max_rms_px: float, worst: str = "") -> None:
    if rms_px > max_rms_px:
        raise CalibrationError(
            f"{what}: RMS reprojection error {rms_px:.2f} px, expected at most "
            f"{max_rms_px:g} px (--max-rms-px){worst}. Typical causes: image pairs that do not "
            f"match up by sorted name (a missing or extra image shifts every pair), a wrong "
            f"--board, a board that moved or bent; nothing was written"
        )


def _worst_views(files: Sequence[Path], errors: dict[int, float], n: int = 3) -> str:
    if not errors:
        return ""
    worst = sorted(errors.items(), key=lambda kv: -kv[1])[:n]
    return "; worst: " + ", ".join(f"{files[i].name} {e:.1f} px" for i, e in worst)


def calibrate_from_images(
    image_sets: Sequence[PathLike],
    board: Board,
    names: Sequence[str] | None = None,
    board_pose: BoardPose | PathLike | None = None,
    min_boards: int = DEFAULT_MIN_BOARDS,
    refine_stereo_intrinsics: bool = False,
    max_rms_px: float = DEFAULT_MAX_RMS_PX,
) -> CalibrationReport:
    """Calibrate one camera (one image set) or a stereo pair (two sets matched by sorted name).

    Parameters
    ----------
    image_sets : sequence of path-like, length 1 or 2
        Each a folder of images or a glob pattern.
    board : Board
    names : sequence of str, optional
        Camera names; default ``["cam0"]`` for one camera, ``["left", "right"]`` for a pair.
    board_pose : BoardPose or path-like, optional
        World pose of a board seen in one image (or pair); defines the world frame.
        Without it the (first) camera's frame is the world.
    min_boards : int
        Fewest images (pairs for stereo) with a detected board.
    refine_stereo_intrinsics : bool
        Let `cv2.stereoCalibrate` refine intrinsics instead of fixing them.
    max_rms_px : float
        Largest accepted RMS reprojection error (px) of each camera and of the stereo fit.

    Raises
    ------
    CalibrationError
        Too few boards (says how many were found, needed, and which images failed),
        mismatched pair counts or image sizes, empty image sets; and the slips that show
        only in the numbers: an RMS above ``max_rms_px`` (mis-paired stereo images), a
        square size below `MIN_SQUARE_MM` (metres given), the same images for both
        cameras or a baseline below `MIN_BASELINE_MM`, a board smaller than the one in
        the images.
    """
    if len(image_sets) not in (1, 2):
        raise CalibrationError(
            f"expected 1 image set (one camera) or 2 (stereo pair), found {len(image_sets)}"
        )
    if min_boards < 3:
        raise CalibrationError(
            f"min_boards: expected at least 3 (OpenCV's minimum), found {min_boards}"
        )
    if not (np.isfinite(max_rms_px) and max_rms_px > 0):
        raise CalibrationError(f"max_rms_px: expected a positive number, found {max_rms_px}")
    _check_square(board)
    n_cams = len(image_sets)
    cam_names = (
        list(names) if names is not None else (["cam0"] if n_cams == 1 else ["left", "right"])
    )
    if len(cam_names) != n_cams or len(set(cam_names)) != n_cams:
        raise CalibrationError(f"names: expected {n_cams} distinct camera names, found {cam_names}")
    pose = read_board_pose(board_pose) if isinstance(board_pose, str | os.PathLike) else board_pose

    sources = [str(s) for s in image_sets]
    files = [resolve_images(s) for s in image_sets]
    if n_cams == 2 and len(files[0]) != len(files[1]):
        raise CalibrationError(
            f"stereo image sets must pair up by sorted name: {sources[0]!r} has "
            f"{len(files[0])} images, "
            f"{sources[1]!r} has {len(files[1])}"
        )
    _check_same_images(files, sources)
    detections = [_detect(f, board, s) for f, s in zip(files, sources)]
    for f, d, s in zip(files, detections, sources):
        _check_board_size(f, d[0], board, s)

    intrinsics = []
    for (corners, size, _), f, s, name in zip(detections, files, sources, cam_names):
        found = [c for c in corners if c is not None]
        if len(found) < min_boards:
            failed = [fi for fi, c in zip(f, corners) if c is None]
            raise _too_few(s, name, len(found), min_boards, failed, board)
        intr = calibrate_intrinsics(found, board, size, name=name)
        found_idx = [i for i, c in enumerate(corners) if c is not None]
        view_errors = {i: float(e) for i, e in zip(found_idx, intr.per_view_rms_px)}
        _check_rms(f"camera {name!r} ({s})", intr.rms_px, max_rms_px, _worst_views(f, view_errors))
        intrinsics.append(intr)

    # Per-image results from the intrinsic fit.
    stereo_err: list[dict[int, float]] = [{} for _ in range(n_cams)]
    stereo_rms = baseline = None
    used_pairs: list[int] = []
    cameras = [r.camera for r in intrinsics]
    if n_cams == 2:
        used_pairs = [
            i
            for i, (a, b) in enumerate(zip(detections[0][0], detections[1][0]))
            if a is not None and b is not None
        ]
        if len(used_pairs) < min_boards:
            failed = [files[0][i] for i in range(len(files[0])) if i not in used_pairs]
            raise _too_few(
                f"{sources[0]} + {sources[1]}",
                f"{cam_names[0]}+{cam_names[1]}",
                len(used_pairs),
                min_boards,
                failed,
                board,
                what="pairs (both images)",
            )
        ca: list[NDArray[np.float64]] = [detections[0][0][i] for i in used_pairs]  # type: ignore[misc]
        cb: list[NDArray[np.float64]] = [detections[1][0][i] for i in used_pairs]  # type: ignore[misc]
        stereo = calibrate_stereo(ca, cb, board, cameras[0], cameras[1], refine_stereo_intrinsics)
        cameras = list(stereo.cameras)
        stereo_rms, baseline = stereo.rms_px, stereo.baseline_mm
        pair_errors = {i: float(stereo.per_view_rms_px[j].max()) for j, i in enumerate(used_pairs)}
        _check_rms(
            f"stereo pair {cam_names[0]}+{cam_names[1]}",
            stereo_rms,
            max_rms_px,
            _worst_views(files[0], pair_errors),
        )
        if baseline < MIN_BASELINE_MM:
            raise CalibrationError(
                f"stereo pair {cam_names[0]}+{cam_names[1]}: baseline {baseline:.3g} mm, expected "
                f"at least {MIN_BASELINE_MM:g} mm between the optical centres; are both image "
                f"sets from the same camera?"
            )
        for j, i in enumerate(used_pairs):
            stereo_err[0][i] = float(stereo.per_view_rms_px[j, 0])
            stereo_err[1][i] = float(stereo.per_view_rms_px[j, 1])

    world = f"camera {cam_names[0]!r} frame"
    if pose is not None:
        cameras, world = _apply_board_pose(
            cameras, pose, board, files[0], detections[0][0], n_cams, detections
        )

    reports = []
    for c, (corners, _, notes), f, s, intr, serr in zip(
        cameras, detections, files, sources, intrinsics, stereo_err
    ):
        view = 0
        results = []
        for i, (fi, cor, note) in enumerate(zip(f, corners, notes)):
            if cor is None:
                results.append(ImageResult(fi, False, note=note))
                continue
            err = float(intr.per_view_rms_px[view])
            view += 1
            extra = "" if n_cams == 1 or i in serr else "pair not used: other image lacks the board"
            results.append(
                ImageResult(fi, True, err, serr.get(i), (float(cor[0, 0]), float(cor[0, 1])), extra)
            )
        reports.append(CameraReport(c, s, results, intr.rms_px))
    return CalibrationReport(cameras, reports, world, stereo_rms, baseline, len(used_pairs))


def _apply_board_pose(
    cameras: list[Camera],
    pose: BoardPose,
    board: Board,
    first_files: Sequence[Path],
    first_corners: Sequence[NDArray[np.float64] | None],
    n_cams: int,
    detections: Sequence[tuple[list[NDArray[np.float64] | None], tuple[int, int], list[str]]],
) -> tuple[list[Camera], str]:
    usable = [
        i for i in range(len(first_files)) if all(det[0][i] is not None for det in detections)
    ]
    if pose.image is not None:
        idx = [i for i, f in enumerate(first_files) if f.name == pose.image]
        if not idx:
            raise CalibrationError(
                f"board pose image {pose.image!r}: not among the first image set "
                f"({', '.join(f.name for f in first_files[:10])}"
                f"{' ...' if len(first_files) > 10 else ''})"
            )
        if idx[0] not in usable:
            raise CalibrationError(
                f"board pose image {pose.image!r}: the board was not found there"
                + (" (or in its pair)" if n_cams == 2 else "")
            )
        k = idx[0]
    else:
        k = usable[0]
    corners = first_corners[k]
    if corners is None:  # unreachable: k is in `usable`; keeps the type checker informed
        raise CalibrationError(f"board pose: no board in {first_files[k].name}")
    located = locate_camera(cameras[0], corners, board, pose.world_from_board())
    out = [located]
    if n_cams == 2:
        # Keep the stereo geometry rigid: second_from_world = second_from_first @ first_from_world.
        second_from_first = np.asarray(cameras[1].camera_from_world)  # first camera was the world
        c = cameras[1]
        out.append(
            Camera(c.name, c.image_size, c.K, c.dist, second_from_first @ located.camera_from_world)
        )
    return out, f"board at measured pose in {first_files[k].name}"
