"""2-D keypoints of a session's views with MediaPipe Pose, written as OpenPose BODY_25 JSON.

A stand-in for an OpenPose run where none is at hand: MediaPipe is not a mocapkit
dependency, and this script imports nothing from mocapkit, so it runs in any Python
that has ``mediapipe`` (0.10.x, whose legacy ``solutions.pose`` ships its model in the
wheel) and ``opencv-python``::

    python3 -m venv /tmp/mp && /tmp/mp/bin/pip install mediapipe==0.10.21
    /tmp/mp/bin/python examples/mediapipe_openpose_json.py SESSION OUT

For every camera folder ``SESSION/video/<camera>/`` (images in name order, as
`examples/pose2sim_stereo.py` writes them) or video file ``SESSION/video/<camera>.mp4``
(as ``mocapkit synth`` writes them) it writes ``OUT/<camera>/<frame>_keypoints.json``
in OpenPose's ``--write_json`` layout (BODY_25, confidences = MediaPipe's visibility;
OpenPose's "Neck" and "MidHip" are the shoulder and hip midpoints, as OpenPose's own),
which `mocapkit.io.openpose.read_openpose_folder` reads. One person per frame
(MediaPipe Pose finds the most prominent one).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import cv2
import mediapipe as mp
import numpy as np

# BODY_25 index -> MediaPipe Pose landmark index (-1: midpoint rules below; -2: none)
BODY_25_FROM_MEDIAPIPE = {
    0: 0,  # Nose
    1: -1,  # Neck = shoulder midpoint
    2: 12,  # RShoulder
    3: 14,  # RElbow
    4: 16,  # RWrist
    5: 11,  # LShoulder
    6: 13,  # LElbow
    7: 15,  # LWrist
    8: -1,  # MidHip = hip midpoint
    9: 24,  # RHip
    10: 26,  # RKnee
    11: 28,  # RAnkle
    12: 23,  # LHip
    13: 25,  # LKnee
    14: 27,  # LAnkle
    15: 5,  # REye
    16: 2,  # LEye
    17: 8,  # REar
    18: 7,  # LEar
    19: 31,  # LBigToe (foot index)
    20: -2,  # LSmallToe
    21: 29,  # LHeel
    22: 32,  # RBigToe
    23: -2,  # RSmallToe
    24: 30,  # RHeel
}


def body25(landmarks: np.ndarray) -> list[float]:
    """BODY_25 ``[x, y, c] * 25`` from MediaPipe landmarks (33, 3): x px, y px, visibility."""
    out = np.zeros((25, 3))
    for k, m in BODY_25_FROM_MEDIAPIPE.items():
        if m >= 0:
            out[k] = landmarks[m]
    for k, (a, b) in ((1, (11, 12)), (8, (23, 24))):
        out[k, :2] = 0.5 * (landmarks[a, :2] + landmarks[b, :2])
        out[k, 2] = min(landmarks[a, 2], landmarks[b, 2])
    return [round(float(v), 3) for v in out.reshape(-1)]


def _frames(source: Path):
    """Frames (BGR) of an image folder (name order) or of a video file."""
    if source.is_dir():
        for f in sorted(source.iterdir()):
            yield cv2.imread(str(f))
        return
    cap = cv2.VideoCapture(str(source))
    try:
        while True:
            ok, img = cap.read()
            if not ok:
                return
            yield img
    finally:
        cap.release()


def main(session: Path, out: Path) -> int:
    video = session / "video"
    sources = sorted(
        p for p in video.iterdir() if p.is_dir() or p.suffix.lower() in (".mp4", ".avi", ".mkv")
    )
    for source in sources:
        name = source.name if source.is_dir() else source.stem
        dest = out / name
        dest.mkdir(parents=True, exist_ok=True)
        pose = mp.solutions.pose.Pose(static_image_mode=False, model_complexity=1)
        found = n = 0
        for k, img in enumerate(_frames(source)):
            n += 1
            h, w = img.shape[:2]
            res = pose.process(cv2.cvtColor(img, cv2.COLOR_BGR2RGB))
            people = []
            if res.pose_landmarks is not None:
                lm = np.array(
                    [
                        [p.x * w - 0.5, p.y * h - 0.5, p.visibility]
                        for p in res.pose_landmarks.landmark
                    ]
                )
                people.append({"pose_keypoints_2d": body25(lm)})
                found += 1
            (dest / f"{k:06d}_keypoints.json").write_text(
                json.dumps({"version": 1.3, "people": people})
            )
        print(f"{name}: a person on {found} of {n} frames")
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1]), Path(sys.argv[2])))
