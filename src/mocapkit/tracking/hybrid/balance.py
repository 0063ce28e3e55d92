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
    Solve each frame: when the centre of gravity leaves the support box, find the
    lean that brings it back inside (a margin from the edge); ``tau = 0`` otherwise.
    Each trial lean costs a restore solve. Where the restore leaves head or hands off
    their markers (by more than twice the IK tolerance) without any lean, no lean is
    tried: the markers-first rule would halve it towards nothing (with noisy member
    markers that is most frames, each of which the search and the halving spent 20
    solves on). Otherwise the lean is bisected (14 solves; with ``guided_bisection``
    the same lean, or one already at the goal, from 1-5 where the restored CoG decreases
    with the lean).
    ``restore_without_lean=False`` (the tracker's default,
    `mocapkit.tracking.hybrid.tracker.TRACKING_BALANCE`) skips the restore
    solve wherever no lean is applied, unless an effector is more than
    ``restore_above_mm`` off its target.
``"off"``
    No balance step.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ConfigError, ShapeError
from mocapkit.ik.config import IKConfig
from mocapkit.ik.sdls import SDLSSolver
from mocapkit.skeleton.kinematics import (
    center_of_mass,
    center_of_mass_jacobian,
    forward_kinematics,
)
from mocapkit.skeleton.limbs import SIDES, foot_joints, has_limb, spine_dofs, vertical_root_dof
from mocapkit.skeleton.model import Skeleton

FloatArray = NDArray[np.float64]

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
        Bisection iterations on the lean angle (``"solve"`` mode and the
        calibration of the proportional rule).
    restore_without_lean : bool
        ``"solve"`` mode: where no lean is applied (the centre of gravity already inside
        the margin), still run the restore solve
        (spine frozen) from the pose. When False the pose is returned as it came, with
        no solve (the tracker's smoothing polish solves after the balance step anyway),
        unless an effector is more than ``restore_above_mm`` from its target.
    restore_above_mm : float
        ``restore_without_lean=False``: the restore still runs where an effector is
        this far (mm) from its target (a foot just re-planted, a hand the refinement
        moved); member-marker noise leaves about 5 mm.
    guided_bisection : bool
        ``"solve"`` mode: find the bisection's lean with fewer restore solves
        (`_monotone_bisection`: regula falsi on the bisection's own midpoints, the
        other midpoints' signs inferred where the restored CoG decreases with the lean,
        as it does with the head pinned). The same lean as the plain bisection wherever
        it decreases over the points involved, or a midpoint on the way already within
        `AT_GOAL_MM` of the goal (`mocapkit.tracking.hybrid.tracker.TRACKING_BALANCE`).
        False evaluates every bisection step.
    restore_stall_iterations : int
        The restore solves stop once neither the largest effector error nor their sum
        has dropped by 1 % in this many iterations, and end on the iterate of least
        summed error (`restore_ik_config`, `mocapkit.ik.config.IKConfig.stall_keep_best`);
        0: they run as the solver is configured. With noisy member markers no restore
        reaches the IK tolerance: it settles in 5-10 iterations, then chatters.
    restores_per_frame : int
        ``"solve"`` mode: 0 searches the lean in full on each frame (the bisection);
        n >= 2 carries the search over frames (`_stepped_lean`): each frame restores at
        most n leans, the first the previous frame's (``lean_rad`` of `balance_pose`),
        each next one a secant step towards the goal (or half way back where head and
        hands cannot be restored under it), so a frame costs at most n restore solves
        and a lean held still is reached over a few frames.
    """

    mode: str = "proportional"
    margin_fraction: float = 0.15
    bisection_steps: int = 12
    restore_without_lean: bool = True
    restore_above_mm: float = 20.0
    guided_bisection: bool = False
    restore_stall_iterations: int = 0
    restores_per_frame: int = 0

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
        if self.restores_per_frame < 0 or self.restores_per_frame == 1:
            raise ConfigError(
                "BalanceConfig.restores_per_frame: expected 0 (the full search each frame) "
                "or >= 2 (the previous frame's lean, then steps towards the goal), found "
                f"{self.restores_per_frame}"
            )
        if self.restore_stall_iterations < 0:
            raise ConfigError(
                "BalanceConfig.restore_stall_iterations: expected >= 0 (0: off), found "
                f"{self.restore_stall_iterations}"
            )


#: A restored CoG this close (mm) to the lean search's goal is at it: no lean is tried
#: where zero lean is, and the guided bisection stops at a lean that is (`_monotone_bisection`).
AT_GOAL_MM = 1.0

#: Share by which the errors must drop within `BalanceConfig.restore_stall_iterations`.
RESTORE_STALL_FRACTION = 0.01


def restore_ik_config(ik: IKConfig, config: BalanceConfig) -> IKConfig:
    """The settings of the balance step's restore solver: ``ik`` with the stall stop of
    ``config.restore_stall_iterations`` ending on the best iterate (unchanged when 0)."""
    if config.restore_stall_iterations == 0:
        return ik
    return replace(
        ik,
        stall_iterations=config.restore_stall_iterations,
        stall_fraction=RESTORE_STALL_FRACTION,
        stall_keep_best=True,
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

    The feet are the canonical ankles and the joints below them
    (`mocapkit.skeleton.limbs.foot_joints`). They are planted at their initial
    positions during tracking, and the model has no ankle DoF (a bent knee would tip
    the foot), so the support is taken from the initial (standing) pose and kept.
    """
    sides = [s for s in SIDES if has_limb(skeleton, f"{s}_leg")]
    if not sides:
        raise ShapeError(
            f"skeleton {skeleton.name!r} has no legs (canonical hips, knees, ankles); "
            "no base of support"
        )
    idx = np.concatenate([foot_joints(skeleton, s) for s in sides])
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


@functools.lru_cache(maxsize=64)
def spine_dof_indices(skeleton: Skeleton) -> tuple[int, ...]:
    """Indices of the spine flexion DoFs: the spine's rotations
    (`mocapkit.skeleton.limbs.spine_dofs`) about the mediolateral (x) axis, the axis of
    the paper's bow (§5.3); twists and side bends are left alone. Cached per skeleton
    (frozen, hashed by identity): the balance step asks for them several times a frame."""
    dofs = spine_dofs(skeleton)
    flexion = np.abs(skeleton.dof_axis[dofs, 0]) > 1.0 - 1e-9
    out = tuple(int(d) for d in dofs[flexion])
    if not out:
        raise ShapeError(
            f"skeleton {skeleton.name!r} has no spine flexion DoF (a rotation about x between "
            "the canonical pelvis and neck); the balance step needs one"
        )
    return out


def _spine_split(skeleton: Skeleton, spine: tuple[int, ...]) -> FloatArray:
    lengths = skeleton.bone_length_mm[skeleton.dof_joint[list(spine)]]
    return lengths / lengths.sum()


def _lean_range(skeleton: Skeleton, q: FloatArray) -> tuple[FloatArray, float, float]:
    """How a total lean is split over the spine DoFs (by bone length), and the smallest
    and largest total lean (rad) from ``q`` that keeps every spine DoF in its limits."""
    spine = list(spine_dof_indices(skeleton))
    split = _spine_split(skeleton, tuple(spine))
    base = q[spine]
    lo = float(np.max((skeleton.lower[spine] - base) / split))
    hi = float(np.min((skeleton.upper[spine] - base) / split))
    return split, lo, hi


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


def _bisection_cell(a: float, b: float, steps: int, x: float) -> tuple[float, float]:
    """The cell ``[a_k, b_k]`` of ``steps`` bisections of ``[a, b]`` that holds ``x``, its
    ends computed by the same floating-point operations as the bisection's midpoints."""
    for _ in range(steps):
        m = 0.5 * (a + b)
        if m < x:
            a = m
        else:
            b = m
    return a, b


def _monotone_bisection(
    f: Callable[[float], float],
    f0: float,
    lo: float,
    hi: float,
    steps: int,
    slope: float | None,
) -> tuple[float, float | None]:
    """The lean of `_bisect_lean`'s bisection of ``f`` (``f(0) = f0``) over ``[lo, hi]``,
    with fewer evaluations of ``f`` where ``f`` decreases.

    The bisection's result depends only on the signs of ``f`` at its midpoints. Where
    ``f`` decreases (the restored CoG moves back as the lean grows), the sign at a
    midpoint follows from any evaluated point beyond it (``f > 0`` at a larger lean,
    ``f <= 0`` at a smaller one), and so does whether the range reaches the goal. So
    the crossing is first narrowed down to one cell of the bisection by regula falsi on
    the bisection's own midpoints (Illinois rule; the first guess from ``slope``, the
    CoG's change per radian of lean, or the end of the range that the bisection
    evaluates first), and the bisection then runs with the signs it infers, evaluating
    only the others: the same lean as the plain bisection wherever ``f`` decreases over
    the points involved, with fewer evaluations (restore solves) where the guesses are
    good.

    A midpoint evaluated on the way whose ``|f|`` is below `AT_GOAL_MM` (as zero lean is
    taken below it) ends the search there: the restored CoG moves by 1-2 mm between
    restores of nearby leans (they settle differently), as much as a bisection cell
    moves it, and resolving that noise had cost up to 14 restores a frame.

    Returns the lean and the chord slope of ``f`` from zero lean to the bisection's
    last cell (or to the lean taken; None where it is not known), a guess of ``slope``
    for the next frame.
    """
    known: dict[float, float] = {0.0: f0}

    def value(x: float) -> float:
        if x not in known:
            known[x] = f(x)
        return known[x]

    def positive_at(x: float) -> bool | None:
        """Whether ``f(x) > 0``, where the known values imply it; else None."""
        if x in known:
            return known[x] > 0
        if any(v > 0 for p, v in known.items() if p >= x):
            return True
        if any(not v > 0 for p, v in known.items() if p <= x):
            return False
        return None

    # with the head pinned, a forward bow moves the pelvis (and the CoG) backwards
    a, b = (0.0, hi) if f0 > 0 else (lo, 0.0)
    end = b if f0 > 0 else a
    last_side = 0
    scale = {1: 1.0, -1: 1.0}  # Illinois: halve a side's value when it goes stale
    for _ in range(steps + 2):
        if end in known and np.sign(known[end]) == np.sign(f0):
            break  # the range cannot reach the goal: settled below, as the plain one does
        pos = [x for x, v in known.items() if v > 0]
        neg = [x for x, v in known.items() if not v > 0]
        if pos and neg:
            p, n = max(pos), min(neg)
            if p > n:
                break  # not decreasing: left to the bisection
            if _bisection_cell(a, b, steps, 0.5 * (p + n)) == (p, n):
                break  # the crossing's cell is known
            fp, fn = known[p] * scale[1], known[n] * scale[-1]
            x = p + fp * (n - p) / (fp - fn)
        elif slope is not None and slope < 0:
            # one side known: extrapolate by the secant through that side's two points
            # nearest the crossing where it is negative, else by the slope given
            side_pts = sorted(pos)[-2:] if pos else sorted(neg)[:2]
            near = side_pts[-1] if pos else side_pts[0]
            step_slope = slope
            if len(side_pts) == 2:
                secant = (known[side_pts[1]] - known[side_pts[0]]) / (side_pts[1] - side_pts[0])
                if secant < 0:
                    step_slope = secant
            x = min(max(near - known[near] / step_slope, a), b)
        else:
            x = end
        ca, cb = _bisection_cell(a, b, steps, x)
        todo = [c for c in (ca, cb) if c not in known]
        if not todo:
            break
        pick = min(todo, key=lambda c: abs(c - x))
        if abs(value(pick)) < AT_GOAL_MM:
            # at the goal within the restore's own noise: this lean, already restored
            return pick, (known[pick] - f0) / pick
        side = 1 if known[pick] > 0 else -1
        if side == last_side:
            scale[-side] *= 0.5
        else:
            scale = {1: 1.0, -1: 1.0}
        last_side = side
    # whether the range reaches the goal, as the plain bisection judges it
    reach = positive_at(end)
    if reach is None or reach == (f0 > 0):
        fe = value(end)
        if np.sign(fe) == np.sign(f0) or fe == 0.0:
            fa, fb = (f0, fe) if f0 > 0 else (fe, f0)
            if np.sign(fa) == np.sign(fb):  # the spine range cannot reach it: best end
                return (a if abs(fa) < abs(fb) else b), None
            return _plain_bisection(value, a, b, fa, steps), None
    for _ in range(steps):
        m = 0.5 * (a + b)
        right = positive_at(m)
        if right is None:
            right = value(m) > 0
        if right:
            a = m
        else:
            b = m
    # the chord from zero lean to the crossing's cell: the next frame's first step
    # starts from zero lean too (a cell's own secant is too local and noisy for it)
    far = a if abs(a) > abs(b) else b
    chord = (known[far] - f0) / far if far in known and far != 0.0 else None
    return 0.5 * (a + b), chord


def _plain_bisection(
    f: Callable[[float], float], a: float, b: float, fa: float, steps: int
) -> float:
    """``steps`` bisections of ``[a, b]`` keeping the sign change against ``f(a) = fa``."""
    for _ in range(steps):
        m = 0.5 * (a + b)
        fm = f(m)
        if np.sign(fm) == np.sign(fa):
            a, fa = m, fm
        else:
            b = m
    return 0.5 * (a + b)


def _bisect_lean(
    solver: SDLSSolver,
    q: FloatArray,
    targets: FloatArray,
    active: NDArray[np.bool_] | None,
    goal_mm: float,
    steps: int,
    support: FloatArray,
    at_zero: tuple[FloatArray, FloatArray] | None = None,
    guided: bool = True,
    slope_mm_per_rad: float | None = None,
    made: list[tuple[FloatArray, FloatArray, FloatArray]] | None = None,
) -> tuple[float, float | None]:
    """Total lean (rad) whose restored pose puts the CoG at ``goal_mm`` along the facing axis.

    ``at_zero``: the restore without lean (pose, residuals) when already solved.
    ``guided``: find the bisection's lean with fewer restore solves where the restored
    CoG decreases with the lean (`_monotone_bisection`), starting from
    ``slope_mm_per_rad`` (the previous search's) or else the analytic slope
    (`restored_lean_slope`); False runs every bisection step. Returns the lean and the
    slope found near it (None when not known), the next search's start. ``made``: a list
    that receives each restore solved, ``(taus, q, residual_mm)``, for the caller to
    re-use where it restores the same lean (an unreachable goal's end of the range).
    """
    sk = solver.skeleton
    split, lo, hi = _lean_range(sk, q)

    def f(total: float) -> float:
        if total == 0.0 and at_zero is not None:
            qq = at_zero[0]
        else:
            taus = total * split
            qq, resid = apply_lean(solver, q, taus, targets, active)
            if made is not None:
                made.append((taus, qq, resid))
        return cog_offset_mm(sk, qq, support)[0] - goal_mm

    f0 = f(0.0)
    if abs(f0) < AT_GOAL_MM:
        return 0.0, slope_mm_per_rad
    if guided:
        slope = slope_mm_per_rad
        if slope is None or not slope < 0:
            base = q if at_zero is None else at_zero[0]
            slope = restored_lean_slope(solver, base, targets, active)
        lean, found = _monotone_bisection(f, f0, lo, hi, steps, slope)
        return lean, found if found is not None and found < 0 else slope_mm_per_rad
    # with the head pinned, a forward bow moves the pelvis (and the CoG) backwards
    a, b = (0.0, hi) if f0 > 0 else (lo, 0.0)
    fa, fb = (f0, f(hi)) if f0 > 0 else (f(lo), f0)
    if np.sign(fa) == np.sign(fb):  # the spine range cannot reach the goal: best end
        return (a if abs(fa) < abs(fb) else b), slope_mm_per_rad
    return _plain_bisection(f, a, b, fa, steps), slope_mm_per_rad


#: Relative singular-value cut of the restore's linearisation in `restored_lean_slope`:
#: near a stretched knee the free DoFs' Jacobian has singular values ~1e-10 of its
#: largest, whose least-norm answers reach 1e11 rad (SDLS clamps such terms; the cut
#: drops them). 1e-3 and 1e-4 give the same slopes on the squat poses of the tests.
_SLOPE_RCOND = 1e-3


def restored_lean_slope(
    solver: SDLSSolver,
    q: ArrayLike,
    targets_mm: ArrayLike,
    active: ArrayLike | None = None,
) -> float:
    """Derivative of the restored centre of gravity along the facing axis per radian of lean.

    The restore (`apply_lean`) keeps the active effectors on their targets with the
    spine frozen. Linearised at ``q``, a lean ``d lambda`` split over the spine as
    `_spine_split` moves the effectors by ``J_s s d lambda``, and the restore answers
    with the free DoFs' weighted least-norm correction ``dq_f = -W^-1 (J_f W^-1)^+
    J_s s d lambda`` (``W = diag(mu)``, the solver's DoF weights, so the correction is
    the limit of the SDLS step without damping; the secondary task moves only in the
    null space and is left out; singular values below ``_SLOPE_RCOND`` of the largest
    are cut). The slope is ``f . J_cog (s, dq_f)`` with ``J_cog``
    from `mocapkit.skeleton.kinematics.center_of_mass_jacobian` and ``f`` the facing
    direction (mm per rad; negative where a forward bow moves the CoG backwards, as
    with the head pinned).

    Parameters
    ----------
    solver : SDLSSolver
        The restore's solver (its effectors and weights).
    q : array_like, shape (D,)
    targets_mm : array_like, shape (E, 3)
        Only which rows are finite matters (the active effectors).
    active : array_like of bool, shape (E,), optional
    """
    sk = solver.skeleton
    qa = np.asarray(q, dtype=float)
    t = np.asarray(targets_mm, dtype=float)
    act = np.all(np.isfinite(t), axis=1)
    if active is not None:
        act &= np.asarray(active, dtype=bool)
    spine = list(spine_dof_indices(sk))
    split = _spine_split(sk, tuple(spine))
    dq = np.zeros(sk.n_dofs)
    dq[spine] = split
    if np.any(act):
        _pts, jac, jw = solver.weighted_jacobian(qa)
        rows = np.repeat(act, 3)
        free = ~_spine_mask(sk, tuple(spine))
        moved = jac[rows][:, spine] @ split
        y = np.linalg.lstsq(jw[rows][:, free], -moved, rcond=_SLOPE_RCOND)[0]
        dq[free] = y / solver.mu[free]
    _com, jcog = center_of_mass_jacobian(sk, qa)
    return float(forward_direction(sk, qa) @ (jcog @ dq))


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
        leans[i] = _bisect_lean(
            solver, q, t, None, 0.5 * (back + front), bisection_steps, support, guided=False
        )[0]
    p_total = float(np.sum(leans * dh) / np.sum(dh * dh))
    return BalanceModel(spine, p_total * split)


@dataclass
class BalanceResult:
    """Outcome of the balance step: pose, spine increments and restore residuals, and
    the restored CoG's slope per radian of lean found by the search, a hint for the next
    frame's (None where not known); with `BalanceConfig.restores_per_frame`, the total
    lean (rad) the next frame restores first (None: none carried over)."""

    q: FloatArray
    taus: FloatArray
    residual_mm: FloatArray
    slope_mm_per_rad: float | None = None
    next_lean_rad: float | None = None


@dataclass
class _Steps:
    """What `_stepped_lean` found: the restored lean nearest the goal with head and
    hands on their markers (lean, pose, residuals; None where none), the restore at zero
    lean (where one was made), the next frame's first lean (the one found, else zero)
    and the slope to step with."""

    best: tuple[float, FloatArray, FloatArray] | None
    zero: tuple[FloatArray, FloatArray] | None
    next_lean_rad: float
    slope_mm_per_rad: float | None


def _stepped_lean(
    solver: SDLSSolver,
    q: FloatArray,
    targets: FloatArray,
    active: NDArray[np.bool_] | None,
    goal_mm: float,
    support: FloatArray,
    budget: int,
    steps: int,
    start_rad: float | None,
    slope_mm_per_rad: float | None,
) -> _Steps:
    """The lean search carried over frames: at most ``budget`` restores from ``start_rad``.

    The first restore is at ``start_rad`` (the previous frame's lean; zero lean where
    None), clipped to the spine's range. Each restore whose head and hands stay within
    twice the IK tolerance of their markers is a candidate, and the next lean a secant
    step from it towards ``goal_mm`` (the slope of this frame's last two candidates
    where they differ by more than the restores' own spread, `AT_GOAL_MM` twice, and it
    is negative; else ``slope_mm_per_rad``; else the analytic `restored_lean_slope`).
    A restore that leaves the markers (markers first, Z12) steps half way back to the
    nearest candidate (zero lean where there is none) and halves the steps that follow
    (the slope doubled), and one at zero lean ends the search with no lean, as the full
    search does; a candidate within `AT_GOAL_MM` of the goal ends it too. The candidate
    nearest the goal is taken, and the next frame restores it first (so ``budget`` >=
    2 to step at all): a lean held still is reached within a few frames, one that moves
    is followed a step behind. No step is shorter than a cell of the full search's
    bisection (``steps`` halvings of the spine's range), its resolution.
    """
    sk = solver.skeleton
    split, lo, hi = _lean_range(sk, q)
    limit = 2.0 * solver.config.tol_mm
    slope = slope_mm_per_rad if slope_mm_per_rad is not None and slope_mm_per_rad < 0 else None
    x = float(np.clip(0.0 if start_rad is None else start_rad, lo, hi))
    cell = (hi - lo) / 2**steps  # the full search's resolution: the shortest step
    found: list[tuple[float, float, FloatArray, FloatArray]] = []  # lean, f, q, residuals
    zero: tuple[FloatArray, FloatArray] | None = None
    for _ in range(budget):
        qx, resid = apply_lean(solver, q, x * split, targets, active)
        if x == 0.0:
            zero = (qx, resid)
        if np.nanmax(resid, initial=0.0) > limit:
            # head and hands cannot be restored under this lean (markers first): back
            # half way to the nearest lean they could be restored under (zero lean where
            # none was); without a lean, no lean is tried, as in the full search
            if x == 0.0:
                break
            if found and slope is not None:
                slope *= 2.0  # the step was too long: the next ones half as long
            x = 0.5 * (x + min((c[0] for c in found), key=lambda c: abs(c - x), default=0.0))
            continue
        fx = cog_offset_mm(sk, qx, support)[0] - goal_mm
        found.append((x, fx, qx, resid))
        if abs(fx) < AT_GOAL_MM:
            break
        if len(found) >= 2:
            (x0, f0), (x1, f1) = found[-2][:2], found[-1][:2]
            if abs(f1 - f0) > 2.0 * AT_GOAL_MM and (f1 - f0) / (x1 - x0) < 0:
                slope = (f1 - f0) / (x1 - x0)
        if slope is None:
            s = restored_lean_slope(solver, qx, targets, active)
            slope = s if s < 0 else None
        if slope is None:  # the restored CoG does not move back with the lean here
            break
        dx = -fx / slope
        step = float(np.clip(x + np.sign(dx) * max(abs(dx), cell), lo, hi))
        if step == x:  # the end of the spine's range: the goal is beyond it
            break
        x = step
    if not found:
        return _Steps(None, zero, 0.0, slope)
    lean, _f, qb, rb = min(found, key=lambda c: abs(c[1]))
    return _Steps((lean, qb, rb), zero, lean, slope)


def balance_pose(
    solver: SDLSSolver,
    q: ArrayLike,
    targets_mm: ArrayLike,
    root_height0_mm: float,
    support_mm: ArrayLike,
    model: BalanceModel | None,
    config: BalanceConfig | None = None,
    active: ArrayLike | None = None,
    slope_mm_per_rad: float | None = None,
    lean_rad: float | None = None,
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
    slope_mm_per_rad : float, optional
        The guided bisection's first slope (the previous frame's
        ``BalanceResult.slope_mm_per_rad``); the analytic one (`restored_lean_slope`)
        when None.
    lean_rad : float, optional
        With `BalanceConfig.restores_per_frame`: the first total lean to restore (the
        previous frame's ``BalanceResult.next_lean_rad``); zero lean when None.
    """
    cfg = config or BalanceConfig()
    sk = solver.skeleton
    qa = np.asarray(q, dtype=float)
    spine = spine_dof_indices(sk)
    if cfg.mode == "off":
        return BalanceResult(
            qa.copy(), np.zeros(len(spine)), np.full(len(solver.effectors), np.nan)
        )
    dh = float(qa[vertical_root_dof(sk)] - root_height0_mm)
    t = np.asarray(targets_mm, dtype=float)
    act = None if active is None else np.asarray(active, dtype=bool)
    solved: tuple[FloatArray, FloatArray] | None = None
    zero: tuple[FloatArray, FloatArray] | None = None
    # restores the search made, (taus, q, residual): the same lean restored again (from
    # the same pose) would give the same answer
    made: list[tuple[FloatArray, FloatArray, FloatArray]] = []
    slope = slope_mm_per_rad
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
            if not cfg.restore_without_lean:
                resid = _residuals(solver, qa, t, act)
                if not np.nanmax(resid, initial=0.0) > cfg.restore_above_mm:
                    # balanced: no lean, and no restore asked for
                    return BalanceResult(qa.copy(), taus, resid, slope, 0.0)
        else:
            goal = lo if cog < lo else hi
            split = _spine_split(sk, spine)
            limit = 2.0 * solver.config.tol_mm
            if not cfg.restore_without_lean:
                resid0 = _residuals(solver, qa, t, act)
                worst = float(np.nanmax(resid0, initial=0.0))
                if limit < worst <= cfg.restore_above_mm:
                    # off the markers: no lean (markers first), and no restore
                    return BalanceResult(qa.copy(), np.zeros(len(spine)), resid0, slope, lean_rad)
            if cfg.restores_per_frame:
                step = _stepped_lean(
                    solver,
                    qa,
                    t,
                    act,
                    goal,
                    support,
                    cfg.restores_per_frame,
                    cfg.bisection_steps,
                    lean_rad,
                    slope,
                )
                if step.best is not None:
                    lean, qn, resid = step.best
                    return BalanceResult(
                        qn, lean * split, resid, step.slope_mm_per_rad, step.next_lean_rad
                    )
                # no lean restored with head and hands on their markers: no lean
                none = np.zeros(len(spine))
                if step.zero is not None:
                    qn, resid = step.zero
                elif cfg.restore_without_lean or worst > cfg.restore_above_mm:
                    res = solver.solve(qa, t, active=act, frozen=_spine_mask(sk, spine))
                    qn, resid = res.q, res.residual_mm
                else:
                    qn, resid = qa.copy(), resid0
                return BalanceResult(qn, none, resid, step.slope_mm_per_rad, step.next_lean_rad)
            zero = apply_lean(solver, qa, np.zeros(len(spine)), t, act)
            if np.nanmax(zero[1], initial=0.0) > limit:
                # head and hands are off their markers even without a lean: no lean
                # (the markers-first rule below would halve any lean towards nothing)
                return BalanceResult(zero[0], np.zeros(len(spine)), zero[1], slope)
            total, slope = _bisect_lean(
                solver,
                qa,
                t,
                act,
                goal,
                cfg.bisection_steps,
                support,
                at_zero=zero,
                guided=cfg.guided_bisection,
                slope_mm_per_rad=slope_mm_per_rad,
                made=made,
            )
            solved = zero if total == 0.0 else None
            taus = total * split
    if not np.any(taus):
        if solved is not None:  # the search's own restore at zero lean
            return BalanceResult(solved[0], taus, solved[1], slope)
        res = solver.solve(qa, t, active=act, frozen=_spine_mask(sk, spine))
        return BalanceResult(res.q, taus, res.residual_mm, slope)
    # markers first (Z12): if head and hands cannot be restored under this lean,
    # halve the lean until they can
    tol = 2.0 * solver.config.tol_mm
    for _ in range(4):
        if solved is not None:  # the search already restored this lean
            qn, resid = solved
            solved = None
        else:
            again = [m for m in made if np.array_equal(m[0], taus)]
            qn, resid = (
                (again[0][1], again[0][2]) if again else apply_lean(solver, qa, taus, t, act)
            )
        if not np.nanmax(resid, initial=0.0) > tol:
            break
        taus = 0.5 * taus
    else:
        qn, resid = (
            zero if zero is not None else apply_lean(solver, qa, np.zeros_like(taus), t, act)
        )
        taus = np.zeros_like(taus)
    return BalanceResult(qn, taus, resid, slope)


def _residuals(
    solver: SDLSSolver, q: FloatArray, targets: FloatArray, active: NDArray[np.bool_] | None
) -> FloatArray:
    """Distance (mm) of each effector from its target at ``q``, shape (E,); NaN where
    inactive (as `mocapkit.ik.sdls.IKResult.residual_mm`)."""
    act = np.all(np.isfinite(targets), axis=1)
    if active is not None:
        act &= active
    out = np.full(len(targets), np.nan)
    if np.any(act):
        out[act] = np.linalg.norm(solver.effector_positions(q)[act] - targets[act], axis=1)
    return out


def _spine_mask(sk: Skeleton, spine: tuple[int, ...]) -> NDArray[np.bool_]:
    m = np.zeros(sk.n_dofs, dtype=bool)
    m[list(spine)] = True
    return m
