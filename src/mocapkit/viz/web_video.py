"""Video files a web browser plays, written with OpenCV: VP8 or VP9 in WebM, else JPEG frames.

OpenCV's pip wheels carry an FFmpeg build with the libvpx encoders, so ``VP90``/``VP80``
in a ``.webm`` container usually work; H.264 (``avc1``) usually does not (no encoder in
the wheel), and MPEG-4 part 2 (``mp4v``) writes but Chromium does not decode it. Which
codec works is found by writing a tiny probe video and reading it back, once per process.
Where none works, the frames are written as a numbered JPEG sequence (``<stem>/000000.jpg``)
that a page can flip through: a fallback the caller reports (`WebVideo.codec` is
``"jpeg-sequence"``).
"""

from __future__ import annotations

import contextlib
import functools
import os
import shutil
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType

import cv2
import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import ShapeError

#: Codecs tried in order: (OpenCV fourcc, file suffix, MIME type with codec). VP8 first:
#: OpenCV's libvpx settings encode VP8 about 5x faster than VP9 (640x480 on one busy
#: core: 15 against 2.7 frames/s), for files under twice the size.
WEB_CODECS: tuple[tuple[str, str, str], ...] = (
    ("VP80", ".webm", 'video/webm; codecs="vp8"'),
    ("VP90", ".webm", 'video/webm; codecs="vp9"'),
)
#: `WebVideo.codec` when no codec works and frames are written as JPEG files.
JPEG_SEQUENCE = "jpeg-sequence"


@contextlib.contextmanager
def _quiet_native_stderr() -> Iterator[None]:
    """Silence file descriptor 2 for a moment: OpenCV's FFmpeg backend prints a harmless
    "tag 'VP90' is not supported with codec id 167 ... webm" notice from C code (it then
    writes the right WebM codec tag itself), which Python's stderr cannot catch."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _open_writer(path: str, fourcc: str, fps: float, size: tuple[int, int]) -> cv2.VideoWriter:
    with _quiet_native_stderr():
        return cv2.VideoWriter(path, cv2.VideoWriter.fourcc(*fourcc), fps, size)


@functools.cache
def web_codec() -> tuple[str, str, str] | None:
    """The first entry of `WEB_CODECS` that this OpenCV writes and reads back, or None."""
    with tempfile.TemporaryDirectory(prefix="mocapkit-codec-") as tmp:
        for fourcc, suffix, mime in WEB_CODECS:
            path = os.path.join(tmp, f"probe{suffix}")
            writer = _open_writer(path, fourcc, 30.0, (64, 48))
            try:
                if not writer.isOpened():
                    continue
                for i in range(3):
                    writer.write(np.full((48, 64, 3), 60 * i, dtype=np.uint8))
            finally:
                writer.release()
            cap = cv2.VideoCapture(path)
            try:
                ok, _ = cap.read()
            finally:
                cap.release()
            if ok:
                return fourcc, suffix, mime
    return None


@dataclass(frozen=True)
class WebVideo:
    """A finished web video.

    Attributes
    ----------
    path : Path
        The video file, or the folder of JPEG frames for the fallback.
    codec : str
        OpenCV fourcc (``"VP80"``, ``"VP90"``) or `JPEG_SEQUENCE`.
    mime : str
        MIME type for an HTML ``<source>`` (``"image/jpeg"`` for the fallback).
    n_frames : int
    fps : float
    size : tuple of int
        (width, height) px.
    """

    path: Path
    codec: str
    mime: str
    n_frames: int
    fps: float
    size: tuple[int, int]


class WebVideoWriter:
    """Write BGR frames to ``<folder>/<stem>.webm`` (or a JPEG folder); use as a context manager.

    The file is written under a temporary name and renamed into place when the block
    ends without an exception (an interrupted run leaves no half video).

    Parameters
    ----------
    folder : path-like
        Where the video goes.
    stem : str
        File name without suffix.
    fps : float
        Frame rate (Hz) stored in the file.
    size : tuple of int
        (width, height) px of every frame.
    """

    def __init__(
        self, folder: str | os.PathLike[str], stem: str, fps: float, size: tuple[int, int]
    ) -> None:
        if not (fps > 0 and np.isfinite(fps)):
            raise ShapeError(f"web video {stem!r}: expected a positive frame rate, found {fps!r}")
        self.folder = Path(folder)
        self.stem = stem
        self.fps = float(fps)
        self.size = (int(size[0]), int(size[1]))
        self.n_frames = 0
        self.folder.mkdir(parents=True, exist_ok=True)
        codec = web_codec()
        self._writer: cv2.VideoWriter | None = None
        if codec is None:
            self.codec, self.mime = JPEG_SEQUENCE, "image/jpeg"
            self.final = self.folder / stem
            self._tmp = Path(tempfile.mkdtemp(prefix=f".{stem}.", dir=self.folder))
        else:
            fourcc, suffix, self.mime = codec
            self.codec = fourcc
            self.final = self.folder / f"{stem}{suffix}"
            fd, name = tempfile.mkstemp(prefix=f".{stem}.", suffix=suffix, dir=self.folder)
            os.close(fd)
            self._tmp = Path(name)
            self._writer = _open_writer(name, fourcc, self.fps, self.size)

    def write(self, frame: NDArray[np.uint8]) -> None:
        """Append one BGR frame of shape (height, width, 3)."""
        w, h = self.size
        if frame.shape != (h, w, 3) or frame.dtype != np.uint8:
            raise ShapeError(
                f"web video {self.stem!r}: expected uint8 frames of shape ({h}, {w}, 3), found "
                f"{frame.shape} {frame.dtype}"
            )
        if self._writer is not None:
            self._writer.write(frame)
        else:
            cv2.imwrite(
                str(self._tmp / f"{self.n_frames:06d}.jpg"), frame, [cv2.IMWRITE_JPEG_QUALITY, 85]
            )
        self.n_frames += 1

    def __enter__(self) -> WebVideoWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._writer is not None:
            self._writer.release()
        if exc_type is not None:
            if self._tmp.is_dir():
                shutil.rmtree(self._tmp, ignore_errors=True)
            else:
                self._tmp.unlink(missing_ok=True)
            return
        # mkstemp/mkdtemp make private entries; a video beside a page is for everyone to read
        os.chmod(self._tmp, 0o755 if self._tmp.is_dir() else 0o644)
        if self.final.is_dir():
            shutil.rmtree(self.final)
        os.replace(self._tmp, self.final)

    def result(self) -> WebVideo:
        """What was written (call after the ``with`` block)."""
        return WebVideo(self.final, self.codec, self.mime, self.n_frames, self.fps, self.size)


__all__ = ["JPEG_SEQUENCE", "WEB_CODECS", "WebVideo", "WebVideoWriter", "web_codec"]
