"""Chessboard calibration: synthetic recovery and OpenCV's real stereo sample."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from mocapkit.camera import Camera, look_at
from mocapkit.camera.calibration import (
    Board,
    calibrate_intrinsics,
    calibrate_stereo,
    find_board_corners,
    locate_camera,
    parse_board,
    world_from_board_pose,
)
from mocapkit.camera.triangulation import triangulate_pair
from mocapkit.errors import CalibrationError, ShapeError
from mocapkit.pipelines.calibrate import BoardPose, calibrate_from_images

BOARD = Board(9, 6, 25.0)


def _synthetic_views(
    camera: Camera, rng: np.random.Generator, n_views: int
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Project the board at random poses in front of the camera (corners, camera_from_board)."""
    pts = BOARD.points_in_board() - [100.0, 62.5, 0.0]
    corners, poses = [], []
    while len(corners) < n_views:
        rvec = rng.normal(0.0, 0.35, 3)
        rot = cv2.Rodrigues(rvec)[0]
        t = np.array([rng.uniform(-60, 60), rng.uniform(-40, 40), rng.uniform(450, 700)])
        cam_pts = pts @ rot.T + t
        px = camera.project_camera_points(cam_pts)
        if np.all(camera.in_image(px, margin_px=5)):
            c_from_b = np.eye(4)
            c_from_b[:3, :3] = rot
            c_from_b[:3, 3] = t - rot @ [100.0, 62.5, 0.0]
            corners.append(px + rng.normal(0.0, 0.05, px.shape))
            poses.append(c_from_b)
    return corners, poses


@pytest.fixture
def true_camera() -> Camera:
    k = np.array([[610.0, 0.0, 322.0], [0.0, 605.0, 236.0], [0.0, 0.0, 1.0]])
    return Camera("true", (640, 480), k, [-0.2, 0.05, 0.001, -0.0005, 0.0], np.eye(4))


def test_parse_board() -> None:
    b = parse_board("9x6", 25)
    assert (b.columns, b.rows, b.square_mm, b.n_corners) == (9, 6, 25.0, 54)
    pts = b.points_in_board()
    np.testing.assert_allclose(pts[1] - pts[0], [25.0, 0.0, 0.0])
    np.testing.assert_allclose(pts[9] - pts[0], [0.0, 25.0, 0.0])
    with pytest.raises(CalibrationError, match=r"COLUMNSxROWS.*'9by6'"):
        parse_board("9by6", 25)
    with pytest.raises(CalibrationError, match=r"square size.*-1"):
        parse_board("9x6", -1)


def test_intrinsics_recovered_from_synthetic_views(
    true_camera: Camera, rng: np.random.Generator
) -> None:
    corners, poses = _synthetic_views(true_camera, rng, 12)
    result = calibrate_intrinsics(corners, BOARD, (640, 480), name="c")
    np.testing.assert_allclose(result.camera.K, true_camera.K, rtol=5e-3, atol=1.0)
    assert result.rms_px < 0.1
    assert result.per_view_rms_px.shape == (12,)
    np.testing.assert_allclose(
        result.camera_from_board[:, :3, 3], np.stack(poses)[:, :3, 3], atol=2.0
    )


def test_too_few_views_and_bad_corners(true_camera: Camera, rng: np.random.Generator) -> None:
    corners, _ = _synthetic_views(true_camera, rng, 2)
    with pytest.raises(CalibrationError, match="at least 3 board views, found 2"):
        calibrate_intrinsics(corners, BOARD, (640, 480))
    with pytest.raises(ShapeError, match=r"view 0: expected corners \(54, 2\), found \(53, 2\)"):
        calibrate_intrinsics([corners[0][:-1]] * 3, BOARD, (640, 480))


def test_locate_camera_from_board_at_known_world_pose(true_camera: Camera) -> None:
    # A board on the floor (world z = 0) with its edges along world x and y, origin at
    # (1000, 500, 0) mm, seen by a camera 2.5 m away (hybrid paper's set-up, §3).
    world_from_board = world_from_board_pose([1000.0, 500.0, 0.0], [1, 0, 0], [0, 1, 0])
    cam_from_world = look_at([1100.0, -1500.0, 1500.0], [1100.0, 560.0, 0.0])
    truth = Camera("c", (640, 480), true_camera.K, true_camera.dist, cam_from_world)
    board_world = BOARD.points_in_board() + np.array([1000.0, 500.0, 0.0])
    px = truth.project(board_world)
    assert np.all(truth.in_image(px))
    # Noise-free corners: the pose chain (solvePnP, then board_from_world) must be exact.
    located = locate_camera(true_camera, px, BOARD, world_from_board)
    np.testing.assert_allclose(located.center_in_world, truth.center_in_world, atol=1e-2)
    np.testing.assert_allclose(located.camera_from_world, cam_from_world, atol=1e-2)


def test_board_pose_validation() -> None:
    m = world_from_board_pose([1, 2, 3], [2, 0, 0], [0, 0, 5])
    np.testing.assert_allclose(m[:3, :3], [[1, 0, 0], [0, 0, -1], [0, 1, 0]], atol=1e-12)
    with pytest.raises(CalibrationError, match=r"perpendicular, found 45\.0 degrees"):
        world_from_board_pose([0, 0, 0], [1, 0, 0], [1, 1, 0])
    with pytest.raises(CalibrationError, match="origin_mm: expected 3 finite numbers"):
        world_from_board_pose([0, 0], [1, 0, 0], [0, 1, 0])


def test_stereo_synthetic_recovers_relative_pose(
    true_camera: Camera, rng: np.random.Generator
) -> None:
    second_from_first = look_at([120.0, 0.0, 0.0], [60.0, 0.0, 600.0], up=(0, -1, 0))
    second = Camera("b", (640, 480), true_camera.K, true_camera.dist, second_from_first)
    pts = BOARD.points_in_board() - [100.0, 62.5, 0.0]
    ca, cb = [], []
    while len(ca) < 8:
        rot = cv2.Rodrigues(rng.normal(0.0, 0.3, 3))[0]
        t = np.array([rng.uniform(0, 60), rng.uniform(-30, 30), rng.uniform(500, 700)])
        world = pts @ rot.T + t
        pa, pb = true_camera.project(world), second.project(world)
        if np.all(true_camera.in_image(pa, 5)) and np.all(second.in_image(pb, 5)):
            ca.append(pa + rng.normal(0, 0.05, pa.shape))
            cb.append(pb + rng.normal(0, 0.05, pb.shape))
    result = calibrate_stereo(ca, cb, BOARD, true_camera, second)
    np.testing.assert_allclose(result.second_from_first, second_from_first, atol=0.5)
    assert result.baseline_mm == pytest.approx(120.0, abs=0.5)
    assert result.rms_px < 0.1
    with pytest.raises(
        CalibrationError, match="same number of views in both cameras, found 8 and 7"
    ):
        calibrate_stereo(ca, cb[:-1], BOARD, true_camera, second)


def test_find_board_corners_on_a_rendered_board() -> None:
    # A fronto-parallel 10x7-square board (9x6 inner corners), 30 px squares, white margin.
    img = np.full((300, 400), 255, np.uint8)
    for r in range(7):
        for c in range(10):
            if (r + c) % 2 == 0:
                img[45 + r * 30 : 75 + r * 30, 50 + c * 30 : 80 + c * 30] = 0
    corners = find_board_corners(img, BOARD)
    assert corners is not None and corners.shape == (54, 2)
    xs = np.sort(np.unique(np.round(corners[:, 0])))
    np.testing.assert_allclose(np.diff(xs), 30.0, atol=0.6)
    assert find_board_corners(np.full((300, 400), 128, np.uint8), BOARD) is None


# ------------------------------------------------------------------ real OpenCV stereo sample


@pytest.fixture(scope="module")
def stereo_report(shared_data: Path):  # type: ignore[no-untyped-def]
    folder = shared_data / "calib" / "stereo_chessboard"
    return calibrate_from_images(
        [str(folder / "left*.jpg"), str(folder / "right*.jpg")], parse_board("9x6", 25.0)
    )


def _opencv_stored_left(shared_data: Path) -> np.ndarray:
    fs = cv2.FileStorage(str(shared_data / "calib/stereo_chessboard/left_intrinsics.yml"), 0)
    k = fs.getNode("camera_matrix").mat()
    fs.release()
    return np.asarray(k)


def test_left_intrinsics_match_opencv_stored_result(stereo_report, shared_data: Path) -> None:  # type: ignore[no-untyped-def]
    left = stereo_report.per_camera[0]
    assert left.n_found == 13
    ours = left.camera.K
    ref = _opencv_stored_left(shared_data)
    for i, j in [(0, 0), (1, 1), (0, 2), (1, 2)]:
        assert ours[i, j] == pytest.approx(ref[i, j], rel=0.01), (i, j, ours[i, j], ref[i, j])
    assert left.rms_px < 1.0


def test_stereo_rms_and_triangulated_square_size(stereo_report, shared_data: Path) -> None:  # type: ignore[no-untyped-def]
    assert stereo_report.stereo_rms_px < 1.0
    assert stereo_report.n_pairs_used == 13
    left, right = stereo_report.cameras
    folder = shared_data / "calib" / "stereo_chessboard"
    lefts = sorted(folder.glob("left*.jpg"))
    rights = sorted(folder.glob("right*.jpg"))
    px_l = np.stack([find_board_corners(cv2.imread(str(f), 0), BOARD) for f in lefts])
    px_r = np.stack([find_board_corners(cv2.imread(str(f), 0), BOARD) for f in rights])
    pts = triangulate_pair(left, right, px_l, px_r).reshape(13, 6, 9, 3)
    d_row = np.linalg.norm(np.diff(pts, axis=2), axis=-1)
    d_col = np.linalg.norm(np.diff(pts, axis=1), axis=-1)
    mean_square = np.mean(np.concatenate([d_row.ravel(), d_col.ravel()]))
    assert mean_square == pytest.approx(25.0, rel=0.01)
    assert 50.0 < stereo_report.baseline_mm < 150.0


def test_board_pose_defines_world_frame(shared_data: Path) -> None:
    folder = shared_data / "calib" / "stereo_chessboard"
    pose = BoardPose((100.0, 200.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), image="left03.jpg")
    report = calibrate_from_images(
        [str(folder / "left*.jpg"), str(folder / "right*.jpg")], BOARD, board_pose=pose
    )
    left, right = report.cameras
    px_l = find_board_corners(cv2.imread(str(folder / "left03.jpg"), 0), BOARD)
    px_r = find_board_corners(cv2.imread(str(folder / "right03.jpg"), 0), BOARD)
    pts = triangulate_pair(left, right, px_l, px_r)
    expected = BOARD.points_in_board() + np.array([100.0, 200.0, 0.0])
    assert np.max(np.linalg.norm(pts - expected, axis=-1)) < 2.0
    assert report.world_frame == "board at measured pose in left03.jpg"


def test_checkerboard_cam01_agrees_with_qualisys_file(shared_data: Path) -> None:
    # Independent evidence for the .qca.txt units: Pose2Sim's checkerboard shots of camera 1
    # (4x7 inner corners, 60 mm squares) give the same focal length and the same radial
    # distortion as the Qualisys file read with unscaled (dimensionless) coefficients.
    from mocapkit.io.cameras import read_qualisys

    report = calibrate_from_images(
        [shared_data / "calib" / "single_camera_pose2sim_cam01"], parse_board("4x7", 60.0)
    )
    ours = report.cameras[0]
    qca = read_qualisys(shared_data / "video/pose2sim_demo_singleperson/calibration/Calib.qca.txt")[
        0
    ]
    assert ours.image_size == qca.image_size == (1088, 1920)
    assert ours.K[0, 0] == pytest.approx(qca.K[0, 0], rel=0.01)
    assert ours.K[1, 1] == pytest.approx(qca.K[1, 1], rel=0.01)

    def radial_scale(dist: np.ndarray, r: float) -> float:
        d = np.zeros(5)
        d[: dist.shape[0]] = dist
        return float(1 + d[0] * r**2 + d[1] * r**4 + d[4] * r**6)

    # At normalised radius 0.5 (~840 px off-axis, near the image's long edge): both about
    # 0.997; dividing the file's coefficients by 64 (as Pose2Sim does) would give ~1.000.
    r = 0.5
    assert radial_scale(qca.dist, r) == pytest.approx(radial_scale(ours.dist, r), abs=1e-3)
    assert abs(radial_scale(qca.dist / 64, r) - radial_scale(ours.dist, r)) > 2e-3
