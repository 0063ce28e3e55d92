"""Speed of the monocular tracker (``mocapkit bench mono``).

A synthetic ``upper_stick`` sequence (the body turning, both arms swinging and bending)
seen by a 640x480 camera 3 m away gives true 2-D joints plus 2 px of seeded noise. Two
2-D paths feed the 3-D part (the depth estimate, the flip enumeration with pruning and
the Viterbi step):

- the keypoint path: detector points through the fixed-lag smoother (``fps``);
- the image path of the paper: 640x480 frames drawn from the same joints seen from the
  front (the paper's labels assume the subject faces the camera; head and forearms as
  skin-coloured ellipses on a noisy backdrop, `skin_frames`), skin mask,
  blobs, labels and joints (`mocapkit.tracking.mono.skin_tracking.SkinTracker`, the
  trunk drawn from the head), then the smoother and the 3-D part (``image_fps``).

Timed: the online tracker with a 10-frame lag over pair states (eq. 3,
``MonoTracker.push`` per frame) and over plain states (first-order rotation weight), the
exact offline mode (all frames, then the backtrack), the enumeration alone, and the skin
tracking alone. Times are the process's CPU time (``time.process_time``, all threads;
OpenCV on one thread): on a dedicated core that is the wall time, on a shared machine it
is what the work itself took. The wall-clock rate is reported too (``fps_wall``).
The rates exclude the start-up (after a warm-up), which `mono_startup` times apart in a
fresh process: imports, the session's load, the Numba kernels' cache load (or compile).
`mono_scaling` times the 3-D step against the number of links and of frames.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from mocapkit.camera.pinhole import Camera, intrinsics_from_fov, look_at
from mocapkit.errors import MocapError, ShapeError
from mocapkit.skeleton.kinematics import canonical_positions
from mocapkit.skeleton.limbs import arm, leg
from mocapkit.skeleton.presets import load_preset
from mocapkit.tracking.mono.flips import enumerate_poses
from mocapkit.tracking.mono.skin_tracking import SKIN_JOINTS, SkinTracker
from mocapkit.tracking.mono.stick import StickModel, stick_model
from mocapkit.tracking.mono.tracker import MonoConfig, MonoTracker

FloatArray = NDArray[np.float64]

#: A skin colour the default model accepts (YCrCb 150, 154, 104), BGR.
SKIN_BGR: tuple[int, int, int] = (107, 140, 186)


def _camera(side: float = -1.0) -> Camera:
    """640x480, 3 m away on the y axis (``side`` -1: behind the stick, +1: before it)."""
    return Camera(
        "mono", (640, 480), intrinsics_from_fov((640, 480), 62.0), np.zeros(5),
        look_at((0, side * 3000, 1250), (0, 0, 1250)),
    )  # fmt: skip


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
    lengths = np.linalg.norm(model.link_vectors(joints[0]), axis=-1)
    return joints, _camera(), model, lengths


def legs_sequence(
    n_frames: int, rate_hz: float = 30.0
) -> tuple[FloatArray, Camera, StickModel, FloatArray]:
    """As `mono_sequence` with legs (``zhang21``: arms swinging, legs stepping)."""
    sk = load_preset("zhang21")
    t = np.arange(n_frames) / rate_hz
    q = np.zeros((n_frames, sk.n_dofs))
    q[:, 2] = 1000.0  # pelvis height (mm)
    for side, sign in (("left", 1.0), ("right", -1.0)):
        a = arm(sk, side)
        q[:, a.dofs[0]] = 0.9 + 0.6 * np.sin(2.0 * t + (0.0 if sign > 0 else 1.0))
        q[:, a.dofs[1]] = sign * 0.5
        q[:, a.dofs[3]] = 1.2 + 0.6 * np.sin(3.0 * t)
        g = leg(sk, side)
        q[:, g.dofs[0]] = 0.4 * np.sin(2.5 * t + (0.0 if sign > 0 else np.pi))
        q[:, g.dofs[3]] = 0.6 + 0.5 * np.sin(2.5 * t + (0.5 if sign > 0 else 0.5 + np.pi))
    model = stick_model(legs=True)
    joints = canonical_positions(sk, q, list(model.joint_names))
    cam = Camera(
        "mono", (640, 480), intrinsics_from_fov((640, 480), 62.0), np.zeros(5),
        look_at((0, -4000, 1000), (0, 0, 1000)),
    )  # fmt: skip
    lengths = np.linalg.norm(model.link_vectors(joints[0]), axis=-1)
    return joints, cam, model, lengths


def skin_frames(px: FloatArray, model: StickModel, seed: int = 0) -> list[NDArray[np.uint8]]:
    """640x480 BGR frames with the head and forearms of ``px`` (T, K, 2) drawn as skin.

    The head is an ellipse about the head joint reaching the neck; each forearm an
    ellipse 8 px wide from elbow to wrist; the backdrop green-grey with 4 grey levels of
    seeded noise.
    """
    rng = np.random.default_rng(seed)
    j = {n: k for k, n in enumerate(model.joint_names)}
    frames = []
    for p in px:
        img = np.full((480, 640, 3), (90, 110, 60), dtype=np.int16)
        img += rng.normal(0.0, 4.0, img.shape).astype(np.int16)
        out = np.clip(img, 0, 255).astype(np.uint8)
        head, neck = p[j["head"]], p[j["neck"]]
        r = float(np.linalg.norm(head - neck))
        centre = (round(float(head[0])), round(float(head[1])))
        cv2.ellipse(out, centre, (round(0.75 * r), round(r)), 0, 0, 360, SKIN_BGR, -1)
        for side in ("left", "right"):
            a, b = p[j[f"{side}_elbow"]], p[j[f"{side}_wrist"]]
            half = round(float(np.linalg.norm(b - a)) / 2)
            ang = float(np.degrees(np.arctan2(b[1] - a[1], b[0] - a[0])))
            mid = (round(float(a[0] + b[0]) / 2), round(float(a[1] + b[1]) / 2))
            cv2.ellipse(out, mid, (max(half, 1), 4), ang, 0, 360, SKIN_BGR, -1)
        frames.append(out)
    return frames


def _clocks() -> tuple[float, float]:
    return time.process_time(), time.perf_counter()


def _run(
    cam: Camera,
    model: StickModel,
    lengths: FloatArray,
    px: FloatArray,
    cfg: MonoConfig,
    rate_hz: float,
    images: list[NDArray[np.uint8]] | None = None,
) -> tuple[float, float, list[Any]]:
    """Track ``px`` (or, with ``images``, the joints skin tracking reads off them);
    returns the CPU and wall seconds and the frames."""
    tracker = MonoTracker(lengths, cam, 1.0 / rate_hz, cfg, model)
    skin = SkinTracker(trunk_from_head=True) if images is not None else None
    rows = [SKIN_JOINTS.index(n) for n in model.joint_names] if images is not None else []
    frames: list[Any] = []
    c0, w0 = _clocks()
    for k in range(px.shape[0]):
        if skin is not None and images is not None:
            pts = skin.update(images[k]).joints_px[rows]
        else:
            pts = px[k]
        frames += tracker.push(k / rate_hz, pts)
    frames += tracker.finish()
    c1, w1 = _clocks()
    return c1 - c0, w1 - w0, frames


def _image_lengths(
    images: list[NDArray[np.uint8]], cam: Camera, model: StickModel, cfg: MonoConfig, rate_hz: float
) -> FloatArray:
    """Link lengths from the skin-tracked joints (untimed), as ``track mono --skin`` takes
    them: the trunk drawn from the head does not have the stick's true proportions."""
    from mocapkit.pipelines.mono import video_lengths

    tr = SkinTracker(trunk_from_head=True)
    rows = [SKIN_JOINTS.index(n) for n in model.joint_names]
    px = np.stack([tr.update(im).joints_px[rows] for im in images])
    return video_lengths(px, model, cam, cfg, 1.0 / rate_hz, None)[0]


def _median_rate(n: int, times: list[float]) -> float:
    return float(n / np.median(times))


def bench_mono(
    repeats: int = 3, n_frames: int = 150, rate_hz: float = 30.0, seed: int = 0
) -> dict[str, float | str]:
    """Frames per CPU second of the mono tracker (2-D + 3-D) at 640x480.

    Returns
    -------
    dict
        ``fps`` (keypoints, online pair-state, median over repeats), ``fps_min``,
        ``fps_wall``, ``ms_per_frame``; ``image_fps`` (skin tracking from the 640x480
        frames + the same 3-D step) and ``image_2d_fps`` (the skin tracking alone);
        ``first_order_fps`` (online plain Viterbi), ``offline_fps`` (exact pair-state
        Viterbi), ``enumerations_per_s``, ``survivors_mean``, ``candidates_mean``,
        ``pruned_share``, ``latency_frames``, ``mean_flip_accuracy``, sizes and the
        pipeline description; the start-up cost apart (`mono_startup`: ``startup_*``).
    """
    if repeats < 1 or n_frames < 10:
        raise ShapeError(
            f"bench_mono: expected repeats >= 1 and n_frames >= 10, found {repeats}, {n_frames}"
        )
    joints, cam, model, lengths = mono_sequence(n_frames, rate_hz)
    rng = np.random.default_rng(seed)
    px = cam.project(joints) + rng.normal(scale=2.0, size=(n_frames, model.n_joints, 2))
    front = _camera(+1.0)
    images = skin_frames(front.project(joints), model, seed)
    online = MonoConfig(lag=10)
    img_lengths = _image_lengths(images, front, model, online, rate_hz)
    first_order = MonoConfig(lag=10, cost="rotation")
    offline = MonoConfig()
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        _run(cam, model, lengths, px[:20], online, rate_hz)  # warm-up: compile the kernels
        _run(cam, model, lengths, px[:20], first_order, rate_hz)
        _run(front, model, img_lengths, px[:20], online, rate_hz, images[:20])
        on, on_wall, fo, off, img, img2d = [], [], [], [], [], []
        frames: list[Any] = []
        for _ in range(repeats):
            cpu, wall, frames = _run(cam, model, lengths, px, online, rate_hz)
            on.append(cpu)
            on_wall.append(wall)
            fo.append(_run(cam, model, lengths, px, first_order, rate_hz)[0])
            off.append(_run(cam, model, lengths, px, offline, rate_hz)[0])
            img.append(_run(front, model, img_lengths, px, online, rate_hz, images)[0])
            tr = SkinTracker(trunk_from_head=True)
            c0, _ = _clocks()
            for im in images:
                tr.update(im)
            img2d.append(_clocks()[0] - c0)
        root = cam.to_camera(joints)[0, 0]
        rays = px[0] - cam.K[:2, 2]
        rays = rays / np.array([cam.K[0, 0], cam.K[1, 1]])
        n_enum = 2000
        c0, _ = _clocks()
        for _ in range(n_enum):
            enumerate_poses(model, lengths, rays, root, perspective=True)
        enum_rate = n_enum / (_clocks()[0] - c0)
    finally:
        cv2.setNumThreads(threads)
    truth = cam.to_camera(joints)
    est = np.stack([f.joints_in_camera for f in frames])
    dz_t = truth[:, model.child, 2] - truth[:, model.parent, 2]
    dz_e = est[:, model.child, 2] - est[:, model.parent, 2]
    counted = np.abs(dz_t) >= 0.2 * lengths
    flips = float(((np.sign(dz_t) == np.sign(dz_e)) & counted).sum() / max(counted.sum(), 1))
    cand = np.array([f.n_candidates for f in frames], dtype=float)
    surv = np.array([f.n_survivors for f in frames], dtype=float)
    fps = _median_rate(n_frames, on)
    return {
        "fps": fps,
        "fps_min": float(n_frames / np.max(on)),
        "fps_wall": _median_rate(n_frames, on_wall),
        "ms_per_frame": 1000.0 / fps,
        "image_fps": _median_rate(n_frames, img),
        "image_2d_fps": _median_rate(n_frames, img2d),
        "first_order_fps": _median_rate(n_frames, fo),
        "offline_fps": _median_rate(n_frames, off),
        "enumerations_per_s": float(enum_rate),
        "survivors_mean": float(surv.mean()),
        "candidates_mean": float(cand.mean()),
        "pruned_share": float(np.mean(1.0 - surv / np.maximum(cand, 1.0))),
        "latency_frames": float(online.smooth_lag + (online.lag or 0)),
        "mean_flip_accuracy": flips,
        "n_frames": float(n_frames),
        "image_size": "640x480",
        "clock": "CPU (process_time); fps_wall: wall clock",
        **mono_startup(),
        "pipeline": "2-D keypoints + 2 px noise (fps) or skin blobs from 640x480 frames "
        "(image_fps) -> fixed-lag smoother -> depth bound -> flips with pruning during "
        "the search -> Viterbi, lag 10 (online; fps: pair states, first_order_fps: plain "
        "states)",
    }


#: Run in a fresh interpreter by `mono_startup`: the import of the mono pipeline, the
#: session's load and two `track_mono` runs of the session (the first loads or compiles
#: the Numba kernels); prints the wall and CPU seconds as JSON.
_STARTUP_CHILD = """
import json, sys, time
c, w = time.process_time, time.perf_counter
t = [(c(), w())]
from mocapkit.pipelines.mono import load_keypoints, track_mono
from mocapkit.io.session import load_session
t.append((c(), w()))
s = load_session(sys.argv[1]); load_keypoints(s, s.camera_names[0], None)
t.append((c(), w()))
track_mono(sys.argv[1], None)
t.append((c(), w()))
track_mono(sys.argv[1], None)
t.append((c(), w()))
d = [(b[0] - a[0], b[1] - a[1]) for a, b in zip(t, t[1:])]
print(json.dumps({"import": d[0], "session": d[1], "first": d[2], "warm": d[3]}))
"""


def mono_startup(n_frames: int = 30, rate_hz: float = 30.0, seed: int = 0) -> dict[str, float]:
    """Start-up cost of ``track mono`` apart from its per-frame work, in a fresh process.

    A session of `mono_sequence` (true 2-D + 2 px noise, ``n_frames``) is written to a
    temporary folder and tracked twice by `mocapkit.pipelines.mono.track_mono` in a new
    interpreter: the first run pays the one-off costs, the second only the frames.

    Returns
    -------
    dict
        Wall seconds (``*_s``) and CPU seconds (``*_cpu_s``) of ``startup_import``
        (importing the mono pipeline: NumPy, SciPy, OpenCV, Numba, mocapkit),
        ``startup_session`` (loading the session and its keypoints) and
        ``startup_kernels`` (the first run less the second: loading the Numba kernels
        from their cache, or compiling them on a fresh install, and lazy imports);
        ``startup_total`` their sum; ``startup_frames``.
    """
    from mocapkit.io.cameras import write_cameras
    from mocapkit.io.session import write_session_json
    from mocapkit.io.session_csv import write_keypoints_csv

    joints, cam, model, _ = mono_sequence(n_frames, rate_hz)
    rng = np.random.default_rng(seed)
    px = cam.project(joints) + rng.normal(scale=2.0, size=(n_frames, model.n_joints, 2))
    with tempfile.TemporaryDirectory(prefix="mocapkit-bench-mono-") as tmp:
        folder = Path(tmp)
        write_cameras(folder / "cameras.json", [cam])
        write_session_json(folder / "session.json", {"rates": {"video_hz": rate_hz}})
        (folder / "keypoints").mkdir()
        write_keypoints_csv(
            folder / "keypoints" / f"{cam.name}.csv",
            np.arange(n_frames) / rate_hz,
            model.joint_names,
            px,
        )
        done = subprocess.run(
            [sys.executable, "-c", _STARTUP_CHILD, str(folder)],
            capture_output=True,
            text=True,
            check=False,
        )
    if done.returncode != 0:
        raise MocapError(f"bench mono start-up: the child process failed:\n{done.stderr}")
    d = json.loads(done.stdout.strip().splitlines()[-1])
    parts = {
        "startup_import": d["import"],
        "startup_session": d["session"],
        "startup_kernels": [a - b for a, b in zip(d["first"], d["warm"])],
    }
    out: dict[str, float] = {}
    for key, (cpu, wall) in parts.items():
        out[f"{key}_s"] = float(wall)
        out[f"{key}_cpu_s"] = float(cpu)
    out["startup_total_s"] = sum(out[f"{k}_s"] for k in parts)
    out["startup_frames"] = float(n_frames)
    return out


def mono_scaling(
    frame_counts: tuple[int, ...] = (75, 150, 300, 600),
    repeats: int = 3,
    rate_hz: float = 30.0,
    seed: int = 0,
    say: Callable[[str], None] = lambda _line: None,
) -> list[dict[str, float]]:
    """CPU time of the 3-D step per frame against links and frames (keypoint input).

    For the upper body (8 links, `mono_sequence`) and with legs (14 links,
    `legs_sequence`) and each frame count: online pair-state (lag 10) and exact offline
    CPU ms per frame (median over ``repeats``), the mean candidates and survivors per
    frame and the enumeration's CPU microseconds per frame.
    """
    rows = []
    for name, seq in (("upper", mono_sequence), ("legs", legs_sequence)):
        for n in frame_counts:
            joints, cam, model, lengths = seq(n, rate_hz)
            rng = np.random.default_rng(seed)
            px = cam.project(joints) + rng.normal(scale=2.0, size=(n, model.n_joints, 2))
            _run(cam, model, lengths, px[:20], MonoConfig(lag=10, legs=model.n_links > 8), rate_hz)
            on, off = [], []
            frames: list[Any] = []
            for _ in range(repeats):
                cpu, _, frames = _run(
                    cam, model, lengths, px, MonoConfig(lag=10, legs=model.n_links > 8), rate_hz
                )
                on.append(cpu)
                off.append(
                    _run(cam, model, lengths, px, MonoConfig(legs=model.n_links > 8), rate_hz)[0]
                )
            root = cam.to_camera(joints)[0, 0]
            rays = (px[0] - cam.K[:2, 2]) / np.array([cam.K[0, 0], cam.K[1, 1]])
            c0, _ = _clocks()
            for _ in range(200):
                enumerate_poses(model, lengths, rays, root, perspective=True)
            enum_us = 1e6 * (_clocks()[0] - c0) / 200
            row = {
                "links": float(model.n_links),
                "frames": float(n),
                "online_ms": 1e3 * float(np.median(on)) / n,
                "offline_ms": 1e3 * float(np.median(off)) / n,
                "candidates": float(np.mean([f.n_candidates for f in frames])),
                "survivors": float(np.mean([f.n_survivors for f in frames])),
                "enumeration_us": enum_us,
            }
            say(
                f"{name:<6}{row['links']:6.0f}{n:7d}{row['online_ms']:10.2f}"
                f"{row['offline_ms']:11.2f}{row['candidates']:8.1f}{row['survivors']:8.1f}"
                f"{enum_us:9.0f}"
            )
            rows.append(row)
    return rows
