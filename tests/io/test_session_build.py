"""`mocapkit session`: videos + a calibration (+ OpenPose) -> a session folder."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from mocapkit.camera import Camera, intrinsics_from_fov, look_at
from mocapkit.cli.main import main
from mocapkit.errors import InputWarning, SessionError
from mocapkit.io.calib_toml import write_calib_toml
from mocapkit.io.cameras import read_cameras
from mocapkit.io.openpose import write_openpose_frame
from mocapkit.io.session import load_session
from mocapkit.io.session_build import build_session
from mocapkit.io.video import padding_px

DEMO = Path("video/pose2sim_demo_singleperson")


def _video(path: Path, n: int, size: tuple[int, int] = (64, 48), fps: float = 30.0) -> Path:
    w = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), fps, size)
    for i in range(n):
        w.write(np.full((size[1], size[0], 3), 50 + 10 * i, np.uint8))
    w.release()
    return path


def _camera(name: str, size: tuple[int, int] = (64, 48), x_mm: float = 0.0) -> Camera:
    return Camera(
        name,
        size,
        intrinsics_from_fov(size, 60.0),
        [],
        look_at((x_mm, -3000.0, 1000.0), (0.0, 0.0, 1000.0)),
    )


def _rig(tmp_path: Path, n: tuple[int, int] = (5, 5)) -> tuple[list[Path], Path]:
    vids = [_video(tmp_path / "cam1.avi", n[0]), _video(tmp_path / "cam2.avi", n[1])]
    cal = tmp_path / "Calib.toml"
    write_calib_toml(cal, [_camera("cam_01", x_mm=-500.0), _camera("cam_02", x_mm=500.0)])
    return vids, cal


def _openpose(folder: Path, n: int, x_px: float = 30.0) -> None:
    folder.mkdir(parents=True)
    person = np.zeros((25, 3))
    person[:, 0], person[:, 1], person[:, 2] = x_px, 20.0 + np.arange(25), 0.9
    for i in range(n):
        write_openpose_frame(folder / f"v_{i:012d}_keypoints.json", [person])


def test_builds_a_session_with_keypoints(tmp_path: Path) -> None:
    vids, cal = _rig(tmp_path)
    _openpose(tmp_path / "pose" / "cam1_json", 5)
    _openpose(tmp_path / "pose" / "cam2", 5, x_px=40.0)
    built = build_session(vids, [cal], tmp_path / "s", keypoints=tmp_path / "pose")
    assert built.cameras == ("cam1", "cam2") and built.n_frames == 5 and built.keypoints
    s = load_session(tmp_path / "s")
    assert s.video_cameras == ("cam1", "cam2")  # renamed from cam_01, cam_02
    np.testing.assert_allclose(s.camera("cam2").camera_from_world[:3, 3], read_cameras(
        tmp_path / "s" / "cameras.json")[1].camera_from_world[:3, 3])  # fmt: skip
    np.testing.assert_allclose(s.video("cam1").time_s, np.arange(5) / 30.0)
    np.testing.assert_allclose(s.keypoints["cam2"].pixels[:, 3, 0], 40.0)  # left_shoulder x
    assert s.keypoints["cam1"].time_s.shape == (5,)


def test_cli_builds_the_session(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    vids, cal = _rig(tmp_path)
    argv = ["session", *map(str, vids), "--calibration", str(cal), "--out", str(tmp_path / "s")]
    assert main(argv) == 0
    assert "cameras cam1, cam2, 5 frames at 30 Hz, no keypoints" in capsys.readouterr().out
    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / "notes.txt").write_text("mine", "utf-8")
    assert main([*argv[:-1], str(tmp_path / "junk")]) == 2
    assert "holds files and no session.json" in capsys.readouterr().err
    assert (tmp_path / "junk" / "notes.txt").read_text("utf-8") == "mine"


def test_refuses_different_frame_counts_before_writing(tmp_path: Path) -> None:
    vids, cal = _rig(tmp_path, n=(5, 7))
    with pytest.raises(SessionError, match=r"videos of different lengths \(cam1 5, cam2 7 frames"):
        build_session(vids, [cal], tmp_path / "s")
    assert not (tmp_path / "s").exists()


def test_refuses_different_frame_rates(tmp_path: Path) -> None:
    vids, cal = _rig(tmp_path)
    _video(vids[1], 5, fps=25.0)
    with pytest.raises(SessionError, match=r"different frame rates \(cam1 30, cam2 25 Hz\)"):
        build_session(vids, [cal], tmp_path / "s")


def test_refuses_a_camera_missing_from_the_calibration(tmp_path: Path) -> None:
    vids, cal = _rig(tmp_path)
    other = _video(tmp_path / "side.avi", 5)
    with pytest.raises(SessionError, match=r"no camera named 'side' .* has \['cam_01', 'cam_02'\]"):
        build_session([vids[0], other], [cal], tmp_path / "s")


def test_refuses_missing_keypoint_folder(tmp_path: Path) -> None:
    vids, cal = _rig(tmp_path)
    _openpose(tmp_path / "pose" / "cam1", 5)
    with pytest.raises(SessionError, match=r"camera 'cam2', named 'cam2' or 'cam2_json'; found "
                       r"neither \(folders there: \['cam1'\]\)"):  # fmt: skip
        build_session(vids, [cal], tmp_path / "s", keypoints=tmp_path / "pose")
    with pytest.raises(SessionError, match=r"expected a folder of OpenPose JSON folders .*found a"):
        build_session(vids, [cal], tmp_path / "s", keypoints=cal)


def test_padding_rule() -> None:
    assert padding_px((1080, 1920), (1088, 1920), "c.mp4", "c") == (8, 0)
    assert padding_px((1088, 1920), (1088, 1920), "c.mp4", "c") == (0, 0)
    assert padding_px((1920, 1080), (1920, 1088), "c.mp4", "c") == (0, 8)
    assert padding_px((160, 120), (160, 120), "c.mp4", "c") == (0, 0)
    for size in ((544, 960), (1920, 1088), (1070, 1920)):  # scaled, rotated, cropped
        with pytest.raises(SessionError, match=r"expected the same size \(or the calibration's"):
            padding_px(size, (1088, 1920), "c.mp4", "c")


def test_padded_video_is_read_at_the_calibrated_size(tmp_path: Path) -> None:
    vids = [_video(tmp_path / "cam1.avi", 5, size=(60, 48)), _video(tmp_path / "cam2.avi", 5)]
    cal = tmp_path / "Calib.toml"
    write_calib_toml(cal, [_camera("cam1"), _camera("cam2")])  # both 64x48
    with pytest.warns(InputWarning, match=r"cam1\.avi: the video is 4 columns and 0 rows smaller"):
        build_session(vids, [cal], tmp_path / "s")
    with pytest.warns(InputWarning, match=r"cam1\.avi: the video's frames are 4 columns"):
        s = load_session(tmp_path / "s")
    assert s.camera("cam1").image_size == (64, 48)
    for smp in s.samples():
        img = smp.image("cam1")
        assert img.shape == (48, 64, 3) and img[:, 60:].max() == 0 and img[:, :60].max() > 0
        assert smp.image("cam2").shape == (48, 64, 3)
    assert s.video("cam1").read(4).shape == (48, 64, 3)
    with pytest.raises(SessionError, match=r"cam2\.avi: the video is 32x24 px, the calibration"):
        _video(tmp_path / "s" / "video" / "cam2.avi", 5, size=(32, 24))
        load_session(tmp_path / "s")


def test_pose2sim_demo(shared_data: Path, tmp_path: Path) -> None:
    """The real demo: 1080 px videos against a 1088 px Qualisys calibration."""
    data = shared_data / DEMO
    vids = sorted((data / "videos").glob("cam0*.mp4"))
    with pytest.warns(InputWarning, match=r"cam0[12]\.mp4: the video is 8 columns") as rec:
        build_session(vids, [data / "calibration" / "Calib.qca.txt"], tmp_path / "s")
    assert len([w for w in rec if issubclass(w.category, InputWarning)]) == 2  # cam01, cam02
    with pytest.warns(InputWarning, match=r"cam0[12]\.mp4: the video's frames are 8 columns"):
        s = load_session(tmp_path / "s")
    assert [c.image_size for c in s.cameras] == [(1088, 1920)] * 4
    assert s.video("cam03").n_frames == 100 and s.rates["video_hz"] == 60.0
    stream = s.samples()
    smp = next(stream)
    assert {smp.image(c).shape for c in s.video_cameras} == {(1920, 1088, 3)}
    stream.close()
    write_calib_toml(tmp_path / "Calib.toml", s.cameras)  # the same rig again, from a Calib.toml
    with pytest.warns(InputWarning):
        build_session(vids, [tmp_path / "Calib.toml"], tmp_path / "s2")
    with pytest.warns(InputWarning):
        k4 = load_session(tmp_path / "s2").camera("cam04").K
    np.testing.assert_allclose(k4, s.camera("cam04").K, atol=1e-9)


def test_one_opencv_yaml_per_camera(tmp_path: Path) -> None:
    """OpenCV calibrations come one file per camera, named by its stem."""
    vids = [_video(tmp_path / "cam1.avi", 5), _video(tmp_path / "cam2.avi", 5)]
    files = []
    for cam in (_camera("cam1", x_mm=-500.0), _camera("cam2", x_mm=500.0)):
        path = tmp_path / f"{cam.name}.yml"
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
        fs.write("image_width", cam.image_size[0])
        fs.write("image_height", cam.image_size[1])
        fs.write("camera_matrix", cam.K)
        fs.write("distortion_coefficients", np.zeros((5, 1)))
        fs.write("R", cam.camera_from_world[:3, :3])
        fs.write("T", cam.camera_from_world[:3, 3].reshape(3, 1))
        fs.release()
        files.append(path)
    build_session(vids, files, tmp_path / "s")
    s = load_session(tmp_path / "s")
    np.testing.assert_allclose(
        s.camera("cam2").camera_from_world, _camera("cam2", x_mm=500.0).camera_from_world
    )
