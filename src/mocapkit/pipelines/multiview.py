"""Model-based multi-view tracking of a session with 2-D keypoints: the default of
``mocapkit track stereo`` (and ``batch``) on a session that has keypoints for its cameras.

`track_multiview_session` measures the subject's segment lengths once from the take
(`mocapkit.tracking.multiview.lengths.subject_lengths_mm`), streams the frames through
`mocapkit.tracking.multiview.tracker.MultiviewTracker` with the shared runner, smooths
the poses as configured (`SMOOTHING`) and writes the result folder with ``fit.csv``.
`far_spans` finds the time spans where a joint stays far from its detections in most
views; they are printed as warnings and make `mocapkit batch` call the take ``poor``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import SessionError, unknown_name
from mocapkit.io.markers import true_runs
from mocapkit.io.motion import Motion
from mocapkit.pipelines.input_speeds import pixel_input_speeds
from mocapkit.pipelines.run import run_tracker, write_run_folder
from mocapkit.skeleton.model import Skeleton
from mocapkit.skeleton.smoothing import filter_poses
from mocapkit.timing import CompileTime, numba_compiling
from mocapkit.tracking.base import FrameResult
from mocapkit.tracking.multiview.config import (
    SMOOTHING,
    STEREO_METHODS,
    MultiviewConfig,
    MultiviewRunConfig,
)
from mocapkit.tracking.multiview.tracker import MultiviewTracker, multiview_skeleton

if TYPE_CHECKING:
    from mocapkit.io.session import Session

FloatArray = NDArray[np.float64]

#: A joint far from its detections (`MultiviewConfig.warn_px`) on at least this many
#: consecutive frames is warned about.
FAR_MIN_FRAMES = 5


@dataclass
class MultiviewRun:
    """A tracked session: the motion, the per-frame results, the segment lengths used,
    the far spans (joint, first s, last s, frames), the seconds of the 3-D step (CPU) and
    the Numba compilation in them (a first run: `mocapkit.timing.numba_compiling`)."""

    motion: Motion
    results: list[FrameResult]
    lengths_mm: dict[str, float]
    far: list[tuple[str, float, float, int]]
    seconds: float
    out_dir: Path | None = None
    compiled: CompileTime = field(default_factory=CompileTime)


def _smooth_q(
    sk: Skeleton, q: FloatArray, time_s: FloatArray, run: MultiviewRunConfig
) -> FloatArray:
    """Poses (T, D) smoothed over each stretch of frames with a pose: each joint's Euler
    triple as a rotation, every other DoF as it is (`mocapkit.skeleton.smoothing`), so
    the fit's moving from one triple to its equivalent is not drawn as a swing."""
    if run.smoothing == "none" or q.shape[0] < 2:
        return q
    out = q.copy()
    ok = np.isfinite(q).all(axis=1)
    dt = float(np.median(np.diff(time_s))) if time_s.shape[0] > 1 else 1.0 / 30.0
    for a, b in true_runs(ok):
        if run.smoothing == "butterworth":
            from scipy.signal import butter, filtfilt

            nyq = 0.5 / dt
            if b - a <= 15 or run.cutoff_hz >= nyq:
                continue
            bb, aa = butter(4, run.cutoff_hz / nyq)
            out[a:b] = filter_poses(sk, q[a:b], partial(filtfilt, bb, aa, axis=0))
        else:
            out[a:b] = filter_poses(sk, q[a:b], partial(_one_euro, time_s[a:b], run))
    return out


def _one_euro(time_s: FloatArray, run: MultiviewRunConfig, x: FloatArray) -> FloatArray:
    """``x`` (T, K) through a fresh one-euro filter, frame by frame (online)."""
    from mocapkit.tracking.hybrid.tracker import OneEuroFilter

    f = OneEuroFilter(run.cutoff_hz, run.one_euro_beta)
    return np.array([f(float(t), row) for t, row in zip(time_s, x, strict=True)])


def far_spans(
    results: Sequence[FrameResult], names: Sequence[str], min_frames: int = FAR_MIN_FRAMES
) -> list[tuple[str, float, float, int]]:
    """Spans of at least ``min_frames`` frames where a joint is far from its detections
    in most views that see it (the per-frame rule of `MultiviewTracker`, from the
    ``<joint>_<camera>_px`` figures and `MultiviewConfig.warn_px`)."""
    out: list[tuple[str, float, float, int]] = []
    warn = MultiviewConfig().warn_px
    for n in names:
        cols = [
            k
            for k in (results[0].fit if results else {})
            if k.startswith(f"{n}_") and k.endswith("_px")
        ]
        if not cols:
            continue
        err = np.array([[r.fit.get(c, math.nan) for c in cols] for r in results])
        det = np.isfinite(err)
        with np.errstate(invalid="ignore"):
            flag = (det.sum(axis=1) >= 2) & ((err > warn).sum(axis=1) * 2 > det.sum(axis=1))
        for a, b in true_runs(flag):
            if b - a >= min_frames:
                out.append((n, results[a].time_s, results[b - 1].time_s, int(b - a)))
    return sorted(out, key=lambda s: (s[1], s[0]))


def track_multiview_session(
    session_dir: str | os.PathLike[str] | Session,
    out_dir: str | os.PathLike[str] | None = None,
    cameras: str | Sequence[str] | None = None,
    config: MultiviewRunConfig | None = None,
    max_frames: int | None = None,
    point_offsets_mm: Mapping[str, Sequence[float]] | None = None,
) -> MultiviewRun:
    """Track a session's 2-D keypoints with the model-based multi-view fit.

    Parameters
    ----------
    session_dir : path or Session
        Session with two or more cameras and ``keypoints/<camera>.csv`` for each.
    out_dir : path, optional
        Result folder (``motion.npz``, ``joints.csv``, ``motion.bvh``, ``fit.csv``).
    cameras : str or sequence of str, optional
        ``"A,B[,C...]"``; default every camera with keypoints.
    config : MultiviewRunConfig, optional
    max_frames : int, optional
    point_offsets_mm : mapping of str to (3,) array, optional
        The detector's offset per canonical joint (`MultiviewTracker`); default: the table
        of the backend that ``keypoints/detect.json`` names for every camera
        (`mocapkit.tracking.multiview.detector_offsets`), none for other keypoints.
    """
    import time

    from mocapkit.detect.run import detected_backend
    from mocapkit.io.session import load_session
    from mocapkit.pipelines.camera_check import check_session_cameras
    from mocapkit.pipelines.run import check_result_folder
    from mocapkit.tracking.multiview.detector_offsets import (
        detector_offsets,
        offset_segments,
    )
    from mocapkit.tracking.multiview.lengths import subject_lengths_mm
    from mocapkit.tracking.stereo.tracker import azad_skeleton

    run_cfg = config or MultiviewRunConfig()
    if out_dir is not None:
        check_result_folder(out_dir)
    session = load_session(session_dir)
    all_names = [c.name for c in session.cameras]
    available = [c for c in all_names if c in session.keypoints]
    if cameras is None:
        names = available
    else:
        names = (
            [c.strip() for c in cameras.split(",")] if isinstance(cameras, str) else list(cameras)
        )
        for c in names:
            if c not in all_names:
                raise unknown_name("camera", c, all_names, "--cameras")
        missing = [c for c in names if c not in session.keypoints]
        if missing:
            raise SessionError(
                f"{session.path}: the multi-view fit needs keypoints/<camera>.csv for {missing}"
            )
    if len(names) < 2:
        raise SessionError(
            f"{session.path}: the multi-view fit needs keypoints of two or more cameras, found "
            f"{names}"
        )
    kps = [session.keypoints[c] for c in names]
    joint_names = kps[0].joint_names
    for c, k in zip(names, kps, strict=True):
        if k.joint_names != joint_names:
            raise SessionError(
                f"{session.path}: keypoints/{c}.csv: expected the joints of "
                f"keypoints/{names[0]}.csv ({list(joint_names)}), found {list(k.joint_names)}"
            )
    n = min(k.pixels.shape[0] for k in kps)
    if max_frames is not None:
        n = min(n, int(max_frames))
    # the cameras against what the data allow, before any fitting: the subject's
    # population proportions at its stature stand in for the lengths not measured yet
    check_session_cameras(
        session, names, skeleton=azad_skeleton(session.bone_lengths_mm, session.segment_vectors_mm)
    )
    cams = [session.camera(c) for c in names]
    pixels = np.stack([k.pixels[:n] for k in kps])  # (V, T, K, 2)
    t0 = time.process_time()
    with numba_compiling(time.process_time) as compiled:
        lengths, vectors = subject_lengths_mm(
            cams, joint_names, pixels, reject_mm=run_cfg.reject_mm, good_mm=run_cfg.good_mm
        )
        if point_offsets_mm is None:
            point_offsets_mm = detector_offsets(detected_backend(session.path, names))
        lengths, vectors = offset_segments(
            multiview_skeleton(), lengths, vectors, dict(point_offsets_mm)
        )
        sk = multiview_skeleton(lengths, height_mm=session.height_mm, vectors_mm=vectors)
        rebuilt = sorted({j for k in kps for j in k.rebuilt_joints})
        tracker = MultiviewTracker(
            sk, cams, joint_names, run_cfg.fit, rebuilt=rebuilt, point_offsets_mm=point_offsets_mm
        )
        time_s = kps[0].time_s[:n]
        samples = (
            _Sample(float(time_s[i]), {c: pixels[v, i] for v, c in enumerate(names)})
            for i in range(n)
        )
        run = run_tracker(
            tracker,
            samples,
            n,
            None,
            label=f"track stereo {session.path.name}",
            source=f"multi-view fit (cameras {','.join(names)}) on {session.path}",
        )
        q = _smooth_q(sk, run.motion.q, run.motion.time_s, run_cfg)
        motion = Motion.from_q(sk, run.motion.time_s, q, source=run.motion.source)
    seconds = time.process_time() - t0
    far = far_spans(run.results, tracker.names)
    out = None
    if out_dir is not None:
        out = write_run_folder(
            out_dir,
            motion,
            run.results,
            partial(pixel_input_speeds, cams, list(pixels), joint_names),
        )
    return MultiviewRun(motion, run.results, lengths, far, seconds, out, compiled)


def bench_multiview(repeats: int = 3, seconds: float = 4.0) -> dict[str, Any]:
    """Frames per CPU second of the 3-D step as `track_multiview_session` runs it by default
    (segment lengths from the take, the fit of every frame, smoothing; reading the CSV
    keypoints and writing no folder), four views of the ``ring`` rig, full body.

    The session is the built-in table-tennis rally rendered at 320x240 (only its keypoints
    are used); its keypoints get detector-like faults first (Gaussian noise of 3 px, 5 %
    of the points moved 30-90 px, seeded), since exact keypoints converge in fewer steps.
    The time is the process's CPU time, so the figure is one core's; medians over
    ``repeats`` after a warm-up run.
    """
    import tempfile
    import time

    from mocapkit.io.session import load_session
    from mocapkit.io.session_csv import write_keypoints_csv
    from mocapkit.synth.session_writer import SynthOptions, synthesize_session

    rng = np.random.default_rng(0)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench"
        synthesize_session(
            "builtin:table-tennis",
            path,
            SynthOptions(rig="ring", seconds=seconds, image_size=(320, 240)),
        )
        session = load_session(path)
        for cam, kp in session.keypoints.items():
            px = kp.pixels + rng.normal(0.0, 3.0, kp.pixels.shape)
            wild = rng.random(px.shape[:2]) < 0.05
            px[wild] += rng.uniform(30.0, 90.0, (int(wild.sum()), 1)) * rng.choice(
                (-1, 1), (int(wild.sum()), 2)
            )
            write_keypoints_csv(path / "keypoints" / f"{cam}.csv", kp.time_s, kp.joint_names, px)
        rates, walls = [], []
        n = 0
        for r in range(repeats + 1):
            t0 = time.perf_counter()
            run = track_multiview_session(path)
            wall = time.perf_counter() - t0
            n = run.motion.n_frames
            if r > 0:
                rates.append(n / max(run.seconds, 1e-9))
                walls.append(n / max(wall, 1e-9))
    return {
        "fps": float(np.median(rates)),
        "fps_runs": [round(x, 1) for x in rates],
        "fps_wall": float(np.median(walls)),
        "ms_per_frame": 1e3 / float(np.median(rates)),
        "views": 4,
        "n_frames": n,
        "joints": 15,
        "pipeline": "mocapkit track stereo SESSION (default: the multi-view fit, butterworth "
        "smoothing): segment lengths from the take, the fit of every frame, smoothing",
        "clock": "CPU time of the process (the 3-D step; CSV reading and writing left out)",
    }


@dataclass
class _Sample:
    time_s: float
    keypoints_px: dict[str, Any]


def far_spans_in_folder(result_dir: str | os.PathLike[str]) -> list[tuple[str, float, float, int]]:
    """`far_spans` of a result folder's ``fit.csv`` (empty when it has no per-view
    reprojection figures, as the results of other trackers)."""
    from mocapkit.pipelines.run import FIT_FILE, read_fit_csv

    path = Path(result_dir) / FIT_FILE
    if not path.is_file():
        return []
    rows, numeric = read_fit_csv(path)
    names = [k[: -len("_views")] for k in numeric if k.endswith("_views")]
    if not names:
        return []
    results = [
        FrameResult(
            float(numeric["time_s"][i]),
            np.zeros(0),
            np.zeros((0, 3)),
            {},
            {k: float(v[i]) for k, v in numeric.items() if k.endswith("_px")},
            "",
        )
        for i in range(len(rows))
    ]
    return far_spans(results, names)


#: ``auto`` takes the model-based fit only where two views' optical axes are at least this
#: far apart (rad): on a narrow stereo pair (axes about 2 deg apart) the fit places the
#: upper body 47 mm off from exact keypoints where the paper's tracker, which is built for
#: such a pair, is within 11 mm; from 60 deg (the `multi` rig) the fit is ahead.
FIT_MIN_VIEW_ANGLE_RAD = math.radians(20.0)


def resolve_stereo_method(
    session_dir: str | os.PathLike[str] | Session, method: str = "auto", cameras: str | None = None
) -> str:
    """``fit``, ``filter`` or ``skin`` for a session: ``auto`` takes the fit when every
    camera used has keypoints and the views span at least `FIT_MIN_VIEW_ANGLE_RAD`, the
    paper's tracker on the keypoints (``filter``) for a narrower rig. Keypoints missing
    for a camera with video are detected first where a 2-D detector is installed
    (`mocapkit.detect.run.ensure_keypoints`, said on stderr); skin colour where there is
    none. Give the loaded `Session` when the chosen tracker is to run on it: it is read
    once."""
    from mocapkit.camera.triangulation import widest_view_angle_rad
    from mocapkit.detect.backend import default_backend
    from mocapkit.detect.run import ensure_keypoints
    from mocapkit.io.session import load_session
    from mocapkit.pipelines.stereo import parse_cameras

    if method not in STEREO_METHODS:
        raise unknown_name("stereo method", method, STEREO_METHODS, "--method")
    if method != "auto":
        return method
    session = load_session(session_dir)
    names = (
        parse_cameras(cameras, session.video_cameras)
        if cameras
        else [c.name for c in session.cameras]
    )
    missing = [c for c in names if c not in session.keypoints]
    if missing and default_backend() is not None and set(missing) <= set(session.video_cameras):
        ensure_keypoints(session, names)  # detected into the session, reused next time
        missing = []
    if not names or missing:
        return "skin"
    angle = widest_view_angle_rad([session.camera(c) for c in names])
    return "fit" if angle >= FIT_MIN_VIEW_ANGLE_RAD else "filter"


def track_stereo_auto(
    session_dir: str | os.PathLike[str],
    out_dir: str | os.PathLike[str] | None = None,
    method: str = "auto",
) -> Any:
    """The ``stereo`` method of `mocapkit batch`: the model-based fit on a session with
    keypoints for every camera (`track_multiview_session`), the paper's skin-colour
    tracker otherwise (`mocapkit.pipelines.stereo.track_stereo_session`), or as
    ``method`` says (`STEREO_METHODS`)."""
    from mocapkit.io.session import load_session
    from mocapkit.pipelines.stereo import track_stereo_session

    session = load_session(session_dir)
    chosen = resolve_stereo_method(session, method)
    if chosen == "fit":
        return track_multiview_session(session, out_dir)
    return track_stereo_session(session, out_dir, use_keypoints=chosen == "filter")


__all__ = [
    "FAR_MIN_FRAMES",
    "FIT_MIN_VIEW_ANGLE_RAD",
    "SMOOTHING",
    "STEREO_METHODS",
    "MultiviewRun",
    "MultiviewRunConfig",
    "bench_multiview",
    "far_spans",
    "far_spans_in_folder",
    "resolve_stereo_method",
    "track_multiview_session",
    "track_stereo_auto",
]
