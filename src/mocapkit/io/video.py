"""Video frames of one camera: an mp4 read through OpenCV or a folder of images in frame order.

`VideoSource` gives random access by index; `VideoSource.open` gives a sequential
`FrameStream` (cheap ``grab``, decode on demand) whose frames are handed out as
`LazyFrame` objects, decoded only when a tracker needs the image.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import SessionError
from mocapkit.io.frame_files import in_frame_order
from mocapkit.io.session_options import PAD_MULTIPLE_PX

FloatArray = NDArray[np.float64]
#: File extensions of the images in an image-folder video (lower case).
IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


class VideoSource:
    """Frames of one camera: an mp4 (read with `cv2.VideoCapture`) or an image folder.

    Parameters
    ----------
    camera : str
    path : Path
        The video file or the image folder.
    time_s : (N,) float array
        Frame times (from ``timestamps.csv`` or the nominal rate).
    """

    def __init__(
        self, camera: str, path: Path, time_s: FloatArray, pad_px: tuple[int, int] = (0, 0)
    ) -> None:
        self.camera = camera
        self.path = path
        self.time_s = time_s
        self.pad_px = pad_px
        self.is_folder = path.is_dir()
        self._files: list[Path] = image_files(path) if self.is_folder else []

    def padded(self, image: NDArray[np.uint8]) -> NDArray[np.uint8]:
        """``image`` with ``pad_px`` = (right, bottom) black columns and rows added."""
        right, bottom = self.pad_px
        if not (right or bottom):
            return image
        return np.asarray(
            cv2.copyMakeBorder(image, 0, bottom, 0, right, cv2.BORDER_CONSTANT, value=0),
            dtype=np.uint8,
        )

    @property
    def n_frames(self) -> int:
        """Number of frames."""
        return int(self.time_s.shape[0])

    def read(self, index: int) -> NDArray[np.uint8]:
        """One frame (H, W, 3) BGR by index (random access; slow for videos)."""
        if not 0 <= index < self.n_frames:
            raise SessionError(f"{self.path}: frame {index} out of range [0, {self.n_frames})")
        if self.is_folder:
            return self.padded(read_image(self._files[index]))
        cap = cv2.VideoCapture(str(self.path))
        try:
            cap.set(cv2.CAP_PROP_POS_FRAMES, index)
            ok, img = cap.read()
        finally:
            cap.release()
        if not ok:
            raise SessionError(f"{self.path}: cannot decode frame {index}")
        return self.padded(np.asarray(img, dtype=np.uint8))

    def open(self) -> FrameStream:
        """A sequential reader (cheap `grab`, decode on demand)."""
        return FrameStream(self)


def read_image(path: Path) -> NDArray[np.uint8]:
    """One image file as (H, W, 3) uint8 BGR; `SessionError` when it cannot be read."""
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise SessionError(f"{path}: cannot read image")
    return np.asarray(img, dtype=np.uint8)


def image_files(folder: Path) -> list[Path]:
    """The images of an image-folder video (`IMAGE_EXTENSIONS`) in frame order: by the
    number in their names, without gaps or repeats (`mocapkit.io.frame_files`)."""
    images = [p for p in folder.iterdir() if p.suffix.lower() in IMAGE_EXTENSIONS]
    return in_frame_order(images, folder, "images")


def probe_video(path: Path, camera: str) -> tuple[int, float]:
    """Frame count and nominal rate of a video file or an image folder.

    Parameters
    ----------
    path : Path
        An mp4 (any file OpenCV opens) or a folder of images.
    camera : str
        The camera, for messages.

    Returns
    -------
    n_frames : int
        At least 1.
    fps : float
        The file's nominal rate (Hz); 0.0 for an image folder or when the file has none.

    Raises
    ------
    SessionError
        A folder without images, a file OpenCV cannot open, or a video without frames.
    """
    if path.is_dir():
        n = len(image_files(path))
        if n == 0:
            raise SessionError(
                f"{path}: image folder of camera {camera!r} holds no images "
                f"({', '.join(IMAGE_EXTENSIONS)})"
            )
        return n, 0.0
    cap = cv2.VideoCapture(str(path))
    try:
        if not cap.isOpened():
            raise SessionError(f"{path}: cannot open video of camera {camera!r}")
        n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        fps = float(cap.get(cv2.CAP_PROP_FPS))
    finally:
        cap.release()
    if n <= 0:
        raise SessionError(f"{path}: video of camera {camera!r} has no frames")
    return n, fps


def frame_size(path: Path, camera: str) -> tuple[int, int]:
    """``(width, height)`` in px of a video file or of an image folder's first image."""
    if path.is_dir():
        probe_video(path, camera)  # refuses a folder without images
        h, w = read_image(image_files(path)[0]).shape[:2]
        return int(w), int(h)
    cap = cv2.VideoCapture(str(path))
    try:
        if not cap.isOpened():
            raise SessionError(f"{path}: cannot open video of camera {camera!r}")
        w, h = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
    finally:
        cap.release()
    if w <= 0 or h <= 0:
        raise SessionError(f"{path}: video of camera {camera!r} has no frame size")
    return w, h


def padding_px(
    video_size: tuple[int, int], image_size: tuple[int, int], where: str, camera: str
) -> tuple[int, int]:
    """The (right, bottom) px that turn a video's frames into its camera's calibrated image.

    ``(0, 0)`` when the sizes are equal. When the calibration's width and height are the
    video's rounded up to a multiple of `PAD_MULTIPLE_PX` (an encoder's padding: a 1080 px
    wide video, a 1088 px calibration), the video is the calibrated image with its last
    columns or rows cut off: the principal point, counted from the top-left corner, is
    unchanged, and black columns and rows on the right and bottom give the frames back
    the calibrated size. Any other difference (a scaled, cropped or rotated video) raises
    `SessionError`.
    """
    padded = all(
        v == c or (v < c and c == -(-v // PAD_MULTIPLE_PX) * PAD_MULTIPLE_PX)
        for v, c in zip(video_size, image_size)
    )
    if not padded:
        raise SessionError(
            f"{where}: the video is {video_size[0]}x{video_size[1]} px, the calibration of "
            f"camera {camera!r} {image_size[0]}x{image_size[1]} px; expected the same size (or "
            f"the calibration's as the video's rounded up to a multiple of {PAD_MULTIPLE_PX} "
            "px, an encoder's padding); a scaled or cropped video needs its own calibration"
        )
    return image_size[0] - video_size[0], image_size[1] - video_size[1]


class FrameStream:
    """Sequential frame access: `advance_to` grabs the next frame, `retrieve` decodes it."""

    def __init__(self, source: VideoSource) -> None:
        self.source = source
        self.index = -1
        self._cap = None if source.is_folder else cv2.VideoCapture(str(source.path))
        self._cache: tuple[int, NDArray[np.uint8]] | None = None

    def advance_to(self, index: int) -> None:
        """Grab frames until the stream is at ``index`` (never moves backwards)."""
        while self.index < index:
            self.index += 1
            if self._cap is not None and not self._cap.grab():
                raise SessionError(f"{self.source.path}: cannot read frame {self.index}")

    def retrieve(self, index: int) -> NDArray[np.uint8]:
        """Decode frame ``index``: the current frame, or the last one decoded."""
        if self._cache is not None and self._cache[0] == index:
            return self._cache[1]
        if index != self.index:
            raise SessionError(
                f"{self.source.path}: frame {index} is no longer available (the stream is at "
                f"frame {self.index}); load images before advancing to the next sample"
            )
        if self._cap is None:
            img = read_image(self.source._files[index])
        else:
            ok, raw = self._cap.retrieve()
            if not ok:
                raise SessionError(f"{self.source.path}: cannot decode frame {index}")
            img = np.asarray(raw, dtype=np.uint8)
        img = self.source.padded(img)
        self._cache = (index, img)
        return img

    def close(self) -> None:
        """Release the video file."""
        if self._cap is not None:
            self._cap.release()


class LazyFrame:
    """A video frame decoded only when `load` is called (valid until the stream advances)."""

    def __init__(self, stream: FrameStream, index: int, time_s: float) -> None:
        self._stream = stream
        self.index = index
        self.time_s = time_s

    def load(self) -> NDArray[np.uint8]:
        """The frame (H, W, 3) uint8 BGR."""
        return self._stream.retrieve(self.index)


__all__ = [
    "IMAGE_EXTENSIONS",
    "PAD_MULTIPLE_PX",
    "FrameStream",
    "LazyFrame",
    "VideoSource",
    "frame_size",
    "image_files",
    "padding_px",
    "probe_video",
    "read_image",
]
