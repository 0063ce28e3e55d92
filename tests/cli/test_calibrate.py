"""``mocapkit calibrate`` end to end, and its refusals."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from mocapkit.camera.calibration import parse_board
from mocapkit.cli.main import main
from mocapkit.errors import CalibrationError, FormatError
from mocapkit.io.cameras import read_cameras
from mocapkit.pipelines.calibrate import calibrate_from_images, read_board_pose


def test_stereo_cli_writes_cameras_and_reports(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = shared_data / "calib" / "stereo_chessboard"
    out = tmp_path / "cameras.json"
    code = main(
        [
            "calibrate",
            "--board",
            "9x6",
            "--square-mm",
            "25",
            "--out",
            str(out),
            str(folder / "left*.jpg"),
            str(folder / "right*.jpg"),
        ]
    )
    assert code == 0
    text = capsys.readouterr().out
    assert "board found in 13 of 13 images" in text
    assert "left02.jpg" in text and "reprojection" in text
    assert "stereo: 13 pairs, RMS" in text
    left, right = read_cameras(out)
    assert (left.name, right.name) == ("left", "right")
    np.testing.assert_array_equal(left.camera_from_world, np.eye(4))
    assert 50.0 < np.linalg.norm(right.center_in_world) < 150.0


def test_single_camera_with_board_pose(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = shared_data / "calib" / "stereo_chessboard"
    pose = tmp_path / "pose.json"
    pose.write_text(
        json.dumps(
            {
                "origin_mm": [500, 0, 0],
                "x_axis": [0, 1, 0],
                "y_axis": [-1, 0, 0],
                "image": "left05.jpg",
            }
        )
    )
    out = tmp_path / "cam.json"
    code = main(
        [
            "calibrate",
            "--board",
            "9x6",
            "--square-mm",
            "25",
            "--out",
            str(out),
            "--board-pose",
            str(pose),
            "--names",
            "webcam",
            str(folder / "left*.jpg"),
        ]
    )
    assert code == 0
    assert "world frame: board at measured pose in left05.jpg" in capsys.readouterr().out
    (cam,) = read_cameras(out)
    # The board's origin corner projects onto its detected pixel in left05.jpg.
    img = cv2.imread(str(folder / "left05.jpg"), cv2.IMREAD_GRAYSCALE)
    ok, corners = cv2.findChessboardCorners(img, (9, 6))
    assert ok
    assert np.linalg.norm(cam.project([500.0, 0.0, 0.0]) - corners.reshape(-1, 2)[0]) < 2.0


def test_folder_without_boards_is_refused(
    tmp_path: Path, rng: np.random.Generator, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "blank_shots"
    folder.mkdir()
    for i in range(3):
        noise = rng.integers(0, 256, size=(120, 160), dtype=np.uint8)
        cv2.imwrite(str(folder / f"shot{i}.png"), noise)
    with pytest.raises(
        CalibrationError,
        match=r"blank_shots\): board 9x6 found in 0 images, need at least 5; "
        r"not found in: shot0\.png, shot1\.png, shot2\.png",
    ):
        calibrate_from_images([folder], parse_board("9x6", 25))
    code = main(
        [
            "calibrate",
            "--board",
            "9x6",
            "--square-mm",
            "25",
            "--out",
            str(tmp_path / "c.json"),
            str(folder),
        ]
    )
    assert code == 2
    assert "blank_shots" in capsys.readouterr().err
    assert not (tmp_path / "c.json").exists()


def test_too_few_pairs_names_failed_images(shared_data: Path, tmp_path: Path) -> None:
    src = shared_data / "calib" / "stereo_chessboard"
    left, right = tmp_path / "L", tmp_path / "R"
    left.mkdir()
    right.mkdir()
    for i, n in enumerate(["01", "03", "04", "05", "06", "07", "08"]):
        for side, folder, blank in (("left", left, 0), ("right", right, 1)):
            target = folder / f"{i}.jpg"
            if i == blank:  # left misses the board in pair 0, right in pair 1
                cv2.imwrite(str(target), np.full((480, 640), 127, np.uint8))
            else:
                shutil.copy(src / f"{side}{n}.jpg", target)
    with pytest.raises(
        CalibrationError,
        match=r"found in 5 pairs \(both images\), need at least 6; not found in: 0.jpg, 1.jpg",
    ):
        calibrate_from_images([left, right], parse_board("9x6", 25), min_boards=6)
    shutil.copy(src / "left09.jpg", left / "9.jpg")
    with pytest.raises(CalibrationError, match=r"has 8 images, .* has 7"):
        calibrate_from_images([left, right], parse_board("9x6", 25))


def test_empty_image_set_and_bad_board_pose(tmp_path: Path) -> None:
    with pytest.raises(CalibrationError, match=r"empty.*folder matches no image files"):
        (tmp_path / "empty").mkdir()
        calibrate_from_images([tmp_path / "empty"], parse_board("9x6", 25))
    pose = tmp_path / "pose.json"
    pose.write_text(json.dumps({"origin_mm": [0, 0, 0], "x_axis": [1, 0, 0]}))
    with pytest.raises(FormatError, match=r"pose\.json: missing key\(s\) y_axis"):
        read_board_pose(pose)
    pose.write_text(json.dumps({"origin_mm": [0, 0], "x_axis": [1, 0, 0], "y_axis": [0, 1, 0]}))
    with pytest.raises(FormatError, match=r"origin_mm: expected 3 finite numbers, found \[0, 0\]"):
        read_board_pose(pose)


# ---------------------------------------------------------------- slips that show in the numbers


def _pairs(folder: Path, tmp: Path, shift: int) -> tuple[Path, Path]:
    """Copy the stereo set so that right image i pairs with left image i + shift."""
    lefts = sorted(folder.glob("left*.jpg"))
    rights = sorted(folder.glob("right*.jpg"))
    a, b = tmp / "L", tmp / "R"
    a.mkdir()
    b.mkdir()
    for i, f in enumerate(lefts):
        shutil.copy(f, a / f"{i:02d}.jpg")
        shutil.copy(rights[(i + shift) % len(rights)], b / f"{i:02d}.jpg")
    return a, b


def test_mispaired_stereo_is_refused_and_nothing_written(
    shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    a, b = _pairs(shared_data / "calib" / "stereo_chessboard", tmp_path, shift=1)
    out = tmp_path / "cameras.json"
    args = ["calibrate", "--board", "9x6", "--square-mm", "25", "--out", str(out)]
    assert main([*args, str(a), str(b)]) == 2
    err = capsys.readouterr().err
    assert "stereo pair left+right: RMS reprojection error 5" in err
    assert "expected at most 2 px (--max-rms-px)" in err
    assert not out.exists()
    # the threshold is an option: a user who knows better can raise it
    report = calibrate_from_images([a, b], parse_board("9x6", 25.0), max_rms_px=200.0)
    assert report.stereo_rms_px is not None and report.stereo_rms_px > 10.0


def test_square_size_in_metres_is_refused() -> None:
    with pytest.raises(CalibrationError, match=r"given in metres \(0.025 m = 25 mm\)"):
        calibrate_from_images(["unused"], parse_board("9x6", 0.025))


def test_same_images_for_both_cameras_is_refused(shared_data: Path) -> None:
    left = shared_data / "calib" / "stereo_chessboard" / "left*.jpg"
    with pytest.raises(CalibrationError, match="found the same 13 images in both"):
        calibrate_from_images([left, left], parse_board("9x6", 25.0))


def test_board_smaller_than_the_one_in_the_images_is_refused(shared_data: Path) -> None:
    left = shared_data / "calib" / "stereo_chessboard" / "left*.jpg"
    with pytest.raises(CalibrationError, match=r"8x6 inner corners given, .* at least 9x6"):
        calibrate_from_images([left], parse_board("8x6", 25.0))


def test_max_rms_must_be_positive() -> None:
    with pytest.raises(CalibrationError, match="max_rms_px: expected a positive number"):
        calibrate_from_images(["unused"], parse_board("9x6", 25.0), max_rms_px=0.0)


def test_out_naming_a_folder_is_refused_before_the_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`calibrate --out DIR` used to fail after the calibration, naming an internal
    ``.DIR.xxxx.tmp`` file (issue 14): refused while parsing, by its own name."""
    from mocapkit.cli.main import main

    folder = tmp_path / "calib_out"
    folder.mkdir()
    argv = ["calibrate", "--board", "9x6", "--square-mm", "25", "--out", str(folder), "x*.jpg"]
    with pytest.raises(SystemExit) as exc:
        main(argv)
    err = capsys.readouterr().err
    assert exc.value.code == 2
    assert f"argument --out: {folder}: expected a file to write, found a folder" in err
    assert ".tmp" not in err
