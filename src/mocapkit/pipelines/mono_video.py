"""The monocular tracker on a plain video file (no session): skin blobs -> 3-D -> montage.

For real footage such as the Sports2D and Pose2Sim demos (``docs/mono.md``):

1. frames of the whole video are read at a working size (longest side ``size_px``);
2. the background is the per-pixel median of every third frame
   (`mocapkit.cues.foreground.median_background`), and each frame's skin mask is kept
   only inside one moving region (`foreground_mask`, `largest_region`, grown by
   ``grow_px``): the subject followed is the largest moving region of the clip's first
   frame, then in each frame the region overlapping the last one most;
3. `mocapkit.tracking.mono.skin_tracking.SkinTracker` labels the blobs and reads the
   joints, with ``trunk_from_head`` (no golden belt in these videos);
4. the 3-D step runs on the frames of ``[start_s, start_s + seconds)``: orthographic
   without a camera (the paper's model; lengths in px from the video), perspective with
   one (its intrinsics scaled to the working size);
5. a montage of ``tiles`` frames evenly spread over the clip: the frame with the skin
   pixels kept tinted magenta, the labelled ellipses (yellow), the 2-D joints read off
   them (white dots), the chosen 3-D pose reprojected (orange stick) and, in the corner,
   the same pose seen from the subject's left side (depth to the right, blue), which
   shows the flips chosen. Frames without a pose say so.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.cues.blobs import Blob, mask_blobs
from mocapkit.cues.foreground import foreground_mask, largest_region, median_background
from mocapkit.cues.skin import skin_mask
from mocapkit.errors import ConfigError, SessionError
from mocapkit.io.atomic import atomic_write
from mocapkit.progress import Progress
from mocapkit.tracking.mono.skin_tracking import SKIN_JOINTS, SkinFrame, SkinTracker
from mocapkit.tracking.mono.stick import StickModel, stick_model
from mocapkit.tracking.mono.tracker import MonoConfig, MonoFrame

FloatArray = NDArray[np.float64]
UInt8Array = NDArray[np.uint8]


@dataclass
class VideoTrack:
    """What `track_video` produced.

    Attributes
    ----------
    frames_bgr : list of (H, W, 3) uint8
        The clip's frames at the working size.
    time_s : (T,) float
    skin : list of SkinFrame
    kept_masks : list of (H, W) uint8
        Skin pixels kept (inside the moving region).
    pixels : (T, K, 2) float
        Stick joints read off the blobs (px at the working size), NaN where unseen.
    poses : list of MonoFrame
        The 3-D step's answer per frame (empty when no frame had a trunk).
    model : StickModel
    camera : Camera or None
        The camera at the working size (None: orthographic).
    """

    frames_bgr: list[UInt8Array]
    time_s: FloatArray
    skin: list[SkinFrame]
    kept_masks: list[UInt8Array]
    pixels: FloatArray
    poses: list[MonoFrame]
    model: StickModel
    camera: Camera | None

    def summary(self) -> dict[str, float]:
        """Frames, frames with each blob label, with a pose, mean survivors and pruned share."""
        n = len(self.skin)
        out = {"frames": float(n)}
        for label in ("head", "left_hand", "right_hand", "waist"):
            out[f"{label}_frames"] = float(sum(label in f.blobs for f in self.skin))
        posed = [f for f in self.poses if f.code >= 0]
        out["posed_frames"] = float(len(posed))
        if posed:
            cand = np.array([f.n_candidates for f in posed], dtype=float)
            surv = np.array([f.n_survivors for f in posed], dtype=float)
            out["survivors_mean"] = float(surv.mean())
            out["pruned_share_mean"] = float(np.mean(1.0 - surv / np.maximum(cand, 1.0)))
        return out


def read_frames(path: str | os.PathLike[str], size_px: int) -> tuple[list[UInt8Array], float]:
    """Every frame of a video, resized so that its longest side is ``size_px``; and its fps."""
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise SessionError(f"{path}: cannot open the video")
    fps = float(cap.get(cv2.CAP_PROP_FPS)) or 30.0
    frames: list[UInt8Array] = []
    try:
        while True:
            ok, img = cap.read()
            if not ok:
                break
            s = size_px / max(img.shape[:2])
            frames.append(
                np.asarray(cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA))
            )
    finally:
        cap.release()
    if not frames:
        raise SessionError(f"{path}: the video has no frames")
    return frames, fps


def scaled_camera(camera: Camera, size: tuple[int, int]) -> Camera:
    """The camera with its intrinsics scaled to an image of ``size`` (W, H) px.

    One scale, the ratio of the longest sides: a video a few px narrower than its
    calibration (Pose2Sim's cam01: 1080 wide, calibrated at 1088) is taken as cropped at
    the right, not squeezed.
    """
    s = max(size) / max(camera.image_size)
    k = np.array(camera.K, dtype=float)
    k[:2] *= s
    return replace(camera, K=k, image_size=(int(size[0]), int(size[1])))


def track_video(
    video: str | os.PathLike[str],
    start_s: float = 0.0,
    seconds: float = 4.0,
    size_px: int = 640,
    camera: Camera | None = None,
    grow_px: int = 12,
    threshold: float = 30.0,
) -> VideoTrack:
    """Skin-blob 2-D tracking and the 3-D step on a clip of a video (module docstring).

    Parameters
    ----------
    video : path-like
    start_s, seconds : float
        The clip (s).
    size_px : int
        Longest side of the working images (px).
    camera : Camera, optional
        Calibration of the full-size video: perspective model; else orthographic.
    grow_px : int
        Growth of the moving region the skin must lie in (px).
    threshold : float
        Foreground threshold (grey levels).
    """
    if seconds <= 0 or start_s < 0 or size_px < 32:
        raise ConfigError(
            f"track_video: expected start_s >= 0, seconds > 0, size_px >= 32; found "
            f"{start_s}, {seconds}, {size_px}"
        )
    frames, fps = read_frames(video, size_px)
    background = median_background(frames[::3])
    first = round(start_s * fps)
    last = min(len(frames), first + round(seconds * fps))
    if first >= last:
        raise ConfigError(
            f"{video}: the clip {start_s}-{start_s + seconds} s lies after the video's end "
            f"({len(frames) / fps:.2f} s)"
        )
    clip = frames[first:last]
    t = (first + np.arange(len(clip))) / fps
    tracker = SkinTracker(trunk_from_head=True)
    skin: list[SkinFrame] = []
    kept: list[UInt8Array] = []
    region: UInt8Array | None = None
    with Progress(len(clip), "skin blobs") as prog:
        for img in clip:
            fg = foreground_mask(img, background, threshold, 2)
            region = largest_region(fg, grow_px, region)
            mask = np.where(region != 0, skin_mask(img), 0).astype(np.uint8)
            kept.append(mask)
            skin.append(tracker.update_blobs(mask_blobs(mask, tracker.min_area_px, 2)))
            prog.update()
    h, w = clip[0].shape[:2]
    cam = None if camera is None else scaled_camera(camera, (w, h))
    cfg = MonoConfig(camera_model="orthographic" if cam is None else "perspective")
    model = stick_model(cfg.legs, cfg.limits)
    px = np.full((len(clip), model.n_joints, 2), np.nan)
    rows = [SKIN_JOINTS.index(n) for n in model.joint_names]
    for k, f in enumerate(skin):
        px[k] = f.joints_px[rows]
    poses: list[MonoFrame] = []
    trunk = model.child[model.link_index("trunk")]
    if np.isfinite(px[:, [0, trunk]]).all(axis=(1, 2)).any():
        from mocapkit.pipelines.mono import _run, video_lengths

        dt = 1.0 / fps
        lengths, _ = video_lengths(px, model, cam, cfg, dt, None)
        poses = list(_run(lengths, cam, dt, cfg, model, t, px))
    return VideoTrack(clip, t, skin, kept, px, poses, model, cam)


def _pt(p: FloatArray) -> tuple[int, int]:
    return round(float(p[0])), round(float(p[1]))


def _draw_ellipse(img: UInt8Array, b: Blob, colour: tuple[int, int, int]) -> None:
    ang = float(np.degrees(np.arctan2(b.direction[1], b.direction[0])))
    centre = _pt(b.centre)
    axes = (max(round(b.major), 1), max(round(b.minor), 1))
    cv2.ellipse(img, centre, axes, ang, 0, 360, colour, 1, cv2.LINE_AA)


def _draw_stick(
    img: UInt8Array, model: StickModel, pts: FloatArray, colour: tuple[int, int, int], r: int
) -> None:
    for a, b in zip(model.parent, model.child):
        if np.isfinite(pts[[a, b]]).all():
            cv2.line(img, _pt(pts[a]), _pt(pts[b]), colour, 2, cv2.LINE_AA)
    for p in pts:
        if np.isfinite(p).all():
            cv2.circle(img, _pt(p), r, colour, -1, cv2.LINE_AA)


def _projected(track: VideoTrack, f: MonoFrame) -> FloatArray:
    pos = f.joints_in_camera
    if track.camera is None:
        return np.asarray(pos[:, :2], dtype=float)
    out = np.full((pos.shape[0], 2), np.nan)
    ok = np.isfinite(pos).all(axis=1)
    if ok.any():
        out[ok] = track.camera.project_camera_points(pos[ok])
    return out


def _side_view(track: VideoTrack, f: MonoFrame, size: int) -> UInt8Array:
    """The pose from the subject's left: camera depth to the right, image y down."""
    pane = np.full((size, size, 3), 40, dtype=np.uint8)
    pos = f.joints_in_camera
    ok = np.isfinite(pos).all(axis=1)
    if not ok.any():
        return pane
    side = np.stack([pos[:, 2], pos[:, 1]], axis=1)
    c = np.nanmean(side[ok], axis=0)
    extent = max(float(np.nanmax(np.abs(side[ok] - c))), 1e-6)
    pts = (side - c) * (0.42 * size / extent) + size / 2
    _draw_stick(pane, track.model, pts, (255, 160, 60), 2)
    cv2.putText(pane, "side", (3, 12), cv2.FONT_HERSHEY_SIMPLEX, 0.35, (200, 200, 200), 1)
    return pane


def draw_frame(track: VideoTrack, k: int) -> UInt8Array:
    """Frame ``k`` of the clip with the overlays of the module docstring."""
    img = track.frames_bgr[k].copy()
    skin = track.kept_masks[k] != 0
    img[skin] = (0.5 * img[skin] + 0.5 * np.array([255, 0, 255])).astype(np.uint8)
    for blob in track.skin[k].blobs.values():
        _draw_ellipse(img, blob, (0, 255, 255))
    pose = track.poses[k] if k < len(track.poses) else None
    if pose is not None and pose.code >= 0:
        _draw_stick(img, track.model, _projected(track, pose), (0, 165, 255), 2)
        pane = _side_view(track, pose, max(img.shape[0] // 4, 40))
        img[: pane.shape[0], -pane.shape[1] :] = pane
        text = f"{track.time_s[k]:.2f} s  {pose.n_survivors}/{pose.n_candidates} poses"
    else:
        text = f"{track.time_s[k]:.2f} s  no pose"
    for j in track.pixels[k]:
        if np.isfinite(j).all():
            cv2.circle(img, _pt(j), 3, (255, 255, 255), -1)
    labels = ", ".join(sorted(track.skin[k].blobs)) or "no blobs"
    cv2.rectangle(img, (0, 0), (250, 40), (0, 0, 0), -1)
    cv2.putText(img, text, (4, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1)
    cv2.putText(img, labels, (4, 34), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1)
    return img


def montage(track: VideoTrack, tiles: int = 6, columns: int = 3, tile_px: int = 480) -> UInt8Array:
    """``tiles`` frames of the clip, evenly spread, in a grid of ``columns``.

    Each tile is drawn at the working size and shrunk to a longest side of ``tile_px``;
    colours are kept to 5 bits per channel so that the PNG stays small.
    """
    if tiles < 1 or columns < 1:
        raise ConfigError(f"montage: expected tiles, columns >= 1, found {tiles}, {columns}")
    n = len(track.frames_bgr)
    picks = np.linspace(0, n - 1, min(tiles, n)).round().astype(int)
    images = []
    for k in picks:
        img = draw_frame(track, int(k))
        s = min(1.0, tile_px / max(img.shape[:2]))
        small = np.asarray(cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA))
        images.append(np.asarray((small // 8) * 8 + 4, dtype=np.uint8))
    blank = np.zeros_like(images[0])
    while len(images) % columns:
        images.append(blank)
    rows = [np.hstack(images[i : i + columns]) for i in range(0, len(images), columns)]
    return np.vstack(rows)


def write_png(path: str | os.PathLike[str], image: UInt8Array) -> None:
    """Write a BGR image as PNG, atomically."""
    ok, buf = cv2.imencode(".png", image, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    if not ok:
        raise SessionError(f"{path}: PNG encoding failed")
    with atomic_write(Path(path), "wb") as fh:
        fh.write(buf.tobytes())


__all__ = ["VideoTrack", "draw_frame", "montage", "read_frames", "scaled_camera", "track_video"]
