"""Stereo / multi-view markerless tracking of a session folder, its evaluation and its benchmark.

`track_stereo_session` streams a session (two or more cameras with video; optionally
their 2-D keypoints) through `mocapkit.tracking.stereo.tracker.StereoTracker` and
writes the usual result folder through the shared runner
(`mocapkit.pipelines.run.run_tracker`, with ``fit.csv``). `evaluate_stereo` scores a
result against a synthetic session's truth: the mean error of shoulders, elbows and
wrists and the torso yaw error (the yaw of the line between the shoulders).
`stereo_accuracy` renders in-view excerpts of the project's clips (`STEREO_CLIPS`) and scores
each tracker mode (`ACCURACY_MODES`) on them. `bench_stereo` times the whole per-frame pipeline at
640x480 on a rendered stereo session.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ConfigError, SessionError, unknown_name
from mocapkit.io.markers import true_runs
from mocapkit.io.motion import Motion
from mocapkit.pipelines.camera_check import check_session_cameras
from mocapkit.pipelines.fit_report import SHOWN_SPANS, span_when, worst_spans_lines
from mocapkit.pipelines.harness import HARNESS_DETECTORS, TUNING_CLIPS
from mocapkit.pipelines.input_speeds import keypoint_input_speeds
from mocapkit.pipelines.run import run_tracker
from mocapkit.timing import CompileTime, StageTimer, numba_compiling
from mocapkit.tracking.stereo.arm_filter import ArmFilterConfig
from mocapkit.tracking.stereo.fusion import default_fusion
from mocapkit.tracking.stereo.tracker import (
    StereoConfig,
    StereoPose,
    StereoSample,
    StereoTracker,
    azad_skeleton,
)

if TYPE_CHECKING:
    from mocapkit.io.session import Session, SessionSample

FloatArray = NDArray[np.float64]

#: Joints scored by the accuracy target (mean error <= 40 mm per clip).
ARM_JOINTS = (
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
)


@dataclass(frozen=True)
class ElbowJump:
    """Consecutive frames on which an arm's elbow jumped (``<side>_elbow_jump`` in fit.csv,
    `StereoConfig.elbow_jump_mm_per_s`): the pose of those frames is not to be trusted."""

    side: str
    start_s: float
    end_s: float
    n_frames: int
    top_mm_per_s: float

    def __str__(self) -> str:
        when = span_when(self.start_s, self.end_s, self.n_frames)
        return (
            f"the {self.side} elbow jumps {when}, up to {self.top_mm_per_s / 1000:.1f} m/s "
            "relative to the shoulder"
        )


def elbow_jump_warnings(jumps: Sequence[ElbowJump], shown: int = SHOWN_SPANS) -> list[str]:
    """The end-of-run warning about elbow jumps: a count, the ``shown`` fastest, then how
    many more (`mocapkit.pipelines.fit_report.worst_spans_lines`); nothing without
    jumps."""
    n_frames = sum(j.n_frames for j in jumps)
    header = (
        f"warning: an elbow jumps in {len(jumps)} span{'s' if len(jumps) != 1 else ''} "
        f"({n_frames} frame{'s' if n_frames != 1 else ''}): the arm filter took the other "
        "side of the elbow circle; the pose there is not to be trusted (fit.csv's "
        "left_elbow_jump, right_elbow_jump)"
    )
    return worst_spans_lines(header, [jumps], lambda j: j.top_mm_per_s, shown)


def elbow_jumps(time_s: ArrayLike, fit: Mapping[str, ArrayLike]) -> list[ElbowJump]:
    """The spans of frames flagged ``<side>_elbow_jump``, in time order.

    Parameters
    ----------
    time_s : (T,) array-like
    fit : mapping of str to (T,) array-like
        fit.csv's columns (`mocapkit.pipelines.run.read_fit_csv`); without the jump
        columns (another tracker's result) there are no jumps.
    """
    t = np.asarray(time_s, dtype=float)
    out = []
    for side in ("left", "right"):
        if f"{side}_elbow_jump" not in fit:
            continue
        flag = np.asarray(fit[f"{side}_elbow_jump"], dtype=float) > 0
        speed = np.asarray(fit[f"{side}_elbow_speed_mm_per_s"], dtype=float)
        for a, b in true_runs(flag):
            top = float(np.nanmax(speed[a:b]))
            out.append(ElbowJump(side, float(t[a]), float(t[b - 1]), int(b - a), top))
    return sorted(out, key=lambda j: (j.start_s, j.side))


def elbow_jumps_in_folder(result_dir: str | os.PathLike[str]) -> list[ElbowJump]:
    """`elbow_jumps` of a result folder's fit.csv (none when it has no jump columns)."""
    from mocapkit.pipelines.run import FIT_FILE, read_fit_csv

    _, columns = read_fit_csv(Path(result_dir) / FIT_FILE)
    return elbow_jumps(columns["time_s"], columns)


@dataclass
class StereoRun:
    """A tracked session: the motion, per-frame diagnostics, `StereoPose` results, the
    elbow jumps found in them (`elbow_jumps`) and the Numba compilation of the run
    (`mocapkit.timing.numba_compiling`: a first run's)."""

    motion: Motion
    yaw_rad: FloatArray  # (T,)
    measured_mm: FloatArray  # (T, 3, 3)
    n_ik: NDArray[np.int64]  # (T, 2)
    seconds: float  # reading and tracking, without writing
    results: list[StereoPose] = field(default_factory=list)  # per frame, as fit.csv
    jumps: list[ElbowJump] = field(default_factory=list)
    compiled: CompileTime = field(default_factory=CompileTime)  # Numba, on a first run


def parse_cameras(text: str | None, available: Sequence[str]) -> list[str]:
    """``A,B[,C...]`` to camera names (default: every camera with a video)."""
    if text is None:
        cams = list(available)
    else:
        cams = [c.strip() for c in text.split(",") if c.strip()]
        for c in cams:
            if c not in available:
                raise unknown_name("camera", c, available, "--cameras")
        if len(set(cams)) != len(cams):
            raise ConfigError(f"--cameras: a camera is named twice in {text!r}")
    if len(cams) < 2:
        raise ConfigError(f"the stereo tracker needs two or more cameras with video, found {cams}")
    return cams


def _open_session(
    session_dir: str | os.PathLike[str] | Session,
    cameras: str | Sequence[str] | None,
    cfg: StereoConfig,
) -> tuple[Session, list[str], StereoTracker]:
    """The session, its camera names (``--cameras``) and a `StereoTracker` on them, fitted
    to the subject; refuses keypoint mode without every camera's keypoints."""
    from mocapkit.io.session import load_session

    session = load_session(session_dir)
    names = (
        parse_cameras(cameras, session.video_cameras)
        if cameras is None or isinstance(cameras, str)
        else parse_cameras(",".join(cameras), session.video_cameras)
    )
    kp_names: tuple[str, ...] = ()
    if cfg.use_keypoints:
        from mocapkit.detect.run import ensure_keypoints

        ensure_keypoints(session, names)  # detected into the session when missing
        kp_names = tuple(session.keypoints[names[0]].joint_names)
    return session, names, stereo_tracker(session, names, cfg, kp_names)


def stereo_tracker(
    session: Session, names: Sequence[str], cfg: StereoConfig, keypoint_names: Sequence[str]
) -> StereoTracker:
    """A `StereoTracker` on the named cameras of a session, fitted to its subject."""
    sk = azad_skeleton(session.bone_lengths_mm, session.segment_vectors_mm)
    check_session_cameras(session, names, skeleton=sk)  # before any tracker is built
    cams = [session.camera(c) for c in names]
    return StereoTracker(sk, cams, cfg, keypoint_names=tuple(keypoint_names))


def stereo_sample(s: SessionSample, names: Sequence[str]) -> StereoSample:
    """A session sample as the stereo tracker's: the named cameras' images, keypoints."""
    return StereoSample(s.time_s, {c: s.image(c) for c in names}, dict(s.keypoints_px))


def _samples(session: Session, names: Sequence[str], n: int) -> Iterator[StereoSample]:
    """The first ``n`` frames of the named cameras as `StereoSample` (images, keypoints)."""
    for k, s in enumerate(session.samples(list(names))):
        if k >= n:
            break
        yield stereo_sample(s, names)


def track_stereo_session(
    session_dir: str | os.PathLike[str] | Session,
    out_dir: str | os.PathLike[str] | None = None,
    cameras: str | Sequence[str] | None = None,
    use_keypoints: bool = False,
    n_particles: int | None = None,
    config: StereoConfig | None = None,
    max_frames: int | None = None,
) -> StereoRun:
    """Track a session with the stereo / multi-view markerless tracker.

    Parameters
    ----------
    session_dir : path or Session
        Session folder with two or more cameras with video (`mocapkit.io.session`).
    out_dir : path, optional
        Result folder (``motion.npz``, ``joints.csv``, ``motion.bvh``, ``fit.csv``), written
        by `mocapkit.pipelines.run.run_tracker`.
    cameras : str or sequence of str, optional
        ``"A,B[,C...]"``; default every camera with a video.
    use_keypoints : bool
        Head and hands from ``keypoints/<camera>.csv`` instead of skin blobs.
    n_particles : int, optional
        Particles per arm and run (default 150).
    config : StereoConfig, optional
        Full settings (``use_keypoints`` and ``n_particles`` override it).
    max_frames : int, optional
        Stop after this many frames.
    """

    cfg = config or StereoConfig()
    if use_keypoints:
        cfg = replace(cfg, use_keypoints=True)
    if n_particles is not None:
        cfg = replace(cfg, arm=replace(cfg.arm, n_particles=int(n_particles)))
    session, names, tracker = _open_session(session_dir, cameras, cfg)
    n = session.video(names[0]).n_frames
    if max_frames is not None:
        n = min(n, int(max_frames))
    samples = _samples(session, names, n)
    mode = "keypoints" if cfg.use_keypoints else "skin blobs"
    timer = StageTimer()
    with numba_compiling() as compiled:
        run = run_tracker(
            tracker,
            samples,
            n,
            out_dir,
            label=f"track stereo {session.path.name}",
            source=f"stereo tracker ({mode}, cameras {','.join(names)}) on {session.path}",
            timer=timer,
            input_speeds=keypoint_input_speeds(session, names),
        )
    poses = [cast(StereoPose, r) for r in run.results]
    fit_keys = poses[0].fit if poses else {}
    totals = timer.totals_s()
    return StereoRun(
        run.motion,
        np.array([p.torso_yaw_rad for p in poses]),
        np.array([p.measured_mm for p in poses]),
        np.array([[p.arms[s].n_ik for s in ("left", "right")] for p in poses], dtype=np.int64),
        totals.get("input", 0.0) + totals.get("track", 0.0),
        poses,
        elbow_jumps([p.time_s for p in poses], {k: [p.fit[k] for p in poses] for k in fit_keys}),
        compiled,
    )


def truth_yaw_rad(joints_mm: FloatArray, names: Sequence[str]) -> FloatArray:
    """Torso yaw (T,) of the truth: direction of left -> right shoulder in the floor plane."""
    li, ri = list(names).index("left_shoulder"), list(names).index("right_shoulder")
    d = joints_mm[:, ri] - joints_mm[:, li]
    return np.arctan2(d[:, 1], d[:, 0])


def evaluate_stereo(run: StereoRun, session_dir: str | os.PathLike[str]) -> dict[str, Any]:
    """Errors of a run against the session's truth (frames matched by time).

    Returns a dict: ``per_joint_mm`` (the six arm joints), ``arm_mean_mm`` (their
    mean), ``torso_yaw_error_deg`` (mean absolute), ``frames``.
    """
    from mocapkit.eval.metrics import evaluate_joints
    from mocapkit.io.session import load_session

    session = load_session(session_dir)
    session.require(truth=True)
    truth = session.truth
    if truth is None:  # unreachable after require
        raise SessionError(f"{session_dir}: no truth.npz")
    m = run.motion
    rep = evaluate_joints(
        m.time_s,
        m.joint_names,
        m.joints_mm,
        truth.time_s,
        truth.joint_names,
        truth.joints_mm,
        joints=ARM_JOINTS,
    )
    per = {k: float(v) for k, v in rep.per_joint_mm.items()}
    ty = truth_yaw_rad(truth.joints_mm, truth.joint_names)
    idx = np.clip(np.searchsorted(truth.time_s, m.time_s), 0, len(truth.time_s) - 1)
    err = np.abs(np.remainder(run.yaw_rad - ty[idx] + math.pi, 2 * math.pi) - math.pi)
    return {
        "per_joint_mm": per,
        "arm_mean_mm": float(np.mean(list(per.values()))),
        "torso_yaw_error_deg": float(np.degrees(np.mean(err))),
        "frames": int(m.n_frames),
    }


def bench_stereo(
    session_dir: str | os.PathLike[str] | None = None,
    n_frames: int = 60,
    repeats: int = 3,
    n_particles: int = 150,
    more_particles: int | None = 1500,
) -> dict[str, Any]:
    """Frames per CPU second of the whole per-frame pipeline (images in memory).

    Renders (or reads) a 640x480 stereo session, decodes its frames once, then times
    `StereoTracker.update` over them after a warm-up pass; medians over ``repeats``.
    The time is the process's CPU time (`time.process_time`; OpenCV on one thread,
    Numba single-threaded), so the figure is one core's and a shared machine's load
    does not enter it; ``fps_wall`` gives the wall-clock rate beside it.

    Returns
    -------
    dict
        ``fps`` (frames per CPU second, median), ``fps_runs``, ``fps_wall``,
        ``ms_per_frame``, ``stages_ms`` (CPU ms a frame per stage of
        `StereoTracker.update`: ``skin``, ``head_hands``, ``gradients``, ``arms``, and
        ``other``: the rest of the frame), ``particles``, ``runs_per_frame``,
        ``image_size``, ``views``, ``n_frames``; with ``more_particles``, also
        ``fps_<N>_particles`` and ``arms_ms_<N>_particles`` for N = ``more_particles``.
    """
    import tempfile

    from mocapkit.io.session import load_session
    from mocapkit.synth.session_writer import SynthOptions, synthesize_session
    from mocapkit.timing import StageTimer

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(session_dir) if session_dir is not None else Path(tmp) / "bench"
        if session_dir is None:
            synthesize_session(
                "builtin:table-tennis",
                path,
                SynthOptions(rig="stereo", seconds=(n_frames + 5) / 30.0, sleeve="long"),
            )
        session = load_session(path)
        names = list(session.video_cameras)[:2]
        frames = []
        for k, s in enumerate(session.samples(names)):
            if k >= n_frames:
                break
            frames.append(StereoSample(s.time_s, {c: s.image(c) for c in names}))
        sk = azad_skeleton(session.bone_lengths_mm, session.segment_vectors_mm)
        cams = [session.camera(c) for c in names]

    def timed(particles: int) -> tuple[list[float], list[float], dict[str, float]]:
        cfg = StereoConfig(arm=ArmFilterConfig(n_particles=particles))
        cpu_rates, wall_rates = [], []
        stage_runs: list[dict[str, float]] = []
        for r in range(repeats + 1):
            timer = StageTimer(time.process_time)
            tracker = StereoTracker(sk, cams, cfg, timer=timer)
            c0, t0 = time.process_time(), time.perf_counter()
            for f in frames:
                tracker.update(f)
            cpu, wall = time.process_time() - c0, time.perf_counter() - t0
            if r > 0:  # the first pass compiles and warms up
                cpu_rates.append(len(frames) / max(cpu, 1e-9))
                wall_rates.append(len(frames) / max(wall, 1e-9))
                ms = {k: 1e3 * v / len(frames) for k, v in timer.totals_s().items()}
                ms["other"] = 1e3 * cpu / len(frames) - sum(ms.values())
                stage_runs.append(ms)
        med = int(np.argsort(cpu_rates)[len(cpu_rates) // 2])
        return cpu_rates, wall_rates, stage_runs[med]

    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)  # figures for one core, as the other benchmarks
    try:
        cpu_rates, wall_rates, stages = timed(n_particles)
        out: dict[str, Any] = {
            "fps": float(np.median(cpu_rates)),
            "fps_runs": [round(x, 1) for x in cpu_rates],
            "fps_wall": float(np.median(wall_rates)),
            "ms_per_frame": 1e3 / float(np.median(cpu_rates)),
            "stages_ms": {k: round(v, 3) for k, v in stages.items()},
            "particles": n_particles,
        }
        if more_particles is not None:
            more_rates, _wall, more_stages = timed(int(more_particles))
            out[f"fps_{int(more_particles)}_particles"] = float(np.median(more_rates))
            out[f"arms_ms_{int(more_particles)}_particles"] = round(more_stages["arms"], 3)
    finally:
        cv2.setNumThreads(threads)
    out.update(
        {
            "runs_per_frame": StereoConfig().arm.n_runs,
            "image_size": f"{cams[0].image_size[0]}x{cams[0].image_size[1]}",
            "views": len(cams),
            "n_frames": len(frames),
            "clock": "CPU time of the process (OpenCV on one thread)",
        }
    )
    return out


#: Start (s) of each clip's 4 s excerpt where the subject stays in front of a fixed stereo
#: rig, the paper's setting (walking clips leave the views; chosen by the pelvis travelling
#: less than 0.8 m in 4 s); a clip not listed starts where its pelvis travels least
#: (`stillest_start_s`). Which clips are run is the project's split
#: (`mocapkit.pipelines.harness.CLIP_SETS`, default the tuning clips).
STEREO_CLIPS: dict[str, float] = {
    "13_26.bvh": 7.5,
    "01_09.amc": 7.5,
    "01_12.amc": 5.0,
    "lambada.amc": 12.5,
    "charleston1.amc": 0.0,
    "01_01.bvh": 7.5,
    "01_01.amc": 7.5,  # the same trial as the BVH
}


def stillest_start_s(
    time_s: ArrayLike, pelvis_mm: ArrayLike, seconds: float, step_s: float = 0.5
) -> float:
    """The start (s from the first frame, on a ``step_s`` grid) of the ``seconds`` long
    window whose pelvis ends nearest where it began (the least net travel: a subject
    staying in front of a fixed rig); 0 for a clip no longer than ``seconds``."""
    t = np.asarray(time_s, dtype=float)
    t = t - t[0]
    p = np.asarray(pelvis_mm, dtype=float)
    best, start = math.inf, 0.0
    for s in np.arange(0.0, t[-1] - seconds + 1e-9, step_s):
        a, b = np.searchsorted(t, s - 1e-9), np.searchsorted(t, s + seconds + 1e-9) - 1
        travel = float(np.linalg.norm(p[b] - p[a]))
        if travel < best:
            best, start = travel, float(s)
    return start


def excerpt_start_s(mocap_dir: str | os.PathLike[str], clip: str, seconds: float) -> float:
    """Start of a clip's excerpt in the stereo studies: `STEREO_CLIPS`' where listed,
    else `stillest_start_s` of the clip's pelvis."""
    if clip in STEREO_CLIPS:
        return STEREO_CLIPS[clip]
    from mocapkit.io.motion_files import read_motion

    motion = read_motion(Path(mocap_dir) / clip)
    return stillest_start_s(motion.time_s, motion.joint("pelvis"), seconds)


def _study_session(
    work: Path, mocap_dir: str | os.PathLike[str], clip: str, start: float, seconds: float
) -> Path:
    """The session of one clip excerpt of a stereo study, rendered once into ``work``.

    Rig ``all`` (the stereo pair and the mono camera), long sleeves, default realism;
    a session already rendered there (it has its ``truth.npz``) is reused. The folder is
    named by clip, start and length, so an excerpt of another length is not taken for it.
    """
    from mocapkit.synth.session_writer import SynthOptions, synthesize_session

    session = work / f"{Path(clip).stem}_{start:g}+{seconds:g}s"
    if not (session / "truth.npz").is_file():
        synthesize_session(
            str(Path(mocap_dir) / clip),
            session,
            SynthOptions(rig="all", start_s=start, seconds=seconds, sleeve="long", overwrite=True),
        )
    return session


ACCURACY_MODES: dict[str, StereoConfig] = {
    "keypoints+torso": StereoConfig(use_keypoints=True, torso="keypoints"),
    # with a measured torso the nominal shoulders are right: 4 DoF per arm
    "keypoints+torso+static": StereoConfig(
        use_keypoints=True,
        torso="keypoints",
        arm=ArmFilterConfig(adaptive_shoulder=False),
    ),
    "keypoints": StereoConfig(use_keypoints=True),
    "skin": StereoConfig(),
}

#: The modes that track from keypoints (the ones a detector can feed).
_KEYPOINT_MODES = tuple(k for k, c in ACCURACY_MODES.items() if c.use_keypoints)


def stereo_accuracy(
    mocap_dir: str | os.PathLike[str],
    work_dir: str | os.PathLike[str],
    clips: Sequence[str] | None = None,
    modes: Sequence[str] = ("keypoints+torso",),
    cameras: str | None = "stereo_left,stereo_right",
    seconds: float = 4.0,
    say: Any = None,
    seed: int = 0,
    n_particles: int | None = None,
    detector: str | None = None,
) -> list[dict[str, Any]]:
    """Render each clip's excerpt (``--rig all``, long sleeves; `STEREO_CLIPS`) once,
    track it in each mode. ``clips``: default the project's tuning clips
    (`mocapkit.pipelines.harness.TUNING_CLIPS`).

    ``seed`` (the filters' random generator, `StereoConfig.seed`) and ``n_particles``
    (default 150) change every mode's settings, to measure the spread between seeds and
    the effect of the particle count.

    The keypoint modes take the session's true 2-D keypoints; with ``detector`` (a
    `mocapkit.detect` backend, e.g. ``"mediapipe"``) they take that detector's, run on
    the tracked cameras' rendered video (kept in ``<session>/detect_<detector>`` and
    reused; `mocapkit.pipelines.harness.detector_keypoints`).

    Returns one row per clip and mode: ``clip``, ``mode``, ``keypoints`` (``"true"`` or
    the detector), ``cameras`` and the figures of `evaluate_stereo` plus
    ``frames_per_s``.
    """
    for m in modes:
        if m not in ACCURACY_MODES:
            raise unknown_name("accuracy mode", m, ACCURACY_MODES, "--modes")
    if detector is not None:
        if detector not in HARNESS_DETECTORS:
            raise unknown_name("detector", detector, HARNESS_DETECTORS, "--detector")
        blind = [m for m in modes if not ACCURACY_MODES[m].use_keypoints]
        if blind:
            raise ConfigError(
                f"--detector: the modes {blind} track from the video, not from keypoints; "
                f"expected keypoint modes ({', '.join(_KEYPOINT_MODES)})"
            )
    rows = []
    work = Path(work_dir)
    for clip in clips or TUNING_CLIPS:
        start = excerpt_start_s(mocap_dir, clip, seconds)
        session = _study_session(work, mocap_dir, clip, start, seconds)
        for m in modes:
            cfg = replace(ACCURACY_MODES[m], seed=int(seed))
            run = track_stereo_session(
                _with_keypoints(session, cameras, detector),
                None,
                cameras=cameras,
                config=cfg,
                n_particles=n_particles,
            )
            ev = evaluate_stereo(run, session)
            row = {
                "clip": clip,
                "start_s": start,
                "mode": m,
                "keypoints": detector or "true",
                "cameras": cameras or "all",
                **ev,
            }
            row["frames_per_s"] = run.motion.n_frames / max(run.seconds, 1e-9)
            rows.append(row)
            if say is not None:
                say(format_accuracy_row(row))
    return rows


def _with_keypoints(session_dir: Path, cameras: str | None, detector: str | None) -> Session:
    """The session, its tracked cameras' keypoints (``cameras``, `parse_cameras`)
    replaced by ``detector``'s on their video (`mocapkit.pipelines.harness.
    detector_keypoints`, cached in the session folder); as it is without a detector."""
    from mocapkit.io.session import load_session
    from mocapkit.io.session_csv import read_keypoints_csv
    from mocapkit.pipelines.harness import detector_keypoints

    session = load_session(session_dir)
    if detector is None:
        return session
    names = parse_cameras(cameras, session.video_cameras)
    found = detector_keypoints(session_dir, session_dir, detector, False, names)
    for c in names:
        kp = read_keypoints_csv(found / "keypoints" / f"{c}.csv")
        session.keypoints[c] = replace(kp, source=f"{kp.source} (detected: {detector})")
    return session


#: Variants of the ablation study (the paper's Figs. 2, 3, 5 and 8 as numbers), each a
#: change of the ``keypoints+torso`` mode.
_BASE = ACCURACY_MODES["keypoints+torso"]
ABLATIONS: dict[str, StereoConfig] = {
    "default": _BASE,
    "no IK sampling": replace(_BASE, arm=replace(_BASE.arm, use_ik=False)),
    "constant noise": replace(_BASE, arm=replace(_BASE.arm, adaptive_noise=False)),
    "static shoulders": replace(_BASE, arm=replace(_BASE.arm, adaptive_shoulder=False)),
    "conventional fusion": replace(_BASE, arm=replace(_BASE.arm, fusion=default_fusion(True))),
    "eq. (1) edges": replace(_BASE, arm=replace(_BASE.arm, oriented_edges=False)),
    "weighted mean estimate": replace(_BASE, arm=replace(_BASE.arm, estimate="mean")),
    "no shoulder pull": replace(_BASE, arm=replace(_BASE.arm, shoulder_pull=0.0)),
}


def arm_errors_per_frame(
    time_s: FloatArray, joint_names: Sequence[str], joints_mm: FloatArray, truth: Any
) -> FloatArray:
    """Mean error (T,) mm of the six `ARM_JOINTS` per frame against a `Truth` (frames matched
    by time: the truth sample at or after each time); NaN joints are left out, a frame
    with none is NaN."""
    idx = np.clip(np.searchsorted(truth.time_s, time_s), 0, len(truth.time_s) - 1)
    tn, mn = list(truth.joint_names), list(joint_names)
    err = np.stack(
        [
            np.linalg.norm(joints_mm[:, mn.index(j)] - truth.joints_mm[idx, tn.index(j)], axis=1)
            for j in ARM_JOINTS
        ],
        axis=1,
    )
    out = np.full(err.shape[0], math.nan)
    seen = np.any(np.isfinite(err), axis=1)
    out[seen] = np.nanmean(err[seen], axis=1)
    return out


def frames_to_converge(
    err_reset: FloatArray, err_free: FloatArray, start: int, tol_mm: float, limit: int
) -> int:
    """Frames from a reset at ``start`` until the reset run's error is within ``tol_mm`` of
    the undisturbed run's (1: already on the reset frame); ``limit + 1`` when not within
    ``limit`` frames. Frames where either error is NaN do not count as converged."""
    for k in range(limit):
        f = start + k
        if f >= err_reset.shape[0]:
            break
        if err_reset[f] <= err_free[f] + tol_mm:  # NaN compares False
            return k + 1
    return limit + 1


def _track_with_reset(
    session_dir: Path, cameras: str | None, cfg: StereoConfig, reset_frame: int | None
) -> tuple[FloatArray, FloatArray, Any]:
    """Stream a session through a `StereoTracker`, resetting its arms before frame
    ``reset_frame``; returns times (T,), the 15 canonical joints (T, 15, 3) and the truth."""
    session, names, tracker = _open_session(session_dir, cameras, cfg)
    session.require(truth=True)
    times, joints = [], []
    for k, sample in enumerate(_samples(session, names, session.video(names[0]).n_frames)):
        if k == reset_frame:
            tracker.reset_arms()
        pose = tracker.update(sample)
        times.append(pose.time_s)
        joints.append(pose.joints_mm)
    return np.array(times), np.array(joints), session.truth


def stereo_ablations(
    mocap_dir: str | os.PathLike[str],
    work_dir: str | os.PathLike[str],
    variants: Sequence[str] = tuple(ABLATIONS),
    clips: Sequence[str] | None = None,
    cameras: str | None = "stereo_left,stereo_right",
    reset_s: float = 1.0,
    tol_mm: float = 10.0,
    limit: int = 30,
    seconds: float = 4.0,
    say: Any = None,
    seed: int = 0,
) -> list[dict[str, Any]]:
    """Mean arm error and frames to converge from a wrong start, per variant and clip
    (``seed``: `StereoConfig.seed` of every variant; ``clips``: default the tuning clips).

    Each clip (rendered as in `stereo_accuracy`) is tracked twice per variant: once
    undisturbed (its arm mean error is the figure) and once with both arm filters reset
    to the initial hanging arm at ``reset_s`` (`StereoTracker.reset_arms`); the frames
    to converge are those until the reset run's error is back within ``tol_mm`` of the
    undisturbed run's (`frames_to_converge`, at most ``limit``; ``limit + 1``: not back).

    Returns one row per clip and variant: ``clip``, ``variant``, ``arm_mean_mm``,
    ``frames_to_converge``, ``error_at_reset_mm`` (the reset run's error on the reset
    frame).
    """
    from mocapkit.skeleton.model import CANONICAL_JOINTS

    for v in variants:
        if v not in ABLATIONS:
            raise unknown_name("ablation variant", v, ABLATIONS, "--variants")
    if not 0.0 < reset_s < seconds:
        raise ConfigError(
            f"stereo ablations: expected the reset time within the excerpt (0 < reset_s < "
            f"{seconds:g} s), found reset_s = {reset_s:g} s"
        )
    rows = []
    for clip in clips or TUNING_CLIPS:
        start = excerpt_start_s(mocap_dir, clip, seconds)
        session = _study_session(Path(work_dir), mocap_dir, clip, start, seconds)
        for v in variants:
            cfg = replace(ABLATIONS[v], seed=int(seed))
            t, joints, truth = _track_with_reset(session, cameras, cfg, None)
            free = arm_errors_per_frame(t, CANONICAL_JOINTS, joints, truth)
            reset_frame = int(np.searchsorted(t, t[0] + reset_s))
            t2, joints2, _ = _track_with_reset(session, cameras, cfg, reset_frame)
            reset = arm_errors_per_frame(t2, CANONICAL_JOINTS, joints2, truth)
            row = {
                "clip": clip,
                "variant": v,
                "arm_mean_mm": float(np.nanmean(free)),
                "frames_to_converge": frames_to_converge(reset, free, reset_frame, tol_mm, limit),
                "error_at_reset_mm": float(reset[reset_frame]),
            }
            rows.append(row)
            if say is not None:
                say(
                    f"{clip:<16}{v:<24}{row['arm_mean_mm']:7.1f}{row['frames_to_converge']:7d}"
                    f"{row['error_at_reset_mm']:9.1f}"
                )
    return rows


def format_accuracy_row(row: dict[str, Any]) -> str:
    """One line: clip, mode, keypoints, per-joint errors, arm mean, yaw error."""
    per = row["per_joint_mm"]
    joints = " ".join(f"{per[j]:6.1f}" for j in ARM_JOINTS)
    return (
        f"{row['clip']:<16}{row['mode']:<17}{row.get('keypoints', 'true'):<10}{joints}  "
        f"{row['arm_mean_mm']:6.1f}"
        f"  {row['torso_yaw_error_deg']:5.1f}"
    )


def accuracy_means(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per mode (in the rows' order), the mean over its clips of each figure of
    `format_accuracy_row`, as a row with ``clip`` ``"mean"`` (and the rows' keypoints)."""
    out = []
    for mode in dict.fromkeys(r["mode"] for r in rows):
        mine = [r for r in rows if r["mode"] == mode]
        out.append(
            {
                "clip": "mean",
                "mode": mode,
                "keypoints": "/".join(dict.fromkeys(r.get("keypoints", "true") for r in mine)),
                "per_joint_mm": {
                    j: float(np.mean([r["per_joint_mm"][j] for r in mine])) for j in ARM_JOINTS
                },
                "arm_mean_mm": float(np.mean([r["arm_mean_mm"] for r in mine])),
                "torso_yaw_error_deg": float(np.mean([r["torso_yaw_error_deg"] for r in mine])),
            }
        )
    return out


def accuracy_header() -> str:
    """Column titles of `format_accuracy_row`."""
    short = " ".join(f"{j.replace('left_', 'L').replace('right_', 'R')[:6]:>6}" for j in ARM_JOINTS)
    return f"{'clip':<16}{'mode':<17}{'keypoints':<10}{short}  {'mean':>6}  {'yaw':>5}"


__all__ = [
    "ABLATIONS",
    "ACCURACY_MODES",
    "ARM_JOINTS",
    "STEREO_CLIPS",
    "ElbowJump",
    "StereoRun",
    "accuracy_header",
    "accuracy_means",
    "arm_errors_per_frame",
    "bench_stereo",
    "elbow_jump_warnings",
    "elbow_jumps",
    "elbow_jumps_in_folder",
    "evaluate_stereo",
    "excerpt_start_s",
    "format_accuracy_row",
    "frames_to_converge",
    "parse_cameras",
    "stereo_ablations",
    "stereo_accuracy",
    "stillest_start_s",
    "track_stereo_session",
    "truth_yaw_rad",
]
