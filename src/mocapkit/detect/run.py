"""Run a detector over a video or a session: OpenPose JSON per frame, keypoints CSV, 3-D.

`detect_frames` runs a `Detector` frame by frame and follows one person
(`mocapkit.cues.follow.PersonFollower`, on the keypoints seen with confidence
`mocapkit.cues.follow.MIN_CONFIDENCE` or more); a backend that finds one person per call
(MediaPipe) is asked again on the region round the followed person's last box whenever
the whole frame gives someone else or nobody. Only the followed person enters the
result; bystanders never do.

`detect_video` writes, for one video (a file or an image folder)::

    <json_dir>/<frame:06d>_keypoints.json   OpenPose BODY_25, the followed person or nobody
    <world_path>                             (.npz, when the backend gives 3-D) time_s (T,),
                                             names (25,), world_mm (T, 25, 3) NaN where none

`detect_session` does so for every camera of a session and converts each camera's JSON
into the session's ``keypoints/<camera>.csv`` (`mocapkit.io.openpose.read_openpose_folder`,
which also places the canonical neck and pelvis)::

    keypoints/<camera>.csv               canonical keypoints every tracker reads
    keypoints/openpose/<camera>/         the JSON per frame (what OpenPose would write)
    keypoints3d/<camera>.npz             the backend's 3-D points, when it gives them
    keypoints/detect.json                backend, followed person, frames with a person

A camera whose ``keypoints/<camera>.csv`` exists is skipped (cached) unless
``overwrite``. Every file is written atomically; the JSON folder is built under a
temporary name and swapped in whole.
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.cues.follow import PersonFollower, seen_points
from mocapkit.detect.backend import (
    N_BODY_25,
    Detector,
    FloatArray,
    ImageArray,
    PersonPose,
    default_backend,
    install_hint,
    make_detector,
)
from mocapkit.errors import ConfigError, SessionError, ShapeError
from mocapkit.io.atomic import atomic_folder, atomic_save_npz, atomic_write
from mocapkit.io.openpose import (
    BODY_25,
    REBUILT_JOINTS,
    read_openpose_folder,
    write_openpose_frame,
)
from mocapkit.io.session import Session, load_session
from mocapkit.io.session_csv import read_keypoints_csv, write_keypoints_csv
from mocapkit.io.video import VideoSource, probe_video
from mocapkit.progress import Progress


@dataclass
class VideoDetections:
    """The followed person over one video.

    Attributes
    ----------
    keypoints : (T, 25, 3) float
        BODY_25 x_px, y_px, confidence; all 0 in frames without the person.
    world_mm : (T, 25, 3) float or None
        The backend's 3-D points (NaN where none); None when it gives none.
    followed : str
        Which person was followed (`PersonFollower.describe`).
    backend : str
    """

    keypoints: FloatArray
    world_mm: FloatArray | None
    followed: str
    backend: str
    roi_calls: int = 0

    @property
    def found(self) -> int:
        """Frames with the person."""
        return int(np.count_nonzero(self.keypoints[:, :, 2].max(axis=1) > 0))

    def summary(self) -> dict[str, object]:
        """What `detect_session` writes in ``detect.json`` for one camera."""
        return {
            "backend": self.backend,
            "followed": self.followed,
            "frames": int(self.keypoints.shape[0]),
            "frames_with_person": self.found,
        }


def detect_frames(
    frames: Iterable[ImageArray], detector: Detector, follower: PersonFollower
) -> Iterator[tuple[PersonPose | None, bool]]:
    """The followed person (or None) per frame, and whether the region was searched.

    A one-person backend is asked on the followed person's region (`PersonFollower.
    search_region`) first when it prefers so (``roi_first``), else after the whole frame
    gave nobody or somebody else.
    """
    for t, img in enumerate(frames):
        region = None if detector.multi_person else follower.search_region(img.shape)
        roi_used = region is not None and detector.roi_first
        people = _detect(detector, img, region if roi_used else None)
        pick = follower.choose(t, [seen_points(p.keypoints) for p in people])
        if pick is None and region is not None:
            roi_used = not roi_used
            people = _detect(detector, img, region if roi_used else None)
            pick = follower.choose(t, [seen_points(p.keypoints) for p in people])
        yield (people[pick] if pick is not None else None), roi_used


def _detect(
    detector: Detector, img: ImageArray, region: tuple[float, float, float, float] | None
) -> list[PersonPose]:
    try:
        return detector.detect(img, roi=region)
    except ShapeError:  # a region off the image (`crop_box`): nobody there
        if region is None:
            raise
        return []


def _frames(source: VideoSource) -> Iterator[ImageArray]:
    stream = source.open()
    try:
        for i in range(source.n_frames):
            stream.advance_to(i)
            yield stream.retrieve(i)
    finally:
        stream.close()


def detect_video(
    source: VideoSource,
    json_dir: str | os.PathLike[str],
    detector: Detector,
    *,
    start_px: tuple[float, float] | None = None,
    world_path: str | os.PathLike[str] | None = None,
    label: str = "",
) -> VideoDetections:
    """Detect and follow one person through a video; write OpenPose JSON per frame.

    Parameters
    ----------
    source : VideoSource
    json_dir : path-like
        Folder of the JSON files (replaced whole, atomically).
    detector : Detector
    start_px : (x, y), optional
        Follow the person at this point of the first frame (default: the largest).
    world_path : path-like, optional
        Where to write the backend's 3-D points (.npz), when it gives them.
    label : str
        Shown before the progress counts.
    """
    n = source.n_frames
    kp = np.zeros((n, N_BODY_25, 3))
    world = np.full((n, N_BODY_25, 3), np.nan)
    has_world = False
    follower = PersonFollower(start_px=start_px)
    roi_calls = found = 0
    with atomic_folder(json_dir) as tmp, Progress(n, label or source.camera) as bar:
        for t, (pose, roi_used) in enumerate(detect_frames(_frames(source), detector, follower)):
            roi_calls += roi_used
            if pose is not None:
                found += 1
                kp[t] = pose.keypoints
                if pose.world_mm is not None:
                    world[t], has_world = pose.world_mm, True
            write_openpose_frame(tmp / f"{t:06d}_keypoints.json", [kp[t]] if pose else [])
            bar.status = f"person in {found}"
            bar.update()
    if has_world and world_path is not None:
        atomic_save_npz(world_path, time_s=source.time_s, names=np.array(BODY_25),
                        world_mm=world)  # fmt: skip
    return VideoDetections(kp, world if has_world else None, follower.describe(),
                           detector.name, roi_calls)  # fmt: skip


@dataclass
class SessionDetections:
    """What `detect_session` did per camera."""

    cameras: dict[str, VideoDetections] = field(default_factory=dict)
    cached: list[str] = field(default_factory=list)


def detect_session(
    session_dir: str | os.PathLike[str],
    detector: Detector | str | None = None,
    *,
    start_px: dict[str, tuple[float, float]] | tuple[float, float] | None = None,
    overwrite: bool = False,
    out_dir: str | os.PathLike[str] | None = None,
) -> SessionDetections:
    """Detect the followed person in every camera of a session; write its keypoints.

    Parameters
    ----------
    session_dir : path-like
    detector : Detector, backend name or None
        None: the default installed backend (`make_detector`).
    start_px : (x, y) or camera -> (x, y), optional
        The person to follow (nearest this point on the first frame); default the largest.
    overwrite : bool
        Detect again where ``keypoints/<camera>.csv`` already exists.
    out_dir : path-like, optional
        Where to write (default: the session folder itself).
    """
    session = load_session(session_dir)
    if not session.video_cameras:
        raise SessionError(f"{session.path}: no video to detect people in (video/<camera>)")
    sources = [session.video(c) for c in session.video_cameras]
    out = Path(out_dir) if out_dir is not None else session.path
    return detect_sources(sources, out, detector, start_px=start_px, overwrite=overwrite)


def detect_sources(
    sources: Sequence[VideoSource],
    out_dir: str | os.PathLike[str],
    detector: Detector | str | None = None,
    *,
    start_px: dict[str, tuple[float, float]] | tuple[float, float] | None = None,
    overwrite: bool = False,
) -> SessionDetections:
    """`detect_session` for videos given one by one (each `VideoSource.camera` names its
    files); writes the session layout of the module docstring under ``out_dir``."""
    out = Path(out_dir)
    todo = [
        s for s in sources if overwrite or not (out / "keypoints" / f"{s.camera}.csv").is_file()
    ]
    result = SessionDetections(cached=[s.camera for s in sources if s not in todo])
    if not todo:
        return result
    own = not (detector is None or isinstance(detector, str))
    det = make_detector(detector) if detector is None or isinstance(detector, str) else detector
    summary_path = out / "keypoints" / "detect.json"
    try:
        summary = json.loads(summary_path.read_text()) if summary_path.is_file() else {}
    except json.JSONDecodeError:
        summary = {}
    try:
        for src in todo:
            cam = src.camera
            sp = start_px.get(cam) if isinstance(start_px, dict) else start_px
            json_dir = out / "keypoints" / "openpose" / cam
            res = detect_video(src, json_dir, det, start_px=sp, label=cam,
                               world_path=out / "keypoints3d" / f"{cam}.npz")  # fmt: skip
            kp = read_openpose_folder(json_dir, src.time_s)
            write_keypoints_csv(out / "keypoints" / f"{cam}.csv", kp.time_s, kp.joint_names,
                                kp.pixels)  # fmt: skip
            result.cameras[cam] = res
            summary[cam] = res.summary()
            with atomic_write(summary_path) as fh:
                json.dump(summary, fh, indent=1)
    finally:
        if not own:
            det.close()
    return result


#: Suffixes of the video files `detect_path` takes from a folder (lower case).
VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".webm", ".m4v")


def detect_path(
    source: str | os.PathLike[str],
    out_dir: str | os.PathLike[str] | None,
    detector: Detector | str | None = None,
    *,
    start_px: tuple[float, float] | None = None,
    overwrite: bool = False,
) -> SessionDetections:
    """What ``mocapkit detect SOURCE`` does: SOURCE is a session folder (``session.json``;
    ``out_dir`` defaults to it), a video file, or a folder of video files (`VIDEO_SUFFIXES`;
    ``out_dir`` required). Writes the layout of the module docstring under ``out_dir``,
    one camera per video, named by its file's stem."""
    src = Path(source)
    if not src.exists():
        raise SessionError(f"{src}: no such video, folder of videos or session folder")
    if src.is_dir() and (src / "session.json").is_file():
        return detect_session(src, detector, start_px=start_px, overwrite=overwrite,
                              out_dir=out_dir)  # fmt: skip
    if out_dir is None:
        raise ConfigError(f"{src}: --out is needed for a video or a folder of videos")
    if src.is_dir():
        files = sorted(f for f in src.iterdir() if f.suffix.lower() in VIDEO_SUFFIXES)
        if not files:
            raise SessionError(
                f"{src}: expected a session folder (session.json) or video files "
                f"({', '.join(VIDEO_SUFFIXES)}), found neither"
            )
    else:
        files = [src]
    return detect_sources([video_source(f) for f in files], out_dir, detector,
                          start_px=start_px, overwrite=overwrite)  # fmt: skip


def ensure_keypoints(
    session: Session,
    cameras: Sequence[str],
    detector: Detector | str | None = None,
    say: Callable[[str], None] | None = None,
) -> tuple[str, ...]:
    """Give every named camera of a loaded session its ``keypoints/<camera>.csv``: the
    ones missing are detected (`detect_session`, written into the session, so the next
    run reuses them) and put into ``session.keypoints``; what was done is said.

    The hook the trackers' pipelines call before they need keypoints.

    Returns
    -------
    tuple of str
        The cameras detected now (empty when all had keypoints).

    Raises
    ------
    SessionError
        Keypoints missing and no detector installed (the message says how to install one
        or where to put OpenPose JSON), or a camera without keypoints and without video.
    """
    missing = [c for c in cameras if c not in session.keypoints]
    if not missing:
        _mark_detected(session, cameras)
        return ()
    no_video = [c for c in missing if c not in session.video_cameras]
    if no_video:
        raise SessionError(
            f"{session.path}: no keypoints/<camera>.csv and no video to detect them in, for "
            f"cameras {no_video}"
        )
    if detector is None and default_backend() is None:
        raise SessionError(
            f"{session.path}: no keypoints/<camera>.csv for cameras {missing}; " + install_hint()
        )
    tell = say if say is not None else (lambda line: print(line, file=sys.stderr))
    name = default_backend() if detector is None else getattr(detector, "name", detector)
    tell(
        f"{session.path}: no keypoints for {', '.join(missing)}: detecting them with "
        f"{name} into keypoints/ (kept and reused next time)"
    )
    sources = [session.video(c) for c in missing]
    res = detect_sources(sources, session.path, detector)
    for cam in missing:
        session.keypoints[cam] = read_keypoints_csv(session.path / "keypoints" / f"{cam}.csv")
        d = res.cameras.get(cam)
        if d is not None:
            tell(f"{cam}: a person on {d.found} of {d.keypoints.shape[0]} frames; followed "
                 f"{d.followed}")  # fmt: skip
    _mark_detected(session, cameras)
    return tuple(missing)


def read_detect_summary(session_dir: str | os.PathLike[str]) -> dict[str, Any]:
    """What `detect_session` recorded per camera in ``keypoints/detect.json`` (backend,
    followed person, frames found); empty when the file is absent, unreadable or not a
    mapping of cameras."""
    path = Path(session_dir) / "keypoints" / "detect.json"
    try:
        summary = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return summary if isinstance(summary, dict) else {}


def detected_backend(session_dir: str | os.PathLike[str], cameras: Sequence[str]) -> str | None:
    """The detector backend that wrote every one of ``cameras``' keypoints, as
    ``keypoints/detect.json`` records it; ``None`` when the file is absent or unreadable,
    or the cameras' backends differ or are not given."""
    summary = read_detect_summary(session_dir)
    found = {
        summary[c].get("backend") if isinstance(summary.get(c), dict) else None for c in cameras
    }
    if len(found) != 1:
        return None
    (backend,) = found
    return backend if isinstance(backend, str) else None


def _mark_detected(session: Session, cameras: Sequence[str]) -> None:
    """Keypoints that `detect_session` wrote (``keypoints/detect.json`` lists their camera)
    carry a rebuilt neck and pelvis (`mocapkit.io.openpose.REBUILT_JOINTS`), which the CSV
    cannot say: set it on the session's `Keypoints`, so the trackers treat them as a
    detector's."""
    done = read_detect_summary(session.path)
    for cam in cameras:
        kp = session.keypoints.get(cam)
        if kp is not None and cam in done and not kp.rebuilt_joints:
            backend = done[cam].get("backend", "a detector") if isinstance(done[cam], dict) else ""
            session.keypoints[cam] = replace(
                kp, rebuilt_joints=REBUILT_JOINTS, source=f"{kp.source} (detected: {backend})"
            )


def video_source(path: str | os.PathLike[str], camera: str | None = None) -> VideoSource:
    """A video file or image folder outside a session, timed at its nominal rate (30 Hz
    when it has none)."""
    p = Path(path)
    cam = camera or p.stem
    n, fps = probe_video(p, cam)
    return VideoSource(cam, p, np.arange(n) / (fps if fps > 0 else 30.0))


__all__ = [
    "VIDEO_SUFFIXES",
    "SessionDetections",
    "VideoDetections",
    "detect_frames",
    "detect_path",
    "detect_session",
    "detect_sources",
    "detect_video",
    "detected_backend",
    "ensure_keypoints",
    "read_detect_summary",
    "video_source",
]
