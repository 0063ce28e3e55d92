"""Per-arm particle filter of Azad et al. 2008 (§III-VII): 7-DoF arm, edge + distance cues.

State of one particle (7,): the shoulder's rotation vector ``(theta1, theta2,
theta3)`` in the torso frame, the elbow angle ``theta4`` in [-pi, 0] (the ``azad14``
preset's conventions, see `mocapkit.ik.arm_analytic`) and the adaptive shoulder offset
``d`` (mm, torso frame, within a cuboid; §VI).

Forward kinematics: ``s = s_0 + R_b d``, ``elbow = s + R_b R (0, 0, -a)``,
``wrist = elbow + b f`` with ``f = R_b R (0, -sin theta4, -cos theta4)``, and the
measured hand point ``p_h = wrist + o f`` (``o``: the hand-centre offset beyond the
wrist: the centroid of a skin blob lies in the hand, not on the wrist; 0 with
keypoints, whose wrist is the point).

One compiled call (`arm_weights_nb`) weighs a whole particle batch over every view:
per particle and view, the two contour generators of each cone (upper arm, forearm)
are projected at their ends and sampled every ``step_px`` pixels between them (the
mild lens distortion of the rigs bends one limb outline by well under a pixel),
eq. (1) averages the gradient map along them (bilinear; points off the image or
behind the camera read 0), the views' errors are averaged (Algorithm 1, step 1,
generalised to any number of views), and Algorithm 1 fuses them with the hand
distance (`mocapkit.tracking.stereo.fusion`).

Per frame (recipe A): run 1 resamples, perturbs the particles with noise
proportional to the arm's edge error (§V; floored), and replaces 60 % of them by
samples of the analytic IK (§VII) with alpha uniform in the side's range and the
previous shoulder offset; runs 2-4 resample and perturb; the estimate is the weighted
mean of the last run (rotations by their chordal mean, the paper leaves this open).

Outlines: the exact contour generators of each cone under perspective
(`mocapkit.geometry.cones`), projected with the one shared projection kernel
(`mocapkit.camera.projection`; points nearer than its near plane are not visible and
count as off the image).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numba
import numpy as np
from numpy.typing import NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.camera.projection import (
    CameraArrays,
    camera_arrays,
    project_camera_point_nb,
    to_camera_nb,
)
from mocapkit.cues.chamfer import bilinear_lookup_nb
from mocapkit.errors import ConfigError, ShapeError
from mocapkit.geometry.cones import cone_contour_generators_nb
from mocapkit.geometry.rotations import matrix_rotvec_nb, rotvec_matrix_nb
from mocapkit.ik.arm_analytic import ALPHA_RANGE_RAD, arm_ik, make_problem
from mocapkit.tracking.stereo.fusion import FusionParams, default_fusion, fused_weight_nb
from mocapkit.tracking.stereo.swivel import bound_swivel_nb, swivel_radius_mm, swivel_window_rad

FloatArray = NDArray[np.float64]
Float32Array = NDArray[np.float32]

#: Particle layout.
N_STATE = 7


class ViewStack(NamedTuple):
    """Cameras and gradient maps of one frame, over V views.

    Attributes
    ----------
    cameras : tuple of CameraArrays, length V
        The views in the shared projection's layout (`mocapkit.camera.projection`).
    gradient : (V, H, W) float32
        Gradient maps in [0, 1] (`mocapkit.cues.skin.gradient_map`); 0 where not
        computed. With oriented edges: the gradient's x component
        (`mocapkit.cues.skin.gradient_vector_map`).
    gradient_y : (V, H, W) or (V, 1, 1) float32
        The gradient's y component with oriented edges; unused (1x1) otherwise.
    """

    cameras: tuple[CameraArrays, ...]
    gradient: Float32Array
    gradient_y: Float32Array


class ArmModel(NamedTuple):
    """Everything about one arm that is fixed for a frame.

    Attributes
    ----------
    base_rotation : (3, 3)
        ``R_b``, world from torso.
    shoulder_base_mm : (3,)
        Shoulder position for a zero offset ``d``, world.
    lengths_mm : (3,)
        Upper arm ``a``, forearm ``b``, hand-centre offset ``o``.
    radii_mm : (4,)
        Upper-arm cone radii (proximal, distal), forearm cone radii.
    hand_mm : (3,)
        Measured hand point, world; NaN when not measured (distance cue off).
    sampling : (3,)
        Contour sample spacing (px), the most samples per contour line, and 1 for
        oriented edges (read ``|g . n|`` with ``n`` the outline's image normal from the
        gradient vector maps) or 0 for eq. (1)'s magnitude.
    """

    base_rotation: FloatArray
    shoulder_base_mm: FloatArray
    lengths_mm: FloatArray
    radii_mm: FloatArray
    hand_mm: FloatArray
    sampling: FloatArray


def view_stack(
    cameras: list[Camera],
    gradients: list[Float32Array] | Float32Array,
    gradients_y: list[Float32Array] | Float32Array | None = None,
) -> ViewStack:
    """Pack cameras and their gradient maps (all the same image size) into a `ViewStack`.

    ``gradients_y`` (oriented edges): the y components, ``gradients`` then holding x.
    Maps already stacked as contiguous float32 (V, H, W) arrays are used without a copy.
    """
    if len(cameras) != len(gradients) or not cameras:
        raise ShapeError(
            f"view_stack: expected one gradient map per camera, found {len(cameras)} cameras "
            f"and {len(gradients)} maps"
        )
    shapes = {tuple(g.shape) for g in gradients}
    if len(shapes) != 1:
        raise ShapeError(f"view_stack: gradient maps differ in size: {sorted(shapes)}")
    v = len(cameras)
    cams = tuple(camera_arrays(c.K, c.dist, c.camera_from_world) for c in cameras)
    grad = _stacked(gradients)
    if gradients_y is None:
        grad_y = np.zeros((v, 1, 1), np.float32)
    else:
        grad_y = _stacked(gradients_y)
        if grad_y.shape != grad.shape:
            raise ShapeError(
                f"view_stack: y gradients {grad_y.shape} differ from x gradients {grad.shape}"
            )
    return ViewStack(cams, grad, grad_y)


def _stacked(maps: list[Float32Array] | Float32Array) -> Float32Array:
    if isinstance(maps, np.ndarray) and maps.ndim == 3:
        return np.ascontiguousarray(maps, dtype=np.float32)
    return np.ascontiguousarray(np.stack(list(maps)), dtype=np.float32)


# ------------------------------------------------------------------ compiled kernels


@numba.njit(cache=True, inline="always")
def _read_nb(g: Float32Array, u: float, v: float) -> float:
    """Bilinear gradient at pixel (u, v); 0 off the image (recipe A): the one map look-up
    of `mocapkit.cues.chamfer` on a full-frame map (origin 0, step 1, cap 0)."""
    return bilinear_lookup_nb(g, u, v, 0.0, 0.0, 1.0, 0.0)


@numba.njit(cache=True)
def arm_points_nb(x: FloatArray, model: ArmModel, out: FloatArray) -> None:
    """Forward kinematics of one particle ``x`` (7,): writes shoulder, elbow, wrist and the
    hand point (4, 3), world (module notes)."""
    rb = model.base_rotation
    r_local = np.empty((3, 3))
    rotvec_matrix_nb(x[:3], r_local)
    r = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            r[i, j] = rb[i, 0] * r_local[0, j] + rb[i, 1] * r_local[1, j] + rb[i, 2] * r_local[2, j]
    a = model.lengths_mm[0]
    b = model.lengths_mm[1]
    o = model.lengths_mm[2]
    st = math.sin(x[3])
    ct = math.cos(x[3])
    for i in range(3):
        s = model.shoulder_base_mm[i] + rb[i, 0] * x[4] + rb[i, 1] * x[5] + rb[i, 2] * x[6]
        e = s - a * r[i, 2]
        f = -st * r[i, 1] - ct * r[i, 2]
        out[0, i] = s
        out[1, i] = e
        out[2, i] = e + b * f
        out[3, i] = e + (b + o) * f


@numba.njit(cache=True)
def _edge_error_nb(
    pts: FloatArray, model: ArmModel, views: ViewStack, scratch: FloatArray, gen: FloatArray
) -> float:
    """Eq. (1) averaged over the views for the arm points ``pts`` (4, 3).

    ``scratch`` (2, 3) and ``gen`` (2, 2, 3) are work arrays (no allocation per call).
    """
    n_views = len(views.cameras)
    step = model.sampling[0]
    max_n = int(model.sampling[1])
    oriented = model.sampling[2] > 0.5
    total = 0.0
    for v in range(n_views):
        cam = views.cameras[v]
        acc = 0.0
        count = 0
        for seg in range(2):
            p0 = pts[seg]
            p1 = pts[seg + 1]
            x, y, z = to_camera_nb(cam, p0[0], p0[1], p0[2])
            scratch[0, 0], scratch[0, 1], scratch[0, 2] = x, y, z
            x, y, z = to_camera_nb(cam, p1[0], p1[1], p1[2])
            scratch[1, 0], scratch[1, 1], scratch[1, 2] = x, y, z
            cone_contour_generators_nb(
                scratch[0], scratch[1], model.radii_mm[2 * seg], model.radii_mm[2 * seg + 1], gen
            )
            for side in range(2):
                ua, va, oka = project_camera_point_nb(
                    cam, gen[side, 0, 0], gen[side, 0, 1], gen[side, 0, 2]
                )
                ub, vb, okb = project_camera_point_nb(
                    cam, gen[side, 1, 0], gen[side, 1, 1], gen[side, 1, 2]
                )
                if not (oka and okb):  # not visible: counts as off the image
                    count += 2
                    continue
                length = math.sqrt((ub - ua) ** 2 + (vb - va) ** 2)
                n = min(max(math.ceil(length / step) + 1, 2), max_n)
                # sampled linearly between the projected ends: the lens bends one limb
                # outline by well under a pixel
                du = (ub - ua) / (n - 1)
                dv = (vb - va) / (n - 1)
                if oriented and length > 1e-9:
                    nu = -(vb - va) / length
                    nv = (ub - ua) / length
                    for k in range(n):
                        gx = _read_nb(views.gradient[v], ua + k * du, va + k * dv)
                        gy = _read_nb(views.gradient_y[v], ua + k * du, va + k * dv)
                        acc += abs(gx * nu + gy * nv)
                else:
                    for k in range(n):
                        acc += _read_nb(views.gradient[v], ua + k * du, va + k * dv)
                count += n
        total += 1.0 - (acc / count if count > 0 else 0.0)
    return total / n_views


@numba.njit(cache=True)
def arm_weights_nb(
    particles: FloatArray,
    model: ArmModel,
    views: ViewStack,
    fusion: FusionParams,
    prev_dist_sq_mm2: float,
    out_weight: FloatArray,
    out_edge: FloatArray,
    out_dist_sq: FloatArray,
) -> None:
    """Weigh a particle batch (N, 7) over every view in one call (module notes).

    Writes the fused weights (Algorithm 1), the raw edge errors (view-averaged eq. (1))
    and the raw squared hand distances (mm^2; NaN without a measured hand), all (N,).
    """
    pts = np.empty((4, 3))
    scratch = np.empty((2, 3))
    gen = np.empty((2, 2, 3))
    h = model.hand_mm
    for i in range(particles.shape[0]):
        arm_points_nb(particles[i], model, pts)
        eg = _edge_error_nb(pts, model, views, scratch, gen)
        d2 = (pts[3, 0] - h[0]) ** 2 + (pts[3, 1] - h[1]) ** 2 + (pts[3, 2] - h[2]) ** 2
        out_edge[i] = eg
        out_dist_sq[i] = d2
        out_weight[i] = fused_weight_nb(eg, d2, prev_dist_sq_mm2, fusion)


@numba.njit(cache=True)
def _chordal_mean_rotvec_nb(rotvecs: FloatArray, weights: FloatArray, out: FloatArray) -> None:
    """Weighted sum of the rotation matrices of ``rotvecs`` (N, 3) into ``out`` (3, 3)."""
    m = np.empty((3, 3))
    out[:, :] = 0.0
    for i in range(rotvecs.shape[0]):
        rotvec_matrix_nb(rotvecs[i], m)
        for j in range(3):
            for k in range(3):
                out[j, k] += weights[i] * m[j, k]


@numba.njit(cache=True)
def _elbows_nb(particles: FloatArray, model: ArmModel, out: FloatArray) -> None:
    """Elbow positions (N, 3) of a particle batch (N, 7)."""
    pts = np.empty((4, 3))
    for i in range(particles.shape[0]):
        arm_points_nb(particles[i], model, pts)
        out[i] = pts[1]


# ------------------------------------------------------------------ the filter


#: Recipe A's half-size of the shoulder offset cuboid (mm), `ArmFilterConfig.shoulder_box_mm`.
SHOULDER_BOX_MM = 50.0


@dataclass(frozen=True)
class ArmFilterConfig:
    """Settings of one arm's particle filter (paper values by default; recipe A).

    Parameters
    ----------
    n_particles : int
        Particles per run (paper: 150).
    n_runs : int
        Runs per frame (paper: 4; the first mixes in the IK samples).
    ik_fraction : float
        Share of the first run's particles drawn from the analytic IK (paper: 0.6).
    use_ik : bool
        IK sampling on (§VII). Off: conventional sampling only (ablation).
    adaptive_noise : bool
        Noise proportional to the edge error (§V); off: the constant noise below.
    adaptive_shoulder : bool
        7 DoF with the shoulder offset (§VI); off: 4 DoF, offset fixed at 0.
    noise_rad_per_error, noise_mm_per_error : float
        Adaptive noise std per unit edge error (recipe A: 0.05 rad and 10 mm at 0.5).
    min_noise_rad, min_noise_mm : float
        Floors of the adaptive noise (recipe A: 0.01 rad, 2 mm).
    constant_noise_rad, constant_noise_mm : float
        Noise without adaptive noise.
    shoulder_box_mm : float, optional
        Half-size of the shoulder offset cuboid. None (default): recipe A's 50 mm, except
        where `mocapkit.tracking.stereo.tracker.StereoTracker` measures the torso from
        keypoints, which confines the offsets to
        ``tracker.KEYPOINT_TORSO_SHOULDER_BOX_MM`` (20 mm): the shoulders are then
        measured, and recipe A's cuboid, meant for an unmeasured torso, lets the weakly
        observed offsets wander and spreads the particles over three loose DoF.
    shoulder_pull : float
        Share by which every perturbation pulls the shoulder offsets back towards 0 (not
        in the paper, which only bounds them; 0 = paper). Measured on two tuning
        excerpts with keypoints and a keypoint torso: arm mean 37.3/48.5 mm without,
        28.8/30.2 mm with 0.1.
    step_px : float
        Contour sample spacing (recipe A: about 5 px).
    max_samples_per_line : int
    oriented_edges : bool
        Score only the gradient component across each outline (``|g . n|``), so that
        edges crossing an outline (a torso's, a fold's) do not count as if they ran
        along it (an extension of eq. (1), which sums the magnitude; off = paper).
    estimate : {"mode", "mean"}
        The frame's estimate: the weighted mean of the particles whose elbow lies
        within ``mode_radius_mm`` of the best particle's (default), or of all particles
        (the paper leaves it open; a bimodal elbow circle makes the plain mean a pose
        between the two).
    mode_radius_mm : float
    fusion : FusionParams
    """

    n_particles: int = 150
    n_runs: int = 4
    ik_fraction: float = 0.6
    use_ik: bool = True
    adaptive_noise: bool = True
    adaptive_shoulder: bool = True
    noise_rad_per_error: float = 0.1
    noise_mm_per_error: float = 20.0
    min_noise_rad: float = 0.01
    min_noise_mm: float = 2.0
    constant_noise_rad: float = 0.08
    constant_noise_mm: float = 15.0
    shoulder_box_mm: float | None = None
    shoulder_pull: float = 0.1
    step_px: float = 5.0
    max_samples_per_line: int = 48
    oriented_edges: bool = True
    estimate: str = "mode"
    mode_radius_mm: float = 60.0
    fusion: FusionParams = field(default_factory=default_fusion)

    def __post_init__(self) -> None:
        if self.n_particles < 2:
            raise ConfigError(f"n_particles: expected at least 2, found {self.n_particles}")
        if self.n_runs < 1:
            raise ConfigError(f"n_runs: expected at least 1, found {self.n_runs}")
        if not 0.0 <= self.ik_fraction <= 1.0:
            raise ConfigError(f"ik_fraction: expected a share in [0, 1], found {self.ik_fraction}")
        if self.estimate not in ("mode", "mean"):
            raise ConfigError(f"estimate: expected 'mode' or 'mean', found {self.estimate!r}")
        if self.shoulder_box_mm is not None and not self.shoulder_box_mm >= 0:
            raise ConfigError(
                f"shoulder_box_mm: expected >= 0 mm (or None), found {self.shoulder_box_mm}"
            )
        if not (self.step_px > 0 and self.max_samples_per_line >= 2):
            raise ConfigError(
                f"step_px/max_samples_per_line: expected > 0 and >= 2, found {self.step_px} "
                f"and {self.max_samples_per_line}"
            )


def systematic_resample(weights: FloatArray, rng: np.random.Generator) -> NDArray[np.int64]:
    """Indices (N,) of systematic resampling of normalised-or-not weights (N,)."""
    w = np.asarray(weights, dtype=float)
    n = w.shape[0]
    total = w.sum()
    if not (total > 0 and np.isfinite(total)):
        return np.arange(n)
    c = np.cumsum(w / total)
    c[-1] = 1.0
    pos = (rng.random() + np.arange(n)) / n
    return np.minimum(np.searchsorted(c, pos, side="right"), n - 1).astype(np.int64)


@dataclass
class ArmEstimate:
    """One arm's result for a frame."""

    state: FloatArray  # (7,)
    points_mm: FloatArray  # (4, 3): shoulder, elbow, wrist, hand point
    edge_error: float
    dist_mm: float
    n_ik: int


class ArmParticleFilter:
    """Particle filter for one arm (module notes).

    Parameters
    ----------
    side : {"left", "right"}
    config : ArmFilterConfig
    rng : numpy Generator
    """

    def __init__(self, side: str, config: ArmFilterConfig, rng: np.random.Generator) -> None:
        if side not in ALPHA_RANGE_RAD:
            raise ConfigError(f"side: expected 'left' or 'right', found {side!r}")
        self.side = side
        self.config = config
        self.rng = rng
        n = config.n_particles
        self.particles = np.zeros((n, N_STATE))
        self.particles[:, 3] = -0.3  # a slightly bent arm hanging down
        self.weights = np.full(n, 1.0 / n)
        self.prev_dist_sq = math.inf
        self.edge_error = 1.0
        self.last_n_ik = 0
        self._w = np.empty(n)
        self._eg = np.empty(n)
        self._d2 = np.empty(n)
        #: the last estimate's elbow relative to its shoulder (mm); None before the first
        self._elbow_rel: FloatArray | None = None
        #: a jump of the estimate's mode held back last frame: its elbow (mm), else None
        self._held_jump: FloatArray | None = None
        #: the last estimate's elbow relative to its shoulder, torso frame (mm), and its
        #: distance from the shoulder-hand axis (the swivel bound's reference)
        self._elbow_torso: FloatArray | None = None
        self._swivel_radius_mm = 0.0

    def _noise_scale(self) -> tuple[float, float]:
        c = self.config
        if not c.adaptive_noise:
            return c.constant_noise_rad, c.constant_noise_mm
        e = self.edge_error
        return max(c.noise_rad_per_error * e, c.min_noise_rad), max(
            c.noise_mm_per_error * e, c.min_noise_mm
        )

    def _perturb(self, p: FloatArray) -> None:
        c = self.config
        s_rad, s_mm = self._noise_scale()
        n = p.shape[0]
        p[:, :4] += self.rng.normal(0.0, s_rad, size=(n, 4))
        np.clip(p[:, 3], -math.pi, 0.0, out=p[:, 3])
        if c.adaptive_shoulder:
            if c.shoulder_pull > 0:  # weakly seen offsets drift: pull them home a little
                p[:, 4:] *= 1.0 - c.shoulder_pull
            p[:, 4:] += self.rng.normal(0.0, s_mm, size=(n, 3))
            box = SHOULDER_BOX_MM if c.shoulder_box_mm is None else c.shoulder_box_mm
            np.clip(p[:, 4:], -box, box, out=p[:, 4:])
        else:
            p[:, 4:] = 0.0

    def _weigh(self, p: FloatArray, model: ArmModel, views: ViewStack) -> None:
        arm_weights_nb(
            p, model, views, self.config.fusion, self.prev_dist_sq, self._w, self._eg, self._d2
        )

    def _fused_edge(self) -> float:
        """Weighted mean of the fused edge error (1 outside the minimum radius)."""
        t2 = self.config.fusion.t_d_mm**2
        eg = np.where(np.isfinite(self._d2) & (self._d2 >= t2), 1.0, self._eg)
        w = self._w
        s = w.sum()
        return float((eg * w).sum() / s) if s > 0 else 1.0

    def step(
        self, model: ArmModel, views: ViewStack, max_elbow_step_mm: float = math.inf
    ) -> ArmEstimate:
        """One frame: ``n_runs`` runs, the first with IK samples; returns the estimate.

        ``max_elbow_step_mm``: with the ``mode`` estimate, the farthest the elbow may move
        in this frame relative to its shoulder. The estimate's swivel (the elbow's angle
        about its shoulder-hand axis) turns at most that far along the elbow's circle
        from the last estimate's (`mocapkit.tracking.stereo.swivel`): where the cues
        favour the other side of the circle for a few frames, the elbow is drawn over at
        that speed and back, never in one jump, while the particles keep sampling the
        whole circle (the paper's IK sampling, which finds the right side again after a
        wrong one). A heaviest particle whose elbow lies beyond the step (the
        other side of the circle, or a move of the hand axis) is taken only when the next
        frame's heaviest lies there again; until then the estimate stays in the mode
        within reach."""
        c = self.config
        n = c.n_particles
        have_hand = bool(np.all(np.isfinite(model.hand_mm)))
        d_prev = self.estimate_offset()
        self.last_n_ik = 0
        for run in range(c.n_runs):
            idx = systematic_resample(self.weights, self.rng)
            p = self.particles[idx]
            self._perturb(p)
            if run == 0 and c.use_ik and have_hand:
                n_ik = round(c.ik_fraction * n)
                if n_ik > 0:
                    p[:n_ik] = self._ik_samples(model, d_prev, n_ik)
                    self.last_n_ik = n_ik
            self._weigh(p, model, views)
            self.particles = p
            self.weights = self._w.copy()
            self.edge_error = self._fused_edge()
        return self._estimate(model, views, max_elbow_step_mm)

    def estimate_offset(self) -> FloatArray:
        """Weighted mean shoulder offset of the current particles (mm, torso frame)."""
        w = self.weights / max(self.weights.sum(), 1e-300)
        return np.asarray(w @ self.particles[:, 4:], dtype=float)

    def _ik_samples(self, model: ArmModel, d_prev: FloatArray, n_ik: int) -> FloatArray:
        lo, hi = ALPHA_RANGE_RAD[self.side]  # the side's bounds (paper §VII, errata A9)
        alphas = self.rng.uniform(lo, hi, n_ik)
        rb = model.base_rotation
        s = model.shoulder_base_mm + rb @ d_prev
        a, b, o = model.lengths_mm
        # the measured point lies on the forearm's extension: solve for a forearm of b + o
        prob = make_problem(rb, s, model.hand_mm, float(a), float(b + o))
        q, _elbow = arm_ik(prob, alphas)
        out = np.empty((n_ik, N_STATE))
        out[:, :4] = q
        out[:, 4:] = d_prev
        return out

    def _mode_particle(self, w: FloatArray, elbow_rel: FloatArray, max_step_mm: float) -> int:
        """The particle whose mode is the estimate: the heaviest, unless its elbow lies
        beyond ``max_step_mm`` of the last estimate's and no held jump confirms it; then
        the heaviest within reach (`step`)."""
        best = int(np.argmax(w))
        held, self._held_jump = self._held_jump, None
        last = self._elbow_rel
        if last is None or not math.isfinite(max_step_mm):
            return best
        if float(np.linalg.norm(elbow_rel[best] - last)) <= max_step_mm:
            return best
        if held is not None and float(np.linalg.norm(elbow_rel[best] - held)) <= max_step_mm:
            return best  # the far mode won twice running: a real move
        within = np.linalg.norm(elbow_rel - last, axis=1) <= max_step_mm
        if not within.any():
            return best
        self._held_jump = elbow_rel[best].copy()
        return int(np.flatnonzero(within)[np.argmax(w[within])])

    def _estimate(
        self, model: ArmModel, views: ViewStack, max_elbow_step_mm: float = math.inf
    ) -> ArmEstimate:
        w = self.weights / max(self.weights.sum(), 1e-300)
        p = self.particles
        window = math.inf
        if self.config.estimate == "mode":
            # the weighted mean of the particles whose elbow lies near the best one's: the
            # elbow circle often leaves two modes, whose mean would be neither
            elbows = np.empty((p.shape[0], 3))
            _elbows_nb(p, model, elbows)
            elbow_rel = elbows - model.shoulder_base_mm
            best = self._mode_particle(w, elbow_rel, max_elbow_step_mm)
            if self._elbow_torso is not None:
                window = swivel_window_rad(max_elbow_step_mm, self._swivel_radius_mm)
            near = np.linalg.norm(elbows - elbows[best], axis=1) < self.config.mode_radius_mm
            w = np.where(near, w, 0.0)
            w /= w.sum()
        # chordal mean of the shoulder rotations: robust where rotation vectors wrap at pi
        m = np.empty((3, 3))
        _chordal_mean_rotvec_nb(np.ascontiguousarray(p[:, :3]), w, m)
        u, _s, vt = np.linalg.svd(m)
        r = u @ vt
        if np.linalg.det(r) < 0:
            u[:, -1] *= -1
            r = u @ vt
        state = np.empty(N_STATE)
        rv = np.empty(3)
        matrix_rotvec_nb(np.ascontiguousarray(r), rv)
        state[:3] = rv
        state[3] = float(w @ p[:, 3])
        state[4:] = w @ p[:, 4:]
        if math.isfinite(window):
            a, b, o = (float(v) for v in model.lengths_mm)
            bound_swivel_nb(state[None, :], a, b + o, np.asarray(self._elbow_torso), window)
        one = state[None, :].copy()
        wt, eg, d2 = np.empty(1), np.empty(1), np.empty(1)
        arm_weights_nb(one, model, views, self.config.fusion, self.prev_dist_sq, wt, eg, d2)
        if np.isfinite(d2[0]):
            self.prev_dist_sq = float(d2[0])  # errata A10: the raw error of the estimate
        pts = np.empty((4, 3))
        arm_points_nb(state, model, pts)
        self._elbow_rel = pts[1] - model.shoulder_base_mm
        rb_t = model.base_rotation.T
        self._elbow_torso = rb_t @ (pts[1] - pts[0])
        self._swivel_radius_mm = swivel_radius_mm(self._elbow_torso, rb_t @ (pts[3] - pts[0]))
        return ArmEstimate(
            state,
            pts,
            float(eg[0]),
            float(math.sqrt(d2[0])) if np.isfinite(d2[0]) else math.nan,
            self.last_n_ik,
        )


__all__ = [
    "N_STATE",
    "ArmEstimate",
    "ArmFilterConfig",
    "ArmModel",
    "ArmParticleFilter",
    "ViewStack",
    "arm_points_nb",
    "arm_weights_nb",
    "systematic_resample",
    "view_stack",
]
