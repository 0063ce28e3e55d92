"""2-D pose detection built in: keypoints from plain videos (docs/detect.md).

Backends (one module each) find people as OpenPose BODY_25 keypoints
(`backend.Detector`); `follow` keeps one person through a video; `run` writes OpenPose
JSON per frame and a session's ``keypoints/<camera>.csv``. A side package beside `io`:
it reads images and writes keypoints through `mocapkit.io`, and is used from `pipelines`
and `cli`.
"""

from mocapkit.detect.backend import (
    Detector,
    DetectorUnavailable,
    PersonPose,
    backend_names,
    default_backend,
    install_hint,
    make_detector,
)
from mocapkit.detect.run import detect_session, detect_video, video_source

__all__ = [
    "Detector",
    "DetectorUnavailable",
    "PersonPose",
    "backend_names",
    "default_backend",
    "detect_session",
    "detect_video",
    "install_hint",
    "make_detector",
    "video_source",
]
