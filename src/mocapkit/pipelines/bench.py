"""Speed benchmarks: batched kinematics and the per-frame hybrid tracker (Zhang et al. 2011 §6).

Every benchmark warms up first (Numba compilation, caches), times several repeats
and reports medians. OpenCV is held to one thread while timing (the targets are
for one core); NumPy's BLAS is left as installed. Timings are figures to read, never
asserted by tests.
"""

from __future__ import annotations

import os
import platform
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from mocapkit.errors import ConfigError, unknown_name
from mocapkit.io.atomic import atomic_write
from mocapkit.pipelines.mono_bench import bench_mono
from mocapkit.skeleton import forward_kinematics, load_preset
from mocapkit.skeleton.kinematics import points_and_jacobian
from mocapkit.skeleton.limbs import arm, head_joint, leg

#: Image size of the hybrid benchmark (the issue's 640x480).
HYBRID_IMAGE_SIZE = (640, 480)


def _median_rate(fn: Callable[[], Any], count: int, repeats: int) -> tuple[float, float]:
    """Median and minimum of ``count / seconds`` over ``repeats`` timed calls (after a warm-up)."""
    fn()
    rates = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        rates.append(count / (time.perf_counter() - t0))
    return float(np.median(rates)), float(np.min(rates))


def bench_kinematics(
    repeats: int = 5, n_poses: int = 10_000, n_jacobians: int = 1_000, seed: int = 0
) -> dict[str, float]:
    """Forward kinematics and effector Jacobians of ``zhang21`` per second.

    Poses are drawn uniformly inside the joint limits (seeded). Jacobians are for the
    paper's five effectors: head centre, both wrists, both ankles.

    Returns
    -------
    dict
        ``fk_poses_per_s``, ``jacobians_per_s`` (medians), their minima, sizes.
    """
    if repeats < 1 or n_poses < 1 or n_jacobians < 1:
        raise ConfigError(
            f"bench_kinematics: expected repeats, n_poses, n_jacobians >= 1, found {repeats}, "
            f"{n_poses}, {n_jacobians}"
        )
    sk = load_preset("zhang21")
    rng = np.random.default_rng(seed)
    lo = np.where(np.isfinite(sk.lower), sk.lower, -500.0)
    hi = np.where(np.isfinite(sk.upper), sk.upper, 500.0)
    q = rng.uniform(lo, hi, (n_poses, sk.n_dofs))
    # head centre, wrists and ankles, found through the canonical names
    joints = [head_joint(sk)] + [
        part(sk, side).end for part in (arm, leg) for side in ("left", "right")
    ]
    points = np.zeros((5, 3))
    points[0] = sk.canonical["head"][1]
    qj = q[:n_jacobians]
    fk_rate, fk_min = _median_rate(lambda: forward_kinematics(sk, q), n_poses, repeats)
    jac_rate, jac_min = _median_rate(
        lambda: points_and_jacobian(sk, qj, joints, points), n_jacobians, repeats
    )
    return {
        "fk_poses_per_s": fk_rate,
        "fk_poses_per_s_min": fk_min,
        "jacobians_per_s": jac_rate,
        "jacobians_per_s_min": jac_min,
        "n_poses": float(n_poses),
        "n_jacobians": float(n_jacobians),
        "n_effectors": 5.0,
        "repeats": float(repeats),
    }


#: Clips of ``shared/data/mocap`` the hybrid benchmark renders as sessions, with the
#: excerpt (start s, length s): three of the accuracy study's clips
#: (`mocapkit.pipelines.accuracy.HYBRID_CLIPS`), 4 s each.
BENCH_CLIPS: dict[str, tuple[float, float]] = {
    "13_26.bvh": (11.5, 4.0),
    "01_09.amc": (27.0, 4.0),
    "lambada.amc": (11.0, 4.0),
}
#: Built-in motions rendered instead when the shared clips are absent.
BUILTIN_BENCH_CLIPS: dict[str, tuple[float, float]] = {
    "builtin:table-tennis": (0.0, 4.0),
    "builtin:wave": (0.0, 4.0),
}
#: Stages of the per-frame pipeline, in order (see `bench_hybrid`).
HYBRID_STAGES: tuple[str, ...] = (
    "load",
    "input",
    "ik",
    "edges",
    "refinement",
    "balance",
    "smoothing",
    "write",
)


def bench_sessions(
    work_dir: str | os.PathLike[str], mocap_dir: str | os.PathLike[str] | None = None
) -> list[Path]:
    """The benchmark's sessions (640x480 mono, default realism, seed 0), rendered once.

    Parameters
    ----------
    work_dir : path-like
        Cache folder: a session already there (``session.json`` present) is re-used.
    mocap_dir : path-like, optional
        Folder of `BENCH_CLIPS` (default ``shared/data/mocap`` when found); without it
        the `BUILTIN_BENCH_CLIPS` are rendered.
    """
    from mocapkit.pipelines.demo import find_shared_data
    from mocapkit.synth.session_writer import SynthOptions, synthesize_session

    if mocap_dir is None:
        data = find_shared_data()
        mocap_dir = data / "mocap" if data is not None else None
    if mocap_dir is not None and all((Path(mocap_dir) / c).is_file() for c in BENCH_CLIPS):
        clips = {str(Path(mocap_dir) / c): v for c, v in BENCH_CLIPS.items()}
    else:
        import warnings

        from mocapkit.errors import InputWarning

        where = f"{mocap_dir}" if mocap_dir is not None else "shared/data/mocap (not found)"
        warnings.warn(
            f"{where}: expected the clips {', '.join(BENCH_CLIPS)}; benchmarking the "
            f"built-in motions {', '.join(BUILTIN_BENCH_CLIPS)} instead (figures not "
            "comparable with the shared clips')",
            InputWarning,
            stacklevel=2,
        )
        clips = dict(BUILTIN_BENCH_CLIPS)
    out = []
    for spec, (start, seconds) in clips.items():
        name = f"{Path(spec.split(':')[-1]).stem}_{start:g}+{seconds:g}s_640x480"
        folder = Path(work_dir) / name
        if not (folder / "session.json").is_file():
            synthesize_session(
                spec,
                folder,
                SynthOptions(
                    rig="mono",
                    start_s=start,
                    seconds=seconds,
                    seed=0,
                    image_size=HYBRID_IMAGE_SIZE,
                    overwrite=True,
                ),
            )
        out.append(folder)
    return out


def bench_hybrid(
    repeats: int = 3,
    work_dir: str | os.PathLike[str] | None = None,
    mocap_dir: str | os.PathLike[str] | None = None,
    sessions: Sequence[str | os.PathLike[str]] | None = None,
) -> dict[str, Any]:
    """Frames per second of ``mocapkit track hybrid`` as shipped, end to end, one core.

    Sessions rendered from real motion (`bench_sessions`: three CMU clips, 4 s each,
    640x480, markers at 120 Hz with noise and drop-outs) are tracked with the default
    configuration of ``mocapkit track hybrid SESSION --out DIR``
    (`mocapkit.pipelines.hybrid.track_hybrid_session`: oriented marker sets, video
    refinement with the elbow-jump penalty, balance, smoothing) through the runner,
    from loading the session to the written result folder. One untimed run compiles
    and warms the caches first; each repeat tracks every session, and the figures are
    the medians over repeats. OpenCV runs on one thread. Times are the process's CPU
    time (``time.process_time``, all its threads): on a dedicated core that is the wall
    time, and on a shared machine it is what the work itself took (the wall time is
    reported too).

    Parameters
    ----------
    repeats : int
        Timed runs (>= 1).
    work_dir : path-like, optional
        Cache folder of the rendered sessions (default ``mocapkit-bench-hybrid`` in the
        temporary folder).
    mocap_dir : path-like, optional
        Folder of the clips (`bench_sessions`).
    sessions : sequence of path-like, optional
        Session folders to track instead of `bench_sessions` (e.g. jittered copies of
        them, ``bench/hybrid_jitter.py``).

    Returns
    -------
    dict
        ``fps`` (frames of all sessions per CPU second, median), ``fps_min``,
        ``fps_wall`` (per wall-clock second), ``ms_per_frame`` (CPU); ``frame_ms``: the
        tracker's ``update`` per frame (CPU ms; median, 99th percentile and max over every
        frame of every repeat: what a live feed waits for);
        ``stages_ms``: CPU milliseconds per frame of each stage
        (`HYBRID_STAGES`: ``load`` the session, ``input`` the marker samples and the
        video frames' grab, ``ik`` the solves and foot re-planting, ``edges`` the frame's
        decoding (lazy: only where an arm is refined) and whole-frame edge preparation,
        ``refinement`` both arms' RoI edge maps and searches,
        ``balance``, ``smoothing`` with its IK polish, ``write`` the result folder),
        ``other`` (the rest of ``update``) and ``io`` (load + input + write);
        ``ik_solves_per_frame``, ``ik_iterations_per_solve``; ``ik_micro_solves_per_s``
        (the warm-started IK micro-benchmark, `mocapkit.pipelines.ik_bench.bench_ik`);
        ``elbow_jump_penalty`` (on in the tracked configuration); sessions and sizes.
    """
    if repeats < 1:
        raise ConfigError(f"bench_hybrid: expected repeats >= 1, found {repeats}")
    import tempfile

    from mocapkit.pipelines.hybrid import track_hybrid_session_run
    from mocapkit.pipelines.ik_bench import bench_ik
    from mocapkit.timing import StageTimer
    from mocapkit.tracking.hybrid.arm_refinement import RefineConfig

    cache = (
        Path(work_dir)
        if work_dir is not None
        else Path(tempfile.gettempdir()) / "mocapkit-bench-hybrid"
    )
    sessions = (
        bench_sessions(cache / "sessions", mocap_dir)
        if sessions is None
        else [Path(s) for s in sessions]
    )
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    fps_list: list[float] = []
    wall_fps: list[float] = []
    per_stage: dict[str, list[float]] = {}
    solves, iters, frames = [], [], 0
    per_frame_s: list[float] = []
    try:
        with tempfile.TemporaryDirectory(prefix="mocapkit-bench-") as tmp:
            track_hybrid_session_run(sessions[0], Path(tmp) / "warm")  # compile, warm up
            for r in range(repeats):
                timer = StageTimer(clock=time.process_time, record=("track",))
                frames = 0
                t0, c0 = time.perf_counter(), time.process_time()
                for s in sessions:
                    run = track_hybrid_session_run(s, Path(tmp) / f"{r}_{s.name}", timer=timer)
                    frames += run.motion.n_frames
                cpu = time.process_time() - c0
                wall_fps.append(frames / (time.perf_counter() - t0))
                fps_list.append(frames / cpu)
                totals = timer.totals_s()
                for name in (*HYBRID_STAGES, "track"):
                    per_stage.setdefault(name, []).append(1e3 * totals.get(name, 0.0) / frames)
                per_frame_s += timer.durations_s("track")
                counts = timer.counts()
                solves.append(counts.get("ik_solves", 0) / frames)
                iters.append(counts.get("ik_iterations", 0) / max(counts.get("ik_solves", 0), 1))
    finally:
        cv2.setNumThreads(threads)
    stages = {n: float(np.median(v)) for n, v in per_stage.items()}
    inner = ("ik", "edges", "refinement", "balance", "smoothing")
    stages["other"] = max(stages.pop("track") - sum(stages[n] for n in inner), 0.0)
    stages["io"] = stages["load"] + stages["input"] + stages["write"]
    ik = bench_ik(n_frames=500, repeats=repeats)
    fps = float(np.median(fps_list))
    return {
        "fps": fps,
        "fps_min": float(np.min(fps_list)),
        "fps_wall": float(np.median(wall_fps)),
        "ms_per_frame": 1e3 / fps,
        "frame_ms": {
            "median": 1e3 * float(np.median(per_frame_s)),
            "p99": 1e3 * float(np.percentile(per_frame_s, 99)),
            "max": 1e3 * float(np.max(per_frame_s)),
        },
        "stages_ms": stages,
        "ik_solves_per_frame": float(np.median(solves)),
        "ik_iterations_per_solve": float(np.median(iters)),
        "ik_micro_solves_per_s": float(ik["solves_per_s"]),
        "elbow_jump_penalty": RefineConfig().elbow_jump_weight_per_mm > 0,
        "sessions": ", ".join(s.name for s in sessions),
        "image_size": f"{HYBRID_IMAGE_SIZE[0]}x{HYBRID_IMAGE_SIZE[1]}",
        "pipeline": "mocapkit track hybrid SESSION --out DIR (default configuration): load, "
        "decode, IK, edges, both arm refinements, balance, smoothing, write",
        "n_frames": float(frames),
        "repeats": float(repeats),
    }


def _bench_stereo(repeats: int = 3) -> dict[str, Any]:
    """The stereo tracker's figures (`mocapkit.pipelines.stereo.bench_stereo`)."""
    from mocapkit.pipelines.stereo import bench_stereo

    return bench_stereo(repeats=repeats)


def _bench_detect(repeats: int = 3) -> dict[str, Any]:
    """The 2-D detector's figures (`mocapkit.pipelines.detect_bench.bench_detect`)."""
    from mocapkit.pipelines.detect_bench import bench_detect

    return bench_detect(repeats=repeats)


def _bench_live(repeats: int = 1) -> dict[str, Any]:
    """Latency of each tracker live (`mocapkit.pipelines.live_bench.bench_live`)."""
    from mocapkit.pipelines.live_bench import bench_live

    return bench_live(repeats=repeats)


def _bench_multiview(repeats: int = 3) -> dict[str, Any]:
    """The multi-view fit's figures (`mocapkit.pipelines.multiview.bench_multiview`)."""
    from mocapkit.pipelines.multiview import bench_multiview

    return bench_multiview(repeats=repeats)


BENCHMARKS: dict[str, Callable[..., dict[str, Any]]] = {
    "kinematics": bench_kinematics,
    "hybrid": bench_hybrid,
    "mono": bench_mono,
    "stereo": _bench_stereo,
    "detect": _bench_detect,
    "live": _bench_live,
    "multiview": _bench_multiview,
}


def benchmark_choices() -> tuple[str, ...]:
    """The names ``mocapkit bench`` accepts: every benchmark and ``all``."""
    return (*BENCHMARKS, "all")


#: Benchmarks that ``all`` leaves out: ``live`` needs ``mocapkit[live]`` and runs in real time.
NOT_IN_ALL: tuple[str, ...] = ("live",)


def run_benchmarks(
    name: str, repeats: int = 3, work_dir: str | os.PathLike[str] | None = None
) -> dict[str, dict[str, Any]]:
    """Run one benchmark by name, or ``"all"``; returns ``{name: figures}``.

    Parameters
    ----------
    name : str
        A key of `BENCHMARKS` or ``"all"``.
    repeats : int
        Timed repeats per figure (medians are reported).
    work_dir : path-like, optional
        Cache folder of the hybrid benchmark's sessions (`bench_hybrid`).
    """
    if name != "all" and name not in BENCHMARKS:
        raise unknown_name("benchmark", name, [*BENCHMARKS, "all"], "mocapkit bench")
    if repeats < 1:
        raise ConfigError(f"--repeats: expected at least 1, found {repeats}")
    names = [n for n in BENCHMARKS if n not in NOT_IN_ALL] if name == "all" else [name]
    return {
        n: BENCHMARKS[n](repeats=repeats, work_dir=work_dir)
        if n == "hybrid"
        else BENCHMARKS[n](repeats=repeats)
        for n in names
    }


def machine_info() -> dict[str, str]:
    """Where the figures were taken (stored beside them)."""
    return {
        "python": platform.python_version(),
        "machine": platform.machine(),
        "processor": platform.processor() or platform.machine(),
        "cpu_count": str(os.cpu_count()),
        "opencv": cv2.__version__,
        "numpy": np.__version__,
    }


def save_results(results: dict[str, dict[str, Any]], folder: str | Path) -> list[Path]:
    """Write ``<folder>/<name>.json`` per benchmark atomically; returns the paths."""
    import json

    paths = []
    for name, figures in results.items():
        path = Path(folder) / f"{name}.json"
        with atomic_write(path, "w") as fh:
            json.dump({name: figures, "machine": machine_info()}, fh, indent=2, sort_keys=True)
            fh.write("\n")
        paths.append(path)
    return paths


def format_table(results: dict[str, dict[str, Any]]) -> str:
    """Plain-text table of the figures, one block per benchmark."""
    lines = []
    for name, figures in results.items():
        lines.append(name)
        width = max(len(k) for k in figures)
        for key, value in figures.items():
            if isinstance(value, dict):
                lines.append(f"  {key}")
                for k, v in value.items():
                    shown = f"{v:,.3f}" if isinstance(v, float) else str(v)
                    lines.append(f"    {k:<{width - 2}}  {shown}")
                continue
            shown = f"{value:,.3f}" if isinstance(value, float) else str(value)
            lines.append(f"  {key:<{width}}  {shown}")
    return "\n".join(lines)


__all__ = [
    "BENCHMARKS",
    "bench_hybrid",
    "bench_kinematics",
    "bench_sessions",
    "format_table",
    "machine_info",
    "run_benchmarks",
    "save_results",
]
