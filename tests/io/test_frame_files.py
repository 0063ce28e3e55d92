"""Per-frame files in frame order: by the number in the name, never by text order."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from mocapkit.errors import SessionError
from mocapkit.io.frame_files import frame_number, in_frame_order
from mocapkit.io.openpose import MAPPED_JOINTS, read_openpose_folder, write_openpose_frame
from mocapkit.io.video import VideoSource, image_files, probe_video


def _person(x_px: float) -> np.ndarray:
    p = np.zeros((25, 3))
    p[:, 0], p[:, 1], p[:, 2] = x_px + np.arange(25), 100.0 + 3 * np.arange(25), 0.9
    return p


def test_frame_number() -> None:
    assert frame_number(Path("frame_12.json")) == 12
    assert frame_number(Path("video_000000000012_keypoints.json")) == 12
    assert frame_number(Path("cam01_000012_keypoints.json")) == 12
    assert frame_number(Path("7.png")) == 7
    assert frame_number(Path("frame.png")) is None


def test_openpose_frame_0_to_60_in_number_order(tmp_path: Path) -> None:
    """ffmpeg's %d names: text order puts frame_10 before frame_2."""
    n = 61
    for i in range(n):
        write_openpose_frame(tmp_path / f"frame_{i}.json", [_person(100.0 + 5 * i)])
    kp = read_openpose_folder(tmp_path, np.arange(n) / 30.0)
    wrist = MAPPED_JOINTS.index("right_wrist")
    np.testing.assert_allclose(np.diff(kp.pixels[:, wrist, 0]), 5.0)


def test_image_folder_0_to_60_in_number_order(tmp_path: Path) -> None:
    for i in range(61):
        cv2.imwrite(str(tmp_path / f"{i}.png"), np.full((4, 4, 3), i, np.uint8))
    assert probe_video(tmp_path, "cam") == (61, 0.0)
    src = VideoSource("cam", tmp_path, np.arange(61) / 30.0)
    assert [int(src.read(i)[0, 0, 0]) for i in (0, 2, 10, 60)] == [0, 2, 10, 60]
    stream = src.open()
    for i in range(12):
        stream.advance_to(i)
        assert int(stream.retrieve(i)[0, 0, 0]) == i


@pytest.mark.parametrize(
    ("names", "match"),
    [
        (["0.png", "1.png", "3.png"], r"frame numbers jump from 1 \('1\.png'\) to 3 \('3\.png'\); "
         r"frame 2 missing"),
        (["0.png", "1.png", "01.png"], r"'01\.png' and '1\.png' both have frame number 1"),
        (["0.png", "1.png", "cover.png"], r"expected a frame number in every file name, found "
         r"'cover\.png'"),
    ],
)  # fmt: skip
def test_image_folder_gaps_and_repeats_refused(
    tmp_path: Path, names: list[str], match: str
) -> None:
    for name in names:
        cv2.imwrite(str(tmp_path / name), np.zeros((4, 4, 3), np.uint8))
    with pytest.raises(SessionError, match=rf"{tmp_path.name}: images: {match}"):
        image_files(tmp_path)


def test_openpose_gaps_and_repeats_refused(tmp_path: Path) -> None:
    for i in (0, 1, 2, 5):
        write_openpose_frame(tmp_path / f"frame_{i}.json", [_person(100.0)])
    gap = r"frame numbers jump from 2 \('frame_2\.json'\) to 5 \('frame_5\.json'\); frames 3-4"
    with pytest.raises(SessionError, match=rf"OpenPose JSON files: {gap} missing"):
        read_openpose_folder(tmp_path, np.arange(4) / 30.0)
    (tmp_path / "frame_5.json").unlink()
    write_openpose_frame(tmp_path / "frame_002.json", [_person(100.0)])
    with pytest.raises(SessionError, match=r"'frame_002\.json' and 'frame_2\.json' both have"):
        read_openpose_folder(tmp_path, np.arange(4) / 30.0)


def test_first_number_may_be_any(tmp_path: Path) -> None:
    files = [tmp_path / f"img{i:03d}.jpg" for i in (12, 10, 11)]
    assert [f.name for f in in_frame_order(files, tmp_path, "images")] == [
        "img010.jpg", "img011.jpg", "img012.jpg"
    ]  # fmt: skip
