"""Streaming hybrid tracker: head and hand marker sets plus one camera (Zhang et al. 2011).

Per sample (Fig. 3): marker targets -> IK (:mod:`mocapkit.ik.sdls`) -> optional video
refinement of each arm (``refiner`` hook) -> balance heuristic
(:mod:`mocapkit.tracking.hybrid.balance`) -> optional temporal smoothing -> pose.

Streams (§3): markers and video run at different rates; the caller samples them as
the paper does, giving each `HybridSample` the video frame and the newest marker
sample with its own time stamp (``marker_time_s``).

Occlusions: a marker set missing (NaN) for up to ``gap_limit_s`` is bridged by
constant-velocity extrapolation from its last two observations; beyond that its
effector is released (dropped from the IK task) and the gap is reported in
``HybridPose.released`` and `HybridTracker.events`, never pinned to a stale position.

Smoothing (the paper's own remedy for the oscillation it reports, §6-7): a causal
one-euro filter on ``q`` (Casiez et al. 2012) followed by an IK polish that puts the
effectors back on their markers; off when ``paper=True`` (which also selects the
paper's proportional balance rule).
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.cues.edges import EdgeConfig, prepare_frame
from mocapkit.errors import ConfigError, ShapeError, unknown_name
from mocapkit.geometry.transforms import points_in_frame
from mocapkit.ik.config import IKConfig, IKResult
from mocapkit.ik.effectors import Effector
from mocapkit.ik.sdls import SDLSSolver
from mocapkit.skeleton.kinematics import canonical_positions, forward_kinematics
from mocapkit.skeleton.limbs import (
    SIDES,
    arm,
    head_joint,
    leg,
    limbs_present,
    part_dofs,
    thorax_joint,
    vertical_root_dof,
)
from mocapkit.skeleton.model import CANONICAL_JOINTS, PRISMATIC, Skeleton
from mocapkit.timing import NULL_TIMER, StageTimer
from mocapkit.tracking.base import (
    BRIDGE_S,
    INPUT_SPEED_FACTOR,
    REJOIN_BLEND_S,
    UNSEEN_SPEED_MM_S,
    FrameResult,
    canonical_joints_mm,
    fit_summary,
    nan_unobserved,
)
from mocapkit.tracking.hybrid.arm_refinement import ArmDiagnostics, RefineConfig, refine_arms
from mocapkit.tracking.hybrid.balance import (
    BalanceConfig,
    BalanceModel,
    balance_pose,
    calibrate_balance,
    restore_ik_config,
    support_points,
)
from mocapkit.tracking.hybrid.posture import SEATED_LEFT_OUT, Crouch, standing_relaxed_pose
from mocapkit.tracking.hybrid.reseed import arm_seeds, nearest_fit

FloatArray = NDArray[np.float64]

#: Marker-set names the hybrid tracker drives, and their default effectors on ``zhang21``.
MARKER_SETS: tuple[str, ...] = ("head", "left_hand", "right_hand")
FEET: tuple[str, ...] = ("left_foot", "right_foot")
#: Optional marker sets of a full-body file: on the pelvis (the canonical ``pelvis``
#: point) and on each foot (its ankle); a foot set takes the place of that foot's plant.
LEG_SETS: tuple[str, ...] = ("pelvis", *FEET)
#: Optional marker sets that ride on one trunk segment (`segment_set_effector`): the
#: pelvis, and the thorax (the chest's joint, `mocapkit.skeleton.limbs.thorax_joint`),
#: which holds the trunk's twist that head and hands leave free.
SEGMENT_SETS: tuple[str, ...] = ("pelvis", "thorax")
#: Every optional marker set, in the order the tracker takes them.
OPTIONAL_SETS: tuple[str, ...] = (*LEG_SETS, "thorax")

Refiner = Callable[..., FloatArray]


def _takes_previous_elbows(refiner: Refiner) -> bool:
    """Whether ``refiner`` accepts ``previous_elbows_mm`` and ``elapsed_s`` (as `refine_arms`)."""
    try:
        params = inspect.signature(refiner).parameters.values()
    except (TypeError, ValueError):  # builtins and some compiled callables have none
        return False
    names = {p.name for p in params}
    var_kw = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params)
    return var_kw or {"previous_elbows_mm", "elapsed_s"} <= names


def default_marker_effectors(skeleton: Skeleton) -> dict[str, Effector]:
    """Head centre (canonical ``head`` point) and both wrists, with zero marker offsets.

    Joints are found through the canonical names (`mocapkit.skeleton.limbs`).
    """
    hp = tuple(float(x) for x in skeleton.canonical["head"][1])
    names = skeleton.joint_names
    return {
        "head": Effector("head", names[head_joint(skeleton)], (hp[0], hp[1], hp[2])),
        "left_hand": Effector("left_hand", names[arm(skeleton, "left").end]),
        "right_hand": Effector("right_hand", names[arm(skeleton, "right").end]),
    }


def marker_set_effectors(skeleton: Skeleton) -> dict[str, Effector]:
    """`default_marker_effectors` and those of the `OPTIONAL_SETS`: the segment sets'
    (`segment_set_effector`) and the ankles, with zero marker offsets (the sets' members,
    calibrated, carry where the markers sit)."""
    effs = default_marker_effectors(skeleton)
    effs.update({n: segment_set_effector(skeleton, n) for n in SEGMENT_SETS})
    effs.update({e.name: e for e in foot_effectors(skeleton)})
    return effs


def segment_set_effector(skeleton: Skeleton, name: str) -> Effector:
    """The effector of a segment set (`SEGMENT_SETS`): ``pelvis`` at the canonical pelvis
    point, ``thorax`` at the chest joint's origin (`thorax_joint`)."""
    if name == "pelvis":
        pj, pp = skeleton.canonical["pelvis"]
        return Effector(name, pj, (float(pp[0]), float(pp[1]), float(pp[2])))
    if name == "thorax":
        return Effector(name, skeleton.joint_names[thorax_joint(skeleton)])
    raise unknown_name("segment marker set", name, SEGMENT_SETS)


def foot_effectors(skeleton: Skeleton) -> list[Effector]:
    """The planted-foot effectors ``left_foot``, ``right_foot`` on the canonical ankles."""
    names = skeleton.joint_names
    return [Effector(f"{side}_foot", names[leg(skeleton, side).end]) for side in ("left", "right")]


#: The tracker's IK settings: each iteration does the work of three of the paper's
#: (`IKConfig.term_clamp_scale`, `IKConfig.relax_substeps`), 30 iterations a solve instead
#: of 100 (see `HybridConfig.ik`), and LAPACK's dgesvd without U where no DoF is locked at
#: a joint limit (``IKConfig.svd="gesvd"``). A single run had moved one accuracy clip's
#: default-configuration elbow 43 -> 55 mm (round-off chaos); averaged over four jittered
#: repeats (`mocapkit accuracy hybrid --jitter-repeats 4`) every figure of the three
#: configurations is within 0.3 mm of dgesdd's or better (docs/design-notes/hybrid.md,
#: Speed).
TRACKING_IK = IKConfig(max_iterations=30, term_clamp_scale=3.0, relax_substeps=3, svd="gesvd")
#: Bisection steps of the share of a re-plant's relaxation taken in a frame
#: (`HybridTracker._bound_relaxation`): within 1/64 of the bound.
_RELAX_BISECTION_STEPS = 6
#: Bisection steps of the balance lean (`BalanceConfig.bisection_steps`) in ``"solve"`` mode.
TRACKING_BISECTION_STEPS = 6
#: The tracker's balance step (without paper mode): the lean bisected in
#: `TRACKING_BISECTION_STEPS` where one is needed, and no restore solve where none is
#: applied (the CoG inside the margin, or head and hands 2 x tol to
#: `BalanceConfig.restore_above_mm` off their markers; the smoothing polish solves next
#: anyway): 2.4 ms a frame against 6.0 (bench, same load). The bisection is guided
#: (`BalanceConfig.guided_bisection`: the plain bisection's leans, or one already at the
#: goal, from fewer restore solves). The restore solves stop where they stall and end on
#: their best iterate (`BalanceConfig.restore_stall_iterations`): 10-15 iterations instead
#: of the cap's 30, whose last step lands anywhere in the chatter.
TRACKING_BALANCE = BalanceConfig(
    mode="solve",
    bisection_steps=TRACKING_BISECTION_STEPS,
    restore_without_lean=False,
    guided_bisection=True,
    restore_stall_iterations=3,
    restores_per_frame=2,
)


class _CountedSolver(SDLSSolver):
    """`SDLSSolver` that counts its solves and iterations on a `StageTimer`
    (``"ik_solves"``, ``"ik_iterations"``), wherever it is called from (balance too)."""

    timer: StageTimer = NULL_TIMER

    def solve(
        self,
        q0: ArrayLike,
        targets_mm: ArrayLike,
        active: ArrayLike | None = None,
        frozen: ArrayLike | None = None,
        record_trace: bool = False,
    ) -> IKResult:
        """`SDLSSolver.solve`, counted."""
        res = super().solve(q0, targets_mm, active, frozen, record_trace)
        self.timer.count("ik_solves", 1)
        self.timer.count("ik_iterations", res.iterations)
        return res


@dataclass(frozen=True)
class HybridConfig:
    """Settings of the hybrid tracker.

    Parameters
    ----------
    ik : IKConfig
        Default `TRACKING_IK` (also with ``paper=True``; ``IKConfig()`` is the paper's
        iteration). Marker noise keeps the largest error above ``tol_mm`` (with member
        markers it settles near 5 mm after 3-5 iterations), so each solve runs to
        ``max_iterations``, and the later iterations matter: they cross the flat valley
        of the least-squares problem along terms of small singular value, which SDLS
        bounds to a few milliradians per iteration (the same with the secondary task
        off; `IKConfig.term_clamp_scale`). Measured on one accuracy clip (oriented
        sets, IK only, the paper's iteration): stopping when the error stalls (4
        iterations, 1 %) gave elbow 38.1 mm and MPJPE 43.8 mm against 20.4 and 33.1; at
        least 50 iterations, 21.4 and 35.3 mm. `TRACKING_IK` does the work of three
        iterations in one (30 a solve), which keeps the accuracy; ten in one (10 a
        solve) was better on two accuracy clips (elbow 15.7 and 15.8 mm against 17.4 and
        15.9) but let a third's trunk turn 40 deg off in the flat valley and flip the
        left arm (MPJPE 26.6 -> 39.5 mm), and five in one did the same (38.6 mm).
    paper : bool
        Follow the paper literally: no temporal smoothing, proportional balance rule.
    use_video : bool
        Run the arm refinement when a camera, an image and a refiner are available.
    gap_limit_s : float
        Longest marker gap bridged by extrapolation (s).
    balance : BalanceConfig or None
        Default: ``"proportional"`` in paper mode, ``"solve"`` otherwise.
    smoothing_min_cutoff_hz, smoothing_beta : float
        One-euro filter parameters (cut-off at rest; speed coefficient, per rad/s,
        per 1000 mm/s for the root translation).
    marker_offsets_mm : mapping of str to (3,) array_like
        Marker-set offsets in the effector's joint frame, added to the effector point.
    refine_config : Any
        Passed through to the refiner. Default `RefineConfig()` (oriented chamfer,
        elbow-jump penalty); in paper mode the paper's plain chamfer without the
        penalty, ``RefineConfig(edges=EdgeConfig(), elbow_jump_weight_per_mm=0)``. With a
        `RefineConfig` whose penalty is on, the refiner is also given the previous
        frame's elbows and the time since (``previous_elbows_mm``, ``elapsed_s``).
    init_iterations : int
        Cold-start solves (of ``ik.max_iterations`` each) on the first sample.
    smoothing_polish_tol_mm : float
        After smoothing, effectors further than this from their markers are put back
        by IK. A tolerance near the marker noise keeps the smoothing (a tight one would
        re-inject the noise into the redundant DoFs, e.g. the elbow swivel). The arm
        re-seed also takes its solves within this of the best fit as equally good.
    smoothing_polish_stall_iterations : int
        The polish also stops when the largest error has not dropped by 1 % in this
        many iterations (0: never): with member markers the error settles near the
        tolerance and half the polishes ran their 100 iterations for nothing. Measured
        (two accuracy clips, oriented sets, IK only): elbow 20.4 and
        15.8 mm without the stop, 20.5 and 16.3 mm with it; 25 % less time per frame.
        Default 3: of the polish's 14 iterations a frame (154 of 363 polishes on the
        bench sessions ran to the 30-iteration cap, the error stalled above the
        tolerance, the pose crawling along the redundant DoFs, i.e. undoing the
        smoothing) 4.7 remain; smoothing 1.77 -> 0.67 ms a frame, the accuracy within
        0.5 mm in the default configuration and 1 mm in the other two
        (`git log -p docs/design-notes/hybrid.md`).
    member_offsets_mm : mapping of str to mapping of str to (3,) array_like
        Per marker set, its member markers' offsets (mm) in the effector joint's frame,
        from the default effector point (as ``marker_offsets_mm``). Each member then
        becomes a point effector of its own, so the IK sees the set's orientation as well
        as its position; for the glasses this fixes the body's turn, which the three set
        centres leave free (`zhang21` has no spine or neck twist, so the head's yaw is
        the trunk's). An extension: the paper uses the set positions only. Members
        are used while seen and their set is not bridged or released.
    start_upright : bool
        The subject starts standing upright: the first pose is lifted or lowered so
        that the model's head meets the head marker, and the feet are planted where
        that pose has them (a subject on a step or a box, a floor that is not at z = 0).
        False keeps the feet of the first pose on z = 0.
    replant_mm : float
        With planted feet: when a marker effector stays further than this off its
        marker, the subject has stepped; the feet are put down again under the new
        pose (0 keeps them where they started, as the paper does). Measured on the
        accuracy clips with oriented marker sets (IK only): upper-body MPJPE 41.5, 40.8
        and 42.3 mm at 5, 8 and 11 mm, 44.5 mm at 15 mm, 52.4 mm at 15 mm with the
        feet held at their first height. Raw marker files use 15 mm
        (`mocapkit.pipelines.hybrid.RAW_MARKERS_REPLANT_MM`).
    replant_speed_factor, replant_min_speed_mm_s : float
        Speed bound of a re-plant's relaxation (`HybridTracker._replant_if_stepped`):
        the pelvis and legs move at most ``replant_speed_factor`` times the head set's
        speed plus ``replant_min_speed_mm_s`` (mm/s) in that part of the re-plant that
        head and hands do not ask for (the relaxed-pose pull of the feet-free solve);
        the rest is carried into the next frames.
    plant_feet : bool
        Hold the feet at their initial positions (the paper's assumption). Set False
        for takes where the subject walks; the feet are then free (no foot effector)
        and the balance step is skipped (no base of support).
    posture : str
        ``"standing"`` (default) or ``"seated"``. Seated: no foot is planted or
        re-planted, no balance step runs (the seat, not the feet, carries the body),
        and the leg joints (`mocapkit.tracking.hybrid.posture.SEATED_LEFT_OUT`) are NaN in the
        results. The skeleton must sit already
        (`mocapkit.tracking.hybrid.posture.seat_skeleton`: pelvis held at the seat's height,
        legs held bent); ``auto`` is resolved before the tracker
        (`mocapkit.tracking.hybrid.posture.choose_posture`).
    reseed_arm_mm : float
        Where a hand set is further than this (mm) from the model after the frame's
        solve, its arm is solved again from several seeds, the trunk held
        (`HybridTracker._reseed_lost_arms`); 0 never. Raw marker files use
        `mocapkit.pipelines.hybrid_markers.RAW_MARKERS_RESEED_MM`.
    rejoin_blend_s : float
        A hand set released after a long gap holds its arm's last observed pose (relative
        to the shoulder's parent); when the set is seen again its IK targets (the set and
        its members) go from where the held arm puts them to the markers, linearly over
        this time, instead of the arm snapping there in one frame (0: snap). The fit
        (``residual_mm``) is measured against the markers throughout.
    """

    ik: IKConfig = field(default_factory=lambda: TRACKING_IK)
    paper: bool = False
    use_video: bool = True
    gap_limit_s: float = BRIDGE_S
    balance: BalanceConfig | None = None
    smoothing_min_cutoff_hz: float = 3.0
    smoothing_beta: float = 0.5
    marker_offsets_mm: Mapping[str, Sequence[float]] = field(default_factory=dict)
    refine_config: Any = None
    init_iterations: int = 3
    plant_feet: bool = True
    smoothing_polish_tol_mm: float = 5.0
    smoothing_polish_stall_iterations: int = 3
    replant_mm: float = 8.0
    replant_speed_factor: float = INPUT_SPEED_FACTOR
    replant_min_speed_mm_s: float = UNSEEN_SPEED_MM_S
    member_offsets_mm: Mapping[str, Mapping[str, Sequence[float]]] = field(default_factory=dict)
    start_upright: bool = True
    posture: str = "standing"
    reseed_arm_mm: float = 0.0
    rejoin_blend_s: float = REJOIN_BLEND_S

    def __post_init__(self) -> None:
        if self.posture not in ("standing", "seated"):
            raise ConfigError(
                "HybridConfig.posture: expected 'standing' or 'seated' ('auto' is "
                f"resolved before the tracker), found {self.posture!r}"
            )
        if not self.reseed_arm_mm >= 0:
            raise ConfigError(
                f"HybridConfig.reseed_arm_mm: expected >= 0 mm, found {self.reseed_arm_mm}"
            )
        if not (self.rejoin_blend_s >= 0 and math.isfinite(self.rejoin_blend_s)):
            raise ConfigError(
                f"HybridConfig.rejoin_blend_s: expected a finite time >= 0 s, found "
                f"{self.rejoin_blend_s}"
            )
        if not (self.replant_speed_factor >= 0 and self.replant_min_speed_mm_s > 0):
            raise ConfigError(
                "HybridConfig: expected replant_speed_factor >= 0 and "
                f"replant_min_speed_mm_s > 0 mm/s, found {self.replant_speed_factor}, "
                f"{self.replant_min_speed_mm_s}"
            )
        if not self.gap_limit_s >= 0:
            raise ConfigError(
                f"HybridConfig.gap_limit_s: expected >= 0 s, found {self.gap_limit_s}"
            )
        if not self.smoothing_min_cutoff_hz > 0 or not self.smoothing_beta >= 0:
            raise ConfigError(
                "HybridConfig: expected smoothing_min_cutoff_hz > 0 and smoothing_beta >= 0, found "
                f"{self.smoothing_min_cutoff_hz}, {self.smoothing_beta}"
            )

    @property
    def feet_planted(self) -> bool:
        """Whether feet are planted: ``plant_feet`` for a standing subject, never seated."""
        return self.plant_feet and self.posture == "standing"

    @property
    def balance_config(self) -> BalanceConfig:
        """The balance settings in effect."""
        if not self.feet_planted:
            return BalanceConfig(mode="off")
        if self.balance is not None:
            return self.balance
        if self.paper:
            return BalanceConfig(mode="proportional")
        return TRACKING_BALANCE

    @property
    def smoothing(self) -> bool:
        """Temporal smoothing is on unless in paper mode."""
        return not self.paper


@dataclass(frozen=True)
class HybridSample:
    """One input sample.

    Parameters
    ----------
    time_s : float
        Time of the sample (the video frame's time when video drives the loop).
    markers_mm : mapping of str to array_like (3,)
        Marker-set positions in the world frame (mm); NaN or absent when occluded.
    marker_time_s : float, optional
        Time stamp of the marker sample used (the newest one); ``time_s`` by default.
    image : ndarray or callable, optional
        Video frame (H, W) or (H, W, 3) for the refinement, or a function without
        arguments that returns it (decoded only when an arm is refined: with oriented
        hand sets most frames need no image, and decoding a 640x480 frame costs about
        0.5 ms).
    members_mm : mapping of str to array_like (3,), optional
        Member markers of the sets in ``HybridConfig.member_offsets_mm``, by marker name
        (NaN or absent when occluded).
    """

    time_s: float
    markers_mm: Mapping[str, ArrayLike]
    marker_time_s: float | None = None
    image: NDArray[Any] | Callable[[], NDArray[Any]] | None = None
    members_mm: Mapping[str, ArrayLike] = field(default_factory=dict)


@dataclass
class HybridPose(FrameResult):
    """Tracker output for one sample: a `FrameResult` with the hybrid's own details.

    Attributes
    ----------
    time_s : float
    q : ndarray (D,)
    joints_mm : ndarray (15, 3)
        Canonical joints (`CANONICAL_JOINTS` order, NaN where the skeleton has none).
    status : dict of str to str
        Per marker set: ``seen``, ``bridged`` (extrapolated over a short gap),
        ``released`` (dropped after a long gap) or ``missing`` (not seen yet).
    fit : dict of str to float
        ``"<effector>_mm"``: distance of each effector (marker sets, planted feet, member
        markers) to its target after the whole pipeline, NaN when not in the task;
        ``"rms_mm"``, ``"max_mm"`` over those in the task; ``"<side>_arm_edge"``: the
        refined arm's image term (oriented chamfer, px) where the video ran.
    worst : str
        The effector at ``fit["max_mm"]``.
    iterations : int
        IK iterations of this sample.
    residual_mm : dict of str to float
        Distance of each effector to its target after the whole pipeline (NaN if released).
    released : tuple of str
        Marker sets dropped from the task (gap longer than the limit).
    bridged : tuple of str
        Marker sets extrapolated over a short gap.
    spine_lean_rad : ndarray (3,)
        Balance increments applied to the spine.
    marker_time_s : float
    refined : bool
        Whether the video refinement ran (on at least one arm).
    """

    iterations: int = 0
    residual_mm: dict[str, float] = field(default_factory=dict)
    released: tuple[str, ...] = ()
    bridged: tuple[str, ...] = ()
    spine_lean_rad: FloatArray = field(default_factory=lambda: np.zeros(0))
    marker_time_s: float = math.nan
    refined: bool = False


class OneEuroFilter:
    """Causal one-euro filter on a vector (Casiez, Roussel, Vogel 2012).

    Parameters
    ----------
    min_cutoff_hz : float
        Cut-off when still; lower means smoother.
    beta : array_like, shape (n,) or scalar
        Speed coefficient; the cut-off grows as ``min_cutoff + beta |dx/dt|``, so fast
        motion is followed with little lag.
    d_cutoff_hz : float
        Cut-off of the speed estimate.
    """

    def __init__(self, min_cutoff_hz: float, beta: ArrayLike, d_cutoff_hz: float = 1.0) -> None:
        self.min_cutoff = float(min_cutoff_hz)
        self.beta = np.asarray(beta, dtype=float)
        self.d_cutoff = float(d_cutoff_hz)
        self._x: FloatArray | None = None
        self._dx: FloatArray | None = None
        self._t: float | None = None

    @staticmethod
    def _alpha(cutoff: ArrayLike, dt: float) -> FloatArray:
        tau = 1.0 / (2.0 * math.pi * np.asarray(cutoff, dtype=float))
        return 1.0 / (1.0 + tau / dt)

    def __call__(self, t_s: float, x: ArrayLike) -> FloatArray:
        """Filter the value ``x`` observed at time ``t_s``; returns the smoothed value."""
        xa = np.asarray(x, dtype=float)
        if self._x is None or self._t is None or t_s <= self._t:
            self._x, self._dx, self._t = xa.copy(), np.zeros_like(xa), float(t_s)
            return xa.copy()
        dt = float(t_s) - self._t
        dx = (xa - self._x) / dt
        a_d = self._alpha(self.d_cutoff, dt)
        assert self._dx is not None
        self._dx = a_d * dx + (1.0 - a_d) * self._dx
        cutoff = self.min_cutoff + self.beta * np.abs(self._dx)
        a = self._alpha(cutoff, dt)
        self._x = a * xa + (1.0 - a) * self._x
        self._t = float(t_s)
        return self._x.copy()


@dataclass
class _Track:
    """Last observations of one marker set (for gap bridging)."""

    t: list[float] = field(default_factory=list)
    p: list[FloatArray] = field(default_factory=list)
    released: bool = False
    gap_start_s: float | None = None
    #: The set is seen again after a release (this sample); its blend starts.
    rejoined: bool = False
    #: The arm's DoF values of the last frame the set was seen or bridged (hand sets).
    held_q: FloatArray | None = None
    #: Rejoin blend: its start time and, per target row (the set, its members), the
    #: offset (mm) from the marker to where the held pose put the effector.
    blend_start_s: float = math.nan
    blend_offsets: dict[int, FloatArray] = field(default_factory=dict)

    def velocity_mm_s(self) -> FloatArray:
        """The set's velocity over its last two observations (mm/s); zero before two."""
        if len(self.t) == 2 and self.t[-1] > self.t[0]:
            return (self.p[-1] - self.p[0]) / (self.t[-1] - self.t[0])
        return np.zeros(3)


class HybridTracker:
    """Streaming tracker: ``update(sample) -> HybridPose``.

    Parameters
    ----------
    skeleton : Skeleton
        Usually ``load_preset("zhang21")`` scaled to the subject (optionally with
        ``root_rotation``).
    camera : Camera, optional
        Needed for the video refinement.
    config : HybridConfig
    refiner : callable, optional
        ``refine(skeleton, camera, q, image, hand_targets_mm, config) -> q``; by default
        ``mocapkit.tracking.hybrid.arm_refinement.refine_arms`` when that module is installed.
        When ``config`` is a `RefineConfig` with the elbow-jump penalty on (its
        default) and the refiner accepts them, calls after the first also pass
        ``previous_elbows_mm`` (side -> the previous frame's elbow carried by the
        current trunk, world mm) and ``elapsed_s``.
    initial_q : array_like, shape (D,), optional
        Start pose; by default the relaxed pose placed under the head marker
        (`initial_pose`).
    marker_effectors : mapping of str to Effector, optional
        Effector driven by each marker set (default `default_marker_effectors`).
    timer : StageTimer, optional
        Receives the per-stage wall times (``"ik"``, ``"edges"``, ``"refinement"``,
        ``"balance"``, ``"smoothing"``) and the IK counts (``"ik_solves"``,
        ``"ik_iterations"``); `NULL_TIMER` by default. May be replaced between updates
        (attribute ``timer``).
    """

    def __init__(
        self,
        skeleton: Skeleton,
        camera: Any = None,
        config: HybridConfig | None = None,
        refiner: Refiner | None = None,
        initial_q: ArrayLike | None = None,
        marker_effectors: Mapping[str, Effector] | None = None,
        timer: StageTimer = NULL_TIMER,
    ) -> None:
        self.skeleton = skeleton
        self.camera = camera
        self.config = config or HybridConfig()
        effs = dict(marker_effectors or default_marker_effectors(skeleton))
        for name, off in self.config.marker_offsets_mm.items():
            if name not in effs:
                raise unknown_name("marker set", name, effs, "HybridConfig.marker_offsets_mm")
            o = np.asarray(off, dtype=float)
            if o.shape != (3,) or not np.all(np.isfinite(o)):
                raise ConfigError(
                    f"HybridConfig.marker_offsets_mm[{name!r}]: expected 3 finite "
                    f"numbers (mm), found {off!r}"
                )
            e = effs[name]
            p = np.add(e.point_mm, o)
            effs[name] = Effector(e.name, e.joint, (float(p[0]), float(p[1]), float(p[2])))
        base_effs = dict(marker_effectors or default_marker_effectors(skeleton))
        #: (marker set, member marker) of each member effector, after the feet.
        self.members: tuple[tuple[str, str], ...] = ()
        member_effs: list[Effector] = []
        for name, members in self.config.member_offsets_mm.items():
            if name not in effs:
                raise unknown_name("marker set", name, effs, "HybridConfig.member_offsets_mm")
            for member, off in members.items():
                o = np.asarray(off, dtype=float)
                if o.shape != (3,) or not np.all(np.isfinite(o)):
                    raise ConfigError(
                        f"HybridConfig.member_offsets_mm[{name!r}][{member!r}]: expected 3 "
                        f"finite numbers (mm), found {off!r}"
                    )
                e = base_effs[name]
                p = np.add(e.point_mm, o)
                member_effs.append(
                    Effector(f"{name}/{member}", e.joint, (float(p[0]), float(p[1]), float(p[2])))
                )
                self.members += ((name, member),)
        #: Marker sets that drive a foot (`LEG_SETS`): their effectors take the feet's
        #: rows, the markers' place that of the plant while seen.
        self.foot_sets = tuple(n for n in FEET if n in effs)
        self.marker_sets = tuple(n for n in effs if n not in FEET)
        feet = [effs.get(e.name, e) for e in foot_effectors(skeleton)]
        effectors = [effs[n] for n in self.marker_sets] + feet + member_effs
        #: The balance step in effect: none where a segment or foot set places the
        #: trunk or the lower body (its lean would move them off their markers).
        self._balance_config = (
            BalanceConfig(mode="off")
            if self.foot_sets or set(SEGMENT_SETS) & set(self.marker_sets)
            else self.config.balance_config
        )
        self.solver = _CountedSolver(skeleton, effectors, self.config.ik)
        polish_cfg = replace(
            self.config.ik,
            secondary_gain=0.0,
            min_iterations=0,
            tol_mm=self.config.smoothing_polish_tol_mm,
            stall_iterations=self.config.smoothing_polish_stall_iterations,
            stall_fraction=0.01,
        )
        self._polish = _CountedSolver(skeleton, effectors, polish_cfg)
        #: The re-plant's feet-free solve without the relaxed-pose pull: only what head
        #: and hands ask for (`_replant_if_stepped`).
        self._unpulled = _CountedSolver(
            skeleton, effectors, replace(self.config.ik, secondary_gain=0.0)
        )
        n_sets = len(self.marker_sets)
        #: Target rows of the hand sets (`_arm_dofs`) and their members: they place the
        #: arms, and drive no re-plant's move of the pelvis and legs (`_bound_relaxation`).
        self._hand_rows = [
            row
            for i, name in enumerate(self.marker_sets)
            if name.removesuffix("_hand") in SIDES and name.endswith("_hand")
            for row in (
                i,
                *(n_sets + 2 + k for k, (s, _) in enumerate(self.members) if s == name),
            )
        ]
        #: DoFs of the root, trunk and legs (all but the arms'): those a re-plant's
        #: relaxation holds back (`_bound_relaxation`); the arms take it whole.
        arm_dofs = [np.zeros(0, np.int64)] + [
            np.concatenate([lmb.dofs, lmb.translation_dofs])
            for lmb in limbs_present(skeleton, "arm")
        ]
        self._lower_dofs = np.setdiff1d(np.arange(skeleton.n_dofs), np.concatenate(arm_dofs))
        #: The same DoFs as a mask: frozen where the arms are solved again over a
        #: bounded pelvis and trunk (`_bound_polish`).
        self._lower_frozen = np.zeros(skeleton.n_dofs, dtype=bool)
        self._lower_frozen[self._lower_dofs] = True
        #: Joints of the pelvis and legs, whose move a re-plant's relaxation bounds.
        self._lower_joints = np.unique(
            np.concatenate(
                [
                    [lmb.parent, *lmb.chain, *([lmb.tip] if lmb.tip >= 0 else [])]
                    for lmb in limbs_present(skeleton, "leg")
                ]
            ).astype(np.int64)
        )
        # After the video refinement, the balance step's restore of head and hands must
        # not run the relaxed-pose task: it would pull the refined arms back to the IK's
        # swivel (the paper: "each process modifies only a specific part of the pose").
        restore_ik = restore_ik_config(self.config.ik, self.config.balance_config)
        self._restore = _CountedSolver(
            skeleton, effectors, replace(restore_ik, secondary_gain=0.0, min_iterations=0)
        )
        # without a refinement the restore keeps the relaxed-pose task (the IK's own)
        self._restore_relaxed = (
            self.solver
            if restore_ik == self.config.ik
            else _CountedSolver(skeleton, effectors, restore_ik)
        )
        self._arms = {side: arm(skeleton, side) for side in SIDES}
        #: Per side, the arm with its clavicle (`mocapkit.skeleton.limbs.part_dofs`): what a
        #: released hand set's arm is held by (`_arm_dofs`) and all an arm re-seed moves.
        self._arm_part_dofs = {side: part_dofs(skeleton, f"{side}_arm") for side in SIDES}
        #: Per side, the DoFs an arm re-seed holds (`_reseed_lost_arms`): all but those.
        self._reseed_frozen: dict[str, NDArray[np.bool_]] = {}
        for side, dofs in self._arm_part_dofs.items():
            held = np.ones(skeleton.n_dofs, dtype=bool)
            held[dofs] = False
            self._reseed_frozen[side] = held
        #: The relaxed legs follow the head's height over the feet (`Crouch`): a standing
        #: subject with planted feet and no leg sets, outside paper mode.
        self._crouch: Crouch | None = None
        if (
            self.config.feet_planted
            and not self.config.paper
            and "head" in self.marker_sets
            and not self.foot_sets
            and "pelvis" not in self.marker_sets
        ):
            self._crouch = Crouch.of(skeleton)
            if self._crouch is not None:
                omega = standing_relaxed_pose(skeleton, self.solver.secondary.omega)
                self._relax_legs(omega[self._crouch.dofs])
        self._timer: StageTimer = NULL_TIMER
        self.timer = timer
        #: Per side, what the last video refinement did (when the refiner is `refine_arms`).
        self.arm_diagnostics: dict[str, ArmDiagnostics] = {}
        self._refiner: Refiner = refine_arms if refiner is None else refiner
        # the refiner's hand penalty must pull towards the same points the IK places on
        # the markers, offsets included
        base = self.config.refine_config or (
            RefineConfig(edges=EdgeConfig(), elbow_jump_weight_per_mm=0.0)
            if self.config.paper
            else RefineConfig()
        )
        self._refine_config = base
        if isinstance(base, RefineConfig) and "left_hand" in effs and "right_hand" in effs:
            lp, rp = effs["left_hand"].point_mm, effs["right_hand"].point_mm
            self._refine_config = replace(
                base,
                effector_points_mm=(
                    (float(lp[0]), float(lp[1]), float(lp[2])),
                    (float(rp[0]), float(rp[1]), float(rp[2])),
                ),
            )
        #: whether the refiner gets the previous frame's elbows (the elbow-jump penalty)
        self._elbow_prior = (
            self.config.use_video
            and isinstance(self._refine_config, RefineConfig)
            and self._refine_config.elbow_jump_weight_per_mm > 0
            and _takes_previous_elbows(self._refiner)
        )
        self._initial_q = None if initial_q is None else np.asarray(initial_q, dtype=float)
        self._q: FloatArray | None = None
        #: The pose last returned (`_blend_rejoined` starts from it).
        self._out_q: FloatArray | None = None
        #: Its time (the polish's bound, `_bound_polish`).
        self._out_time_s: float | None = None
        #: The pelvis and legs (`_lower_points_mm`) of the pose last returned, and its
        #: time: the polish's bound computes them once (`_bound_polish`).
        self._out_lower: tuple[float | None, FloatArray] = (None, np.zeros((0, 3)))
        self._prev_elbows: dict[str, FloatArray] | None = None
        self._prev_time_s = 0.0
        self._feet: FloatArray | None = None
        #: The feet whose marker set is seen in the current sample (`_put_marked_feet`).
        self._marked_feet = np.zeros(2, dtype=bool)
        self._support: FloatArray | None = None
        self._root_z0 = 0.0
        #: Frames left in which a re-plant's relaxation, cut short by its speed bound,
        #: goes on (`_bound_relaxation`), and the time of the last frame the re-plant saw.
        self._relax_frames = 0
        self._replant_time_s: float | None = None
        #: Lowest height (mm) a re-planted foot effector may take: the lower of the
        #: feet's heights in the first pose and the model's ankle height standing on z = 0
        #: (the lab floor), so a subject who starts on a box may later step down from it.
        self._floor_z_mm = 0.0
        self._balance_model: BalanceModel | None = None
        #: The balance search's last slope of the CoG per radian of lean (its next start),
        #: and the lean it restores first on the next frame.
        self._balance_slope: float | None = None
        self._balance_lean: float | None = None
        self._tracks = {n: _Track() for n in self.marker_sets}
        self._filter: OneEuroFilter | None = None
        #: Log of events: (time_s, marker set or "feet",
        #: "bridging" | "released" | "recovered" | "replanted").
        self.events: list[tuple[float, str, str]] = []

    # ------------------------------------------------------------------ pieces

    @property
    def timer(self) -> StageTimer:
        """The stage timer in use (see the class parameters)."""
        return self._timer

    @timer.setter
    def timer(self, value: StageTimer) -> None:
        self._timer = value
        for solver in (
            self.solver,
            self._polish,
            self._restore,
            self._restore_relaxed,
            self._unpulled,
        ):
            solver.timer = value

    def refiner(self) -> Refiner:
        """The video refinement in use (`refine_arms` unless another was given)."""
        return self._refiner

    def _targets(self, sample: HybridSample) -> tuple[FloatArray, list[str], list[str]]:
        """Effector targets of one sample, the sets bridged and the sets released.

        One age rule for every way a marker sample can be old (markers that end before
        the video, clocks that do not overlap, a stalled stream): a marker sample older
        than ``gap_limit_s`` at the frame time is no observation of this frame. Its sets
        are then absent, and the gap since their last observation, measured on the
        frame's clock, bridges or releases them as any occlusion would.
        """
        t_m = sample.time_s if sample.marker_time_s is None else float(sample.marker_time_s)
        stale = not sample.time_s - t_m <= self.config.gap_limit_s
        if stale:
            t_m = float(sample.time_s)
        n = len(self.marker_sets)
        targets = np.full((n + 2 + len(self.members), 3), np.nan)
        sets_seen: dict[str, bool] = {}
        for k, (set_name, member) in enumerate(self.members):
            raw = sample.members_mm.get(member)
            p = None if raw is None else np.asarray(raw, dtype=float).reshape(-1)
            if p is not None and p.shape != (3,):
                raise ShapeError(
                    f"sample.members_mm[{member!r}]: expected 3 coordinates (mm), "
                    f"found shape {p.shape}"
                )
            set_seen = sets_seen.get(set_name)
            if set_seen is None:
                raw_set = sample.markers_mm.get(set_name)
                set_seen = raw_set is not None and bool(np.all(np.isfinite(raw_set)))
                sets_seen[set_name] = set_seen
            if p is not None and set_seen and not stale and np.all(np.isfinite(p)):
                targets[n + 2 + k] = p
        bridged: list[str] = []
        released: list[str] = []
        for i, name in enumerate(self.marker_sets):
            tr = self._tracks[name]
            raw = sample.markers_mm.get(name)
            p = None if raw is None else np.asarray(raw, dtype=float).reshape(-1)
            if p is not None and p.shape != (3,):
                raise ShapeError(
                    f"sample.markers_mm[{name!r}]: expected 3 coordinates (mm), "
                    f"found shape {p.shape}"
                )
            if p is not None and not stale and np.all(np.isfinite(p)):
                if tr.released or tr.gap_start_s is not None:
                    self.events.append((t_m, name, "recovered"))
                tr.rejoined = tr.released
                tr.released, tr.gap_start_s = False, None
                if not tr.t or t_m > tr.t[-1]:
                    tr.t, tr.p = [*tr.t, t_m][-2:], [*tr.p, p][-2:]
                targets[i] = p
                continue
            new_gap = tr.gap_start_s is None
            if tr.gap_start_s is None:
                tr.gap_start_s = tr.t[-1] if tr.t else t_m
            gap = t_m - tr.gap_start_s
            if tr.t and not tr.released and gap <= self.config.gap_limit_s:
                if new_gap:
                    self.events.append((t_m, name, "bridging"))
                targets[i] = tr.p[-1] + tr.velocity_mm_s() * (t_m - tr.t[-1])
                bridged.append(name)
            else:
                if not tr.released:
                    self.events.append((t_m, name, "released"))
                tr.released = True
                released.append(name)
        return targets, bridged, released

    def initial_pose(self, targets: FloatArray) -> FloatArray:
        """Relaxed pose with the pelvis below the head marker, facing the camera.

        Root x, y put the model's head over the head marker; with
        ``HybridConfig.start_upright`` the root height puts the head at the marker's
        height too, otherwise it stays at the model's standing height (feet on z = 0). With
        the ``root_yaw`` DoF the subject is assumed to start facing the camera, as in
        the paper's set-up (the camera stands in front of the player): the body's
        front (+Y at rest) points horizontally from the head marker to the camera.
        Without a camera the body's right (+X at rest) points from the left-hand to
        the right-hand marker (hands roughly symmetric about the sagittal plane), which
        is ambiguous when the arms cross or one is raised; pass ``initial_q`` then.
        When the head set's members are seen (``member_offsets_mm``), the body is
        turned so the model's head faces the way the glasses do instead.
        """
        sk = self.skeleton
        q = (
            self.solver.secondary.omega.copy()
            if self._initial_q is None
            else self._initial_q.copy()
        )
        if self._initial_q is not None:
            return np.clip(q, sk.lower, sk.upper)
        names = list(self.marker_sets)
        head_target = targets[names.index("head")] if "head" in names else np.full(3, np.nan)
        if (
            "root_yaw" in sk.dof_names
            and self.camera is not None
            and np.all(np.isfinite(head_target))
        ):
            front = self.camera.center_in_world - head_target
            if np.hypot(front[0], front[1]) > 1e-6:
                # R_z(yaw) @ (0, 1, 0) = (-sin yaw, cos yaw) must point along ``front``
                q[sk.dof_index("root_yaw")] = math.atan2(-front[0], front[1])
        elif "root_yaw" in sk.dof_names and "left_hand" in names and "right_hand" in names:
            lh, rh = targets[names.index("left_hand")], targets[names.index("right_hand")]
            if np.all(np.isfinite(lh)) and np.all(np.isfinite(rh)):
                right = rh - lh
                if np.hypot(right[0], right[1]) > 1e-6:
                    q[sk.dof_index("root_yaw")] = math.atan2(right[1], right[0])
        if "root_yaw" in sk.dof_names:
            turn = self._member_turn_rad(q, targets, "head")
            if turn is not None:
                q[sk.dof_index("root_yaw")] += turn
        if "head" in names and np.all(np.isfinite(targets[names.index("head")])):
            head_now = self.solver.effector_positions(q)[names.index("head")]
            q[0] += targets[names.index("head"), 0] - head_now[0]
            q[1] += targets[names.index("head"), 1] - head_now[1]
            if self.config.start_upright:
                q[2] += targets[names.index("head"), 2] - head_now[2]
        return np.clip(q, sk.lower, sk.upper)

    def _n_members_seen(self, targets: FloatArray, set_name: str) -> int:
        seen = np.all(np.isfinite(targets[len(self.marker_sets) + 2 :]), axis=1)
        return sum(1 for (s, _), ok in zip(self.members, seen, strict=True) if ok and s == set_name)

    def _member_turn_rad(self, q: FloatArray, targets: FloatArray, set_name: str) -> float | None:
        """The turn about the vertical that best aligns the model's member markers of one
        set with the seen ones (least squares over the horizontal components of the
        members' offsets from their set centre); None with fewer than two seen members."""
        n = len(self.marker_sets)
        rows = [n + 2 + k for k, (s, _) in enumerate(self.members) if s == set_name]
        seen = [r for r in rows if np.all(np.isfinite(targets[r]))]
        if len(seen) < 2:
            return None
        model = self.solver.effector_positions(q)[seen, :2]
        observed = targets[seen, :2]
        a = model - model.mean(axis=0)
        b = observed - observed.mean(axis=0)
        cross = float(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]))
        dot = float(np.sum(a * b))
        if math.hypot(cross, dot) < 1e-9:
            return None
        return math.atan2(cross, dot)

    def _replant_if_stepped(
        self,
        q: FloatArray,
        targets: FloatArray,
        marker_residual_mm: FloatArray | None,
        sample: HybridSample,
    ) -> tuple[FloatArray, int]:
        """Move the planted feet when they keep head or hands off their markers.

        The paper holds the feet where they started (§3); a subject who steps or turns
        then drags head and hands away from their markers. When an active marker
        effector stays more than ``replant_mm`` off after the solve, the frame is solved
        again with the feet free, the feet are put down where that pose has them and
        held there from now on. Where the floor is not known (``start_upright``: the
        first pose hangs from the head marker) they keep that pose's height, so a
        subject who steps up onto a box or climbs stands on it (holding the old height
        would hang the body from the head marker with the legs stretched down to a
        floor it has left), but never go below the floor (`_floor_z_mm`). Where it is
        known (``start_upright=False``: the lab floor, z = 0) they stay on it, since the
        free pose's straight legs would put the feet of a subject who jumps or reaches
        up far above where they are (a tennis serve: 440 mm against the ankle markers'
        165 mm). The free solve's pull on the pelvis and legs is spread over frames at
        the head's pace (`_bound_relaxation`). ``q`` is the frame's solve with the feet
        held and ``marker_residual_mm`` its marker sets' errors; a frame that goes on with
        a cut relaxation (``_relax_frames``) re-plants whatever that solve finds, so it is
        not run there: ``q`` is the previous frame's pose and the errors None, and the
        relaxation goes on from that pose. Returns the pose and the extra iterations.
        """
        assert self._feet is not None
        n = len(self.marker_sets)
        dt_s = None if self._replant_time_s is None else sample.time_s - self._replant_time_s
        self._replant_time_s = float(sample.time_s)
        carried = marker_residual_mm is None
        if marker_residual_mm is not None:  # a fresh frame: re-plant only where needed
            finite = np.isfinite(marker_residual_mm)
            if not (np.any(finite) and np.nanmax(marker_residual_mm) > self.config.replant_mm):
                return q, 0
        free = targets.copy()
        free[n : n + 2][~self._marked_feet] = np.nan
        res_free = self.solver.solve(q, free)
        q_free, extra = self._bound_relaxation(q, free, res_free.q, dt_s, carried)
        feet = self.solver.effector_positions(q_free)[n : n + 2]
        if self.config.start_upright:
            np.maximum(feet[:, 2], self._floor_z_mm, out=feet[:, 2])
        else:
            feet[:, 2] = self._feet[:, 2]  # the lab floor is known: stay on it
        feet[self._marked_feet] = targets[n : n + 2][self._marked_feet]  # the markers' place
        self._feet = feet
        self._support = support_points(self.skeleton, q_free)
        targets[n : n + 2] = feet
        res = self.solver.solve(q_free, targets)
        self.events.append((sample.time_s, "feet", "replanted"))
        q, held = self._hold_feet(res.q, targets)
        return q, res_free.iterations + extra + res.iterations + held

    def _head_speed_mm_s(self) -> float:
        """The head set's speed over its last two observations (mm/s); the fastest set's
        without a head set, 0 before two observations."""
        names = ["head"] if "head" in self._tracks else list(self._tracks)
        speeds = [float(np.linalg.norm(self._tracks[nm].velocity_mm_s())) for nm in names]
        return max(speeds, default=0.0)

    def _bound_relaxation(
        self,
        q: FloatArray,
        free: FloatArray,
        q_free: FloatArray,
        dt_s: float | None,
        carried: bool,
    ) -> tuple[FloatArray, int]:
        """Bound the part of a re-plant's feet-free pose that head and hands do not ask for.

        The feet-free solve's relaxed-pose pull moves the pelvis and legs under the body,
        which keeps them plausible, but in one frame: a body bent at the hips with its
        feet held can swing its hips forward and its trunk back by half a metre (a branch
        switch in the solve's null space, which head and hands do not see). Where the
        pelvis and legs (`_lower_joints`) would move further than the previous frame's
        pose allows at ``replant_speed_factor`` times the head set's speed plus
        ``replant_min_speed_mm_s``, the DoFs of the root, trunk and legs (`_lower_dofs`)
        are taken that share of the way from the same solve without the pull and without
        the hand sets (what the head asks for, kept whole, however far) towards
        ``q_free``, the arms' are ``q_free``'s (the hands' sets place them, whatever the
        pelvis does: a hand set an arm held by its joint limits cannot reach would drag
        the freed pelvis and legs after it, 150-300 mm in a frame); the following
        frames re-plant again from there, for as many frames as the whole move takes at
        the bound (``_relax_frames``), so the correction is spread, not dropped: on those
        frames (``carried``, ``q`` the previous frame's pose, `_replant_if_stepped`) the
        pelvis and legs go on from where they are, at most the bound towards ``q_free``,
        and no solve without the pull is run. Returns the pose and the extra iterations.
        """
        left, self._relax_frames = self._relax_frames, 0
        if self._q is None or dt_s is None or not dt_s > 0:
            return q_free, 0
        bound_mm = self._lower_bound_mm(dt_s)
        before = self._lower_points_mm(self._q)
        if self._lower_move_mm(q_free, before) <= bound_mm:
            return q_free, 0
        if carried:
            q_head, iterations = q, 0
        else:
            head = free.copy()
            head[self._hand_rows] = np.nan
            res = self._unpulled.solve(q, head)
            q_head, iterations = res.q, res.iterations
        limit_mm = max(bound_mm, self._lower_move_mm(q_head, before))
        # spread over the frames the whole move takes at the bound, counted from its start
        self._relax_frames = (
            left - 1 if left > 0 else math.ceil(self._lower_move_mm(q_free, before) / limit_mm) - 1
        )
        return self._share_lower(q_head, q_free, limit_mm, before), iterations

    def _lower_bound_mm(self, dt_s: float) -> float:
        """How far the pelvis and legs may move in ``dt_s`` (mm): ``replant_speed_factor``
        times the head set's speed plus ``replant_min_speed_mm_s``."""
        cfg = self.config
        return (
            cfg.replant_speed_factor * self._head_speed_mm_s() + cfg.replant_min_speed_mm_s
        ) * dt_s

    def _lower_points_mm(self, q: FloatArray) -> FloatArray:
        """The pelvis and legs (`_lower_joints`) of pose ``q``: positions (L, 3) in mm."""
        return forward_kinematics(self.skeleton, q)[self._lower_joints, :3, 3]

    def _lower_move_mm(self, q: FloatArray, before: FloatArray) -> float:
        """The largest move of the pelvis and legs from ``before`` (`_lower_points_mm` of
        the previous frame's pose) to pose ``q`` (mm)."""
        move = self._lower_points_mm(q) - before
        return float(np.max(np.linalg.norm(move, axis=1)))

    def _share_lower(
        self, q_head: FloatArray, q_free: FloatArray, limit_mm: float, before: FloatArray
    ) -> FloatArray:
        """``q_free`` with the root, trunk and leg DoFs (`_lower_dofs`) taken the largest
        share of the way from ``q_head`` that keeps the pelvis and legs within ``limit_mm``
        of ``before`` (the previous frame's, bisection); the arms' are ``q_free``'s."""
        dofs = self._lower_dofs

        def share(w: float) -> FloatArray:
            out = q_free.copy()
            out[dofs] = q_head[dofs] + w * (q_free[dofs] - q_head[dofs])
            return out

        lo, hi = 0.0, 1.0
        for _ in range(_RELAX_BISECTION_STEPS):
            mid = 0.5 * (lo + hi)
            if self._lower_move_mm(share(mid), before) <= limit_mm:
                lo = mid
            else:
                hi = mid
        return np.clip(share(lo), self.skeleton.lower, self.skeleton.upper)

    def _bound_polish(
        self,
        solved: FloatArray,
        smoothed: FloatArray,
        polished: FloatArray,
        targets: FloatArray,
        time_s: float,
    ) -> tuple[FloatArray, int]:
        """The smoothing's polish, its move of the pelvis and legs bounded.

        The polish puts the smoothed pose's effectors back on their markers; where the
        frame's solve had left the pelvis and legs far from theirs (a pelvis set 150 mm
        off for frames), the polish can take them there in one frame, further than the
        solve itself went. From the pose last returned, the pelvis and legs move at most
        as far as the frame's own solve (``solved``, before the filter) moved them, or
        the re-plant's bound (`_lower_bound_mm`) where that is further; beyond it the
        root, trunk and legs are taken that share of the way from ``smoothed`` to
        ``polished`` (`_share_lower`) and the arms polished again over them. The next
        frame starts from the solve, not from this pose, so nothing is dropped. Returns
        the pose and the extra iterations.
        """
        if self._out_q is None or self._out_time_s is None or not time_s > self._out_time_s:
            return polished, 0
        last_s, before = self._out_lower
        if last_s != self._out_time_s:
            before = self._lower_points_mm(self._out_q)
        after = self._lower_points_mm(polished)
        move_mm = float(np.max(np.linalg.norm(after - before, axis=1)))
        limit_mm = self._lower_bound_mm(time_s - self._out_time_s)
        if move_mm > limit_mm:
            limit_mm = max(limit_mm, self._lower_move_mm(solved, before))
        if not move_mm > limit_mm:
            self._out_lower = (time_s, after)  # the arms' holds leave them as they are
            return polished, 0
        # the arms put back on their markers over the pelvis and trunk the bound allows
        res = self._polish.solve(
            self._share_lower(smoothed, polished, limit_mm, before),
            targets,
            frozen=self._lower_frozen,
        )
        return res.q, res.iterations

    def _arm_dofs(self, name: str) -> NDArray[np.int64] | None:
        """The DoFs of the arm a hand set (``<side>_hand``) places, with the clavicle that
        carries it alone (`mocapkit.skeleton.limbs.part_dofs`, the part a result folder
        holds); None for other sets."""
        side = name.removesuffix("_hand")
        return self._arm_part_dofs[side] if side in SIDES and side != name else None

    def _hold_released_arms(self, q: FloatArray, released: Sequence[str]) -> None:
        """Put each released hand set's arm at its last observed values (in place)."""
        for name in released:
            dofs, held = self._arm_dofs(name), self._tracks[name].held_q
            if dofs is not None and held is not None:
                q[dofs] = held

    def _held_arm_dofs(self, released: Sequence[str]) -> NDArray[np.int64]:
        """The DoFs `_hold_released_arms` holds (`FrameResult.held_dofs`): `_blend_rejoined`
        brings them back, so the result folder leaves them as they are."""
        held = [
            dofs
            for name in released
            if (dofs := self._arm_dofs(name)) is not None and self._tracks[name].held_q is not None
        ]
        return np.concatenate(held).astype(np.int64) if held else np.zeros(0, dtype=np.int64)

    def _remember_arms(self, q: FloatArray, released: Sequence[str]) -> None:
        """Keep the arm DoFs of the hand sets observed (seen or bridged) in ``q``."""
        for name in self.marker_sets:
            dofs = self._arm_dofs(name)
            if dofs is not None and name not in released:
                self._tracks[name].held_q = q[dofs].copy()

    def _set_rows(self, i: int) -> list[int]:
        """Target rows of marker set ``i`` (of `marker_sets`): its centre and members."""
        n, name = len(self.marker_sets), self.marker_sets[i]
        return [i] + [n + 2 + k for k, (s, _) in enumerate(self.members) if s == name]

    def _blend_rejoined(self, targets: FloatArray, time_s: float, unseen: Sequence[str]) -> None:
        """Rejoin blend (`HybridConfig.rejoin_blend_s`), targets in place.

        On the sample where a released set is seen again, the offsets from its markers
        (the set's and its members') to the effectors of the previous pose, whose arm
        holds its last observed pose, are kept; over the blend the targets are the
        markers plus the offsets times ``1 - (t - t0) / rejoin_blend_s``. A member not seen
        on that sample is left out until the blend ends; a set bridged or released again
        ends it. The previous pose is the one returned (after the balance step and the
        smoothing), as the user saw it.
        """
        blend_s = self.config.rejoin_blend_s
        now: FloatArray | None = None
        for i, name in enumerate(self.marker_sets):
            tr = self._tracks[name]
            rows = self._set_rows(i)
            if tr.rejoined and blend_s > 0 and self._out_q is not None:
                if now is None:
                    now = self.solver.effector_positions(self._out_q)
                tr.blend_start_s = float(time_s)
                tr.blend_offsets = {
                    r: now[r] - targets[r] for r in rows if np.all(np.isfinite(targets[r]))
                }
            tr.rejoined = False
            if not tr.blend_offsets:
                continue
            w = (float(time_s) - tr.blend_start_s) / blend_s
            if name in unseen or not w < 1.0:
                tr.blend_offsets = {}
                continue
            for r in rows:
                off = tr.blend_offsets.get(r)
                targets[r] = np.nan if off is None else targets[r] + (1.0 - w) * off

    def _relax_legs(self, flexion_rad: FloatArray) -> None:
        """Set the relaxed pose's leg flexions (`Crouch.dofs`) in every solver's
        relaxed-pose task (in place: the compiled solve reads the same array)."""
        assert self._crouch is not None
        for solver in {
            id(s): s for s in (self.solver, self._polish, self._restore, self._restore_relaxed)
        }.values():
            solver.secondary.omega[self._crouch.dofs] = flexion_rad

    def _crouch_to_head(self, targets: FloatArray) -> None:
        """The relaxed legs for this sample's head target over the planted feet
        (`Crouch`); kept from the last sample while the head set is released."""
        if self._crouch is None:
            return
        assert self._feet is not None
        head = targets[self.marker_sets.index("head")]
        if np.all(np.isfinite(head)):
            self._relax_legs(self._crouch.flexion_rad(float(head[2] - self._feet[:, 2].mean())))

    def _put_marked_feet(self, targets: FloatArray, sample: HybridSample) -> None:
        """Targets of the feet whose marker set (`foot_sets`) is seen: the markers, which
        also become the plant that holds the foot while they are unseen."""
        assert self._feet is not None
        n = len(self.marker_sets)
        self._marked_feet = np.zeros(2, dtype=bool)
        for k, name in enumerate(FEET):
            raw = sample.markers_mm.get(name) if name in self.foot_sets else None
            if raw is None:
                continue
            p = np.asarray(raw, dtype=float).reshape(-1)
            if p.shape != (3,):
                raise ShapeError(
                    f"sample.markers_mm[{name!r}]: expected 3 coordinates (mm), "
                    f"found shape {p.shape}"
                )
            if np.all(np.isfinite(p)):
                targets[n + k] = p
                self._feet[k] = p
                self._marked_feet[k] = True

    def _reseed_lost_arms(self, q: FloatArray, targets: FloatArray) -> tuple[FloatArray, int]:
        """Start an arm again where its hand set is lost.

        The IK is local and warm-started: an arm driven into its joint limits (a tennis
        serve's racket drop asks the shoulder for more lateral rotation than its range)
        can stay folded there, its hand set hundreds of mm off, for seconds. Where a hand
        set is further than ``reseed_arm_mm`` from the model after the solve, the arm is
        solved again from the seeds of `mocapkit.tracking.hybrid.reseed.arm_seeds` (the
        relaxed pose's arm, the secondary task's ``omega``, and the current arm turned
        about its shoulder-wrist axis), with all but the arm and its clavicle held
        (``_reseed_frozen``: a whole-body solve swung the trunk, the shoulder 250-360 mm
        in a frame, and the pelvis and legs with it). Of the solves that fit the set
        within ``smoothing_polish_tol_mm`` (the marker noise) of the best, the one whose
        elbow moved least (`nearest_fit`) is kept if it brings the set closer. A set's fit
        is its largest distance over its centre and its members seen (`_set_rows`): a
        forearm member tells the branches apart. Returns the pose and the extra
        iterations.
        """
        now = self.solver.effector_positions(q)
        extra = 0
        for i, name in enumerate(self.marker_sets):
            side = name.removesuffix("_hand")
            if side not in SIDES or not np.all(np.isfinite(targets[i])):
                continue
            off = float(np.linalg.norm(now[i] - targets[i]))
            if not off > self.config.reseed_arm_mm:
                continue
            rows = [r for r in self._set_rows(i) if np.all(np.isfinite(targets[r]))]
            elbow = self._arms[side].middle
            elbow_mm = forward_kinematics(self.skeleton, q)[elbow, :3, 3]
            solved, fit, move = [], [], []
            for seed in arm_seeds(self.skeleton, q, side, self.solver.secondary.omega):
                res = self.solver.solve(seed, targets, frozen=self._reseed_frozen[side])
                extra += res.iterations
                solved.append(res.q)
                reached = self.solver.effector_positions(res.q)[rows]
                fit.append(float(np.max(np.linalg.norm(reached - targets[rows], axis=1))))
                moved = forward_kinematics(self.skeleton, res.q)[elbow, :3, 3] - elbow_mm
                move.append(float(np.linalg.norm(moved)))
            k = nearest_fit(fit, move, self.config.smoothing_polish_tol_mm)
            if fit[k] < float(np.max(np.linalg.norm(now[rows] - targets[rows], axis=1))):
                q = solved[k]
                now = self.solver.effector_positions(q)
        return q, extra

    def _hold_feet(self, q: FloatArray, targets: FloatArray) -> tuple[FloatArray, int]:
        """Lift feet that the whole-body solve pulled below the floor, with the legs alone.

        Where the floor is not known (``start_upright``), re-planted feet are promised
        never to go below the floor they started on (`_replant_if_stepped`). But when
        head or hands are lower than the legs can crouch, SDLS spreads the remaining
        error over every effector, planted feet included, and how far below the floor
        it drags them depends on round-off (BLAS kernels differed by 40 mm). So where a
        foot ends more than ``replant_mm`` under its plant, the legs are solved again with
        everything above them frozen: the upper body keeps its pose and the feet their
        plants. On a known lab floor (``start_upright=False``, raw marker files) the
        whole-body compromise is kept: holding the feet there cost the real tennis
        serve's right elbow 226 -> 272 mm.
        """
        if not self.config.start_upright:
            return q, 0
        n = len(self.marker_sets)
        feet_now = self.solver.effector_positions(q)[n : n + 2]
        below = targets[n : n + 2, 2] - feet_now[:, 2]
        if not np.nanmax(below) > self.config.replant_mm:
            return q, 0
        legs = np.concatenate([lmb.dofs for lmb in limbs_present(self.skeleton, "leg")])
        frozen = np.ones(self.skeleton.n_dofs, dtype=bool)
        frozen[legs] = False
        active = np.zeros(len(targets), dtype=bool)
        active[n : n + 2] = True
        res = self.solver.solve(q, targets, active=active, frozen=frozen)
        return res.q, res.iterations

    # ------------------------------------------------------------------ update

    def _shoulder_parents_and_elbows(
        self, q: FloatArray, world: FloatArray | None = None
    ) -> dict[str, tuple[FloatArray, FloatArray]]:
        """Per side: the world transform (4, 4) of the shoulder's parent (the trunk or
        clavicle) and the elbow (3,) in the world, mm, under pose ``q`` (``world``: its
        `forward_kinematics`, if already computed)."""
        if world is None:
            world = forward_kinematics(self.skeleton, q)
        out = {}
        for side in SIDES:
            limb = self._arms[side]
            out[side] = (world[limb.parent], world[limb.middle, :3, 3])
        return out

    def _elbows_in_shoulder_parents(
        self, q: FloatArray, world: FloatArray | None = None
    ) -> dict[str, FloatArray]:
        """Each elbow in the frame of its shoulder's parent, mm.

        The elbow-jump penalty compares elbows in this frame, carried to the world by
        the current trunk, so a trunk that turns between frames (a root-yaw correction)
        is not taken for a jumping elbow.
        """
        return {
            side: parent[:3, :3].T @ (elbow - parent[:3, 3])
            for side, (parent, elbow) in self._shoulder_parents_and_elbows(q, world).items()
        }

    def _previous_elbows_in_world(self, q: FloatArray) -> dict[str, FloatArray]:
        """The previous frame's elbows (`_elbows_in_shoulder_parents`) under pose ``q``."""
        assert self._prev_elbows is not None
        return {
            side: parent[:3, :3] @ self._prev_elbows[side] + parent[:3, 3]
            for side, (parent, _elbow) in self._shoulder_parents_and_elbows(q).items()
        }

    def reset(self) -> None:
        """Forget the state (pose, feet, gaps, filter, the crouch's standing height); the
        next sample initialises again."""
        if self._crouch is not None:
            self._crouch.standing_mm = math.nan
            self._relax_legs(self._crouch.lowered_rad(0.0))
        self._q = None
        self._out_q = None
        self._out_time_s = None
        self._out_lower = (None, np.zeros((0, 3)))
        self._prev_elbows = None
        self._feet = None
        self._filter = None
        self._balance_slope = None
        self._balance_lean = None
        self._relax_frames = 0
        self._replant_time_s = None
        self._tracks = {n: _Track() for n in self.marker_sets}
        self.events = []

    def update(self, sample: HybridSample) -> HybridPose:
        """Track one sample; returns the pose (see `HybridPose`)."""
        if not math.isfinite(sample.time_s):
            raise ShapeError(f"sample.time_s: expected a finite time (s), found {sample.time_s}")
        sk = self.skeleton
        timer = self._timer
        targets, bridged, released = self._targets(sample)
        # the fit is measured against the markers, also while a rejoin blend moves the
        # IK's targets (`_blend_rejoined`)
        observed = targets
        n = len(self.marker_sets)
        if self._q is None and not np.any(np.isfinite(targets[:n])):
            # nothing observed yet (the video starts before the markers): no pose, and
            # the first pose is placed when the markers come
            return self._no_pose(sample, bridged, released)
        iterations = 0
        with timer.stage("ik"):
            if self._q is None:
                q = self.initial_pose(targets)
                feet = self.solver.effector_positions(q)[n : n + 2]
                self._feet = feet
                self._support = support_points(sk, q)
                self._root_z0 = float(q[vertical_root_dof(sk)])
                standing = self.solver.effector_positions(
                    np.clip(sk.zero_pose(), sk.lower, sk.upper)
                )
                self._floor_z_mm = float(min(feet[:, 2].min(), standing[n : n + 2, 2].min()))
                targets[n : n + 2] = feet if self.config.feet_planted else np.nan
                self._put_marked_feet(targets, sample)
                self._crouch_to_head(targets)
                for _ in range(max(self.config.init_iterations, 1)):
                    res = self.solver.solve(q, targets)
                    q = res.q
                    iterations += res.iterations
                if self._balance_config.mode == "proportional":
                    self._balance_model = calibrate_balance(self.solver, q)
            else:
                assert self._feet is not None
                targets[n : n + 2] = self._feet if self.config.feet_planted else np.nan
                self._put_marked_feet(targets, sample)
                self._crouch_to_head(targets)
                observed = targets.copy()
                self._blend_rejoined(targets, sample.time_s, (*bridged, *released))
                replants = (
                    self.config.feet_planted
                    and self.config.replant_mm > 0
                    and not self.config.paper
                    and not self._marked_feet.all()  # foot sets place both feet
                )
                if replants and self._relax_frames > 0:
                    # a frame that goes on with a cut relaxation re-plants whatever the
                    # solve with the feet held would find: that solve is not run
                    q, extra = self._replant_if_stepped(self._q, targets, None, sample)
                    iterations += extra
                else:
                    res = self.solver.solve(self._q, targets)
                    q = res.q
                    iterations += res.iterations
                    if replants:
                        q, extra = self._replant_if_stepped(q, targets, res.residual_mm[:n], sample)
                        iterations += extra
                if self.config.reseed_arm_mm > 0:
                    q, extra = self._reseed_lost_arms(q, targets)
                    iterations += extra
            self._hold_released_arms(q, released)
        refined = False
        edge_fit: dict[str, float] = {}
        ref = (
            self.refiner()
            if (self.config.use_video and self.camera is not None and sample.image is not None)
            else None
        )
        if ref is not None:
            # an arm whose hand set's orientation is seen (two or more members) is fixed
            # by the markers up to the shoulder: the forearm's direction is the set's, so
            # the swivel the refinement resolves is no longer ambiguous
            oriented = {
                name for name in self.marker_sets if self._n_members_seen(targets, name) >= 2
            }
            hands = {
                name: targets[i].copy()
                for i, name in enumerate(self.marker_sets)
                if name in ("left_hand", "right_hand")
                and name not in oriented
                and np.all(np.isfinite(targets[i]))
            }
            if hands:
                extra_kw: dict[str, Any] = {}
                cfg_r = self._refine_config
                if self._elbow_prior and self._prev_elbows is not None:
                    extra_kw = {
                        "previous_elbows_mm": self._previous_elbows_in_world(q),
                        "elapsed_s": float(sample.time_s - self._prev_time_s),
                    }
                with timer.stage("edges"):
                    # a lazy frame is decoded here, only for frames whose arms are refined
                    image: Any = sample.image() if callable(sample.image) else sample.image
                    if ref is refine_arms and isinstance(cfg_r, RefineConfig):
                        # the whole-frame part of the edge cue, timed on its own;
                        # refine_arms takes the prepared frame as it is
                        image = prepare_frame(image, cfg_r.edges)
                if ref is refine_arms and isinstance(cfg_r, RefineConfig):
                    self.arm_diagnostics = {}
                    extra_kw["diagnostics"] = self.arm_diagnostics
                with timer.stage("refinement"):
                    q = np.asarray(
                        ref(sk, self.camera, q, image, hands, cfg_r, **extra_kw), dtype=float
                    )
                sk.check_q(q, "refiner output")
                refined = True
                for side, diag in self.arm_diagnostics.items():
                    if diag.refined:
                        edge_fit[f"{side}_arm_edge"] = float(diag.chamfer_after)
        # warm start of the next frame: the pose before the balance post-process, so
        # the spine bow is recomputed from dh each frame rather than accumulated
        self._q = q.copy()
        assert self._support is not None
        with timer.stage("balance"):
            bal = balance_pose(
                self._restore if refined else self._restore_relaxed,
                q,
                targets,
                self._root_z0,
                self._support,
                self._balance_model,
                self._balance_config,
                slope_mm_per_rad=self._balance_slope,
                lean_rad=self._balance_lean,
            )
        if bal.slope_mm_per_rad is not None:
            self._balance_slope = bal.slope_mm_per_rad
        self._balance_lean = bal.next_lean_rad
        q = bal.q
        if self.config.smoothing:
            with timer.stage("smoothing"):
                if self._filter is None:
                    beta = np.where(
                        sk.dof_kind == PRISMATIC,
                        self.config.smoothing_beta / 1000.0,
                        self.config.smoothing_beta,
                    )
                    self._filter = OneEuroFilter(self.config.smoothing_min_cutoff_hz, beta)
                solved = q
                q = self._filter(sample.time_s, q)
                # the filter smooths the redundant DoFs; put the effectors back on the markers
                res = self._polish.solve(q, targets)
                q, extra = self._bound_polish(solved, q, res.q, targets, float(sample.time_s))
                iterations += res.iterations + extra
        self._hold_released_arms(q, released)
        self._remember_arms(q, released)
        self._out_q = q.copy()
        self._out_time_s = float(sample.time_s)
        resid_arr = np.linalg.norm(self.solver.effector_positions(q) - observed, axis=1)
        names = self.marker_sets + FEET + tuple(m for _, m in self.members)
        residual = {nm: float(r) for nm, r in zip(names, resid_arr, strict=True)}
        world = forward_kinematics(sk, q)
        joints = canonical_positions(sk, q, world=world)
        if self._elbow_prior:
            self._prev_elbows = self._elbows_in_shoulder_parents(q, world)
            self._prev_time_s = float(sample.time_s)
        fit, worst = fit_summary(residual)
        fit.update(edge_fit)
        return HybridPose(
            time_s=float(sample.time_s),
            q=q,
            joints_mm=self._unobserved_to_nan(canonical_joints_mm(sk, joints), released),
            status=self._status(bridged, released),
            fit=fit,
            worst=worst,
            held_dofs=self._held_arm_dofs(released),
            iterations=iterations,
            residual_mm=residual,
            released=tuple(released),
            bridged=tuple(bridged),
            spine_lean_rad=bal.taus,
            marker_time_s=float(
                sample.time_s if sample.marker_time_s is None else sample.marker_time_s
            ),
            refined=refined,
        )

    def _unobserved_to_nan(self, joints_mm: FloatArray, released: Sequence[str]) -> FloatArray:
        """Canonical joints (15, 3) with those of released marker sets set to NaN.

        A released set's effector is out of the IK task, so its limb hangs in the
        relaxed pose the secondary task pulls it to: made up, not measured. The joints
        it alone places (`mocapkit.tracking.base.unobserved_part`, the rule the runner
        applies to every tracker) are NaN; with every set released, all are.
        A seated subject's legs (`SEATED_LEFT_OUT`) are NaN on every frame.
        ``q`` keeps the pose (BVH cannot hold NaN) and the status says ``released``.
        """
        out = joints_mm.copy()
        if released and all(name in released for name in self.marker_sets):
            out[:] = np.nan
            return out
        if self.config.posture == "seated":
            # the legs are held bent under a seat: no marker sees them
            for joint in SEATED_LEFT_OUT:
                out[CANONICAL_JOINTS.index(joint)] = np.nan
        return nan_unobserved(out, dict.fromkeys(released, "released"))

    def _no_pose(
        self, sample: HybridSample, bridged: Sequence[str], released: Sequence[str]
    ) -> HybridPose:
        """The result of a frame without a pose (NaN ``q`` and joints)."""
        names = self.marker_sets + FEET + tuple(m for _, m in self.members)
        fit, worst = fit_summary(dict.fromkeys(names, math.nan))
        return HybridPose(
            time_s=float(sample.time_s),
            q=np.full(self.skeleton.n_dofs, np.nan),
            joints_mm=np.full((len(CANONICAL_JOINTS), 3), np.nan),
            status=self._status(bridged, released),
            fit=fit,
            worst=worst,
            residual_mm=dict.fromkeys(names, math.nan),
            released=tuple(released),
            bridged=tuple(bridged),
            marker_time_s=float(
                sample.time_s if sample.marker_time_s is None else sample.marker_time_s
            ),
        )

    def _status(self, bridged: Sequence[str], released: Sequence[str]) -> dict[str, str]:
        """Per marker set: seen, bridged, released or missing (never seen yet)."""
        out = {}
        for name in self.marker_sets:
            if name in bridged:
                out[name] = "bridged"
            elif name in released:
                out[name] = "released" if self._tracks[name].t else "missing"
            else:
                out[name] = "seen"
        return out


def calibrate_marker_offsets(
    skeleton: Skeleton,
    q: ArrayLike,
    markers_mm: ArrayLike,
    effectors: Sequence[Effector],
) -> FloatArray:
    """Marker-to-joint offsets from frames where the pose is known.

    Averages ``R_j^T (m - o_j)`` (the marker in the effector joint's frame) over frames.

    Parameters
    ----------
    skeleton : Skeleton
    q : array_like, shape (N, D)
        Known poses.
    markers_mm : array_like, shape (N, E, 3)
        Marker-set positions (NaN for missing).
    effectors : sequence of Effector, length E

    Returns
    -------
    ndarray, shape (E, 3)
        Each marker set's position in its effector joint's frame (mm), i.e. the
        effector point to use; minus the default point it is the offset for
        ``HybridConfig.marker_offsets_mm``. NaN when never seen.
    """
    from mocapkit.skeleton.kinematics import forward_kinematics

    qa = np.asarray(q, dtype=float)
    m = np.asarray(markers_mm, dtype=float)
    if qa.ndim != 2 or m.shape != (qa.shape[0], len(effectors), 3):
        raise ShapeError(
            f"calibrate_marker_offsets: expected q (N, D) and markers (N, "
            f"{len(effectors)}, 3), found {qa.shape} and {m.shape}"
        )
    world = forward_kinematics(skeleton, qa)
    out = np.full((len(effectors), 3), np.nan)
    for e, eff in enumerate(effectors):
        local = points_in_frame(world[:, skeleton.joint_index(eff.joint)], m[:, e])
        ok = np.all(np.isfinite(local), axis=1)
        if ok.any():
            out[e] = local[ok].mean(axis=0)
    return out
