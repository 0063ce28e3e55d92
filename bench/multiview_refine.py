"""The paper's arm particle filter as a refinement of the multi-view fit, measured.

Measured, not shipped (docs/design-notes/multiview.md): on the report clips it does not
move arm MPJPE from MediaPipe beyond the clip-to-clip spread and costs accuracy from exact
2-D. The refinement lives here so that the figures can be rerun.

The refinement: each frame, each arm of the fitted pose is turned into one particle of
the paper's 7-DoF arm model (`mocapkit.tracking.stereo.arm_filter`: shoulder rotation,
elbow angle, shoulder offset; the torso frame is the world's, the segment lengths the
fit's), the filter's particles are all set to it, and the filter's own runs (resample,
perturb with noise proportional to the edge error, weigh) search around it with the edge
cue (eq. (1) on oriented gradient maps of every view, `mocapkit.cues.skin`, in the box the
arms can reach) fused with the distance cue of Algorithm 1, whose hand point is the fit's
wrist: particles within `ArmRefineConfig.hand_radius_mm` of it are ranked by the edges
alone. The refined shoulder, elbow and wrist replace the fit's; ``+smooth`` low-passes the
correction as the fit's poses are (zero-lag Butterworth, the fit's cut-off).

For each clip of a set (the project's split, `multiview_peers.TUNING` / ``REPORT``) on the
``ring`` rig, from the sessions `bench/multiview_peers.py` renders and detects (its
``--work`` folder, read only: the sessions are copied to ``--out``, the videos linked),
the script runs the shipped multi-view fit (`track_multiview_session`) on

- ``mediapipe``: MediaPipe's detections on the rendered videos (with MediaPipe's
  keypoint offsets, as ``keypoints/detect.json`` names the backend),
- ``faults``: the same with `multiview_peers`' injected faults, and
- ``exact``: the truth's exact projections,

then refines its arms on the rendered video and prints arm MPJPE (shoulders, elbows,
wrists; mm, against the truth) of the fit and of each refinement variant, per clip and
on the mean with the change per clip, and frames per CPU second of the fit, of decoding
the four videos and of each refinement (one process, one core's CPU time).

Usage::

    .venv/bin/python bench/multiview_refine.py --set report --work /tmp/mvbench \\
        --out /tmp/mvrefine [--sources mediapipe,exact] \\
        [--grid "name:field=value,...;blank:"] [--displaced DEG] [--json f]

The figures of the design notes::

    bench/multiview_refine.py --set tuning --grid "default:;blank:"
    bench/multiview_refine.py --set report --sources mediapipe,faults,exact \\
        --grid "default:;blank:"
    bench/multiview_refine.py --set report --sources mediapipe,faults,exact \\
        --grid "wide:spread_rad=0.1,n_runs=5,n_particles=200"
    bench/multiview_refine.py --set tuning --clips 13_26 --sources exact --displaced 5
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.cues.edges import Roi, roi_around_points
from mocapkit.cues.skin import GradientConfig, gradient_vector_map
from mocapkit.errors import ConfigError, ShapeError
from mocapkit.eval.metrics import evaluate_joints
from mocapkit.geometry.rotations import rotvec_from_matrix
from mocapkit.io.session import load_session
from mocapkit.pipelines.multiview import track_multiview_session
from mocapkit.pipelines.stereo import ARM_JOINTS
from mocapkit.skeleton.model import CANONICAL_JOINTS
from mocapkit.tracking.multiview.config import MultiviewRunConfig
from mocapkit.tracking.stereo.arm_filter import (
    N_STATE,
    ArmFilterConfig,
    ArmModel,
    ArmParticleFilter,
    arm_weights_nb,
    view_stack,
)
from mocapkit.tracking.stereo.fusion import FusionParams, default_fusion

sys.path.insert(0, str(Path(__file__).resolve().parent))
from multiview_peers import REPORT, TUNING, record_backend

FloatArray = NDArray[np.float64]
SIDES = ("left", "right")
#: Canonical rows of each arm's shoulder, elbow and wrist.
ARM_ROWS = {
    s: [CANONICAL_JOINTS.index(f"{s}_{j}") for j in ("shoulder", "elbow", "wrist")] for s in SIDES
}


@dataclass(frozen=True)
class ArmRefineConfig:
    """Settings of the arm refinement (module notes).

    Parameters
    ----------
    n_particles, n_runs : int
        Particles per run and runs per frame of each arm's filter.
    noise_rad_per_error : float
        The filter's adaptive noise (rad per unit edge error; the shoulder offset's is
        200 mm per rad of it, as the paper's filter); floored at 0.01 rad.
    shoulder_box_mm : float
        Half-size of the cuboid the shoulder may move in around the fit's (0: the fit's
        shoulder is kept).
    hand_radius_mm : float
        Algorithm 1's minimum radius around the fit's wrist.
    spread_rad : float
        Spread (std) of the first run's particles around the fit's arm in the shoulder's
        rotation and the elbow angle, before the filter's own noise (0: all at the fit's).
    radii_mm : (4,)
        Cone radii of the upper arm (proximal, distal) and forearm (mm).
    gradient : GradientConfig
    seed : int
    """

    n_particles: int = 100
    n_runs: int = 3
    noise_rad_per_error: float = 0.05
    shoulder_box_mm: float = 20.0
    hand_radius_mm: float = 60.0
    spread_rad: float = 0.0
    radii_mm: tuple[float, float, float, float] = (48.0, 40.0, 38.0, 30.0)
    gradient: GradientConfig = field(default_factory=GradientConfig)
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("noise_rad_per_error", "shoulder_box_mm", "hand_radius_mm", "spread_rad"):
            v = getattr(self, name)
            if not v >= 0:
                raise ConfigError(f"ArmRefineConfig.{name}: expected >= 0, found {v}")
        if len(self.radii_mm) != 4 or not all(r > 0 for r in self.radii_mm):
            raise ConfigError(
                f"ArmRefineConfig.radii_mm: expected four positive radii, found {self.radii_mm}"
            )

    def filter_config(self) -> ArmFilterConfig:
        """The arm filter's settings: no IK samples (the fit is the start), the noise and
        the distance cue's radius above."""
        fusion: FusionParams = default_fusion()._replace(t_d_mm=self.hand_radius_mm)
        return ArmFilterConfig(
            n_particles=self.n_particles,
            n_runs=self.n_runs,
            use_ik=False,
            noise_rad_per_error=self.noise_rad_per_error,
            noise_mm_per_error=200.0 * self.noise_rad_per_error,
            adaptive_shoulder=self.shoulder_box_mm > 0,
            shoulder_box_mm=self.shoulder_box_mm,
            shoulder_pull=0.1,
            fusion=fusion,
        )


def arm_state(shoulder: FloatArray, elbow: FloatArray, wrist: FloatArray) -> FloatArray:
    """The arm filter's state (7,) of an arm given by its three joints, in a torso frame
    equal to the world's with the shoulder at the base (offset 0): the inverse of
    `mocapkit.tracking.stereo.arm_filter.arm_points_nb` for the lengths of these joints.
    A straight arm takes any elbow axis (the state is then not unique)."""
    u = elbow - shoulder
    u = u / max(float(np.linalg.norm(u)), 1e-9)
    f = wrist - elbow
    f = f / max(float(np.linalg.norm(f)), 1e-9)
    c = float(np.clip(f @ u, -1.0, 1.0))
    y = f - c * u
    ny = float(np.linalg.norm(y))
    if ny < 1e-9:  # straight: any axis across the upper arm
        y = np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0])
        ny = float(np.linalg.norm(y))
    y = y / ny
    z = -u
    r = np.stack([np.cross(y, z), y, z], axis=1)
    out = np.zeros(N_STATE)
    out[:3] = rotvec_from_matrix(r)
    out[3] = -float(np.arccos(c))
    return out


class ArmRefiner:
    """Refines the arms of fitted poses frame by frame (module notes).

    Parameters
    ----------
    cameras : sequence of Camera
        The views, all of one image size.
    config : ArmRefineConfig, optional
    """

    def __init__(self, cameras: Sequence[Camera], config: ArmRefineConfig | None = None) -> None:
        self.config = cfg = config or ArmRefineConfig()
        self.cameras = list(cameras)
        sizes = {c.image_size for c in self.cameras}
        if len(sizes) != 1 or not self.cameras:
            raise ShapeError(f"cameras: expected one image size for every view, found {sizes}")
        w, h = self.cameras[0].image_size
        self._gx = np.zeros((len(self.cameras), h, w), np.float32)
        self._gy = np.zeros((len(self.cameras), h, w), np.float32)
        self.arm_config = cfg.filter_config()
        rng = np.random.default_rng(cfg.seed)
        self.filters = {s: ArmParticleFilter(s, self.arm_config, rng) for s in SIDES}
        self._sampling = np.array(
            [self.arm_config.step_px, float(self.arm_config.max_samples_per_line), 1.0]
        )
        self._radii = np.asarray(cfg.radii_mm, dtype=float)

    def _rois(self, joints_mm: FloatArray) -> list[Roi | None]:
        """Per view: the box of both arms' joints grown by the reach of the noise."""
        rows = ARM_ROWS["left"] + ARM_ROWS["right"]
        pts = joints_mm[rows]
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        pad = max(self.config.radii_mm) + 100.0
        corners = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
        box = (pts[:, None, :] + pad * corners[None]).reshape(-1, 3)
        out: list[Roi | None] = []
        for c in self.cameras:
            px = c.project(box)
            out.append(
                roi_around_points(px, c.image_size, 4.0) if np.all(np.isfinite(px)) else None
            )
        return out

    def update(
        self, joints_mm: FloatArray, images: Sequence[NDArray[np.uint8]]
    ) -> tuple[FloatArray, dict[str, float]]:
        """Refine one frame's fitted joints (15, 3) with the views' images (BGR); returns the
        joints and, per arm, the edge error of the fit's and of the refined arm."""
        if len(images) != len(self.cameras):
            raise ShapeError(
                f"ArmRefiner.update: expected {len(self.cameras)} images, found {len(images)}"
            )
        out = np.array(joints_mm, dtype=float, copy=True)
        fit: dict[str, float] = {}
        arms = {s: out[ARM_ROWS[s]] for s in SIDES}
        usable = {s: bool(np.all(np.isfinite(arms[s]))) for s in SIDES}
        if not any(usable.values()):
            for s in SIDES:
                fit[f"{s}_edge_fit"] = fit[f"{s}_edge_refined"] = float("nan")
            return out, fit
        for i, (img, roi) in enumerate(zip(images, self._rois(out), strict=True)):
            gradient_vector_map(
                img, roi=roi, config=self.config.gradient, out=(self._gx[i], self._gy[i])
            )
        views = view_stack(self.cameras, self._gx, self._gy)
        eye = np.eye(3)
        for s in SIDES:
            if not usable[s]:
                fit[f"{s}_edge_fit"] = fit[f"{s}_edge_refined"] = float("nan")
                continue
            sh, el, wr = arms[s]
            model = ArmModel(
                eye,
                sh.copy(),
                np.array([np.linalg.norm(el - sh), np.linalg.norm(wr - el), 0.0]),
                self._radii,
                wr.copy(),
                self._sampling,
            )
            start = arm_state(sh, el, wr)
            filt = self.filters[s]
            filt.particles[:] = start
            if self.config.spread_rad > 0:
                p = filt.particles
                p[:, :4] += filt.rng.normal(0.0, self.config.spread_rad, (p.shape[0], 4))
                np.clip(p[:, 3], -np.pi, 0.0, out=p[:, 3])
            filt.weights[:] = 1.0 / filt.weights.shape[0]
            wt, eg, d2 = np.empty(1), np.empty(1), np.empty(1)
            arm_weights_nb(start[None, :], model, views, self.arm_config.fusion, 0.0, wt, eg, d2)
            filt.edge_error = float(eg[0])
            filt.prev_dist_sq = 0.0
            est = filt.step(model, views)
            out[ARM_ROWS[s]] = est.points_mm[:3]
            fit[f"{s}_edge_fit"] = float(eg[0])
            fit[f"{s}_edge_refined"] = float(est.edge_error)
        return out, fit


SOURCES = {"mediapipe": "mp", "faults": "mp_faults", "exact": "truth"}


def copy_session(src: Path, out: Path) -> Path:
    """A copy of a session's files with its video folder linked (the source untouched)."""
    if (out / "keypoints").is_dir():
        return out
    tmp = out.parent / (out.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    for f in ("session.json", "cameras.json", "truth.npz"):
        shutil.copy(src / f, tmp / f)
    shutil.copytree(src / "keypoints", tmp / "keypoints")
    os.symlink((src / "video").resolve(), tmp / "video")
    tmp.rename(out)
    return out


def arm_errors(session: Path, time_s: Any, joints: Any) -> dict[str, float]:
    """Arm MPJPE and its parts (mm) against the session's truth."""
    truth = load_session(session).truth
    if truth is None:
        raise SystemExit(f"{session}: no truth.npz to score against")
    rep = evaluate_joints(
        time_s,
        CANONICAL_JOINTS,
        joints,
        truth.time_s,
        truth.joint_names,
        truth.joints_mm,
        joints=ARM_JOINTS,
    )
    per = {k: float(v) for k, v in rep.per_joint_mm.items()}
    out = {"arm": float(np.mean(list(per.values())))}
    for part in ("shoulder", "elbow", "wrist"):
        out[part] = float(np.mean([v for k, v in per.items() if k.endswith(part)]))
    return out


def fitted(session: Path) -> tuple[np.ndarray, np.ndarray, float]:
    """The shipped fit's joints (T, 15, 3), times and CPU seconds."""
    run = track_multiview_session(session)
    return run.motion.joints_mm, run.motion.time_s, run.seconds


def smoothed(fit: np.ndarray, refined: np.ndarray, time_s: np.ndarray, hz: float) -> np.ndarray:
    """The refinement's correction low-passed as the fit's poses are (zero-lag Butterworth)."""
    from scipy.signal import butter, filtfilt

    d = refined - fit
    ok = np.isfinite(d).all(axis=(1, 2))
    if ok.sum() <= 15 or not ok.all():
        return refined
    b, a = butter(4, hz / (0.5 / float(np.median(np.diff(time_s)))))
    return fit + filtfilt(b, a, d, axis=0)


def displaced(session: Path, time_s: np.ndarray, joints: np.ndarray, deg: float) -> np.ndarray:
    """The truth's joints at the fit's times with each arm turned ``deg`` about its
    shoulder around a random axis (seeded): a start whose error the edges can see."""
    from scipy.spatial.transform import Rotation

    truth = load_session(session).truth
    if truth is None:
        raise SystemExit(f"{session}: no truth.npz to displace")
    rng = np.random.default_rng(0)
    out = joints.copy()
    tn = list(truth.joint_names)
    for k, t in enumerate(time_s):
        i = int(np.argmin(np.abs(truth.time_s - t)))
        for j, name in enumerate(CANONICAL_JOINTS):
            if name in tn:
                out[k, j] = truth.joints_mm[i, tn.index(name)]
        for side in SIDES:
            sh, el, wr = ARM_ROWS[side]
            axis = rng.normal(size=3)
            r = Rotation.from_rotvec(np.radians(deg) * axis / np.linalg.norm(axis)).as_matrix()
            out[k, [el, wr]] = out[k, sh] + (out[k, [el, wr]] - out[k, sh]) @ r.T
    return out


def run_one(
    session: Path, configs: dict[str, ArmRefineConfig], displaced_deg: float = 0.0
) -> dict[str, Any]:
    joints, time_s, fit_s = fitted(session)
    if displaced_deg > 0:
        joints = displaced(session, time_s, joints, displaced_deg)
    s = load_session(session)
    names = sorted(s.keypoints)
    cams = [s.camera(c) for c in names]
    refiners = {k: ArmRefiner(cams, c) for k, c in configs.items()}
    out = {k: joints.copy() for k in configs}
    cpu = dict.fromkeys(configs, 0.0)
    decode_s = 0.0
    n = joints.shape[0]
    for k, smp in enumerate(s.samples(names)):
        if k >= n:
            break
        if abs(smp.time_s - time_s[k]) > 1e-3:
            raise SystemExit(f"{session}: frame {k} at {smp.time_s} s, pose at {time_s[k]}")
        t0 = time.process_time()
        imgs = [smp.image(c) for c in names]
        decode_s += time.process_time() - t0
        for key, ref in refiners.items():
            t0 = time.process_time()
            # the control: the same filter on blank images (no edges anywhere)
            seen = [np.zeros_like(im) for im in imgs] if key.startswith("blank") else imgs
            out[key][k] = ref.update(joints[k], seen)[0]
            cpu[key] += time.process_time() - t0
    rows: dict[str, Any] = {"fit": arm_errors(session, time_s, joints), "fit_fps": n / fit_s}
    for key in configs:
        rows[key] = arm_errors(session, time_s, out[key])
        rows[key + "+smooth"] = arm_errors(
            session, time_s, smoothed(joints, out[key], time_s, MultiviewRunConfig().cutoff_hz)
        )
        rows[key + "_fps"] = n / (fit_s + decode_s + cpu[key])
        rows[key + "_refine_fps"] = n / cpu[key]
    rows["decode_fps"] = n / decode_s
    return rows


def parse_grid(text: str) -> dict[str, ArmRefineConfig]:
    """``name:field=value,field=value;name2:...`` to named refinement settings."""
    out = {}
    for item in filter(None, text.split(";")):
        name, _, rest = item.partition(":")
        kw: dict[str, Any] = {}
        for pair in filter(None, rest.split(",")):
            f, _, v = pair.partition("=")
            kw[f] = type(getattr(ArmRefineConfig(), f))(v)
        out[name] = ArmRefineConfig(**kw)
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--set", choices=("tuning", "report"), default="tuning")
    p.add_argument("--clips", help="comma-separated clip names (default: the whole set)")
    p.add_argument("--work", type=Path, default=Path("/tmp/mvbench"))
    p.add_argument("--out", type=Path, default=Path("/tmp/mvrefine"))
    p.add_argument("--sources", default="mediapipe,exact")
    p.add_argument(
        "--grid",
        default="default:",
        help="refinement settings to compare, 'name:field=value,...;name2:...' "
        "(ArmRefineConfig fields; default: the shipped defaults); a name starting with "
        "'blank' runs on blank images (a control: what the filter does without edges)",
    )
    p.add_argument(
        "--displaced",
        type=float,
        default=0.0,
        metavar="DEG",
        help="start from the truth with each arm turned DEG about its shoulder instead of "
        "the fit (the 'fit' column is then that start): what the edges bring back",
    )
    p.add_argument("--json", type=Path)
    a = p.parse_args()
    configs = parse_grid(a.grid)
    clips = [c.split(".")[0] for c in (TUNING if a.set == "tuning" else REPORT)]
    if a.clips:
        clips = a.clips.split(",")
    rows: dict[str, dict[str, Any]] = {}
    first = copy_session(a.work / "ring" / clips[0] / "truth", a.out / clips[0] / "exact")
    track_multiview_session(first, max_frames=10)  # compiles the fit's kernels (not timed)
    variants = [k + sfx for k in configs for sfx in ("", "+smooth")]
    print(
        "arm MPJPE (mm): fit, then each variant; frames per CPU s: the fit, video decoding, "
        "each variant's refinement alone and the three together"
    )
    print(f"{'clip':12} {'source':9} {'fit':>6} " + " ".join(f"{v:>16}" for v in variants))
    for clip in clips:
        for src in a.sources.split(","):
            session = copy_session(a.work / "ring" / clip / SOURCES[src], a.out / clip / src)
            if src in ("mediapipe", "faults"):
                record_backend(session)
            r = run_one(session, configs, a.displaced)
            rows[f"{clip}/{src}"] = r
            print(
                f"{clip:12} {src:9} {r['fit']['arm']:6.1f} "
                + " ".join(f"{r[v]['arm']:16.1f}" for v in variants)
                + f"   fps fit {r['fit_fps']:.0f}, decode {r['decode_fps']:.0f}, "
                + ", ".join(
                    f"{k} {r[k + '_refine_fps']:.0f} (all {r[k + '_fps']:.0f})" for k in configs
                ),
                flush=True,
            )
    for src in a.sources.split(","):
        sel = [v for k, v in rows.items() if k.endswith("/" + src)]
        if not sel:
            continue
        print(
            f"{'mean':12} {src:9} {np.mean([v['fit']['arm'] for v in sel]):6.1f} "
            + " ".join(f"{np.mean([v[x]['arm'] for v in sel]):16.1f}" for x in variants)
        )
        for x in variants:
            d = np.array([v[x]["arm"] - v["fit"]["arm"] for v in sel])
            parts = " ".join(
                f"{q} {np.mean([v['fit'][q] for v in sel]):.1f}->"
                f"{np.mean([v[x][q] for v in sel]):.1f}"
                for q in ("shoulder", "elbow", "wrist")
            )
            sd = float(np.std(d, ddof=1)) if len(d) > 1 else 0.0
            print(
                f"    {src} {x}: change per clip {' '.join(f'{y:+.1f}' for y in d)} "
                f"(mean {d.mean():+.2f}, sd {sd:.2f}); {parts}"
            )
    if a.json:
        a.json.write_text(json.dumps({"grid": a.grid, "set": a.set, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
