"""Balance heuristic: bow the spine so the centre of gravity stays over the feet (Zhang §5.3).

The paper rotates the three spine bones about the mediolateral axis by
``tau_i = p_i dh``, with ``dh`` the change of the root height from the first frame
(negative in a squat, so ``p_i < 0`` for forward flexion, errata Z12). Rotating the
spine alone moves head and hands off their markers (Z12), so after the bow the
pose is restored by IK with the spine frozen: the root translation, legs, neck
and arms take the head and hands back onto their markers (with the head pinned,
this shifts the pelvis backwards, as a real squat does). The centre of gravity
is judged after that restore, which is what `calibrate_balance` and the per-frame
mode bisect over.

Modes
-----
``"proportional"``
    The paper's rule, ``tau = p dh``, ``p`` calibrated per subject model (recipe Z):
    on a grid of squat depths (head and hands lowered by ``dh``, feet planted) the
    total lean that puts the centre of gravity over the centre of the support box
    is found by bisection; ``p`` is the least-squares slope through 0 and is split
    over the spine bones in proportion to their lengths.
``"solve"``
    Solve each frame: when the centre of gravity leaves the support box, bisect the
    lean that brings it back inside (a margin from the edge); ``tau = 0`` otherwise.
``"off"``
    No balance step.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ConfigError, ShapeError
from mocapkit.ik.sdls import SDLSSolver
from mocapkit.skeleton.kinematics import center_of_mass, forward_kinematics
from mocapkit.skeleton.model import Skeleton

FloatArray = NDArray[np.float64]

SPINE_DOFS: tuple[str, ...] = ("spine1_flexion", "spine2_flexion", "spine3_flexion")
FOOT_JOINTS: tuple[str, ...] = ("l_foot", "l_foot_end", "r_foot", "r_foot_end")
_BALANCE_MODES = ("proportional", "solve", "off")


@dataclass(frozen=True)
class BalanceConfig:
    """Settings of the balance step.

    Parameters
    ----------
    mode : {"proportional", "solve", "off"}
    margin_fraction : float
        ``"solve"`` mode: keep the centre of gravity this fraction of the box depth
        inside the front and back edges.
    bisection_steps : int
        Bisection iterations on the lean angle.
    """

    mode: str = "proportional"
    margin_fraction: float = 0.15
    bisection_steps: int = 12

    def __post_init__(self) -> None:
        if self.mode not in _BALANCE_MODES:
            raise ConfigError(
                f"BalanceConfig.mode: expected one of {_BALANCE_MODES}, found {self.mode!r}"
            )
        if not 0.0 <= self.margin_fraction < 0.5:
            raise ConfigError(
                f"BalanceConfig.margin_fraction: expected [0, 0.5), found {self.margin_fraction}"
            )
        if self.bisection_steps < 1:
            raise ConfigError(
                f"BalanceConfig.bisection_steps: expected >= 1, found {self.bisection_steps}"
            )


def forward_direction(skeleton: Skeleton, q: ArrayLike) -> FloatArray:
    """Horizontal unit vector the subject faces (the root frame's +Y), shape (3,)."""
    world = forward_kinematics(skeleton, q)
    f = world[0, :3, :3] @ np.array([0.0, 1.0, 0.0])
    f[2] = 0.0
    n = np.linalg.norm(f)
    return f / n if n > 1e-9 else np.array([0.0, 1.0, 0.0])


def support_points(skeleton: Skeleton, q: ArrayLike) -> FloatArray:
    """Ankle and toe-end positions (n, 3) of both feet at pose ``q`` (mm).

    The feet are planted at their initial positions during tracking, and the model
    has no ankle DoF (a bent knee would tip the foot), so the support is taken from
    the initial (standing) pose and kept.
    """
    idx = [skeleton.joint_index(n) for n in FOOT_JOINTS if n in skeleton.joint_names]
    if not idx:
        raise ShapeError(
            f"skeleton {skeleton.name!r} has no foot joints {FOOT_JOINTS}; no base of support"
        )
    return forward_kinematics(skeleton, q)[idx, :3, 3]


def cog_offset_mm(
    skeleton: Skeleton, q: ArrayLike, support_mm: ArrayLike | None = None
) -> tuple[float, float, float]:
    """Centre of gravity relative to the support box along the facing direction.

    Parameters
    ----------
    skeleton : Skeleton
    q : array_like, shape (D,)
    support_mm : array_like, shape (n, 3), optional
        Points spanning the base of support (`support_points` of the initial pose);
        those of ``q`` when omitted.

    Returns
    -------
    (cog, back, front) : floats
        Projections of the centre of gravity and of the box's back and front limits
        on the forward direction (mm).
    """
    fwd = forward_direction(skeleton, q)
    pts = support_points(skeleton, q) if support_mm is None else np.asarray(support_mm, float)
    proj = pts @ fwd
    return float(center_of_mass(skeleton, q) @ fwd), float(proj.min()), float(proj.max())


@dataclass(frozen=True)
class BalanceModel:
    """The calibrated proportional rule ``tau_i = p_i dh`` of one skeleton.

    Attributes
    ----------
    spine_dofs : tuple of int
        Indices of the spine flexion DoFs.
    p_rad_per_mm : ndarray, shape (n_spine,)
        Factors ``p_i`` (rad per mm of root height change).
    """

    spine_dofs: tuple[int, ...]
    p_rad_per_mm: FloatArray

    def taus(self, dh_mm: float) -> FloatArray:
        """Spine flexion increments ``tau_i = p_i dh`` (rad), shape (n_spine,)."""
        return self.p_rad_per_mm * float(dh_mm)


def spine_dof_indices(skeleton: Skeleton, names: Sequence[str] = SPINE_DOFS) -> tuple[int, ...]:
    """Indices of the spine flexion DoFs."""
    return tuple(skeleton.dof_index(n) for n in names)


def _spine_split(skeleton: Skeleton, spine: tuple[int, ...]) -> FloatArray:
    lengths = skeleton.bone_length_mm[skeleton.dof_joint[list(spine)]]
    return lengths / lengths.sum()


def apply_lean(
    solver: SDLSSolver,
    q: ArrayLike,
    taus: ArrayLike,
    targets_mm: ArrayLike,
    active: ArrayLike | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Add ``taus`` to the spine flexion, then restore the effectors with the spine frozen (Z12).

    Parameters
    ----------
    solver : SDLSSolver
    q : array_like, shape (D,)
    taus : array_like, shape (3,)
        Flexion increments of the spine DoFs (rad).
    targets_mm : array_like, shape (E, 3)
    active : array_like of bool, shape (E,), optional

    Returns
    -------
    q : ndarray (D,)
    residual_mm : ndarray (E,)
    """
    sk = solver.skeleton
    spine = spine_dof_indices(sk)
    qn = np.array(q, dtype=float)
    qn[list(spine)] += np.asarray(taus, dtype=float)
    qn = np.clip(qn, sk.lower, sk.upper)
    frozen = np.zeros(sk.n_dofs, dtype=bool)
    frozen[list(spine)] = True
    res = solver.solve(qn, targets_mm, active=active, frozen=frozen)
    return res.q, res.residual_mm


def _bisect_lean(
    solver: SDLSSolver,
    q: FloatArray,
    targets: FloatArray,
    active: NDArray[np.bool_] | None,
    goal_mm: float,
    steps: int,
    support: FloatArray,
) -> float:
    """Total lean (rad) whose restored pose puts the CoG at ``goal_mm`` along the facing axis."""
    sk = solver.skeleton
    spine = spine_dof_indices(sk)
    split = _spine_split(sk, spine)
    base = q[list(spine)]
    lo = float(np.max((sk.lower[list(spine)] - base) / split))
    hi = float(np.min((sk.upper[list(spine)] - base) / split))

    def f(total: float) -> float:
        qq, _ = apply_lean(solver, q, total * split, targets, active)
        return cog_offset_mm(sk, qq, support)[0] - goal_mm

    f0 = f(0.0)
    if abs(f0) < 1.0:
        return 0.0
    # with the head pinned, a forward bow moves the pelvis (and the CoG) backwards
    a, b = (0.0, hi) if f0 > 0 else (lo, 0.0)
    fa, fb = (f0, f(hi)) if f0 > 0 else (f(lo), f0)
    if np.sign(fa) == np.sign(fb):  # the spine range cannot reach the goal: best end
        return a if abs(fa) < abs(fb) else b
    for _ in range(steps):
        m = 0.5 * (a + b)
        fm = f(m)
        if np.sign(fm) == np.sign(fa):
            a, fa = m, fm
        else:
            b, fb = m, fm
    return 0.5 * (a + b)


def calibrate_balance(
    solver: SDLSSolver,
    q_rest: ArrayLike | None = None,
    dh_grid_mm: ArrayLike = (-50.0, -100.0, -150.0, -200.0, -250.0, -300.0),
    bisection_steps: int = 12,
) -> BalanceModel:
    """Fit ``p_i`` of ``tau_i = p_i dh`` on synthetic squats (recipe Z; see module docstring).

    Parameters
    ----------
    solver : SDLSSolver
        IK with effectors ``head``, ``left_hand``, ``right_hand`` and planted feet.
    q_rest : array_like, shape (D,), optional
        Standing pose (default: the solver's relaxed pose).
    dh_grid_mm : array_like
        Root-height changes (negative: squat) of the calibration squats.
    """
    sk = solver.skeleton
    q0 = solver.secondary.omega.copy() if q_rest is None else np.asarray(q_rest, float).copy()
    s0 = solver.effector_positions(q0)
    lowered = [
        solver.effector_index(n)
        for n in ("head", "left_hand", "right_hand")
        if n in solver.effector_names
    ]
    spine = spine_dof_indices(sk)
    split = _spine_split(sk, spine)
    dh = np.asarray(dh_grid_mm, dtype=float)
    if dh.ndim != 1 or dh.size == 0 or np.any(dh == 0) or not np.all(np.isfinite(dh)):
        raise ShapeError(f"dh_grid_mm: expected non-zero finite heights, found {dh}")
    leans = np.empty_like(dh)
    q = q0.copy()
    support = support_points(sk, q0)
    for i, d in enumerate(dh):
        t = s0.copy()
        t[lowered, 2] += d
        for _ in range(20):  # let the secondary task settle the squat pose
            q = solver.solve(q, t).q
        back, front = cog_offset_mm(sk, q, support)[1:]
        leans[i] = _bisect_lean(solver, q, t, None, 0.5 * (back + front), bisection_steps, support)
    p_total = float(np.sum(leans * dh) / np.sum(dh * dh))
    return BalanceModel(spine, p_total * split)


@dataclass
class BalanceResult:
    """Outcome of the balance step: pose, spine increments and restore residuals."""

    q: FloatArray
    taus: FloatArray
    residual_mm: FloatArray


def balance_pose(
    solver: SDLSSolver,
    q: ArrayLike,
    targets_mm: ArrayLike,
    root_height0_mm: float,
    support_mm: ArrayLike,
    model: BalanceModel | None,
    config: BalanceConfig | None = None,
    active: ArrayLike | None = None,
) -> BalanceResult:
    """Apply the balance heuristic to an IK pose and restore head and hands (Z12).

    Parameters
    ----------
    solver : SDLSSolver
    q : array_like, shape (D,)
        Pose after IK (and video refinement).
    targets_mm : array_like, shape (E, 3)
    root_height0_mm : float
        Root height parameter (the ``root_tz`` DoF, mm) in the initial frame.
    support_mm : array_like, shape (n, 3)
        Base of support: `support_points` of the initial pose.
    model : BalanceModel or None
        Calibrated factors (needed by ``"proportional"``).
    config : BalanceConfig
    active : array_like of bool, shape (E,), optional
    """
    cfg = config or BalanceConfig()
    sk = solver.skeleton
    qa = np.asarray(q, dtype=float)
    spine = spine_dof_indices(sk)
    if cfg.mode == "off":
        return BalanceResult(
            qa.copy(), np.zeros(len(spine)), np.full(len(solver.effectors), np.nan)
        )
    dh = float(qa[sk.dof_index("root_tz")] - root_height0_mm)
    t = np.asarray(targets_mm, dtype=float)
    act = None if active is None else np.asarray(active, dtype=bool)
    if cfg.mode == "proportional":
        if model is None:
            raise ConfigError("balance_pose: mode 'proportional' needs a calibrated BalanceModel")
        taus = model.taus(dh)
    else:
        support = np.asarray(support_mm, dtype=float)
        cog, back, front = cog_offset_mm(sk, qa, support)
        margin = cfg.margin_fraction * (front - back)
        lo, hi = back + margin, front - margin
        if lo <= cog <= hi:
            taus = np.zeros(len(spine))
        else:
            goal = lo if cog < lo else hi
            split = _spine_split(sk, spine)
            taus = _bisect_lean(solver, qa, t, act, goal, cfg.bisection_steps, support) * split
    if not np.any(taus):
        res = solver.solve(qa, t, active=act, frozen=_spine_mask(sk, spine))
        return BalanceResult(res.q, taus, res.residual_mm)
    # markers first (Z12): if head and hands cannot be restored under this lean,
    # halve the lean until they can
    tol = 2.0 * solver.config.tol_mm
    for _ in range(4):
        qn, resid = apply_lean(solver, qa, taus, t, act)
        if not np.nanmax(resid, initial=0.0) > tol:
            break
        taus = 0.5 * taus
    else:
        qn, resid = apply_lean(solver, qa, np.zeros_like(taus), t, act)
        taus = np.zeros_like(taus)
    return BalanceResult(qn, taus, resid)


def _spine_mask(sk: Skeleton, spine: tuple[int, ...]) -> NDArray[np.bool_]:
    m = np.zeros(sk.n_dofs, dtype=bool)
    m[list(spine)] = True
    return m
