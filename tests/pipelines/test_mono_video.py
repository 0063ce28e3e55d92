"""The monocular tracker on a plain video file (`mocapkit.pipelines.mono_video`)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.pipelines.mono_video import montage, track_video, write_png

SKIN_BGR = tuple(
    int(v)
    for v in cv2.cvtColor(np.array([[[150, 154, 104]]], dtype=np.uint8), cv2.COLOR_YCrCb2BGR)[0, 0]
)


def _write_video(path: Path, n: int = 24) -> list[float]:
    """A figure (head, two forearms) walking right past a static skin-coloured lamp.

    Returns the head's true x per frame (px).
    """
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (320, 240))
    xs = []
    for k in range(n):
        img = np.full((240, 320, 3), (90, 110, 60), dtype=np.uint8)
        cv2.circle(img, (290, 25), 14, SKIN_BGR, -1)  # the lamp, topmost
        x = 100 + 3 * k
        xs.append(float(x))
        cv2.rectangle(img, (x - 30, 80), (x + 30, 170), (140, 60, 40), -1)  # a dark shirt
        cv2.ellipse(img, (x, 60), (14, 19), 0, 0, 360, SKIN_BGR, -1)
        cv2.ellipse(img, (x + 40, 120), (25, 6), 70, 0, 360, SKIN_BGR, -1)
        cv2.ellipse(img, (x - 40, 120), (25, 6), 110, 0, 360, SKIN_BGR, -1)
        writer.write(img)
    writer.release()
    return xs


def test_track_video_follows_the_mover_and_draws_a_montage(tmp_path: Path) -> None:
    video = tmp_path / "walk.avi"
    xs = _write_video(video)
    track = track_video(video, 0.0, 0.8, size_px=320)
    assert len(track.skin) == 24 and track.camera is None
    heads = np.array([f.blobs["head"].centre for f in track.skin])
    np.testing.assert_allclose(heads[:, 0], xs, atol=2.0)  # the walker, never the lamp
    np.testing.assert_allclose(heads[:, 1], 60, atol=2.0)
    s = track.summary()
    assert s["frames"] == 24 and s["waist_frames"] == 0
    assert s["posed_frames"] == 24  # the trunk drawn from the head lets every frame pose
    # orthographic: the chosen pose's x, y are the smoothed 2-D joints (px)
    wrist = [track.model.joint_names.index("left_wrist")]
    pose_xy = np.stack([f.joints_in_camera[wrist, :2] for f in track.poses])[:, 0]
    np.testing.assert_allclose(pose_xy[:, 0] - np.array(xs), 40 + 25 * np.cos(np.radians(70)),
                               atol=4.0)  # fmt: skip
    img = montage(track, tiles=6, columns=3, tile_px=160)
    assert img.shape == (2 * 120, 3 * 160, 3)
    write_png(tmp_path / "m.png", img)
    back = cv2.imread(str(tmp_path / "m.png"))
    np.testing.assert_array_equal(back, img)


def test_track_video_refuses_a_clip_past_the_end(tmp_path: Path) -> None:
    video = tmp_path / "walk.avi"
    _write_video(video, 6)
    with pytest.raises(ConfigError, match="lies after the video's end"):
        track_video(video, 5.0, 1.0, size_px=320)
    with pytest.raises(ConfigError, match="seconds > 0"):
        track_video(video, 0.0, 0.0)
