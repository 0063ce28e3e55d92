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

The files are read by their own modules: `mocapkit.io.cameras`, `mocapkit.io.video`
(frames), `mocapkit.io.marker_files` (markers), `mocapkit.io.session_csv` (keypoints and
time stamps) and `mocapkit.io.truth`; this module checks the folder as a whole.

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

import json
import math
import os
import warnings
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.errors import FormatError, InputWarning, SessionError
from mocapkit.io.atomic import atomic_write
from mocapkit.io.cameras import read_cameras
from mocapkit.io.files import read_text
from mocapkit.io.keypoint_checks import (
    check_keypoint_clock,
    drop_outside_image,
    keypoints_at,
    max_age_s,
)
from mocapkit.io.marker_files import read_markers
from mocapkit.io.marker_sets import MarkerSet, evaluate_marker_sets
from mocapkit.io.markers import MarkerData, check_plausible_markers
from mocapkit.io.session_csv import Keypoints, read_keypoints_csv, read_timestamps_csv
from mocapkit.io.truth import Truth, load_truth
from mocapkit.io.video import LazyFrame, VideoSource, frame_size, padding_px, probe_video
from mocapkit.skeleton.model import CANONICAL_JOINTS, CANONICAL_SEGMENTS, TRUNK_SEGMENTS

FloatArray = NDArray[np.float64]
FORMAT_VERSION = 1
MARKER_FILES = ("markers.c3d", "markers.csv")


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
        Per camera with keypoints, the row observed at this frame: the nearest in time,
        or NaN when it is more than one sampling interval away (an old sample is no
        observation, `mocapkit.io.keypoint_checks`).
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
            raise SessionError(
                f"{self.path}: expected a session folder, found a file"
                if self.path.exists()
                else f"{self.path}: session folder not found"
            )
        for name in ("session.json", "cameras.json", "truth.npz", *MARKER_FILES):
            _refuse_non_file(self.path / name)
        for name in ("video", "keypoints"):
            _refuse_non_folder(self.path / name)
        info_path = self.path / "session.json"
        if not info_path.is_file():
            raise SessionError(
                f"{self.path}: missing session.json (every session folder needs one)"
            )
        try:
            info = json.loads(read_text(info_path, "session.json"))
        except json.JSONDecodeError as exc:
            raise FormatError(
                f"{info_path}: not valid JSON (line {exc.lineno}: {exc.msg})"
            ) from None
        if not isinstance(info, dict):
            raise FormatError(f"{info_path}: expected a JSON object, found {type(info).__name__}")
        if info.get("format") != FORMAT_VERSION or isinstance(info.get("format"), bool):
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
        if not isinstance(bones, dict):
            raise FormatError(
                f"{info_path}: subject.bone_lengths_mm: expected an object of segment name -> "
                f"positive length (mm), found {type(bones).__name__}"
            )
        for k, v in bones.items():  # the one bad entry named, not the whole table
            if isinstance(v, bool) or not isinstance(v, int | float) or not v > 0:
                raise FormatError(
                    f"{info_path}: subject.bone_lengths_mm.{k}: expected a positive length "
                    f"(mm), found {v!r}"
                )
        for k in bones:
            if k not in CANONICAL_SEGMENTS:
                raise FormatError(
                    f"{info_path}: subject.bone_lengths_mm: unknown segment {k!r}; expected "
                    f"one of {sorted(CANONICAL_SEGMENTS)}"
                )
        # no segment is half as long as the body (the shank, the longest, is about a
        # quarter of the stature); without a stature, half the tallest one allowed
        longest = 0.5 * (self.height_mm if self.height_mm is not None else 2800.0)
        for k, v in bones.items():
            if v > longest:
                raise FormatError(
                    f"{info_path}: subject.bone_lengths_mm.{k}: expected at most half the "
                    f"stature ({longest:.0f} mm), found {v!r} mm"
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
        cam_file = info.get("cameras", "cameras.json")
        if not isinstance(cam_file, str):
            raise FormatError(
                f"{info_path}: field 'cameras': expected a file name, found {cam_file!r}"
            )
        cam_path = self.path / cam_file
        _refuse_non_file(cam_path)
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
        present = [f for f in MARKER_FILES if (self.path / f).is_file()]
        if len(present) > 1:
            raise SessionError(
                f"{self.path}: both {present[0]} and {present[1]}; keep one marker file"
            )
        self.markers: MarkerData | None = read_markers(self.path / present[0]) if present else None
        if self.markers is not None:
            check_plausible_markers(self.markers)  # the subject's markers: speeds too
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
            unknown = [m for m in self.reference_markers if m not in have]
            if unknown:
                raise SessionError(
                    f"{info_path}: reference_markers names {unknown}, which "
                    f"{present[0]} does not hold (it has {sorted(have)})"
                )
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

        if self.markers is not None:
            for set_name, members_mm in self.marker_member_offsets.items():
                _check_member_spacing(self.markers, set_name, members_mm, info_path)

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
        self._check_lengths()
        for cam, kp in self.keypoints.items():
            self.keypoints[cam] = self.checked_keypoints(cam, kp, kp.source)

    def checked_keypoints(self, camera: str, kp: Keypoints, where: str) -> Keypoints:
        """``kp`` of ``camera`` after the load-time keypoint rules
        (`mocapkit.io.keypoint_checks`): points far outside the image dropped (with a
        warning), a clock that never overlaps the camera's video (else the first video)
        refused."""
        checked = drop_outside_image(kp, self.camera(camera).image_size, where)
        video = self._videos.get(camera) or next(iter(self._videos.values()), None)
        if video is not None and kp.time_s.shape[0]:
            check_keypoint_clock(kp, video.time_s, f"{where} (video of camera {video.camera!r})")
        return checked

    def _check_lengths(self) -> None:
        """Refuse streams that cannot belong to one recording.

        Every video lasts as long as the first (within two of its frames); ``truth.npz``
        has one sample per frame of the first video; the marker stream overlaps the
        video's time line. Markers that start late or end early are allowed: frames
        whose newest marker sample is too old have no marker observation (the hybrid
        tracker's age rule, ``HybridConfig.gap_limit_s``), which the result reports.
        """
        if not self._videos:
            return
        first = next(iter(self._videos.values()))
        t0, t1 = float(first.time_s[0]), float(first.time_s[-1])
        step = (t1 - t0) / max(first.n_frames - 1, 1)
        for cam, v in self._videos.items():
            s0, s1 = float(v.time_s[0]), float(v.time_s[-1])
            if max(abs(s0 - t0), abs(s1 - t1)) > 2 * step + 1e-9:
                raise SessionError(
                    f"{self.path}: video of camera {cam!r} spans {s0:.3f}-{s1:.3f} s, the "
                    f"video of camera {first.camera!r} {t0:.3f}-{t1:.3f} s; expected the "
                    "same recording"
                )
        if self.truth is not None and self.truth.time_s.shape[0] != first.n_frames:
            raise SessionError(
                f"{self.path}: truth.npz has {self.truth.time_s.shape[0]} samples, the video "
                f"of camera {first.camera!r} {first.n_frames} frames; expected one per frame"
            )
        if self.markers is not None:
            m0, m1 = float(self.markers.time_s[0]), float(self.markers.time_s[-1])
            if m1 < t0 or m0 > t1:
                raise SessionError(
                    f"{self.path}: the markers span {m0:.3f}-{m1:.3f} s and the video of "
                    f"camera {first.camera!r} {t0:.3f}-{t1:.3f} s; expected clocks that "
                    "overlap"
                )

    # ------------------------------------------------------------------ video helpers

    def _open_video(self, cam: str, entry: Path) -> VideoSource:
        ts_path = entry.parent / f"{cam}.timestamps.csv"
        n, fps = probe_video(entry, cam)
        if ts_path.is_file():
            t = read_timestamps_csv(ts_path)
            if t.shape[0] != n:
                raise SessionError(
                    f"{ts_path}: expected one time stamp per frame of {entry.name} ({n} frames), "
                    f"found {t.shape[0]}"
                )
        else:
            rate = self.rates.get("video_hz")
            if rate is None and fps > 0:  # an image folder has no rate of its own (fps 0)
                rate = fps
            if rate is None:
                raise SessionError(
                    f"{entry}: no frame times: add {ts_path.name} or rates.video_hz to session.json"
                )
            t = np.arange(n) / rate
        cal_size = self.camera(cam).image_size
        pad = padding_px(frame_size(entry, cam), cal_size, str(entry), cam)
        if pad != (0, 0):
            warnings.warn(
                f"{entry}: the video's frames are {pad[0]} columns and {pad[1]} rows smaller "
                f"than the calibrated image of camera {cam!r} ({cal_size[0]}x{cal_size[1]} px): "
                "taken as that image cut on the right and bottom (encoder padding), padded "
                "back in black",
                InputWarning,
                stacklevel=3,
            )
        return VideoSource(cam, entry, t, pad)

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
        # the keypoints' age rule (`mocapkit.io.keypoint_checks`): a row further than one
        # sampling interval from the frame is no observation of it
        kp_streams = {
            c: self.keypoints[c]
            for c in cams
            if c in self.keypoints and self.keypoints[c].time_s.shape[0]
        }
        kp_ages = {c: max_age_s(k.time_s, self._videos[c].time_s) for c, k in kp_streams.items()}
        try:
            for i, t in enumerate(primary.time_s.tolist()):
                frames: dict[str, LazyFrame] = {}
                for src, st in zip(sources, streams):
                    j = i if src is primary else int(np.argmin(np.abs(src.time_s - t)))
                    j = max(j, st.index)  # streams only move forwards
                    st.advance_to(j)
                    frames[src.camera] = LazyFrame(st, j, float(src.time_s[j]))
                kp = {}
                for c, k in kp_streams.items():
                    kp[c] = keypoints_at(k, t, kp_ages[c])
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


def _refuse_non_file(path: Path) -> None:
    """A session file that exists as a folder (or anything but a file) is named, not
    taken as missing."""
    if path.exists() and not path.is_file():
        what = "a folder" if path.is_dir() else "something that is not a regular file"
        raise SessionError(f"{path}: expected a file, found {what}")


def _refuse_non_folder(path: Path) -> None:
    """A session folder (``video/``, ``keypoints/``) that exists as a file is named."""
    if path.exists() and not path.is_dir():
        raise SessionError(f"{path}: expected a folder, found a file")


def load_session(path: str | os.PathLike[str] | Session) -> Session:
    """Load and validate a session folder; errors name the file, what was expected and found.

    A `Session` already loaded is returned as it is (so that a caller that loaded it to
    decide something passes it on instead of the folder being read again).
    """
    return path if isinstance(path, Session) else Session(path)


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


#: How far (mm) two members of a rigid marker set may be from their declared spacing.
MEMBER_SPACING_TOLERANCE_MM = 100.0


def _check_member_spacing(
    markers: MarkerData, set_name: str, members_mm: Mapping[str, FloatArray], where: Path
) -> None:
    """Refuse a marker set whose members are not where ``members_mm`` puts them.

    The members ride on one rigid body part, so the distance between two of them is the
    distance between their declared offsets, give or take skin motion and noise
    (`MEMBER_SPACING_TOLERANCE_MM`); a member 1e9 mm from its siblings is a glitch
    the IK would chase.
    """
    names = [n for n in members_mm if n in markers.names]
    for a in range(len(names)):
        for b in range(a + 1, len(names)):
            declared = float(np.linalg.norm(members_mm[names[a]] - members_mm[names[b]]))
            pa, pb = markers.trajectory(names[a]), markers.trajectory(names[b])
            seen = np.flatnonzero(np.all(np.isfinite(pa) & np.isfinite(pb), axis=1))
            found = np.linalg.norm(pa[seen] - pb[seen], axis=1)
            bad = np.flatnonzero(np.abs(found - declared) > MEMBER_SPACING_TOLERANCE_MM)
            if bad.size:
                f = int(seen[bad[0]])
                raise SessionError(
                    f"{where}: marker_offsets_mm.{set_name}.members_mm: {names[a]!r} and "
                    f"{names[b]!r} are declared {declared:.0f} mm apart, found "
                    f"{found[bad[0]]:.0f} mm at {markers.time_s[f]:.4f} s in "
                    f"{Path(markers.source).name} ({bad.size} samples off by more than "
                    f"{MEMBER_SPACING_TOLERANCE_MM:.0f} mm)"
                )


def write_session_json(path: str | os.PathLike[str], info: Mapping[str, Any]) -> None:
    """Write ``session.json`` (adds ``format`` and ``units``), atomically."""
    doc = {"format": FORMAT_VERSION, "units": "mm", **dict(info)}
    with atomic_write(path, "w") as fh:
        json.dump(doc, fh, indent=2)
        fh.write("\n")
