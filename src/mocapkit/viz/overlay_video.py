"""A camera's video with captured (and true) canonical skeletons drawn over it, for the web.

Each frame shows the body model's limb silhouettes (`mocapkit.viz.overlay.draw_body`,
blended at a third so that the image stays visible) where joint parameters are known,
then the canonical sticks of every layer (`mocapkit.viz.overlay.draw_sticks`) and a
legend. The frames are encoded with `mocapkit.viz.web_video.WebVideoWriter`.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.errors import ShapeError
from mocapkit.io.video import VideoSource
from mocapkit.progress import Progress
from mocapkit.skeleton.model import Skeleton
from mocapkit.viz.overlay import draw_body, draw_sticks, draw_sticks_px
from mocapkit.viz.web_video import WebVideo, WebVideoWriter

FloatArray = NDArray[np.float64]
Colour = tuple[int, int, int]

#: Share of the body silhouettes in the blended image.
BODY_ALPHA = 0.35


@dataclass(frozen=True)
class OverlayLayer:
    """Canonical joints to draw at each video frame.

    Attributes
    ----------
    name : str
        Legend text.
    joint_names : tuple of str, length K
    joints_mm : ndarray, shape (N, K, 3) or (N, K, 2)
        World positions (mm) at each of the video's N frames, projected through the
        camera; or, with two columns, image points (px) drawn as they are (a detector's
        2-D keypoints); NaN where unknown.
    colour : BGR
    thickness : int
        Stick width (px).
    """

    name: str
    joint_names: tuple[str, ...]
    joints_mm: FloatArray
    colour: Colour
    thickness: int = 2


def write_overlay_video(
    folder: str | os.PathLike[str],
    stem: str,
    source: VideoSource,
    camera: Camera,
    layers: Sequence[OverlayLayer],
    body: tuple[Skeleton, FloatArray] | None = None,
) -> WebVideo:
    """Render the overlay video of one camera into ``folder``.

    Parameters
    ----------
    folder : path-like
    stem : str
        File name without suffix.
    source : VideoSource
        The camera's frames (their times set the frame rate: median step).
    camera : Camera
        Its calibration (image size must match the frames).
    layers : sequence of OverlayLayer
        Drawn in order (the last on top), each with one row per video frame.
    body : (Skeleton, q of shape (N, D)), optional
        Joint parameters per video frame whose silhouettes are blended in first (rows with
        NaN are skipped).

    Returns
    -------
    WebVideo
    """
    n = source.n_frames
    for layer in layers:
        if layer.joints_mm.shape[:2] != (n, len(layer.joint_names)) or layer.joints_mm.shape[
            2:
        ] not in ((3,), (2,)):
            raise ShapeError(
                f"overlay layer {layer.name!r}: expected joints of shape "
                f"({n}, {len(layer.joint_names)}, 3) or image points ({n}, "
                f"{len(layer.joint_names)}, 2) for {n} frames of {source.path}, found "
                f"{layer.joints_mm.shape}"
            )
    if body is not None and body[1].shape != (n, body[0].n_dofs):
        raise ShapeError(
            f"overlay body: expected q of shape ({n}, {body[0].n_dofs}), found {body[1].shape}"
        )
    steps = np.diff(source.time_s)
    fps = 1.0 / float(np.median(steps)) if steps.size and np.median(steps) > 0 else 30.0
    size = camera.image_size
    progress = Progress(n, f"overlay video {source.camera}")
    stream = source.open()
    try:
        with WebVideoWriter(folder, stem, fps, size) as writer:
            for i in range(n):
                stream.advance_to(i)
                image = np.array(stream.retrieve(i), dtype=np.uint8, copy=True)
                if body is not None and np.all(np.isfinite(body[1][i])):
                    painted = draw_body(image.copy(), body[0], camera, body[1][i])
                    image = np.asarray(
                        cv2.addWeighted(painted, BODY_ALPHA, image, 1.0 - BODY_ALPHA, 0.0),
                        dtype=np.uint8,
                    )
                for layer in layers:
                    if layer.joints_mm.shape[2] == 2:
                        draw_sticks_px(image, layer.joint_names, layer.joints_mm[i],
                                       layer.colour, layer.thickness)  # fmt: skip
                        continue
                    draw_sticks(
                        image,
                        camera,
                        layer.joint_names,
                        layer.joints_mm[i],
                        layer.colour,
                        layer.thickness,
                    )
                _legend(image, layers, float(source.time_s[i]))
                writer.write(image)
                progress.update()
    finally:
        stream.close()
        progress.close()
    return writer.result()


def _legend(image: NDArray[np.uint8], layers: Sequence[OverlayLayer], time_s: float) -> None:
    """Layer names in their colours and the frame time, top left, on a dark band."""
    lines = [(f"t = {time_s:.2f} s", (255, 255, 255))] + [(la.name, la.colour) for la in layers]
    h = 8 + 18 * len(lines)
    band = image[:h, :170]
    band[:] = (0.45 * band).astype(np.uint8)
    for k, (text, colour) in enumerate(lines):
        cv2.putText(
            image, text, (6, 18 + 18 * k), cv2.FONT_HERSHEY_SIMPLEX, 0.5, colour, 1, cv2.LINE_AA
        )


__all__ = ["BODY_ALPHA", "OverlayLayer", "write_overlay_video"]
