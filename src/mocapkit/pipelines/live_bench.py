"""``mocapkit bench live``: latency and dropped frames of each tracker run live.

A rendered session (`LIVE_BENCH_CLIP`, 640x480, markers at 60 Hz, video at 30 Hz, seen by
the mono camera and a stereo pair) is replayed in real time by ``mocapkit replay --lsl``
in a separate process, and tracked by ``mocapkit live METHOD`` (`track_live`, default
settings) in this one, pinned to one core with OpenCV on one thread. Each tracker is
compiled and warmed up first on the same session offline. Per tracker: the latency from
each input sample's LSL time stamp to its output sample being sent (median, 99th
percentile, max; ms), the CPU time of each step (the tracker's update and the output, on
the tracking thread: what the latency is on an idle core, less waiting), frames tracked
and dropped, and the process's memory (RSS) at the first and last result. Timings are
figures to read, never asserted by tests.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path
from typing import Any

import cv2

from mocapkit.errors import ConfigError

#: The motion, excerpt (start s, length s) and rates of the benchmark session.
LIVE_BENCH_CLIP = ("builtin:table-tennis", 0.0, 10.0)
MARKER_RATE_HZ = 60.0
VIDEO_RATE_HZ = 30.0
#: The cameras each tracker uses: hybrid the mono camera, stereo the pair, mono the mono
#: camera's keypoints.
STEREO_CAMERAS = ("stereo_left", "stereo_right")


def live_bench_session(work_dir: Path, seconds: float | None = None) -> Path:
    """The benchmark's session, rendered once into ``work_dir``."""
    from mocapkit.synth.session_writer import SynthOptions, synthesize_session

    spec, start, length = LIVE_BENCH_CLIP
    length = length if seconds is None else seconds
    folder = work_dir / f"{spec.split(':')[-1]}_{length:g}s_640x480_{MARKER_RATE_HZ:g}hz"
    if not (folder / "session.json").is_file():
        synthesize_session(
            spec,
            folder,
            SynthOptions(
                rig="all",
                start_s=start,
                seconds=length,
                fps=VIDEO_RATE_HZ,
                marker_rate_hz=MARKER_RATE_HZ,
                image_size=(640, 480),
                seed=0,
                overwrite=True,
            ),
        )
    return folder


def _warm_up(method: str, session: Path) -> None:
    """Compile and warm the tracker offline on the first second of the session."""
    if method == "hybrid":
        from mocapkit.pipelines.hybrid import track_hybrid_session

        track_hybrid_session(session, None)
    elif method == "stereo":
        from mocapkit.pipelines.stereo import track_stereo_session

        track_stereo_session(
            session, None, cameras=list(STEREO_CAMERAS), use_keypoints=True, max_frames=30
        )
    else:
        from mocapkit.pipelines.live_feed import LiveConfig
        from mocapkit.pipelines.mono import track_mono
        from mocapkit.tracking.mono.tracker import MonoConfig

        track_mono(
            session,
            None,
            "mono",
            config=MonoConfig(lag=LiveConfig().mono_lag),
            use_session_lengths=True,
        )


def bench_live_one(
    method: str, session: Path, lead_s: float = 4.0, replay_cpus: set[int] | None = None
) -> dict[str, Any]:
    """One tracker live on a real-time replay of ``session`` (see the module docstring);
    the replay process runs on ``replay_cpus`` (default: as this process)."""
    from mocapkit.io.session import load_session
    from mocapkit.pipelines.live import track_live
    from mocapkit.pipelines.live_feed import LiveConfig, LiveInputs, replay_inputs

    prefix = f"bench{uuid.uuid4().hex[:6]}_"
    r = replay_inputs(load_session(session), prefix)
    if method == "hybrid":
        inputs = LiveInputs(r.markers, {}, {"mono": r.video["mono"]})
    elif method == "stereo":
        inputs = LiveInputs(
            None,
            {c: r.keypoints[c] for c in STEREO_CAMERAS},
            {c: r.video[c] for c in STEREO_CAMERAS},
        )
    else:
        inputs = LiveInputs(None, {"mono": r.keypoints["mono"]}, {})
    _warm_up(method, session)
    cmd = [sys.executable, "-m", "mocapkit.cli.main", "replay", str(session), "--lsl"]
    cmd += ["--prefix", prefix, "--lead-s", str(lead_s)]
    replay = subprocess.Popen(
        cmd,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=None if not replay_cpus else (lambda: os.sched_setaffinity(0, replay_cpus)),
    )
    try:
        t0 = time.perf_counter()
        report = track_live(
            method,
            session,
            inputs,
            stream_name=f"{prefix}joints",
            config=LiveConfig(lost_after_s=1.0, connect_timeout_s=60.0),
        )
        wall = time.perf_counter() - t0
    finally:
        _, err = replay.communicate(timeout=120)
    if replay.returncode != 0:
        raise ConfigError(f"bench live: the replay failed: {err.strip()[-500:]}")
    lat = report.latency_summary()
    cpu = report.step_cpu_summary()
    return {
        "latency_median_ms": lat["median_ms"],
        "latency_p99_ms": lat["p99_ms"],
        "latency_max_ms": lat["max_ms"],
        "step_cpu_median_ms": cpu["median_ms"],
        "step_cpu_p99_ms": cpu["p99_ms"],
        "step_cpu_max_ms": cpu["max_ms"],
        "frames_tracked": float(report.stats.frames_tracked),
        "frames_dropped": float(report.stats.frames_dropped),
        "results_sent": float(report.n_results),
        "rss_first_mb": report.stats.rss_first_mb,
        "rss_last_mb": report.stats.rss_last_mb,
        "wall_s": wall,
        "stopped": report.stop_reason,
    }


def bench_live(
    repeats: int = 1,
    work_dir: str | os.PathLike[str] | None = None,
    methods: tuple[str, ...] = ("hybrid", "stereo", "mono"),
) -> dict[str, Any]:
    """Latency and dropped frames of each tracker live (see the module docstring).

    Parameters
    ----------
    repeats : int
        Runs per tracker; the figures of the run with the median p99 latency are kept.
    work_dir : path-like, optional
        Cache folder of the rendered session (default ``mocapkit-bench-live`` in the
        temporary folder).
    methods : tuple of str
    """
    if repeats < 1:
        raise ConfigError(f"bench_live: expected repeats >= 1, found {repeats}")
    cache = Path(work_dir) if work_dir is not None else Path(tempfile.gettempdir())
    session = live_bench_session(cache / "mocapkit-bench-live")
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    affinity = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else None
    out: dict[str, Any] = {}
    try:
        if affinity:  # this process on one core; the replay process is started beside it
            os.sched_setaffinity(0, {min(affinity)})
        for method in methods:
            runs = [bench_live_one(method, session, replay_cpus=affinity) for _ in range(repeats)]
            runs.sort(key=lambda f: f["latency_p99_ms"])
            out[method] = runs[len(runs) // 2]
    finally:
        cv2.setNumThreads(threads)
        if affinity:
            os.sched_setaffinity(0, affinity)
    out["session"] = f"{session.name}: markers {MARKER_RATE_HZ:g} Hz, video {VIDEO_RATE_HZ:g} Hz"
    out["pipeline"] = (
        "mocapkit replay SESSION --lsl (real time, another process) -> mocapkit live METHOD "
        "(one core): hybrid markers + mono camera, stereo pair + keypoints, mono keypoints "
        "(online, lag 10 + 5 smoother frames)"
    )
    return out


__all__ = ["LIVE_BENCH_CLIP", "bench_live", "bench_live_one", "live_bench_session"]
