"""Speed of the monocular tracker (``mocapkit bench mono``).

A synthetic ``upper_stick`` sequence (the body turning, both arms swinging and bending)
seen by a 640x480 camera 3 m away gives true 2-D joints plus 2 px of seeded noise; the
2-D part is the keypoint path (fixed-lag smoothing of detector points: the image-based
skin tracking of the paper is not built), the 3-D part is the depth estimate, the flip
enumeration with pruning and the Viterbi step. Timed: the online tracker with a 10-frame
lag over pair states (eq. 3, ``MonoTracker.push`` per frame) and over plain states
(first-order rotation weight), the exact offline mode (all frames, then the backtrack)
and the enumeration alone.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mocapkit.camera.pinhole import Camera, intrinsics_from_fov, look_at
from mocapkit.errors import ShapeError
from mocapkit.skeleton.kinematics import canonical_positions
from mocapkit.skeleton.limbs import arm
from mocapkit.skeleton.presets import load_preset
from mocapkit.tracking.mono.flips import enumerate_poses
from mocapkit.tracking.mono.stick import StickModel, stick_model
from mocapkit.tracking.mono.tracker import MonoConfig, MonoTracker

FloatArray = NDArray[np.float64]


def mono_sequence(
    n_frames: int, rate_hz: float = 30.0
) -> tuple[FloatArray, Camera, StickModel, FloatArray]:
    """Stick joints (T, K, 3) in the world, the camera, the stick model and link lengths."""
    sk = load_preset("upper_stick")
    t = np.arange(n_frames) / rate_hz
    q = np.zeros((n_frames, sk.n_dofs))
    q[:, 5] = 0.5 * np.sin(0.8 * t)
    for side, sign in (("left", 1.0), ("right", -1.0)):
        limb = arm(sk, side)
        q[:, limb.dofs[0]] = 0.9 + 0.6 * np.sin(2.0 * t + (0.0 if sign > 0 else 1.0))
        q[:, limb.dofs[1]] = sign * 0.5
        q[:, limb.dofs[3]] = 1.2 + 0.6 * np.sin(3.0 * t)
    model = stick_model()
    joints = canonical_positions(sk, q, list(model.joint_names))
    cam = Camera(
        "mono", (640, 480), intrinsics_from_fov((640, 480), 62.0), np.zeros(5),
        look_at((0, -3000, 1250), (0, 0, 1250)),
    )  # fmt: skip
    lengths = np.linalg.norm(model.link_vectors(joints[0]), axis=-1)
    return joints, cam, model, lengths


def _run(
    cam: Camera,
    model: StickModel,
    lengths: FloatArray,
    px: FloatArray,
    cfg: MonoConfig,
    rate_hz: float,
) -> tuple[float, list[Any]]:
    tracker = MonoTracker(lengths, cam, 1.0 / rate_hz, cfg, model)
    frames: list[Any] = []
    t0 = time.perf_counter()
    for k in range(px.shape[0]):
        frames += tracker.push(k / rate_hz, px[k])
    frames += tracker.finish()
    return time.perf_counter() - t0, frames


def bench_mono(
    repeats: int = 3, n_frames: int = 150, rate_hz: float = 30.0, seed: int = 0
) -> dict[str, float | str]:
    """Frames per second of the mono tracker (2-D smoothing + 3-D) at 640x480.

    Returns
    -------
    dict
        ``fps`` (online pair-state, median over repeats), ``fps_min``, ``ms_per_frame``,
        ``first_order_fps`` (online plain Viterbi), ``offline_fps`` (exact pair-state
        Viterbi), ``enumerations_per_s``,
        ``survivors_mean``, ``candidates_mean``, ``pruned_share``, ``latency_frames``,
        ``mean_flip_accuracy``, sizes and the pipeline description.
    """
    if repeats < 1 or n_frames < 10:
        raise ShapeError(
            f"bench_mono: expected repeats >= 1 and n_frames >= 10, found {repeats}, {n_frames}"
        )
    joints, cam, model, lengths = mono_sequence(n_frames, rate_hz)
    rng = np.random.default_rng(seed)
    px = cam.project(joints) + rng.normal(scale=2.0, size=(n_frames, model.n_joints, 2))
    online = MonoConfig(lag=10)
    first_order = MonoConfig(lag=10, cost="rotation")
    offline = MonoConfig()
    _run(cam, model, lengths, px[:20], online, rate_hz)  # warm-up: compile the kernels
    _run(cam, model, lengths, px[:20], first_order, rate_hz)
    on_times, fo_times, off_times = [], [], []
    frames: list[Any] = []
    for _ in range(repeats):
        dt, frames = _run(cam, model, lengths, px, online, rate_hz)
        on_times.append(dt)
        fo_times.append(_run(cam, model, lengths, px, first_order, rate_hz)[0])
        off_times.append(_run(cam, model, lengths, px, offline, rate_hz)[0])
    truth = cam.to_camera(joints)
    est = np.stack([f.joints_in_camera for f in frames])
    dz_t = truth[:, model.child, 2] - truth[:, model.parent, 2]
    dz_e = est[:, model.child, 2] - est[:, model.parent, 2]
    counted = np.abs(dz_t) >= 0.2 * lengths
    flips = float(((np.sign(dz_t) == np.sign(dz_e)) & counted).sum() / max(counted.sum(), 1))
    root = truth[0, 0]
    rays = px[0] - cam.K[:2, 2]
    rays = rays / np.array([cam.K[0, 0], cam.K[1, 1]])
    n_enum = 2000
    t0 = time.perf_counter()
    for _ in range(n_enum):
        enumerate_poses(model, lengths, rays, root, perspective=True)
    enum_rate = n_enum / (time.perf_counter() - t0)
    cand = np.array([f.n_candidates for f in frames], dtype=float)
    surv = np.array([f.n_survivors for f in frames], dtype=float)
    fps = n_frames / np.array(on_times)
    return {
        "fps": float(np.median(fps)),
        "fps_min": float(np.min(fps)),
        "ms_per_frame": float(1000.0 / np.median(fps)),
        "first_order_fps": float(n_frames / np.median(fo_times)),
        "offline_fps": float(n_frames / np.median(off_times)),
        "enumerations_per_s": float(enum_rate),
        "survivors_mean": float(surv.mean()),
        "candidates_mean": float(cand.mean()),
        "pruned_share": float(np.mean(1.0 - surv / np.maximum(cand, 1.0))),
        "latency_frames": float(online.smooth_lag + (online.lag or 0)),
        "mean_flip_accuracy": flips,
        "n_frames": float(n_frames),
        "image_size": "640x480",
        "pipeline": "2-D keypoints + 2 px noise -> fixed-lag smoother -> depth bound -> flips "
        "with pruning during the search -> Viterbi, lag 10 (online; fps: pair states, "
        "first_order_fps: plain states)",
    }
