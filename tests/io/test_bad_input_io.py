"""Weak cases of the bad-input probe that live in `io`: each now a clear `MocapError`."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from mocapkit.camera import Camera, intrinsics_from_fov, look_at
from mocapkit.cli.main import main
from mocapkit.errors import FormatError, SessionError
from mocapkit.io.cameras import (
    load_cameras,
    read_opencv_calibration,
    read_qualisys,
    write_cameras,
)
from mocapkit.io.openpose import read_openpose_folder, read_openpose_frame, write_openpose_frame
from mocapkit.io.session import load_session, write_session_json
from mocapkit.io.session_csv import write_keypoints_csv


def _session(folder: Path, n: int = 5) -> Path:
    folder.mkdir()
    write_session_json(folder / "session.json", {})
    size = (320, 240)
    cam = Camera(
        "mono", size, intrinsics_from_fov(size, 60.0), [], look_at((0, -3000, 1000), (0, 0, 1000))
    )
    write_cameras(folder / "cameras.json", [cam])
    (folder / "keypoints").mkdir()
    px = np.full((n, 1, 2), 100.0)
    write_keypoints_csv(folder / "keypoints" / "mono.csv", np.arange(n) / 30.0, ["head"], px)
    return folder


@pytest.mark.parametrize("name", ["session.json", "cameras.json", "markers.csv", "truth.npz"])
def test_session_file_that_is_a_folder_is_named_a_folder(tmp_path: Path, name: str) -> None:
    s = _session(tmp_path / "s")
    target = s / name
    if target.exists():
        target.unlink()
    target.mkdir()
    with pytest.raises(SessionError, match=rf"s/{name}: expected a file, found a folder"):
        load_session(s)


@pytest.mark.parametrize(
    ("read", "name"),
    [
        (read_qualisys, "Calib.qca.txt"),
        (read_opencv_calibration, "cam1.yml"),
        (load_cameras, "Calib.toml"),
    ],
)
def test_calibration_that_is_a_folder_is_named_a_folder(
    tmp_path: Path, read: Callable[[Path], object], name: str
) -> None:
    (tmp_path / name).mkdir()
    with pytest.raises(FormatError, match=rf"{name}: expected a .*, found a folder"):
        read(tmp_path / name)


def test_file_given_as_a_session(tmp_path: Path) -> None:
    f = tmp_path / "take.mp4"
    f.write_bytes(b"\x00")
    with pytest.raises(SessionError, match=r"take\.mp4: expected a session folder, found a file"):
        load_session(f)
    with pytest.raises(SessionError, match=r"session folder not found"):
        load_session(tmp_path / "nothing")
    s = _session(tmp_path / "s")
    (s / "keypoints" / "mono.csv").unlink()
    (s / "keypoints").rmdir()
    (s / "keypoints").write_text("x", "utf-8")
    with pytest.raises(SessionError, match=r"s/keypoints: expected a folder, found a file"):
        load_session(s)


def test_openpose_folder_where_nobody_is_detected(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    s = _session(tmp_path / "s")
    op = tmp_path / "op"
    op.mkdir()
    for i in range(5):
        write_openpose_frame(op / f"frame_{i}.json", [])
    with pytest.raises(SessionError, match=r"op: expected a person's keypoints, found nobody "
                       r"detected in any of its 5 OpenPose files"):  # fmt: skip
        read_openpose_folder(op, np.arange(5) / 30.0)
    code = main(["track", "mono", str(s), "--keypoints", str(op), "--out", str(tmp_path / "r")])
    assert code == 2
    assert "found nobody detected in any of its 5 OpenPose files" in capsys.readouterr().err


@pytest.mark.parametrize("value", [90, True])
def test_openpose_confidence_outside_0_1_or_boolean_refused(tmp_path: Path, value: object) -> None:
    flat: list[object] = [100.0, 200.0, 0.9] * 25
    flat[3 * 4 + 2] = value  # RWrist's confidence
    p = tmp_path / "frame_0.json"
    p.write_text(json.dumps({"people": [{"pose_keypoints_2d": flat}]}), "utf-8")
    match = (
        r"people\[0\]\.pose_keypoints_2d: keypoint 4 \(RWrist\) confidence: expected a number "
        r"in \[0, 1\], found 90 \(1 such"
        if value == 90
        else r"people\[0\]\.pose_keypoints_2d\[14\]: expected a number, found True \(bool\)"
    )
    with pytest.raises(FormatError, match=match):
        read_openpose_frame(p)
