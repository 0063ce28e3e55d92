"""A montage of `mocapkit detect` results drawn over their videos (docs/detect_real_montage.png).

    mocapkit detect ../shared/data/video/pose2sim_demo_singleperson/videos --out /tmp/p2s
    mocapkit detect ../shared/data/video/sports2d_demo.mp4 --out /tmp/s2d
    mocapkit detect ../shared/data/video/sports2d_demo.mp4 --out /tmp/s2d_walker --person 1300,700
    python examples/detect_montage.py docs/detect_real_montage.png \\
        /tmp/p2s:cam01:50 /tmp/p2s:cam02:50 /tmp/p2s:cam03:50 /tmp/p2s:cam04:50 \\
        /tmp/s2d:sports2d_demo:120 /tmp/s2d_walker:sports2d_demo:120

Each tile: OUT:CAMERA:FRAME, the video frame with the canonical keypoints every tracker
reads (``OUT/keypoints/CAMERA.csv``) drawn: the right side orange, the left side cyan.
The first row's tiles are scaled to `HEIGHT` px high, the second row's to the first row's width.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import cv2
import numpy as np

from mocapkit.detect.run import video_source
from mocapkit.io.session_csv import read_keypoints_csv
from mocapkit.viz.overlay import draw_sticks_px

#: Height of the first row's tiles (px).
HEIGHT = 360


def tile(out: Path, camera: str, frame: int, video: Path) -> np.ndarray:
    kp = read_keypoints_csv(out / "keypoints" / f"{camera}.csv")
    img = video_source(video, camera).read(frame).copy()
    thick = max(2, img.shape[0] // 300)
    draw_sticks_px(img, kp.joint_names, kp.pixels[frame], (0, 140, 255), thick, (255, 200, 0))
    return img


def _label(img: np.ndarray, text: str) -> None:
    (w, h), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, 0.4, 1)
    cv2.rectangle(img, (0, 0), (w + 8, h + 10), (0, 0, 0), -1)
    cv2.putText(img, text, (4, h + 4), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1,
                cv2.LINE_AA)  # fmt: skip


def main(dest: str, specs: list[str], videos: dict[str, Path]) -> int:
    rows: list[list[np.ndarray]] = [[], []]
    for spec in specs:
        out, cam, frame = spec.split(":")
        info = json.loads((Path(out) / "keypoints" / "detect.json").read_text())[cam]
        img = tile(Path(out), cam, int(frame), videos[cam])
        text = f"{cam} #{frame}: found {info['frames_with_person']}/{info['frames']}"
        row = 0 if img.shape[0] > img.shape[1] else 1
        rows[row].append((img, text))  # type: ignore[arg-type]
    top = []
    for img, text in rows[0]:  # type: ignore[misc]
        s = HEIGHT / img.shape[0]
        t = cv2.resize(img, (round(img.shape[1] * s), HEIGHT), interpolation=cv2.INTER_AREA)
        _label(t, text)
        top.append(t)
    first = np.hstack(top)
    width = first.shape[1] // max(len(rows[1]), 1)
    bottom = []
    for img, text in rows[1]:  # type: ignore[misc]
        s = width / img.shape[1]
        t = cv2.resize(img, (width, round(img.shape[0] * s)), interpolation=cv2.INTER_AREA)
        _label(t, text)
        bottom.append(t)
    parts = [first]
    if bottom:
        second = np.hstack(bottom)
        pad = np.zeros((second.shape[0], first.shape[1] - second.shape[1], 3), np.uint8)
        parts.append(np.hstack([second, pad]))
    cv2.imwrite(dest, np.vstack(parts), [cv2.IMWRITE_PNG_COMPRESSION, 9])
    return 0


if __name__ == "__main__":
    data = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "video"
    vids = {f"cam0{i}": data / "pose2sim_demo_singleperson" / "videos" / f"cam0{i}.mp4"
            for i in range(1, 5)}  # fmt: skip
    vids["sports2d_demo"] = data / "sports2d_demo.mp4"
    sys.exit(main(sys.argv[1], sys.argv[2:], vids))
