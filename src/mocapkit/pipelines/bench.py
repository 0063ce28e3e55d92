"""Speed benchmarks: batched kinematics and the per-frame hybrid tracker (Zhang et al. 2011 §6).

Every benchmark warms up first (Numba compilation, caches), times several repeats
and reports medians. OpenCV is held to one thread while timing (the targets are
for one core); NumPy's BLAS is left as installed. Timings are figures to read, never
asserted by tests.
"""

from __future__ import annotations

import math
import os
import platform
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from mocapkit.camera.pinhole import Camera, intrinsics_from_fov, look_at
from mocapkit.errors import ConfigError, unknown_name
from mocapkit.io.atomic import atomic_write
from mocapkit.skeleton import canonical_positions, forward_kinematics, load_preset
from mocapkit.skeleton.kinematics import points_and_jacobian

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
    head_joint, head_point = sk.canonical["head"]
    joints = [head_joint, "l_hand", "r_hand", "l_foot", "r_foot"]
    points = np.zeros((5, 3))
    points[0] = head_point
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


def _hybrid_sequence(n_frames: int, rate_hz: float) -> tuple[Any, Camera, np.ndarray]:
    """A zhang21 arm-waving motion (both arms, changing swivel) and a front camera."""
    sk = load_preset("zhang21")
    t = np.arange(n_frames) / rate_hz
    q = np.tile(sk.zero_pose(), (n_frames, 1))

    def put(name: str, deg: np.ndarray) -> None:
        q[:, sk.dof_index(name)] = np.radians(deg)

    w = 2 * np.pi * 0.4 * t
    put("l_shoulder_abduction", 40 + 15 * np.sin(w))
    put("l_shoulder_flexion", 25 + 20 * np.sin(0.7 * w + 1))
    put("l_shoulder_rotation", 20 + 15 * np.sin(0.5 * w))
    put("l_elbow_flexion", 70 + 25 * np.sin(0.9 * w + 2))
    put("r_shoulder_abduction", 45 + 15 * np.sin(w + 1))
    put("r_shoulder_flexion", 15 + 20 * np.sin(0.6 * w))
    put("r_shoulder_rotation", -15 + 15 * np.sin(0.8 * w + 0.5))
    put("r_elbow_flexion", 60 + 25 * np.sin(1.1 * w + 1))
    put("spine2_flexion", 5 * np.sin(0.3 * w))
    q = np.clip(q, sk.lower, sk.upper)
    size = HYBRID_IMAGE_SIZE
    cam = Camera(
        "bench",
        size,
        intrinsics_from_fov(size, 60),
        np.zeros(5),
        look_at((300, 3200, 1300), (0, 0, 1250)),
    )
    return sk, cam, q


def _render_frames(sk: Any, cam: Camera, q: np.ndarray, seed: int) -> list[np.ndarray]:
    from mocapkit.viz.overlay import draw_body

    rng = np.random.default_rng(seed)
    w, h = cam.image_size
    bg = (rng.normal(0, 1, (h, w, 3)) * 12 + 170).clip(0, 255).astype(np.uint8)
    bg = np.asarray(cv2.GaussianBlur(bg, (0, 0), 2), dtype=np.uint8)
    colours = {n: (40, 60, 200) for n in ("l_humerus", "l_radius", "l_hand")}
    colours.update({n: (200, 80, 40) for n in ("r_humerus", "r_radius", "r_hand")})
    return [draw_body(bg.copy(), sk, cam, qq, colours, (90, 120, 90)) for qq in q]


def bench_hybrid(
    repeats: int = 3, n_frames: int = 120, rate_hz: float = 30.0, seed: int = 0
) -> dict[str, float | str]:
    """Frames per second of the whole per-frame hybrid pipeline at 640x480, both arms refined.

    A synthetic sequence (zhang21 waving both arms, rendered as filled cones over a
    lightly textured background) is fed to `mocapkit.tracking.hybrid.HybridTracker`
    (IK, edge distance transform in the arm RoIs, both arm refinements, balance,
    smoothing). Frames are rendered before timing. Also reported: the refinement
    alone per arm (distance map plus search), its evaluations, the compiled cost's
    time per evaluation, and warm-started IK solves per second
    (`mocapkit.pipelines.hybrid.bench_ik`).

    Returns
    -------
    dict
        ``fps`` (median), ``fps_min``, ``ms_per_frame``, ``refine_ms_per_arm``,
        ``evaluations_per_arm``, ``cost_eval_us``, ``edge_ms_per_arm`` (Canny and
        distance transform of one arm RoI),
        ``ik_solves_per_s``, ``mean_elbow_error_mm``, ``pipeline`` and sizes.
    """
    if repeats < 1 or n_frames < 2:
        raise ConfigError(
            f"bench_hybrid: expected repeats >= 1 and n_frames >= 2, found {repeats}, {n_frames}"
        )
    from mocapkit.cues.edges import prepare_frame, roi_distance_map
    from mocapkit.pipelines.hybrid import bench_ik
    from mocapkit.tracking.arm_refinement import (
        ArmDiagnostics,
        RefineConfig,
        arm_cost_many_nb,
        arm_problem,
        refine_arms,
    )
    from mocapkit.tracking.hybrid import HybridSample, HybridTracker

    sk, cam, q_true = _hybrid_sequence(n_frames, rate_hz)
    frames = _render_frames(sk, cam, q_true, seed)
    canon = canonical_positions(sk, q_true, ["head", "left_wrist", "right_wrist"])
    samples = [
        HybridSample(
            time_s=i / rate_hz,
            markers_mm={"head": canon[i, 0], "left_hand": canon[i, 1], "right_hand": canon[i, 2]},
            image=frames[i],
        )
        for i in range(n_frames)
    ]
    diags: list[ArmDiagnostics] = []

    def recording_refiner(
        skel: Any, camera: Any, q: Any, image: Any, hands: Any, config: Any
    ) -> Any:
        d: dict[str, ArmDiagnostics] = {}
        out = refine_arms(skel, camera, q, image, hands, config, diagnostics=d)
        diags.extend(x for x in d.values() if x.refined)
        return out

    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        # warm-up: compile every kernel along the path
        warm = HybridTracker(sk, cam, refiner=recording_refiner)
        for s in samples[:5]:
            warm.update(s)
        fps_list, elbow_err = [], math.nan
        for _ in range(repeats):
            diags.clear()
            tracker = HybridTracker(sk, cam, refiner=recording_refiner)
            t0 = time.perf_counter()
            poses = [tracker.update(s) for s in samples]
            fps_list.append(n_frames / (time.perf_counter() - t0))
            est = np.stack([p.q for p in poses])
        names = ["left_elbow", "right_elbow"]
        elbow_err = float(
            np.mean(
                np.linalg.norm(
                    canonical_positions(sk, est, names) - canonical_positions(sk, q_true, names),
                    axis=-1,
                )
            )
        )
        refine_ms = float(np.median([d.elapsed_ms for d in diags]))
        evals = float(np.median([d.n_evaluations for d in diags]))
        # the compiled cost and the edge map alone, on the middle frame
        mid = n_frames // 2
        cfg = RefineConfig()
        frame = prepare_frame(frames[mid], cfg.edges)
        prob = arm_problem(sk, cam, q_true[mid], "left", frame, canon[mid, 1], cfg)
        xs = prob.x0 + np.random.default_rng(seed).normal(0, 0.05, (20_000, 4))
        dmap = prob.maps
        model = prob.model
        eval_rate, _ = _median_rate(lambda: arm_cost_many_nb(xs, model, dmap), len(xs), repeats)
        roi = prob.distance.roi
        edge_rate, _ = _median_rate(
            lambda: roi_distance_map(frame, roi, cfg.edges), 1, max(repeats, 20)
        )
    finally:
        cv2.setNumThreads(threads)
    ik = bench_ik(n_frames=500, repeats=repeats)
    fps = float(np.median(fps_list))
    return {
        "fps": fps,
        "fps_min": float(np.min(fps_list)),
        "ms_per_frame": 1e3 / fps,
        "refine_ms_per_arm": refine_ms,
        "evaluations_per_arm": evals,
        "cost_eval_us": 1e6 / eval_rate,
        "edge_ms_per_arm": 1e3 / edge_rate,
        "ik_solves_per_s": float(ik["solves_per_s"]),
        "mean_elbow_error_mm": elbow_err,
        "image_size": f"{HYBRID_IMAGE_SIZE[0]}x{HYBRID_IMAGE_SIZE[1]}",
        "pipeline": "HybridTracker.update: IK + edge DT in arm RoIs + both arm refinements "
        "+ balance + smoothing",
        "n_frames": float(n_frames),
        "repeats": float(repeats),
    }


def _bench_stereo(repeats: int = 3) -> dict[str, Any]:
    """The stereo tracker's figures (`mocapkit.pipelines.stereo.bench_stereo`)."""
    from mocapkit.pipelines.stereo import bench_stereo

    return bench_stereo(repeats=repeats)


BENCHMARKS: dict[str, Callable[..., dict[str, Any]]] = {
    "kinematics": bench_kinematics,
    "hybrid": bench_hybrid,
    "stereo": _bench_stereo,
}


def run_benchmarks(name: str, repeats: int = 3) -> dict[str, dict[str, Any]]:
    """Run one benchmark by name, or ``"all"``; returns ``{name: figures}``.

    Parameters
    ----------
    name : str
        A key of `BENCHMARKS` or ``"all"``.
    repeats : int
        Timed repeats per figure (medians are reported).
    """
    if name != "all" and name not in BENCHMARKS:
        raise unknown_name("benchmark", name, [*BENCHMARKS, "all"], "mocapkit bench")
    if repeats < 1:
        raise ConfigError(f"--repeats: expected at least 1, found {repeats}")
    names = list(BENCHMARKS) if name == "all" else [name]
    return {n: BENCHMARKS[n](repeats=repeats) for n in names}


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
            shown = f"{value:,.3f}" if isinstance(value, float) else str(value)
            lines.append(f"  {key:<{width}}  {shown}")
    return "\n".join(lines)


__all__ = [
    "BENCHMARKS",
    "bench_hybrid",
    "bench_kinematics",
    "format_table",
    "machine_info",
    "run_benchmarks",
    "save_results",
]
