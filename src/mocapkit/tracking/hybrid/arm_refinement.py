"""Video refinement of the arms: per-arm downhill simplex on the chamfer of projected limb outlines.

Zhang et al. 2011 §5: after IK, each arm's 4 DoFs (3 shoulder + elbow) are refined
separately (§5.2) by a downhill-simplex search (Nelder & Mead) from the IK pose,
minimising eq. 14, ``C = chamfer + lambda * ||t - s||``, over the edge distance map of
the arm's region of interest (:mod:`mocapkit.cues.edges`). This module holds the arm
problem only; its pieces are shared with the other trackers:

- the arm's kinematics: `mocapkit.skeleton.kinematics.fk_pose_nb` on the arm's chain
  (shoulder, elbow, wrist) below the fixed world transform of the shoulder's parent;
  limbs are found by canonical names (`mocapkit.skeleton.limbs.arm`), so ``zhang21``'s
  revolute shoulders and ``azad14``'s ball shoulders both work;
- the limb outlines: the cones' exact contour generators (`mocapkit.geometry.cones`);
- projection and the near-plane rule (`mocapkit.camera.projection`);
- the image term (`mocapkit.cues.chamfer`);
- the search: `mocapkit.ik.nelder_mead` (SciPy's iterates, compiled) and the swivel
  (`mocapkit.ik.swivel`);
- the compiled cost of eq. 14 on named structures (`mocapkit.tracking.hybrid.arm_cost`, with
  the notes on its outline chamfer, errata Z11).

Optimiser. The cost is compiled with Numba; `nelder_mead_arm_nb` runs the generic
compiled Nelder-Mead on it with the cost as a global, so that Numba caches it on disk
(`mocapkit.ik.nelder_mead`). SciPy's pure-Python loop would cost about ten times the
cost itself and break the hybrid tracker's frame budget (>= 120 fps with both arms).
``solver="scipy"`` runs SciPy itself on the same compiled cost. Recipe Z step 4:
explicit initial simplex of +-``simplex_step_rad`` (0.1 rad) per DoF (SciPy's default
5 % steps are far too small for angles), ``xatol=1e-3``, ``maxfev`` about 300,
joint-limit bounds.

Swivel seeding (a deviation, on by default). The outline chamfer's basin along the
IK ambiguity, the swivel of the arm about the shoulder-wrist axis, is only about
half a limb width wide (about +-15 deg in the tests' scene): beyond it the other
side line of the cone locks onto the wrong image edge, and no local search from the
IK pose recovers. Before the simplex, the cost is therefore evaluated at
``swivel_scan_steps`` swivel angles over +-``swivel_scan_rad`` with the hand held
exactly on its marker (Azad's 1-D swivel, recipe Z "better, hold the hand exactly");
the simplex starts from the best. ``swivel_scan_rad=0`` runs the paper's plain search.
The default scans the whole circle in 5 deg steps: on sessions rendered from CMU clips
the IK swivel is often 90 deg or more off (an elbow raised sideways while the relaxed
pose hangs it down), and a +-40 deg scan left those arms where IK put them. The region
of interest covers the elbow's scanned arc (`arm_roi`).

Elbow-jump penalty (a deviation, on by default, off in the paper mode). One view's
outlines leave some swivels ambiguous: an arm pointing at the camera is a short blob
whose outline also fits the torso's inner edges, and a folded arm's elbow towards or
away from the camera projects alike. The per-frame search then jumps between such
minima from one frame to the next, 200-500 mm at a time. The cost therefore adds
``elbow_jump_weight_per_mm`` times how far the elbow lies beyond
``elbow_speed_mm_per_s * dt`` from the previous frame's elbow (a hinge: free within a
plausible speed, so it does not hold on to an old swivel the way a quadratic prior on
the angles did). 3 m/s covers the clips' true elbow speeds (99th percentiles
0.5-3.7 m/s); sports with faster arms (a serve, a throw) need a higher speed or the
weight 0. Measured in ``docs/design-notes/hybrid.md``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.cues.chamfer import ChamferMaps
from mocapkit.cues.edges import (
    DistanceMap,
    EdgeConfig,
    PreparedFrame,
    Roi,
    prepare_frame,
    roi_around_points,
    roi_distance_map,
)
from mocapkit.errors import ConfigError, ShapeError, unknown_name
from mocapkit.ik.nelder_mead import clip_nb, initial_simplex, nelder_mead_core
from mocapkit.ik.swivel import swivel_arm
from mocapkit.skeleton.chains import limb_chain
from mocapkit.skeleton.kinematics import forward_kinematics
from mocapkit.skeleton.limbs import SIDES
from mocapkit.skeleton.model import Skeleton
from mocapkit.tracking.hybrid.arm_cost import (
    ArmModel,
    ArmShape,
    ArmTerms,
    arm_cost_many_nb,
    arm_cost_nb,
    arm_cost_terms_nb,
    arm_dofs,
    arm_fk_nb,
    arm_limb,
    arm_outline_px_nb,
    arm_shape,
    swivel_x_nb,
)

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Keys accepted in ``hand_targets_mm``: the side, or the hybrid tracker's marker-set name.
_SIDE_OF_KEY = {"left": "left", "right": "right", "left_hand": "left", "right_hand": "right"}


@dataclass(frozen=True)
class RefineConfig:
    """Parameters of the per-arm video refinement (Zhang §5, recipe Z steps 3-4).

    Parameters
    ----------
    edges : EdgeConfig
        Edge distance transform (cap, Canny thresholds, equalisation). By default an
        oriented chamfer with 8 orientation bins (an extension of the paper's plain
        chamfer, which ``EdgeConfig()`` gives and ``paper=True`` uses): on the five
        accuracy clips with marker positions only and no elbow-jump penalty, the mean
        elbow error with video is 97 mm against 136 mm with the plain chamfer (144 mm IK
        only; docs/design-notes/hybrid.md).
        8 bins was chosen on an earlier version of the tracker, where 4 bins gave
        116 mm and 8 or 12 bins 100 mm.
    hand_weight_px_per_mm : float
        ``lambda`` of eq. 14: cost (px of mean chamfer) per mm of hand displacement.
    sample_step_px : float
        Spacing of outline samples along each projected contour generator.
    include_hand : bool
        Also score the hand cone's outline (its pose follows the forearm).
    literal_sum : bool
        Use the paper's literal eq. 13 (sum over the filled silhouette) instead of the
        normalised outline chamfer (errata Z11). Needs a much larger ``lambda``.
    simplex_step_rad : float
        Size of the explicit initial simplex around the IK pose.
    xatol, fatol : float
        Stopping tolerances (rad, cost units), as SciPy's Nelder-Mead.
    maxfev : int
        Evaluation budget per arm.
    roi_pad_px : float
        Padding of the bounding box of the projected shoulder, elbow, wrist and hand end.
    effector_points_mm : ((3,), (3,)) floats
        Left and right hand effector in the hand joint's frame (the point IK puts on the
        hand target, `mocapkit.ik.sdls.Effector.point_mm`; the origin is the wrist).
    solver : {"numba", "scipy"}
        `nelder_mead_arm_nb` or `scipy.optimize.minimize(method="Nelder-Mead")`.
    swivel_scan_rad : float
        Half-range of the 1-D swivel scan that seeds the simplex (0 disables it and
        runs the paper's plain search from the IK pose).
    swivel_scan_steps : int
        Number of swivel angles scanned (including 0 when odd).
    elbow_jump_weight_per_mm : float
        Cost per mm that the elbow lies beyond the free distance from the previous
        frame's elbow (the module's "elbow-jump penalty"); 0 turns it off. Applies only
        where `refine_arms` is given ``previous_elbows_mm``.
    elbow_speed_mm_per_s : float
        Elbow speed that costs nothing: the free distance is this times the time since
        the previous frame.
    """

    edges: EdgeConfig = field(default_factory=lambda: EdgeConfig(orientation_bins=8))
    hand_weight_px_per_mm: float = 2.0
    sample_step_px: float = 3.0
    include_hand: bool = True
    literal_sum: bool = False
    simplex_step_rad: float = 0.1
    xatol: float = 1e-3
    fatol: float = 1e-4
    maxfev: int = 300
    roi_pad_px: float = 40.0
    effector_points_mm: tuple[tuple[float, float, float], tuple[float, float, float]] = (
        (0.0, 0.0, 0.0),
        (0.0, 0.0, 0.0),
    )
    solver: Literal["numba", "scipy"] = "numba"
    swivel_scan_rad: float = math.pi
    swivel_scan_steps: int = 73
    elbow_jump_weight_per_mm: float = 0.1
    elbow_speed_mm_per_s: float = 3000.0

    def __post_init__(self) -> None:
        checks = {
            "hand_weight_px_per_mm": self.hand_weight_px_per_mm >= 0,
            "sample_step_px": self.sample_step_px > 0,
            "simplex_step_rad": self.simplex_step_rad > 0,
            "xatol": self.xatol >= 0,
            "fatol": self.fatol >= 0,
            "maxfev": self.maxfev >= 5,
            "roi_pad_px": self.roi_pad_px >= 0,
            "swivel_scan_rad": 0 <= self.swivel_scan_rad <= math.pi,
            "swivel_scan_steps": self.swivel_scan_steps >= 1,
            "elbow_jump_weight_per_mm": self.elbow_jump_weight_per_mm >= 0,
            "elbow_speed_mm_per_s": self.elbow_speed_mm_per_s >= 0,
        }
        for name, ok in checks.items():
            if not ok:
                raise ConfigError(
                    f"RefineConfig.{name}: expected a positive value (maxfev >= 5), found "
                    f"{getattr(self, name)!r}"
                )
        pts = np.asarray(self.effector_points_mm, dtype=float)
        if pts.shape != (2, 3) or not np.all(np.isfinite(pts)):
            raise ConfigError(
                "RefineConfig.effector_points_mm: expected ((x, y, z), (x, y, z)) for the left "
                f"and right hands, found {self.effector_points_mm!r}"
            )
        if self.solver not in ("numba", "scipy"):
            raise ConfigError(
                f"RefineConfig.solver: expected 'numba' or 'scipy', found {self.solver!r}"
            )


@dataclass
class ArmDiagnostics:
    """What one arm's refinement did (filled by `refine_arms` when asked).

    Attributes
    ----------
    side : str
    refined : bool
        False when the arm was skipped (no hand target, empty RoI).
    cost_before, cost_after : float
        Eq. 14 at the IK pose and at the result.
    chamfer_before, chamfer_after : float
        Image term alone (px, or the literal sum).
    hand_offset_before_mm, hand_offset_after_mm : float
        ``||t - s||`` at the IK pose and at the result.
    n_evaluations, n_iterations : int
    converged : bool
        Stopped on the tolerances rather than on ``maxfev``.
    roi : (x0, y0, x1, y1)
    elapsed_ms : float
        Wall time of the distance map plus the search for this arm.
    reason : str
        Why the arm was skipped, empty otherwise.
    """

    side: str
    refined: bool = False
    cost_before: float = math.nan
    cost_after: float = math.nan
    chamfer_before: float = math.nan
    chamfer_after: float = math.nan
    hand_offset_before_mm: float = math.nan
    hand_offset_after_mm: float = math.nan
    n_evaluations: int = 0
    n_iterations: int = 0
    converged: bool = False
    roi: Roi = (0, 0, 0, 0)
    elapsed_ms: float = 0.0
    reason: str = ""


@numba.njit(cache=True)
def swivel_scan_nb(
    x0: FloatArray,
    model: ArmModel,
    maps: ChamferMaps,
    half_range: float,
    steps: int,
    lb: FloatArray,
    ub: FloatArray,
) -> tuple[FloatArray, float, int]:
    """Best of ``x0`` and ``steps`` swivels evenly spread over ``[-half_range, half_range]``.

    Candidates are clipped to the joint limits. Returns ``(x, cost, evaluations)``.
    """
    best = x0.copy()
    fbest = arm_cost_nb(x0, model, maps)
    nfev = 1
    cand = np.empty(4)
    for m in range(steps):
        alpha = -half_range + 2.0 * half_range * m / (steps - 1) if steps > 1 else 0.0
        if alpha == 0.0:
            continue
        if not swivel_x_nb(x0, alpha, model, cand):
            break
        clip_nb(cand, lb, ub)
        f = arm_cost_nb(cand, model, maps)
        nfev += 1
        if f < fbest:
            fbest = f
            best[:] = cand
    return best, fbest, nfev


@numba.njit(cache=True)
def nelder_mead_arm_nb(
    model: ArmModel,
    maps: ChamferMaps,
    initial_simplex: FloatArray,
    lb: FloatArray,
    ub: FloatArray,
    xatol: float,
    fatol: float,
    maxfev: int,
) -> tuple[FloatArray, float, int, int, bool]:
    """`mocapkit.ik.nelder_mead.nelder_mead_nb` on `arm_cost_nb` of one arm, cached on disk.

    ``initial_simplex`` (5, 4), ``lb``, ``ub`` (4,) in rad; returns ``x, fx, nfev, nit,
    converged``.
    """
    return nelder_mead_core(arm_cost_nb, model, maps, initial_simplex, lb, ub, xatol, fatol, maxfev)


# ------------------------------------------------------------------ Python side


@dataclass(frozen=True, eq=False)
class ArmProblem:
    """One arm's refinement problem: the kernels' model and its distance maps.

    Build with `arm_problem`. ``x`` vectors are the arm's 4 joint parameters
    (3 shoulder DoFs in product order, then the elbow), radians.

    Attributes
    ----------
    side : str
    dofs : ndarray of int, shape (4,)
        Indices of the arm's DoFs in the skeleton's ``q``.
    model : ArmModel
        Arm, camera and cost terms for the compiled kernels.
    distance : DistanceMap
    lower, upper : ndarray, shape (4,)
        Joint limits.
    x0 : ndarray, shape (4,)
        Start (the IK pose), clipped into the limits.
    maps : ChamferMaps
        The distance maps the cost reads: the oriented ones when the frame has them
        (and the cost is not the literal sum), else the plain map as one bin.
    """

    side: str
    dofs: IntArray
    model: ArmModel
    distance: DistanceMap
    lower: FloatArray
    upper: FloatArray
    x0: FloatArray
    maps: ChamferMaps

    def cost(self, x: ArrayLike) -> float:
        """Eq. 14 at arm parameters ``x`` (4,)."""
        return float(arm_cost_nb(self._x(x), self.model, self.maps))

    def cost_terms(self, x: ArrayLike) -> tuple[float, float]:
        """``(image term, hand offset mm)`` at ``x`` (4,)."""
        image, hand = arm_cost_terms_nb(self._x(x), self.model, self.maps)
        return float(image), float(hand)

    def joints_mm(self, x: ArrayLike) -> FloatArray:
        """World shoulder, elbow, wrist and hand effector (4, 3) at ``x``."""
        out = np.empty((4, 3))
        arm_fk_nb(self._x(x), self.model, out)
        return out

    def outline_px(self, x: ArrayLike, max_points: int = 4096) -> FloatArray:
        """The outline sample points (M, 2) px the chamfer reads at ``x``."""
        out = np.empty((max_points, 2))
        m = arm_outline_px_nb(self._x(x), self.model, out)
        return out[:m]

    @staticmethod
    def _x(x: ArrayLike) -> FloatArray:
        xa = np.ascontiguousarray(x, dtype=np.float64)
        if xa.shape != (4,):
            raise ShapeError(f"arm parameters: expected shape (4,), found {xa.shape}")
        return xa


def arm_model(
    skeleton: Skeleton,
    camera: Camera,
    q: ArrayLike,
    side: str,
    hand_target_mm: ArrayLike | None,
    config: RefineConfig,
    world: FloatArray | None = None,
    previous_elbow_mm: ArrayLike | None = None,
    elbow_free_mm: float = 0.0,
) -> ArmModel:
    """The `ArmModel` of one arm: its chain at ``q``, its shape, the camera, the cost terms.

    ``hand_target_mm`` None drops the hand term; ``previous_elbow_mm`` (world mm) turns on
    the elbow-jump penalty where it is finite and ``config.elbow_jump_weight_per_mm > 0``.
    """
    limb = arm_limb(skeleton, side)
    chain = limb_chain(skeleton, q, limb.joints, limb.dofs, world)
    shape = arm_shape(
        skeleton, side, config.effector_points_mm[SIDES.index(side)], config.include_hand
    )
    target = np.zeros(3)
    if hand_target_mm is not None:
        target = np.array(hand_target_mm, dtype=float)
        if target.shape != (3,) or not np.all(np.isfinite(target)):
            raise ShapeError(
                f"hand_targets_mm[{side!r}]: expected 3 finite numbers (mm), found "
                f"shape {target.shape} {target.tolist()}"
            )
    prev, weight, free = np.zeros(3), 0.0, 0.0
    if previous_elbow_mm is not None and config.elbow_jump_weight_per_mm > 0:
        p = np.asarray(previous_elbow_mm, dtype=float)
        if p.shape == (3,) and np.all(np.isfinite(p)):
            prev, weight, free = p.copy(), config.elbow_jump_weight_per_mm, float(elbow_free_mm)
    terms = ArmTerms(
        hand_target_mm=target,
        use_target=hand_target_mm is not None,
        hand_weight_px_per_mm=float(config.hand_weight_px_per_mm),
        sample_step_px=float(config.sample_step_px),
        literal_sum=bool(config.literal_sum),
        previous_elbow_mm=prev,
        elbow_jump_weight_per_mm=float(weight),
        elbow_free_mm=free,
    )
    return ArmModel(chain, shape, camera.arrays, terms)


def arm_roi(
    skeleton: Skeleton,
    camera: Camera,
    world: FloatArray,
    side: str,
    pad_px: float,
    swivel_rad: float = 0.0,
) -> Roi:
    """Bounding box of the projected shoulder, elbow, wrist and hand end, padded (§5.2, Fig. 5).

    With a swivel scan of half-range ``swivel_rad`` the box also covers the elbow
    positions the scan visits: the arc of the circle the elbow describes about the
    shoulder-wrist axis (sampled every 15 deg), so no scanned pose falls outside it.
    """
    limb = arm_limb(skeleton, side)
    points = world[list(limb.joints), :3, 3]
    if limb.tip >= 0:
        hand_end = world[limb.tip, :3, 3]
    else:  # no end site: the hand's bone end
        hand_end = world[limb.end, :3, :3] @ skeleton.bone_end_mm[limb.end] + world[limb.end, :3, 3]
    points = np.vstack([points, hand_end])
    if swivel_rad > 0:
        shoulder, elbow, wrist = points[0], points[1], points[2]
        axis = wrist - shoulder
        n = float(np.linalg.norm(axis))
        if n > 1e-9:
            axis /= n
            foot = shoulder + float((elbow - shoulder) @ axis) * axis
            u = elbow - foot
            v = np.cross(axis, u)
            angles = np.linspace(-swivel_rad, swivel_rad, max(3, int(swivel_rad / 0.26) * 2 + 1))
            arc = foot + np.cos(angles)[:, None] * u + np.sin(angles)[:, None] * v
            points = np.vstack([points, arc])
    return roi_around_points(camera.project(points), camera.image_size, pad_px)


def arm_problem(
    skeleton: Skeleton,
    camera: Camera,
    q: ArrayLike,
    side: str,
    frame: PreparedFrame | ArrayLike,
    hand_target_mm: ArrayLike | None,
    config: RefineConfig | None = None,
    world: FloatArray | None = None,
    previous_elbow_mm: ArrayLike | None = None,
    elbow_free_mm: float = 0.0,
) -> ArmProblem:
    """Build one arm's problem: RoI from the pose, its distance map, the kernels' model.

    Parameters
    ----------
    skeleton, camera : Skeleton, Camera
    q : array_like, shape (D,)
    side : {"left", "right"}
    frame : PreparedFrame or image array (H, W[, 3]) uint8
    hand_target_mm : array_like (3,) or None
    config : RefineConfig, optional
    world : ndarray (J, 4, 4), optional
        FK of ``q`` if already computed.
    previous_elbow_mm : array_like (3,), optional
        The previous frame's elbow (world mm) for the elbow-jump penalty; ignored when
        None, not finite, or ``config.elbow_jump_weight_per_mm`` is 0.
    elbow_free_mm : float
        Elbow displacement from ``previous_elbow_mm`` that costs nothing (mm).
    """
    cfg = config or RefineConfig()
    qa = np.asarray(q, dtype=float)
    skeleton.check_q(qa)
    if qa.ndim != 1:
        raise ShapeError(f"q: expected one pose of shape ({skeleton.n_dofs},), found {qa.shape}")
    if not isinstance(frame, PreparedFrame):
        frame = prepare_frame(frame, cfg.edges)
    if frame.image_size != camera.image_size:
        raise ShapeError(
            f"image: expected size {camera.image_size} (w, h) of camera {camera.name!r}, found "
            f"{frame.image_size}"
        )
    if world is None:
        world = forward_kinematics(skeleton, qa)
    roi = arm_roi(skeleton, camera, world, side, cfg.roi_pad_px, cfg.swivel_scan_rad)
    dmap = roi_distance_map(frame, roi, cfg.edges)
    model = arm_model(
        skeleton,
        camera,
        qa,
        side,
        hand_target_mm,
        cfg,
        world=world,
        previous_elbow_mm=previous_elbow_mm,
        elbow_free_mm=elbow_free_mm,
    )
    dofs = arm_dofs(skeleton, side)
    lower = np.ascontiguousarray(skeleton.lower[dofs], dtype=float)
    upper = np.ascontiguousarray(skeleton.upper[dofs], dtype=float)
    x0 = np.clip(qa[dofs], lower, upper)
    maps = dmap.chamfer_maps(oriented=not cfg.literal_sum)
    return ArmProblem(side, dofs, model, dmap, lower, upper, x0, maps)


def solve_arm(problem: ArmProblem, config: RefineConfig) -> tuple[FloatArray, ArmDiagnostics]:
    """Run the downhill simplex on one arm problem; returns the best ``x`` (4,) and diagnostics."""
    diag = ArmDiagnostics(side=problem.side, roi=problem.distance.roi)
    dmap = problem.maps
    x0 = problem.x0
    diag.cost_before = problem.cost(x0)
    diag.chamfer_before, diag.hand_offset_before_mm = problem.cost_terms(x0)
    start, n_scan = x0, 0
    if config.swivel_scan_rad > 0 and config.swivel_scan_steps > 1:
        start, _f, n_scan = swivel_scan_nb(
            x0,
            problem.model,
            dmap,
            config.swivel_scan_rad,
            config.swivel_scan_steps,
            problem.lower,
            problem.upper,
        )
    sim = initial_simplex(start, config.simplex_step_rad)
    if config.solver == "scipy":
        from scipy.optimize import Bounds, minimize

        model = problem.model
        res = minimize(
            lambda x: arm_cost_nb(x, model, dmap),
            start,
            method="Nelder-Mead",
            bounds=Bounds(problem.lower, problem.upper),
            options={
                "initial_simplex": sim,
                "xatol": config.xatol,
                "fatol": config.fatol,
                "maxfev": config.maxfev,
            },
        )
        x = np.asarray(res.x, dtype=float)
        nfev, nit, conv = int(res.nfev), int(res.nit), bool(res.status == 0)
    else:
        x, _fx, nfev, nit, conv = nelder_mead_arm_nb(
            problem.model,
            dmap,
            sim,
            problem.lower,
            problem.upper,
            config.xatol,
            config.fatol,
            config.maxfev,
        )
    diag.refined = True
    diag.cost_after = problem.cost(x)
    diag.chamfer_after, diag.hand_offset_after_mm = problem.cost_terms(x)
    diag.n_evaluations, diag.n_iterations, diag.converged = nfev + n_scan, nit, conv
    return x, diag


def refine_arms(
    skeleton: Skeleton,
    camera: Camera,
    q: ArrayLike,
    image: ArrayLike | PreparedFrame,
    hand_targets_mm: Mapping[str, ArrayLike | None],
    config: RefineConfig | None = None,
    *,
    diagnostics: dict[str, ArmDiagnostics] | None = None,
    previous_elbows_mm: Mapping[str, ArrayLike] | None = None,
    elapsed_s: float = 0.0,
) -> FloatArray:
    """Refine both arms of an IK pose against one video frame (Zhang et al. §5).

    Each arm present in ``hand_targets_mm`` is refined on its own (§5.2): RoI around its
    projected joints, truncated edge distance map inside it, downhill simplex over its
    4 DoFs from the IK pose. The rest of ``q`` is returned unchanged.

    Parameters
    ----------
    skeleton : Skeleton
        Any model whose arms `arm_limb` accepts (``zhang21``, ``azad14``).
    camera : Camera
        Calibrated camera of the frame.
    q : array_like, shape (D,)
        Joint parameters after IK (rad, mm).
    image : array_like of uint8, shape (H, W) or (H, W, 3), or PreparedFrame
        Grey or BGR video frame nearest the marker sample.
    hand_targets_mm : mapping {"left"|"right": array (3,) or None}
        Hand effector targets (world mm). A side that is absent or None is not refined.
        The marker-set names ``"left_hand"``/``"right_hand"`` are accepted as well.
    config : RefineConfig, optional
    diagnostics : dict, optional
        When given, receives one `ArmDiagnostics` per side.
    previous_elbows_mm : mapping {"left"|"right": array (3,)}, optional
        Each side's elbow in the previous frame (world mm), for the elbow-jump penalty
        (`RefineConfig.elbow_jump_weight_per_mm`); a side that is absent has none.
    elapsed_s : float
        Time since that frame (s); the free distance is
        ``config.elbow_speed_mm_per_s * elapsed_s``.

    Returns
    -------
    ndarray, shape (D,)
        The refined pose.
    """
    cfg = config or RefineConfig()
    qa = np.array(q, dtype=float)
    skeleton.check_q(qa)
    if qa.ndim != 1:
        raise ShapeError(f"q: expected one pose of shape ({skeleton.n_dofs},), found {qa.shape}")
    by_side: dict[str, ArrayLike | None] = {}
    for key, value in hand_targets_mm.items():
        if key not in _SIDE_OF_KEY:
            raise unknown_name("arm side", key, _SIDE_OF_KEY, "hand_targets_mm")
        by_side[_SIDE_OF_KEY[key]] = value
    frame = image if isinstance(image, PreparedFrame) else prepare_frame(image, cfg.edges)
    world = forward_kinematics(skeleton, qa)
    out = qa.copy()
    for side in SIDES:
        t0 = time.perf_counter()
        target = by_side.get(side)
        if target is None:
            if diagnostics is not None:
                diagnostics[side] = ArmDiagnostics(side=side, reason="no hand target")
            continue
        prev = None if previous_elbows_mm is None else previous_elbows_mm.get(side)
        problem = arm_problem(
            skeleton,
            camera,
            qa,
            side,
            frame,
            target,
            cfg,
            world=world,
            previous_elbow_mm=prev,
            elbow_free_mm=cfg.elbow_speed_mm_per_s * elapsed_s,
        )
        if problem.distance.distance_px.size == 0:
            if diagnostics is not None:
                diagnostics[side] = ArmDiagnostics(
                    side=side, roi=problem.distance.roi, reason="arm RoI outside the image"
                )
            continue
        x, diag = solve_arm(problem, cfg)
        out[problem.dofs] = x
        diag.elapsed_ms = (time.perf_counter() - t0) * 1e3
        if diagnostics is not None:
            diagnostics[side] = diag
    return out


__all__ = [
    "SIDES",
    "ArmDiagnostics",
    "ArmModel",
    "ArmProblem",
    "ArmShape",
    "ArmTerms",
    "RefineConfig",
    "arm_cost_many_nb",
    "arm_cost_nb",
    "arm_cost_terms_nb",
    "arm_dofs",
    "arm_fk_nb",
    "arm_limb",
    "arm_model",
    "arm_outline_px_nb",
    "arm_problem",
    "arm_roi",
    "arm_shape",
    "initial_simplex",
    "nelder_mead_arm_nb",
    "refine_arms",
    "solve_arm",
    "swivel_arm",
    "swivel_scan_nb",
    "swivel_x_nb",
]
