"""A recording session folder: cameras, videos, markers, 2-D keypoints and (synthetic) truth.

Layout (all lengths in mm, times in s)::

    session.json                 {"format": 1, "units": "mm", "subject": {"height_mm": ...,
                                  "bone_lengths_mm": {segment: mm}, "segment_vectors_mm":
                                  {trunk segment: [x, y, z]}}, "cameras": "cameras.json",
                                  "marker_sets": {"head": ["LFHD", ...], ...},
                                  "marker_offsets_mm": {"head": {"segment": "head",
                                  "offset_mm": [0, 100, 0], "members_mm": {"LFHD":
                                  [x, y, z], ...}}, ...},
                                  "reference_markers": [...], "rates": {"video_hz": 30,
                                  "markers_hz": 120}}
    cameras.json                 see `mocapkit.io.cameras`
    video/<camera>.mp4           or an image folder video/<camera>/000000.png ...
    video/<camera>.timestamps.csv   optional: ``frame,time_s`` per frame (uneven frames)
    markers.c3d | markers.csv    optional marker stream at its own rate
    keypoints/<camera>.csv       optional: ``time_s`` then ``<joint>_x_px, <joint>_y_px``
    truth.npz                    synthetic only: time_s (T,), joint_names (J,),
                                 joints_mm (T, J, 3), marker_names (M,), markers_mm (T, M, 3)

`Session.samples` streams the session in video time order. At every video frame it takes
the newest marker sample at or before the frame time and keeps the time difference, as the
hybrid tracker of Zhang et al. (2011, §3) samples its two independent streams (video at
30 Hz, markers at 120 Hz) "so that both estimations work on the newest tracking data".

Subject bone lengths are keyed by `mocapkit.skeleton.CANONICAL_SEGMENTS` names (what a lab
measures: upper arm, forearm, clavicle, trunk, ...). Marker offsets say where a marker set
sits on the body (glasses in front of the head, an object held in the hand): the canonical
joint it rides on and its offset in that body part's anatomical frame (x right, y forward,
z up in the anatomical position); optionally each member marker's own offset in that frame
(``members_mm``), which lets a tracker read the set's orientation as well as its position.
"""

from __future__ import annotations

import csv
import json
import math
import os
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.errors import FormatError, SessionError, ShapeError
from mocapkit.io.atomic import atomic_write
from mocapkit.skeleton.model import CANONICAL_JOINTS, CANONICAL_SEGMENTS, TRUNK_SEGMENTS

FloatArray = NDArray[np.float64]
FORMAT_VERSION = 1
IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
MARKER_FILES = ("markers.c3d", "markers.csv")


# ====================================================================== small CSV formats


def write_keypoints_csv(
    path: str | os.PathLike[str], time_s: ArrayLike, joint_names: Sequence[str], pixels: ArrayLike
) -> None:
    """Write 2-D keypoints: ``time_s`` then ``<joint>_x_px, <joint>_y_px``; NaN where unseen.

    Parameters
    ----------
    path : path-like
    time_s : (T,) float array
    joint_names : sequence of str
        Canonical joint names (K).
    pixels : (T, K, 2) float array
        Image positions (px, distorted image); NaN where the joint is not seen.
    """
    t = np.asarray(time_s, dtype=float)
    px = np.asarray(pixels, dtype=float)
    names = tuple(joint_names)
    if t.ndim != 1 or px.shape != (t.shape[0], len(names), 2):
        raise ShapeError(
            f"{path}: keypoints: expected time_s (T,) and pixels (T, {len(names)}, 2), found "
            f"{t.shape} and {px.shape}"
        )
    bad = [n for n in names if n not in CANONICAL_JOINTS]
    if bad:
        raise ShapeError(f"{path}: keypoints: not canonical joint names: {bad}")
    header = ["time_s"] + [f"{n}_{a}_px" for n in names for a in "xy"]
    with atomic_write(path, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(header)
        for ti, row in zip(t.tolist(), px.reshape(t.shape[0], -1).tolist()):
            w.writerow([repr(ti)] + ["nan" if v != v else f"{v:.3f}" for v in row])


@dataclass(frozen=True, eq=False)
class Keypoints:
    """2-D joint detections of one camera.

    Attributes
    ----------
    time_s : (T,) float array
    joint_names : tuple of str
        Canonical names (K).
    pixels : (T, K, 2) float array
        Image positions (px); NaN where unseen.
    source : str
    """

    time_s: FloatArray
    joint_names: tuple[str, ...]
    pixels: FloatArray
    source: str = ""


def _read_numeric_csv(path: Path, what: str) -> tuple[list[str], FloatArray]:
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = [r for r in csv.reader(fh) if r]
    except (OSError, UnicodeDecodeError) as exc:
        raise FormatError(f"{path}: cannot read {what} ({exc})") from None
    if not rows:
        raise FormatError(f"{path}: {what}: expected a header line, found an empty file")
    header = [h.strip() for h in rows[0]]
    values = np.empty((len(rows) - 1, len(header)))
    for i, row in enumerate(rows[1:]):
        if len(row) != len(header):
            raise FormatError(
                f"{path}: line {i + 2}: expected {len(header)} columns, found {len(row)}"
            )
        for j, cell in enumerate(row):
            c = cell.strip()
            try:
                values[i, j] = float(c) if c else math.nan
            except ValueError:
                raise FormatError(
                    f"{path}: line {i + 2}, column {header[j]!r}: expected a number, found {c!r}"
                ) from None
    return header, values


def _check_times(t: FloatArray, path: Path | str, what: str) -> None:
    if not np.all(np.isfinite(t)):
        raise FormatError(f"{path}: {what}: expected finite time stamps, found NaN or inf")
    if t.shape[0] > 1 and np.any(np.diff(t) <= 0):
        k = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise FormatError(
            f"{path}: {what}: expected strictly increasing time stamps, found {t[k + 1]!r} s at "
            f"row {k + 1} after {t[k]!r} s"
        )


def read_keypoints_csv(path: str | os.PathLike[str]) -> Keypoints:
    """Read a file written by `write_keypoints_csv`."""
    p = Path(path)
    header, values = _read_numeric_csv(p, "keypoints")
    if header[0] != "time_s" or (len(header) - 1) % 2:
        raise FormatError(
            f"{p}: line 1: expected 'time_s' then pairs '<joint>_x_px,<joint>_y_px', found "
            f"{header[:5]}"
        )
    names: list[str] = []
    for k in range(1, len(header), 2):
        base = header[k][: -len("_x_px")]
        expect = [f"{base}_x_px", f"{base}_y_px"]
        if header[k : k + 2] != expect:
            raise FormatError(f"{p}: line 1: expected columns {expect}, found {header[k : k + 2]}")
        if base not in CANONICAL_JOINTS:
            raise FormatError(
                f"{p}: line 1: column {header[k]!r}: expected a canonical joint "
                f"({', '.join(CANONICAL_JOINTS)}), found {base!r}"
            )
        names.append(base)
    t = values[:, 0]
    _check_times(t, p, "time_s")
    return Keypoints(t, tuple(names), values[:, 1:].reshape(len(t), len(names), 2), str(p))


def write_timestamps_csv(path: str | os.PathLike[str], time_s: ArrayLike) -> None:
    """Write per-frame video time stamps: ``frame,time_s``."""
    t = np.asarray(time_s, dtype=float)
    with atomic_write(path, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["frame", "time_s"])
        for i, ti in enumerate(t.tolist()):
            w.writerow([i, repr(ti)])


def read_timestamps_csv(path: str | os.PathLike[str]) -> FloatArray:
    """Read per-frame video time stamps (a ``time_s`` column; ``frame`` optional)."""
    p = Path(path)
    header, values = _read_numeric_csv(p, "video time stamps")
    if "time_s" not in header:
        raise FormatError(f"{p}: line 1: expected a 'time_s' column, found {header}")
    t = values[:, header.index("time_s")]
    _check_times(t, p, "time_s")
    return t


# ====================================================================== truth


@dataclass(frozen=True, eq=False)
class Truth:
    """Ground truth of a synthetic session (world frame, mm).

    Attributes
    ----------
    time_s : (T,) float array
        The video frame times.
    joint_names : tuple of str
        Canonical names (J).
    joints_mm : (T, J, 3) float array
    marker_names : tuple of str
        Clean markers kept with the truth (incl. the elbow reference markers).
    markers_mm : (T, M, 3) float array
    """

    time_s: FloatArray
    joint_names: tuple[str, ...]
    joints_mm: FloatArray
    marker_names: tuple[str, ...] = ()
    markers_mm: FloatArray = field(default_factory=lambda: np.zeros((0, 0, 3)))

    def __post_init__(self) -> None:
        if not self.marker_names and np.size(self.markers_mm) == 0:
            n = int(np.shape(self.time_s)[0])
            object.__setattr__(self, "markers_mm", np.zeros((n, 0, 3)))

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write ``truth.npz`` atomically (no pickles)."""
        from mocapkit.io.atomic import atomic_save_npz

        atomic_save_npz(
            path,
            time_s=np.asarray(self.time_s, dtype=float),
            joint_names=np.array(self.joint_names, dtype=np.str_),
            joints_mm=np.asarray(self.joints_mm, dtype=float),
            marker_names=np.array(self.marker_names, dtype=np.str_),
            markers_mm=np.asarray(self.markers_mm, dtype=float),
        )


def load_truth(path: str | os.PathLike[str]) -> Truth:
    """Read and validate a ``truth.npz``."""
    p = Path(path)
    try:
        data = np.load(p, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise FormatError(f"{p}: cannot read as .npz ({exc})") from None
    with data:
        missing = [k for k in ("time_s", "joint_names", "joints_mm") if k not in data.files]
        if missing:
            raise FormatError(f"{p}: missing arrays {missing}; found {sorted(data.files)}")
        t = np.asarray(data["time_s"], dtype=float)
        names = tuple(str(n) for n in np.atleast_1d(data["joint_names"]))
        joints = np.asarray(data["joints_mm"], dtype=float)
        mnames = (
            tuple(str(n) for n in np.atleast_1d(data["marker_names"]))
            if ("marker_names" in data.files)
            else ()
        )
        markers = (
            np.asarray(data["markers_mm"], dtype=float)
            if "markers_mm" in data.files
            else (np.zeros((t.shape[0], 0, 3)))
        )
    if t.ndim != 1:
        raise ShapeError(f"{p}: time_s: expected shape (T,), found {t.shape}")
    _check_times(t, p, "time_s")
    if joints.shape != (t.shape[0], len(names), 3):
        raise ShapeError(
            f"{p}: joints_mm: expected shape ({t.shape[0]}, {len(names)}, 3), found {joints.shape}"
        )
    bad = [n for n in names if n not in CANONICAL_JOINTS]
    if bad:
        raise FormatError(f"{p}: joint_names: expected canonical names, found {bad}")
    if markers.shape != (t.shape[0], len(mnames), 3):
        raise ShapeError(
            f"{p}: markers_mm: expected shape ({t.shape[0]}, {len(mnames)}, 3), "
            f"found {markers.shape}"
        )
    return Truth(t, names, joints, mnames, markers)


# ====================================================================== video


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

    def __init__(self, camera: str, path: Path, time_s: FloatArray) -> None:
        self.camera = camera
        self.path = path
        self.time_s = time_s
        self.is_folder = path.is_dir()
        self._files: list[Path] = _image_files(path) if self.is_folder else []

    @property
    def n_frames(self) -> int:
        """Number of frames."""
        return int(self.time_s.shape[0])

    def read(self, index: int) -> NDArray[np.uint8]:
        """One frame (H, W, 3) BGR by index (random access; slow for videos)."""
        if not 0 <= index < self.n_frames:
            raise SessionError(f"{self.path}: frame {index} out of range [0, {self.n_frames})")
        if self.is_folder:
            return _imread(self._files[index])
        cap = cv2.VideoCapture(str(self.path))
        try:
            cap.set(cv2.CAP_PROP_POS_FRAMES, index)
            ok, img = cap.read()
        finally:
            cap.release()
        if not ok:
            raise SessionError(f"{self.path}: cannot decode frame {index}")
        return np.asarray(img, dtype=np.uint8)

    def open(self) -> _FrameStream:
        """A sequential reader (cheap `grab`, decode on demand)."""
        return _FrameStream(self)


def _imread(path: Path) -> NDArray[np.uint8]:
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise SessionError(f"{path}: cannot read image")
    return np.asarray(img, dtype=np.uint8)


def _image_files(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_EXTENSIONS)


class _FrameStream:
    """Sequential frame access: `advance` grabs the next frame, `retrieve` decodes it."""

    def __init__(self, source: VideoSource) -> None:
        self.source = source
        self.index = -1
        self._cap = None if source.is_folder else cv2.VideoCapture(str(source.path))
        self._cache: tuple[int, NDArray[np.uint8]] | None = None

    def advance_to(self, index: int) -> None:
        while self.index < index:
            self.index += 1
            if self._cap is not None and not self._cap.grab():
                raise SessionError(f"{self.source.path}: cannot read frame {self.index}")

    def retrieve(self, index: int) -> NDArray[np.uint8]:
        if self._cache is not None and self._cache[0] == index:
            return self._cache[1]
        if index != self.index:
            raise SessionError(
                f"{self.source.path}: frame {index} is no longer available (the stream is at "
                f"frame {self.index}); load images before advancing to the next sample"
            )
        if self._cap is None:
            img = _imread(self.source._files[index])
        else:
            ok, raw = self._cap.retrieve()
            if not ok:
                raise SessionError(f"{self.source.path}: cannot decode frame {index}")
            img = np.asarray(raw, dtype=np.uint8)
        self._cache = (index, img)
        return img

    def close(self) -> None:
        if self._cap is not None:
            self._cap.release()


class LazyFrame:
    """A video frame decoded only when `load` is called (valid until the stream advances)."""

    def __init__(self, stream: _FrameStream, index: int, time_s: float) -> None:
        self._stream = stream
        self.index = index
        self.time_s = time_s

    def load(self) -> NDArray[np.uint8]:
        """The frame (H, W, 3) uint8 BGR."""
        return self._stream.retrieve(self.index)


# ====================================================================== samples


@dataclass(frozen=True, eq=False)
class SessionSample:
    """One step of a session stream: a video frame and the newest marker sample before it.

    Attributes
    ----------
    index : int
        Frame index in the primary camera.
    time_s : float
        Frame time of the primary camera (s).
    frames : mapping of str to LazyFrame
        Per camera, the frame nearest to ``time_s`` (decode with ``.load()``).
    marker_index : int
        Index of the newest marker sample at or before ``time_s``; -1 when none.
    marker_time_s : float
        Its time stamp (NaN when none).
    marker_dt_s : float
        ``time_s - marker_time_s`` (>= 0; NaN when none).
    markers_mm : (M, 3) float array or None
        All markers of that sample (NaN where occluded).
    marker_names : tuple of str
    marker_sets_mm : mapping of str to (3,) float array
        Marker-set centres of that sample (NaN when unseen).
    keypoints_px : mapping of str to (K, 2) float array
        Per camera, the keypoints row at this frame (when the session has keypoints).
    """

    index: int
    time_s: float
    frames: Mapping[str, LazyFrame]
    marker_index: int = -1
    marker_time_s: float = math.nan
    marker_dt_s: float = math.nan
    markers_mm: FloatArray | None = None
    marker_names: tuple[str, ...] = ()
    marker_sets_mm: Mapping[str, FloatArray] = field(default_factory=dict)
    keypoints_px: Mapping[str, FloatArray] = field(default_factory=dict)

    def image(self, camera: str | None = None) -> NDArray[np.uint8]:
        """Decode the frame of ``camera`` (default: the primary camera)."""
        name = camera if camera is not None else next(iter(self.frames))
        if name not in self.frames:
            raise SessionError(
                f"sample has no frame of camera {name!r}; it has {sorted(self.frames)}"
            )
        return self.frames[name].load()


# ====================================================================== the session


def _as_str_list(value: Any, where: str) -> list[str]:
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise FormatError(f"{where}: expected a list of names, found {value!r}")
    return list(value)


class Session:
    """A loaded, validated recording session (see module docstring for the layout).

    Use `load_session`. Attributes: ``path``, ``info`` (the session.json document),
    ``cameras`` (list of `Camera`), ``height_mm``, ``bone_lengths_mm``, ``marker_sets``
    (set name -> member marker names), ``reference_markers``, ``markers`` (`MarkerData`
    or None), ``keypoints`` (camera -> `Keypoints`), ``truth`` (`Truth` or None).
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        if not self.path.is_dir():
            raise SessionError(f"{self.path}: session folder not found")
        info_path = self.path / "session.json"
        if not info_path.is_file():
            raise SessionError(
                f"{self.path}: missing session.json (every session folder needs one)"
            )
        try:
            info = json.loads(info_path.read_text(encoding="utf-8"))
        except json.JSONDecodeError as exc:
            raise FormatError(
                f"{info_path}: not valid JSON (line {exc.lineno}: {exc.msg})"
            ) from None
        if not isinstance(info, dict):
            raise FormatError(f"{info_path}: expected a JSON object, found {type(info).__name__}")
        if info.get("format") != FORMAT_VERSION:
            raise FormatError(
                f"{info_path}: field 'format': expected {FORMAT_VERSION}, "
                f"found {info.get('format')!r}"
            )
        if info.get("units", "mm") != "mm":
            raise FormatError(f"{info_path}: field 'units': expected 'mm', found {info['units']!r}")
        self.info: dict[str, Any] = info
        subject = info.get("subject", {})
        if not isinstance(subject, dict):
            raise FormatError(
                f"{info_path}: field 'subject': expected an object, found {subject!r}"
            )
        h = subject.get("height_mm")
        if h is not None and not (isinstance(h, int | float) and 500 <= h <= 2800):
            raise FormatError(
                f"{info_path}: subject.height_mm: expected a stature in mm (500-2800), found {h!r}"
            )
        self.height_mm: float | None = None if h is None else float(h)
        bones = subject.get("bone_lengths_mm", {})
        if not isinstance(bones, dict) or not all(
            isinstance(v, int | float) and v > 0 for v in bones.values()
        ):
            raise FormatError(
                f"{info_path}: subject.bone_lengths_mm: expected segment name -> positive "
                f"length (mm), found {bones!r}"
            )
        for k in bones:
            if k not in CANONICAL_SEGMENTS:
                raise FormatError(
                    f"{info_path}: subject.bone_lengths_mm: unknown segment {k!r}; expected "
                    f"one of {sorted(CANONICAL_SEGMENTS)}"
                )
        self.bone_lengths_mm: dict[str, float] = {str(k): float(v) for k, v in bones.items()}
        vectors = subject.get("segment_vectors_mm", {})
        if not isinstance(vectors, dict):
            raise FormatError(
                f"{info_path}: subject.segment_vectors_mm: expected segment name -> [x, y, z] "
                f"(mm), found {vectors!r}"
            )
        self.segment_vectors_mm: dict[str, FloatArray] = {}
        for k, v in vectors.items():
            if k not in TRUNK_SEGMENTS:
                raise FormatError(
                    f"{info_path}: subject.segment_vectors_mm: segment {k!r} has no fixed rest "
                    f"direction; expected one of {list(TRUNK_SEGMENTS)}"
                )
            vec = np.asarray(v, dtype=float)
            if vec.shape != (3,) or not np.all(np.isfinite(vec)):
                raise FormatError(
                    f"{info_path}: subject.segment_vectors_mm.{k}: expected 3 finite numbers, "
                    f"found {v!r}"
                )
            self.segment_vectors_mm[str(k)] = vec
        offsets_doc = info.get("marker_offsets_mm", {})
        self.marker_offsets: dict[str, tuple[str, FloatArray]] = _parse_marker_offsets(
            offsets_doc, info_path
        )
        #: Per marker set with declared ``members_mm``: member -> offset (3,) mm in the
        #: anatomical frame of the set's body part.
        self.marker_member_offsets: dict[str, dict[str, FloatArray]] = _parse_member_offsets(
            offsets_doc, info_path
        )
        rates = info.get("rates", {})
        if not isinstance(rates, dict):
            raise FormatError(f"{info_path}: field 'rates': expected an object, found {rates!r}")
        self.rates: dict[str, float] = {}
        for key, v in rates.items():
            if not (isinstance(v, int | float) and v > 0):
                raise FormatError(
                    f"{info_path}: rates.{key}: expected a positive rate in Hz, found {v!r}"
                )
            self.rates[str(key)] = float(v)

        # ---------------------------------------------------------------- cameras
        from mocapkit.io.cameras import read_cameras

        cam_file = info.get("cameras", "cameras.json")
        if not isinstance(cam_file, str):
            raise FormatError(
                f"{info_path}: field 'cameras': expected a file name, found {cam_file!r}"
            )
        cam_path = self.path / cam_file
        self.cameras: list[Camera] = read_cameras(cam_path) if cam_path.is_file() else []
        if not cam_path.is_file() and "cameras" in info:
            raise SessionError(
                f"{self.path}: session.json names cameras file {cam_file!r}, which is missing"
            )
        names = [c.name for c in self.cameras]

        # ---------------------------------------------------------------- video
        self._videos: dict[str, VideoSource] = {}
        vdir = self.path / "video"
        if vdir.is_dir():
            for entry in sorted(vdir.iterdir()):
                if entry.name.endswith(".timestamps.csv") or entry.name.startswith("."):
                    continue
                cam = entry.name if entry.is_dir() else entry.stem
                if cam not in names:
                    raise SessionError(
                        f"{entry}: video of camera {cam!r}, which {cam_file} does not define "
                        f"(cameras: {names or 'none'})"
                    )
                if cam in self._videos:
                    raise SessionError(
                        f"{vdir}: camera {cam!r} has both a video file and an image folder"
                    )
                self._videos[cam] = self._open_video(cam, entry)
        self._videos = {c: self._videos[c] for c in names if c in self._videos}

        # ---------------------------------------------------------------- markers
        from mocapkit.io.markers import MarkerData, read_markers

        present = [f for f in MARKER_FILES if (self.path / f).is_file()]
        if len(present) > 1:
            raise SessionError(
                f"{self.path}: both {present[0]} and {present[1]}; keep one marker file"
            )
        self.markers: MarkerData | None = read_markers(self.path / present[0]) if present else None
        sets = info.get("marker_sets", {})
        if not isinstance(sets, dict):
            raise FormatError(
                f"{info_path}: field 'marker_sets': expected an object, found {sets!r}"
            )
        self.marker_sets: dict[str, list[str]] = {
            str(k): _as_str_list(v, f"{info_path}: marker_sets.{k}") for k, v in sets.items()
        }
        self.reference_markers: list[str] = _as_str_list(
            info.get("reference_markers", []), f"{info_path}: reference_markers"
        )
        if self.markers is not None:
            have = set(self.markers.names)
            for set_name, members in self.marker_sets.items():
                lost = [m for m in members if m not in have]
                if lost:
                    raise SessionError(
                        f"{info_path}: marker set {set_name!r} uses markers {lost} that "
                        f"{present[0]} does not hold (it has {sorted(have)})"
                    )
        for set_name, members_mm in self.marker_member_offsets.items():
            declared = self.marker_sets.get(set_name)
            strange = [m for m in members_mm if declared is not None and m not in declared]
            if strange:
                raise SessionError(
                    f"{info_path}: marker_offsets_mm.{set_name}.members_mm names {strange}, "
                    f"which are not members of marker set {set_name!r} (members: {declared})"
                )

        # ---------------------------------------------------------------- keypoints, truth
        self.keypoints: dict[str, Keypoints] = {}
        kdir = self.path / "keypoints"
        if kdir.is_dir():
            for f in sorted(kdir.glob("*.csv")):
                if f.stem not in names:
                    raise SessionError(
                        f"{f}: keypoints of camera {f.stem!r}, which {cam_file} does not define "
                        f"(cameras: {names or 'none'})"
                    )
                self.keypoints[f.stem] = read_keypoints_csv(f)
        tpath = self.path / "truth.npz"
        self.truth: Truth | None = load_truth(tpath) if tpath.is_file() else None

    # ------------------------------------------------------------------ video helpers

    def _open_video(self, cam: str, entry: Path) -> VideoSource:
        ts_path = entry.parent / f"{cam}.timestamps.csv"
        if entry.is_dir():
            n = len(_image_files(entry))
            if n == 0:
                raise SessionError(
                    f"{entry}: image folder of camera {cam!r} holds no images "
                    f"({', '.join(IMAGE_EXTENSIONS)})"
                )
        else:
            cap = cv2.VideoCapture(str(entry))
            try:
                if not cap.isOpened():
                    raise SessionError(f"{entry}: cannot open video of camera {cam!r}")
                n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
                fps = float(cap.get(cv2.CAP_PROP_FPS))
            finally:
                cap.release()
            if n <= 0:
                raise SessionError(f"{entry}: video of camera {cam!r} has no frames")
        if ts_path.is_file():
            t = read_timestamps_csv(ts_path)
            if t.shape[0] != n:
                raise SessionError(
                    f"{ts_path}: expected one time stamp per frame of {entry.name} ({n} frames), "
                    f"found {t.shape[0]}"
                )
        else:
            rate = self.rates.get("video_hz")
            if rate is None and not entry.is_dir() and fps > 0:
                rate = fps
            if rate is None:
                raise SessionError(
                    f"{entry}: no frame times: add {ts_path.name} or rates.video_hz to session.json"
                )
            t = np.arange(n) / rate
        return VideoSource(cam, entry, t)

    # ------------------------------------------------------------------ queries

    @property
    def camera_names(self) -> tuple[str, ...]:
        """Names of all calibrated cameras."""
        return tuple(c.name for c in self.cameras)

    @property
    def video_cameras(self) -> tuple[str, ...]:
        """Cameras that have a video (in cameras.json order)."""
        return tuple(self._videos)

    def camera(self, name: str) -> Camera:
        """A camera by name."""
        for c in self.cameras:
            if c.name == name:
                return c
        raise SessionError(f"{self.path}: no camera {name!r}; cameras: {list(self.camera_names)}")

    def video(self, camera: str) -> VideoSource:
        """The video of one camera."""
        if camera not in self._videos:
            raise SessionError(
                f"{self.path}: no video of camera {camera!r}; "
                f"videos: {list(self._videos) or 'none'}"
            )
        return self._videos[camera]

    def marker_set_positions(self, names: Sequence[str] | None = None) -> FloatArray:
        """Marker-set centres over the marker stream, (T_markers, S, 3) mm.

        Uses `mocapkit.io.marker_sets.evaluate_marker_sets` (mean of visible members,
        corrected for drop-outs).
        """
        from mocapkit.io.marker_sets import MarkerSet, evaluate_marker_sets

        self.require(markers=True, marker_sets=tuple(names or ()))
        if self.markers is None:  # unreachable after require; keeps the type checker informed
            raise SessionError(f"{self.path}: session has no markers")
        chosen = list(names) if names is not None else list(self.marker_sets)
        sets = [MarkerSet(n, tuple(self.marker_sets[n])) for n in chosen]
        return evaluate_marker_sets(self.markers, sets)

    def require(
        self,
        *,
        video: bool = False,
        markers: bool = False,
        keypoints: bool = False,
        truth: bool = False,
        cameras: int | Sequence[str] = 0,
        marker_sets: Sequence[str] = (),
        height: bool = False,
    ) -> None:
        """Refuse a session that lacks what a tracker needs.

        Parameters
        ----------
        video, markers, keypoints, truth, height : bool
            Whether a video (of every requested camera), a marker file, keypoints files,
            ``truth.npz`` or ``subject.height_mm`` are needed.
        cameras : int or sequence of str
            At least this many calibrated cameras, or these named cameras.
        marker_sets : sequence of str
            Marker sets that session.json must define.

        Raises
        ------
        SessionError
            Listing everything missing.
        """
        missing: list[str] = []
        wanted = list(cameras) if not isinstance(cameras, int) else []
        if isinstance(cameras, int) and len(self.cameras) < cameras:
            missing.append(
                f"{cameras} calibrated camera(s) in cameras.json (found {len(self.cameras)})"
            )
        for c in wanted:
            if c not in self.camera_names:
                missing.append(f"camera {c!r} in cameras.json (found {list(self.camera_names)})")
        if video:
            for c in wanted or ([] if self._videos else ["any camera"]):
                if c not in self._videos:
                    missing.append(
                        f"video/{c}.mp4 (or an image folder video/{c}/)"
                        if c != "any camera"
                        else "a video under video/"
                    )
        if markers and self.markers is None:
            missing.append("markers.c3d or markers.csv")
        for s in marker_sets:
            if s not in self.marker_sets:
                missing.append(
                    f"marker set {s!r} in session.json marker_sets "
                    f"(defined: {sorted(self.marker_sets) or 'none'})"
                )
        if keypoints:
            for c in wanted or ([] if self.keypoints else ["any camera"]):
                if c not in self.keypoints:
                    missing.append(
                        f"keypoints/{c}.csv" if c != "any camera" else "keypoints/<camera>.csv"
                    )
        if truth and self.truth is None:
            missing.append("truth.npz")
        if height and self.height_mm is None:
            missing.append("subject.height_mm in session.json")
        if missing:
            raise SessionError(f"{self.path}: session lacks " + "; ".join(missing))

    # ------------------------------------------------------------------ streaming

    def samples(self, camera: str | Sequence[str] | None = None) -> Iterator[SessionSample]:
        """Stream the session in time order, one sample per frame of the primary camera.

        Parameters
        ----------
        camera : str or sequence of str, optional
            The camera(s) whose frames to include; the first is the primary (its frames
            set the time line). Default: every camera with a video.

        Yields
        ------
        SessionSample
            Frames are lazy: call ``sample.image(camera)`` before advancing the iterator.
        """
        cams = (
            list(self._videos)
            if camera is None
            else ([camera] if isinstance(camera, str) else list(camera))
        )
        self.require(video=True, cameras=cams)
        if not cams:
            raise SessionError(f"{self.path}: no camera selected")
        sources = [self._videos[c] for c in cams]
        streams = [s.open() for s in sources]
        primary = sources[0]
        m = self.markers
        mt = m.time_s if m is not None else np.zeros(0)
        set_pos = self.marker_set_positions() if (m is not None and self.marker_sets) else None
        try:
            for i, t in enumerate(primary.time_s.tolist()):
                frames: dict[str, LazyFrame] = {}
                for src, st in zip(sources, streams):
                    j = i if src is primary else int(np.argmin(np.abs(src.time_s - t)))
                    j = max(j, st.index)  # streams only move forwards
                    st.advance_to(j)
                    frames[src.camera] = LazyFrame(st, j, float(src.time_s[j]))
                kp = {}
                for c in cams:
                    k = self.keypoints.get(c)
                    if k is not None and k.time_s.shape[0]:
                        r = int(np.argmin(np.abs(k.time_s - t)))
                        kp[c] = k.pixels[r]
                mi = int(np.searchsorted(mt, t, side="right")) - 1
                if m is not None and mi >= 0:
                    sets = (
                        {}
                        if set_pos is None
                        else {n: set_pos[mi, s] for s, n in enumerate(self.marker_sets)}
                    )
                    yield SessionSample(
                        i,
                        t,
                        frames,
                        mi,
                        float(mt[mi]),
                        t - float(mt[mi]),
                        m.positions_mm[mi],
                        m.names,
                        sets,
                        kp,
                    )
                else:
                    yield SessionSample(i, t, frames, keypoints_px=kp)
        finally:
            for st in streams:
                st.close()


def load_session(path: str | os.PathLike[str]) -> Session:
    """Load and validate a session folder; errors name the file, what was expected and found."""
    return Session(path)


def _vector3(value: Any) -> FloatArray | None:
    """``value`` as 3 finite floats (a JSON list of numbers), or None."""
    if not isinstance(value, list) or len(value) != 3:
        return None
    if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value):
        return None
    out = np.asarray(value, dtype=float)
    return out if np.all(np.isfinite(out)) else None


def _parse_marker_offsets(doc: Any, where: Path) -> dict[str, tuple[str, FloatArray]]:
    """``marker_offsets_mm``: marker set -> (canonical joint it rides on, offset (3,) mm).

    The offset is in that body part's anatomical frame: x to the subject's right, y
    forward, z up, with the body standing, arms hanging and palms forward.
    """
    if not isinstance(doc, dict):
        raise FormatError(f"{where}: field 'marker_offsets_mm': expected an object, found {doc!r}")
    out: dict[str, tuple[str, FloatArray]] = {}
    for name, entry in doc.items():
        field = f"{where}: marker_offsets_mm.{name}"
        if not isinstance(entry, dict) or not (
            {"segment", "offset_mm"} <= set(entry) <= {"segment", "offset_mm", "members_mm"}
        ):
            raise FormatError(
                f"{field}: expected {{'segment': canonical joint, 'offset_mm': [x, y, z]}} "
                f"and optionally 'members_mm': {{marker: [x, y, z]}}, found {entry!r}"
            )
        seg = entry["segment"]
        if seg not in CANONICAL_JOINTS:
            raise FormatError(
                f"{field}.segment: expected a canonical joint ({', '.join(CANONICAL_JOINTS)}), "
                f"found {seg!r}"
            )
        off = _vector3(entry["offset_mm"])
        if off is None:
            raise FormatError(
                f"{field}.offset_mm: expected 3 finite numbers, found {entry['offset_mm']!r}"
            )
        out[str(name)] = (str(seg), off)
    return out


def _parse_member_offsets(doc: Any, where: Path) -> dict[str, dict[str, FloatArray]]:
    """``marker_offsets_mm.<set>.members_mm``: member marker -> offset (3,) mm (same frame
    as the set's ``offset_mm``); call after `_parse_marker_offsets` has checked ``doc``."""
    out: dict[str, dict[str, FloatArray]] = {}
    for name, entry in doc.items():
        members = entry.get("members_mm")
        if members is None:
            continue
        field = f"{where}: marker_offsets_mm.{name}.members_mm"
        if not isinstance(members, dict) or not members:
            raise FormatError(f"{field}: expected {{marker: [x, y, z], ...}}, found {members!r}")
        parsed: dict[str, FloatArray] = {}
        for marker, value in members.items():
            off = _vector3(value)
            if off is None:
                raise FormatError(f"{field}.{marker}: expected 3 finite numbers, found {value!r}")
            parsed[str(marker)] = off
        out[str(name)] = parsed
    return out


def write_session_json(path: str | os.PathLike[str], info: Mapping[str, Any]) -> None:
    """Write ``session.json`` (adds ``format`` and ``units``), atomically."""
    doc = {"format": FORMAT_VERSION, "units": "mm", **dict(info)}
    with atomic_write(path, "w") as fh:
        json.dump(doc, fh, indent=2)
        fh.write("\n")
