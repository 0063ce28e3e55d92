"""Side-by-side views of one instant of a session, for documentation and visual checks."""

from __future__ import annotations

import os

import cv2
import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import SessionError
from mocapkit.io.session import load_session


def session_montage(
    session_path: str | os.PathLike[str], time_s: float, panel_width: int = 320
) -> NDArray[np.uint8]:
    """The frames of every camera nearest to ``time_s``, scaled to ``panel_width`` and labelled.

    Parameters
    ----------
    session_path : path-like
        Session folder.
    time_s : float
        Session time (s); the frame of the primary camera nearest to it is used.
    panel_width : int
        Width of each panel (px); heights keep the aspect ratio.

    Returns
    -------
    (H, W, 3) uint8 array
        BGR image with one panel per camera, left to right in cameras.json order.
    """
    session = load_session(session_path)
    session.require(video=True)
    times = session.video(session.video_cameras[0]).time_s
    target = int(np.argmin(np.abs(times - time_s)))
    for sample in session.samples():
        if sample.index != target:
            continue
        panels = []
        for cam in session.video_cameras:
            img = sample.image(cam)
            h, w = img.shape[:2]
            size = (panel_width, round(h * panel_width / w))
            small = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
            cv2.putText(
                small, cam, (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA
            )
            panels.append(small)
        return np.asarray(np.hstack(panels), dtype=np.uint8)
    raise SessionError(f"{session_path}: no frame near {time_s} s")
