"""A session folder from what a lab has: videos, a calibration file, OpenPose keypoints.

`build_session` (``mocapkit session``) takes one video per camera, named by the camera
(``cam01.mp4`` is camera ``cam01``), a calibration in any format `load_cameras` reads
(Pose2Sim/anipose/FreeMoCap ``Calib.toml``, Qualisys ``.qca.txt``, OpenCV YAML/XML, one
file per camera, our ``cameras.json``) and optionally a folder of OpenPose JSON folders,
one per camera, named ``<camera>`` or ``<camera>_json`` (as Pose2Sim's ``pose/``). Every
check runs before anything is written:

- **Names.** Each video's camera is found in the calibration by its exact name, else by
  the name with case, ``_``, ``-``, ``.`` and the leading zeros of numbers ignored
  (``cam_01`` = ``cam01`` = ``Cam1``), when that is unique. Calibrated cameras without a
  video are left out, with a warning.
- **Image size** (`mocapkit.io.video.padding_px`, the session loader's rule). A video the
  size of the calibration's image is taken as it is. A video smaller than the
  calibration's image by what an encoder pads (the calibration's width and height are the
  video's rounded up to a multiple of 16, e.g. 1080 -> 1088) is that image with its last
  columns or rows cut off: the camera keeps its calibration, the session pads the frames
  back in black on the right and bottom when it reads them (`InputWarning`). Any other
  difference (a scaled or cropped video, portrait against landscape) is refused.
- **Frames.** Every video has the same frame count and frame rate (within
  ``RATE_TOLERANCE``); otherwise refused: the trackers pair frames by time, and videos of
  different lengths are not one synchronised recording.
- **Keypoints.** Each camera's OpenPose folder holds one JSON file per video frame
  (`mocapkit.io.openpose.read_openpose_folder`), written as ``keypoints/<camera>.csv``.

The folder is built beside ``out`` and swapped in whole (`mocapkit.io.atomic`), then
loaded with `load_session` (every session check) before the swap.
"""

from __future__ import annotations

import dataclasses
import os
import re
import shutil
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from mocapkit.camera.pinhole import Camera
from mocapkit.errors import InputWarning, SessionError
from mocapkit.io.atomic import atomic_folder, remove_stale_temporaries
from mocapkit.io.cameras import load_cameras, write_cameras
from mocapkit.io.openpose import read_openpose_folder
from mocapkit.io.session import Session, load_session, write_session_json
from mocapkit.io.session_csv import write_keypoints_csv
from mocapkit.io.video import frame_size, padding_px, probe_video

PathLike = str | os.PathLike[str]

#: Largest relative difference between two videos' frame rates taken as the same rate.
RATE_TOLERANCE = 1e-3


@dataclass(frozen=True)
class BuiltSession:
    """What `build_session` wrote.

    Attributes
    ----------
    path : Path
        The session folder.
    cameras : tuple of str
        Camera names, in the order of the videos given.
    n_frames : int
    rate_hz : float
    keypoints : bool
        Whether ``keypoints/<camera>.csv`` were written.
    notes : tuple of str
        What was changed on the way (the same text as the warnings).
    """

    path: Path
    cameras: tuple[str, ...]
    n_frames: int
    rate_hz: float
    keypoints: bool
    notes: tuple[str, ...]


def _name_key(name: str) -> str:
    """``cam_01``, ``Cam01`` and ``cam1`` -> ``cam1``."""
    low = re.sub(r"[\s_.\-]", "", name.lower())
    return re.sub(r"\d+", lambda m: str(int(m.group())), low)


def match_cameras(
    names: Sequence[str], cameras: Sequence[Camera], source: str
) -> tuple[list[Camera], list[str]]:
    """The calibrated camera of each video name, renamed to it, and the cameras left out."""
    by_name = {c.name: c for c in cameras}
    chosen: list[Camera] = []
    for name in names:
        cam = by_name.get(name)
        if cam is None:
            alike = [c for c in cameras if _name_key(c.name) == _name_key(name)]
            if len(alike) != 1:
                raise SessionError(
                    f"{source}: no camera named {name!r} (from the video's file name); the "
                    f"calibration has {[c.name for c in cameras]}: rename the video or the "
                    "camera so that they match"
                )
            cam = dataclasses.replace(alike[0], name=name)
        chosen.append(cam)
    used = {_name_key(n) for n in names} | set(names)
    unused = [c.name for c in cameras if c.name not in used and _name_key(c.name) not in used]
    return chosen, unused


def keypoint_folder(folder: Path, camera: str) -> Path:
    """``folder/<camera>`` or ``folder/<camera>_json`` (exactly one of them)."""
    found = [p for p in (folder / camera, folder / f"{camera}_json") if p.is_dir()]
    if len(found) != 1:
        what = "both" if found else "neither"
        raise SessionError(
            f"{folder}: expected one OpenPose JSON folder for camera {camera!r}, named "
            f"{camera!r} or '{camera}_json'; found {what} (folders there: "
            f"{sorted(p.name for p in folder.iterdir() if p.is_dir())})"
        )
    return found[0]


def _frames(videos: Sequence[Path], names: Sequence[str], rate_hz: float | None) -> float:
    """The videos' common frame rate; refuses different frame counts or rates."""
    counts, rates = [], []
    for video, name in zip(videos, names):
        n, fps = probe_video(video, name)
        counts.append(n)
        rates.append(rate_hz if rate_hz is not None else fps)
    if len(set(counts)) > 1:
        listed = ", ".join(f"{n} {c}" for n, c in zip(names, counts))
        raise SessionError(
            f"videos of different lengths ({listed} frames); expected one synchronised "
            "recording: cut every video to the same frames"
        )
    if any(r <= 0 for r in rates):
        bad = [n for n, r in zip(names, rates) if r <= 0]
        raise SessionError(f"no frame rate for {bad} (an image folder has none): give rate_hz")
    if max(rates) > min(rates) * (1 + RATE_TOLERANCE):
        listed = ", ".join(f"{n} {r:g}" for n, r in zip(names, rates))
        raise SessionError(
            f"videos at different frame rates ({listed} Hz); expected one synchronised "
            "recording at one rate"
        )
    return float(rates[0])


def build_session(
    videos: Sequence[PathLike],
    calibration: Sequence[PathLike],
    out: PathLike,
    keypoints: PathLike | None = None,
    calibration_unit: str | None = None,
    rate_hz: float | None = None,
) -> BuiltSession:
    """Build a session folder at ``out`` (module docstring for the rules).

    Parameters
    ----------
    videos : sequence of path-like
        One video file (or image folder) per camera; its stem names the camera.
    calibration : sequence of path-like
        One calibration file, or one OpenCV YAML/XML file per camera.
    out : path-like
        The session folder to write; an existing folder must be empty or a session.
    keypoints : path-like, optional
        Folder of OpenPose JSON folders, one per camera.
    calibration_unit : {"m", "mm"}, optional
        Unit of a ``Calib.toml``'s translations (default: read from their size).
    rate_hz : float, optional
        Frame rate of every video (default: the files' own).
    """
    paths = [Path(v) for v in videos]
    if not paths:
        raise SessionError("expected one video per camera, found none")
    for p in paths:
        if not p.exists():
            raise SessionError(f"{p}: video not found")
    names = [p.name if p.is_dir() else p.stem for p in paths]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise SessionError(f"two videos of camera(s) {dup}: each file name names one camera")
    target = Path(out)
    if target.exists() and not target.is_dir():
        raise SessionError(f"{target}: expected a session folder to write, found a file")
    if target.is_dir() and any(target.iterdir()) and not (target / "session.json").is_file():
        raise SessionError(
            f"{target}: the folder holds files and no session.json; expected an empty folder "
            "or a session to replace"
        )
    cal_paths = [Path(c) for c in calibration]
    if not cal_paths:
        raise SessionError("expected a calibration file, found none")
    calibrated: list[Camera] = []
    for c in cal_paths:
        calibrated.extend(load_cameras(c, calibration_unit))
    source = ", ".join(str(c) for c in cal_paths)
    cams, unused = match_cameras(names, calibrated, source)
    notes: list[str] = []
    if unused:
        notes.append(f"{source}: camera(s) {unused} have no video and are left out")
        warnings.warn(notes[-1], InputWarning, stacklevel=2)
    for cam, p in zip(cams, paths):
        pad = padding_px(frame_size(p, cam.name), cam.image_size, str(p), cam.name)
        if pad != (0, 0):
            notes.append(
                f"{p}: the video is {pad[0]} columns and {pad[1]} rows smaller than the "
                f"calibrated image of camera {cam.name!r} ({cam.image_size[0]}x"
                f"{cam.image_size[1]} px): taken as that image cut on the right and bottom "
                "(encoder padding); the session pads its frames back in black"
            )
            warnings.warn(notes[-1], InputWarning, stacklevel=2)
    rate = _frames(paths, names, rate_hz)
    kp_dir = Path(keypoints) if keypoints is not None else None
    kp_folders: list[Path] = []
    if kp_dir is not None:
        if not kp_dir.is_dir():
            raise SessionError(
                f"{kp_dir}: expected a folder of OpenPose JSON folders (one per camera), "
                + ("found a file" if kp_dir.exists() else "not found")
            )
        kp_folders = [keypoint_folder(kp_dir, n) for n in names]

    remove_stale_temporaries(target.parent, target.name)
    with atomic_folder(target) as tmp:
        (tmp / "video").mkdir()
        for p, n in zip(paths, names):
            if p.is_dir():
                shutil.copytree(p, tmp / "video" / n)
            else:
                shutil.copyfile(p, tmp / "video" / f"{n}{p.suffix.lower()}")
        write_cameras(tmp / "cameras.json", cams)
        write_session_json(
            tmp / "session.json",
            {
                "rates": {"video_hz": rate},
                "source": {
                    "videos": [str(p) for p in paths],
                    "calibration": [str(c) for c in cal_paths],
                    **({"keypoints": str(kp_dir)} if kp_dir is not None else {}),
                },
            },
        )
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", InputWarning)
            if kp_folders:
                (tmp / "keypoints").mkdir()
                first: Session = load_session(tmp)
                for n, folder in zip(names, kp_folders):
                    kp = read_openpose_folder(folder, first.video(n).time_s)
                    write_keypoints_csv(
                        tmp / "keypoints" / f"{n}.csv", kp.time_s, kp.joint_names, kp.pixels
                    )
            session = load_session(tmp)  # every session check, before the swap
        n_frames = session.video(names[0]).n_frames
    for w in caught:  # the keypoints' warnings (the padding is said above), as of ``out``
        text = str(w.message).replace(str(tmp), str(target))
        if issubclass(w.category, InputWarning) and "encoder padding" not in text:
            if text not in notes:
                notes.append(text)
                warnings.warn(text, InputWarning, stacklevel=2)
    return BuiltSession(target, tuple(names), n_frames, rate, bool(kp_folders), tuple(notes))


__all__ = [
    "RATE_TOLERANCE",
    "BuiltSession",
    "build_session",
    "keypoint_folder",
    "match_cameras",
]
