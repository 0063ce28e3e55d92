"""Selectively damped least-squares IK with a weighted Jacobian and a null-space secondary task.

Zhang, Brunnett & Rusdorf 2011, §4 (Alg. 1), as corrected by errata Z1-Z8 and Z13,
after Buss & Kim 2005 (SDLS) and Buss's released code (``CalcDeltaThetasSDLS``).
One iteration, for the active end effectors only:

1. forward kinematics; effector positions ``s`` and position Jacobian ``J`` (3K, D);
2. per-effector clamped error ``e_l = t_l - s_l`` shortened to ``D_max`` (Z2);
3. weighted Jacobian ``J_w = J diag(mu)^-1`` (Z3), ``psi_j = mu_j theta_j``;
4. SVD ``J_w = U S V^T``; terms with ``sigma_i < 1e-10 sigma_1`` are skipped (with
   `IKConfig.svd` ``"gesvd"`` U is not formed where no DoF is locked: see below);
5. SDLS: ``phi_i = ClampMaxAbs(sigma_i^-1 alpha_i v_i, gamma_i)`` with
   ``gamma_i = Gamma min(1, N_i / M_i)``, ``N_i`` the sum of the norms of the 3-blocks of
   ``u_i`` (Z4), ``M_i = sigma_i^-1 sum_l sum_j |v_ji| |J_w[l, j]|`` (Z5);
6. secondary task ``dphi`` (see :mod:`mocapkit.ik.secondary`) mapped to psi space
   (``mu_j dphi_j``, Z8e) and projected with the exact projector ``P = I - V_r V_r^T`` of
   the undamped SVD (Z7);
7. outer clamp of the sum (Buss & Kim's ``ClampMaxAbs(., Gamma)``, Z6), then
   ``dtheta = dpsi / mu``, clamp into the joint limits;
8. forward kinematics again (Z1: ``s`` is never updated as ``s + J dtheta``).

An iteration may do the work of several (`IKConfig.term_clamp_scale`,
`IKConfig.relax_substeps`): the per-term bounds of step 5 are scaled, and step 6 is
taken several times from the poses it reaches, on the same SVD.

Stop when every active effector is within ``tol_mm`` (after at least ``min_iterations``
steps, so a warm-started frame still relaxes a little) or after ``max_iterations``.

Weights ``mu`` (recipe Z): ``mu_j = sqrt(m_j / m_min)`` with ``m_j`` the carried mass
(complement of the subtree on a planted leg, Z8b) and ``m_min`` the smallest carried
mass of a revolute DoF, so ``min mu = 1`` over rotations and the bound ``Gamma`` on
``dpsi`` also bounds every angle step. Prismatic root DoFs are in mm, not radians:
they are made commensurate by a reference length ``L`` (default: the rest leg length,
hip to ankle), ``psi_j = mu_j q_j / L``, i.e. moving the pelvis by ``L delta`` costs as
much as tilting the whole body by ``delta`` radians about the planted feet, which is
what moving the pelvis over planted feet amounts to. Their step is bounded by
``Gamma L / mu_j`` mm. A model without legs (``azad14``) has no planted feet and
uses its arm length as ``L``.

Effectors, planted feet and the relaxed pose are found through canonical names
(:mod:`mocapkit.skeleton.limbs`), so the same solver runs on every preset. The kernel
`solve_ik_nb` takes the skeleton (`KinematicArrays`), the task (`IKTask`), the
per-DoF weighting (`IKWeighting`) and the settings (`IKSettings`) as named tuples.

Joint limits: a DoF clipped at a limit is locked (its Jacobian column zeroed) until a
later step moves it back inside, so the remaining DoFs take over the task instead
of the solver pushing against the limit every iteration. A zeroed column's step is
round-off from the singular vectors of numpy's SVD (LAPACK dgesdd), and its sign is
what releases the DoF. With `IKConfig.svd` ``"gesvd"`` (the hybrid tracker's), iterations
with a locked DoF keep that SVD of the whole ``J_w`` (`sdls_gesdd_nb`, also the
default's on every iteration) and the others (`sdls_nb`) take LAPACK's dgesvd without U over
the columns of the DoFs not frozen, with ``u_i = J_w v_i / sigma_i``: the same SDLS
response to round-off, 10-20 % cheaper an iteration, and much cheaper where most DoFs
are frozen (foot re-planting). With exact zeros a locked DoF would stay locked for the
rest of the solve (measured: solves stall short of their targets); releasing it by the
sign of ``J^T e`` (the gradient at the start of the step) let the scaled iteration
cycle between release and clip (docs/design-notes/hybrid.md).

`IKConfig.lock_release` ``"kkt"`` (the tracker's) releases by the active-set rule
instead: the locked columns are left out of the SVD like the frozen ones (exact zeros,
so dgesvd without U serves every iteration), and a locked DoF is released when the
step that the problem with its column back wants for it points inside the range
(`free_step_nb`: the damped least-squares step of ``[A a]`` towards the relaxed-pose
task's step, by Sherman-Morrison over the SVD already taken; for a column with a part
``c`` outside the others' range it is ``c . e / |c|^2``, the sign of the bound's
Lagrange multiplier at the constrained optimum, Lawson & Hanson's NNLS rule, not the
gradient ``J^T e`` at the start). No decision then rests on round-off: targets moved by
1e-9 mm move a solve by about 1e-9 rad, where the round-off rule moves it by a median
0.18 rad (tests/ik/test_sdls_locks.py).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import llvmlite.binding
import numba
import numpy as np
from numba.core import types as nb_types
from numba.extending import get_cython_function_address
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ConfigError, ShapeError, unknown_name
from mocapkit.ik.secondary import (
    SecondaryTask,
    carried_mass_planted,
    clamp_max_abs_nb,
    lever_weights_nb,
    planted_feet,
    secondary_task_nb,
)
from mocapkit.skeleton import limbs
from mocapkit.skeleton.kinematics import (
    KinematicArrays,
    fk_points_jacobian_pose_nb,
    kinematic_arrays,
    points_and_jacobian,
)
from mocapkit.skeleton.model import PRISMATIC, REVOLUTE, Skeleton

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Buss's released code uses 45 deg for the global bound Gamma (errata Z6).
DEFAULT_GAMMA_RAD = math.radians(45.0)
#: Singular values below this fraction of the largest are ignored (errata Z6).
SIGMA_CUTOFF = 1e-10
#: Canonical point of each effector name (Zhang et al. 2011 §4: head, hands, feet).
EFFECTOR_CANONICAL: dict[str, str] = {
    "head": "head",
    "left_hand": "left_wrist",
    "right_hand": "right_wrist",
    "left_foot": "left_ankle",
    "right_foot": "right_ankle",
}


@dataclass(frozen=True)
class Effector:
    """A point fixed to a joint that IK drives to a target.

    Parameters
    ----------
    name : str
        Effector name (marker-set name, e.g. ``"left_hand"``).
    joint : str
        Joint carrying the point.
    point_mm : tuple of 3 float
        The point in that joint's frame (mm). For a marker-driven effector this is
        the marker-to-joint offset: the marker set sits at this point.
    """

    name: str
    joint: str
    point_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class IKConfig:
    """Settings of the SDLS solver (defaults follow the errata and recipe Z).

    Parameters
    ----------
    gamma_rad : float
        Global maximum angle change per iteration, Gamma (45 deg).
    dmax_mm : float or None
        Per-effector target clamp; ``None`` means 0.1 x arm length (73 mm for Table 1).
    tol_mm : float
        Stop when every active effector is this close to its target.
    max_iterations, min_iterations : int
        Iteration bounds per solve.
    stall_iterations, stall_fraction : int, float
        Stop when neither the largest active effector error nor the sum of them has
        dropped by the share ``stall_fraction`` within ``stall_iterations`` steps (the
        largest alone would stop the others while one effector is out of reach, e.g.
        planted feet on their way back to their plants). Off (0) by default: slow
        but steady progress (a restore solve with the spine frozen) also looks like a
        stall; 35 steps and 0.5 % suit a caller that only wants a settled answer fast.
    secondary_gain : float
        ``k`` of the secondary task (0 disables it).
    secondary_max_step_rad : float
        ClampMaxAbs bound of the secondary task (errata Z8d uses Gamma). The exact
        projector holds the effectors only to first order (Z7); a null-space step of
        ``delta`` rad drifts an effector by about ``r delta^2 / 2`` (r ~ 700 mm), so with
        Gamma = 45 deg the main task and the secondary task settle into a fixed point
        several mm off the targets. 0.05 rad keeps the drift below 1 mm; relaxation
        accumulates over the frames of a warm-started sequence.
    clamp : {"hard", "soft"}
        ``"hard"``: Buss & Kim's paper clamps (ClampMaxAbs per term and on the sum);
        ``"soft"``: the factors of Buss's released code, ``g / (g + max|phi|)``.
    prismatic_length_mm : float or None
        Reference length ``L`` that converts root translation to an angle-like
        cost (default: rest leg length, hip to ankle).
    term_clamp_scale : float
        The per-term SDLS bounds ``gamma_i`` times this (``m``; 1 is the paper's
        SDLS). A term of small ``sigma_i`` has a small ``gamma_i`` (``N_i / M_i`` is about
        ``sigma_i / sigma_1``), so with an error it cannot remove (marker noise against
        a rigid model) SDLS crosses the flat valley of the least-squares problem by
        ``gamma_i`` per iteration, a few milliradians: measured on the hybrid's
        accuracy clips, the pose still moves by 0.1-0.3 (weighted rad) along terms of
        ``sigma_i`` 3-14 between iterations 10 and 100 while the largest error stays
        put, and the same with the secondary task off. Since ``J_w v_i = sigma_i u_i``,
        the terms do not interact in the linearised problem, and ``m`` SDLS iterations
        on a fixed Jacobian with the hard clamp (``e <- e - J_w dpsi`` between them)
        take each term exactly as far as one iteration with bounds ``m gamma_i``
        (tested); the outer clamp Gamma still bounds the whole step.
    relax_substeps : int
        Gradient steps of the secondary task per iteration (1 is the paper's), each
        from the pose the previous ones reached, within this iteration's null space and
        weights: with ``term_clamp_scale = m`` and ``relax_substeps = m``, one iteration
        does the work of ``m`` in both tasks, for the cost of one SVD.
    svd : {"gesdd", "gesvd"}
        ``"gesdd"``: numpy's SVD of the whole weighted Jacobian on every iteration
        (LAPACK dgesdd, U formed; the paper's solver as before). ``"gesvd"``: where no
        DoF is locked at a joint limit, LAPACK's dgesvd without U over the columns of
        the DoFs not frozen (`sdls_nb`): the same response to round-off, cheaper (module
        doc); iterations with a locked DoF still take dgesdd, whose round-off releases
        the lock. Trajectories differ from ``"gesdd"`` by round-off, which the chaotic
        cases amplify (docs/design-notes/hybrid.md).
    lock_release : {"roundoff", "kkt"}
        How a DoF locked at a joint limit (its column zeroed) is released.
        ``"roundoff"``: when its step, which is round-off from the SVD's singular
        vectors of the zeroed column, points inside (the solver as before; with ``svd
        "gesvd"`` such iterations take dgesdd). ``"kkt"``: the locked columns are left
        out of the SVD (exact zeros, the step of a locked DoF is exactly 0) and a DoF is
        released when the step the problem with its column back wants for it
        (`free_step_nb`: the damped least-squares step towards the relaxed-pose task's,
        the active-set rule) points inside by more than ``release_margin``; it takes
        effect on the next iteration. Deterministic: no decision rests on round-off.
    release_margin : float
        ``"kkt"``: the inward step (psi units, weighted rad) a locked DoF must want to be
        released; a hysteresis against releasing a DoF the next step clips again.
    release_damping : float
        ``"kkt"``: the damping of the release test's least-squares step, as a fraction
        of the largest singular value (``lam = release_damping sigma_1``): a column
        whose part outside the others' range is below it counts as redundant, so a part
        of round-off size does not decide.
    """

    gamma_rad: float = DEFAULT_GAMMA_RAD
    dmax_mm: float | None = None
    tol_mm: float = 1.0
    max_iterations: int = 100
    min_iterations: int = 1
    stall_iterations: int = 0
    stall_fraction: float = 0.005
    secondary_gain: float = 0.3
    secondary_max_step_rad: float = 0.05
    clamp: str = "hard"
    prismatic_length_mm: float | None = None
    relax_substeps: int = 1
    term_clamp_scale: float = 1.0
    svd: str = "gesdd"
    lock_release: str = "roundoff"
    release_margin: float = 1e-6
    release_damping: float = 1e-4

    def __post_init__(self) -> None:
        if not (0.0 < self.gamma_rad <= math.pi):
            raise ConfigError(
                f"IKConfig.gamma_rad: expected a value in (0, pi], found {self.gamma_rad}"
            )
        if self.dmax_mm is not None and not self.dmax_mm > 0:
            raise ConfigError(f"IKConfig.dmax_mm: expected a positive length, found {self.dmax_mm}")
        if not self.tol_mm > 0:
            raise ConfigError(
                f"IKConfig.tol_mm: expected a positive tolerance, found {self.tol_mm}"
            )
        if self.stall_iterations < 0 or not 0 <= self.stall_fraction < 1:
            raise ConfigError(
                "IKConfig: expected stall_iterations >= 0 and 0 <= stall_fraction < 1, found "
                f"{self.stall_iterations}, {self.stall_fraction}"
            )
        if self.max_iterations < 1 or not 0 <= self.min_iterations <= self.max_iterations:
            raise ConfigError(
                "IKConfig: expected 1 <= max_iterations and 0 <= min_iterations <= max_iterations, "
                f"found max_iterations={self.max_iterations}, min_iterations={self.min_iterations}"
            )
        if not 0.0 <= self.secondary_gain <= 1.0:
            raise ConfigError(
                f"IKConfig.secondary_gain: expected k in [0, 1] (recipe: 0.1-0.5), "
                f"found {self.secondary_gain}"
            )
        if not self.secondary_max_step_rad > 0:
            raise ConfigError(
                "IKConfig.secondary_max_step_rad: expected a positive angle, found "
                f"{self.secondary_max_step_rad}"
            )
        if self.svd not in ("gesdd", "gesvd"):
            raise ConfigError(f"IKConfig.svd: expected 'gesdd' or 'gesvd', found {self.svd!r}")
        if self.lock_release not in ("roundoff", "kkt"):
            raise ConfigError(
                f"IKConfig.lock_release: expected 'roundoff' or 'kkt', found {self.lock_release!r}"
            )
        if not (self.release_margin >= 0 and self.release_damping > 0):
            raise ConfigError(
                "IKConfig: expected release_margin >= 0 and release_damping > 0, found "
                f"{self.release_margin}, {self.release_damping}"
            )
        if self.clamp not in ("hard", "soft"):
            raise ConfigError(f"IKConfig.clamp: expected 'hard' or 'soft', found {self.clamp!r}")
        if self.relax_substeps < 1 or not self.term_clamp_scale >= 1.0:
            raise ConfigError(
                "IKConfig: expected relax_substeps >= 1 and term_clamp_scale >= 1, found "
                f"{self.relax_substeps}, {self.term_clamp_scale}"
            )


@dataclass
class IKResult:
    """Outcome of one solve.

    Attributes
    ----------
    q : ndarray, shape (D,)
    iterations : int
    residual_mm : ndarray, shape (E,)
        Distance of each effector to its target (NaN for inactive effectors).
    converged : bool
        Every active effector within ``tol_mm``.
    trace : ndarray, shape (iterations, 4) or None
        Per iteration: max effector error before the step (mm), max |dtheta| over
        revolute DoFs (rad), max |dpsi| (weighted units), max |dq| over prismatic DoFs (mm).
    """

    q: FloatArray
    iterations: int
    residual_mm: FloatArray
    converged: bool
    trace: FloatArray | None = field(default=None)


# ------------------------------------------------------------------ kernel arguments


class IKTask(NamedTuple):
    """What one solve asks for, in the layout `solve_ik_nb` takes (active effectors only).

    Attributes
    ----------
    eff_joint : ndarray of int64, shape (K,)
        Joint carrying each active effector.
    eff_point : ndarray of float64, shape (K, 3)
        Effector point in its joint's frame (mm).
    targets : ndarray of float64, shape (K, 3)
        Target of each effector (world, mm).
    frozen : ndarray of bool, shape (D,)
        DoFs held fixed.
    """

    eff_joint: NDArray[np.int64]
    eff_point: FloatArray
    targets: FloatArray
    frozen: BoolArray


class IKWeighting(NamedTuple):
    """Per-DoF weights, joint limits and the secondary task of one solver.

    Attributes
    ----------
    mu : ndarray, shape (D,)
        Cost weights of the weighted Jacobian (`dof_weights`, errata Z3).
    lower, upper : ndarray, shape (D,)
        Joint limits (rad, mm).
    omega : ndarray, shape (D,)
        Relaxed pose of the secondary task.
    sec_mask : ndarray of bool, shape (D,)
        DoFs the secondary task acts on (Z13).
    planted : ndarray of bool, shape (D,)
        DoFs that carry the complement of their subtree (Z8b).
    mass : ndarray, shape (J,)
        Segment masses (kg).
    com_local : ndarray, shape (J, 3)
        Segment centres of mass in their joint frames (mm).
    """

    mu: FloatArray
    lower: FloatArray
    upper: FloatArray
    omega: FloatArray
    sec_mask: BoolArray
    planted: BoolArray
    mass: FloatArray
    com_local: FloatArray


class IKSettings(NamedTuple):
    """Scalar settings of `solve_ik_nb`, from `IKConfig` (see there).

    Attributes
    ----------
    gain : float
        Secondary-task gain ``k`` (0 disables it).
    sec_max : float
        ClampMaxAbs bound of the secondary task (rad).
    dmax : float
        Per-effector target clamp (mm, Z2).
    gamma : float
        Global step bound Gamma (rad).
    soft : bool
        Buss's soft clamp factors instead of the paper's hard clamps.
    tol : float
        Stop when every active effector is this close (mm).
    max_iter, min_iter : int
        Iteration bounds.
    stall_iter : int
        Stop when neither the largest error nor the sum of the errors has dropped by
        ``stall_fraction`` in this many steps (0: off).
    stall_fraction : float
    substeps : int
        Gradient steps of the secondary task per iteration (`IKConfig.relax_substeps`).
    term_scale : float
        Factor on the per-term SDLS bounds (`IKConfig.term_clamp_scale`).
    thin_svd : bool
        `sdls_nb` where no DoF is locked (`IKConfig.svd` ``"gesvd"``), else `sdls_gesdd_nb`
        (with ``kkt_release``: `sdls_nb` on every iteration, locked columns left out).
    kkt_release : bool
        `IKConfig.lock_release` ``"kkt"``.
    release_margin, release_damping : float
        `IKConfig.release_margin`, `IKConfig.release_damping`.
    """

    gain: float
    sec_max: float
    dmax: float
    gamma: float
    soft: bool
    tol: float
    max_iter: int
    min_iter: int
    stall_iter: int
    stall_fraction: float
    substeps: int = 1
    term_scale: float = 1.0
    thin_svd: bool = False
    kkt_release: bool = False
    release_margin: float = 1e-6
    release_damping: float = 1e-4


# ------------------------------------------------------------------ compiled pieces

# LAPACK's dgesvd from SciPy's Cython bindings, bound by symbol name (not by address) so
# the kernels that call it stay in Numba's on-disk cache. ``np.linalg.svd`` in Numba
# always forms the thin U (dgesdd, jobz="S"); SDLS needs only the singular values, V and
# the few numbers of each term that ``u_i = J_w v_i / sigma_i`` gives (`sdls_nb`).
_DGESVD_SYMBOL = "mocapkit_sdls_dgesvd"
llvmlite.binding.add_symbol(
    _DGESVD_SYMBOL, get_cython_function_address("scipy.linalg.cython_lapack", "dgesvd")
)
_dgesvd: Any = nb_types.ExternalFunction(_DGESVD_SYMBOL, nb_types.void(*([nb_types.voidptr] * 14)))
#: ``jobu``, ``jobvt`` of dgesvd: no U, the first min(m, n) rows of V^T.
_JOB_NONE = ord("N")
_JOB_THIN = ord("S")


@numba.njit(cache=True)
def clamp_error_nb(s: FloatArray, t: FloatArray, dmax: float, out: FloatArray) -> None:
    """Per-effector target clamp (errata Z2): ``out[l] = t_l - s_l`` shortened to ``dmax``.

    ``s``, ``t`` (K, 3); ``out`` (3K,).
    """
    for k in range(s.shape[0]):
        dx = t[k, 0] - s[k, 0]
        dy = t[k, 1] - s[k, 1]
        dz = t[k, 2] - s[k, 2]
        n = math.sqrt(dx * dx + dy * dy + dz * dz)
        f = 1.0
        if n > dmax:
            f = dmax / n
        out[3 * k] = dx * f
        out[3 * k + 1] = dy * f
        out[3 * k + 2] = dz * f


@numba.njit(cache=True)
def thin_svd_v_nb(a: FloatArray, s: FloatArray, vt: FloatArray) -> None:
    """Singular values and right singular vectors of an (m, n) matrix, LAPACK dgesvd.

    ``a`` (n, m) is the matrix in column-major order (``a[j, r]`` its entry ``(r, j)``)
    and is overwritten. With ``jobu="N"``, ``jobvt="S"``: ``s`` (k,) descending and
    ``vt`` (n, k) with ``vt[j, i]`` the component ``j`` of ``v_i``, ``k = min(m, n)``.
    Raises ``np.linalg.LinAlgError`` where the QR iteration does not converge.
    """
    n_c, n_rows = a.shape
    k = min(n_rows, n_c)
    ints = np.empty(7, dtype=np.int32)  # m, n, lda, ldu, ldvt, lwork, info
    lwork = 8 * (n_rows + n_c)
    work = np.empty(lwork)
    u_dummy = np.empty(1)
    jobs = np.empty(2, dtype=np.uint8)
    jobs[0] = _JOB_NONE
    jobs[1] = _JOB_THIN
    ints[0] = n_rows
    ints[1] = n_c
    ints[2] = n_rows
    ints[3] = 1
    ints[4] = k
    ints[5] = lwork
    ints[6] = 0
    _dgesvd(
        jobs[0:].ctypes,
        jobs[1:].ctypes,
        ints[0:].ctypes,
        ints[1:].ctypes,
        a.ctypes,
        ints[2:].ctypes,
        s.ctypes,
        u_dummy.ctypes,
        ints[3:].ctypes,
        vt.ctypes,  # V^T (k, n) column-major: vt[j, i] = V^T[i, j]
        ints[4:].ctypes,
        work.ctypes,
        ints[5:].ctypes,
        ints[6:].ctypes,
    )
    if ints[6] != 0:
        raise np.linalg.LinAlgError("SVD did not converge")


@numba.njit(cache=True)
def sdls_nb(
    jw: FloatArray,
    e: FloatArray,
    gamma: float,
    soft: bool,
    dpsi: FloatArray,
    vr: FloatArray,
    n_out: FloatArray,
    m_out: FloatArray,
    term_scale: float,
    skip: BoolArray,
    s_out: FloatArray,
) -> int:
    """SDLS response ``dpsi`` (D,) of ``jw`` (3K, D) to the error ``e`` (3K,), per-term clamped.

    Writes the rows of ``V^T`` kept (rank r) into ``vr[:r]`` (for the null-space
    projector), ``N_i``, ``M_i`` into ``n_out[:r]``, ``m_out[:r]`` and the kept singular
    values into ``s_out[:r]``. Returns r.
    ``term_scale`` multiplies every per-term bound ``gamma_i`` (`IKConfig.term_clamp_scale`).
    ``skip`` (D,) marks zero columns to leave out of the SVD (frozen DoFs; their
    ``dpsi`` and ``vr`` entries are exactly 0). The SVD is LAPACK's dgesvd without U
    (`thin_svd_v_nb`); ``u_i = J_w v_i / sigma_i`` gives ``alpha_i`` and ``N_i``.
    The outer clamp is left to the caller (it also covers the secondary task).
    """
    n_rows, n_cols = jw.shape
    for j in range(n_cols):
        dpsi[j] = 0.0
    # the columns ``skip`` (frozen DoFs: zero) add only zero singular values (below
    # the cut-off) and null vectors, so the SVD is taken of the others alone. Their
    # ``dpsi`` is then exactly 0; for a DoF locked at a joint limit that would keep it
    # locked for good, so `solve_ik_nb` takes `sdls_gesdd_nb` on such iterations
    cols = np.empty(n_cols, dtype=np.int64)
    n_c = 0
    for j in range(n_cols):
        if not skip[j]:
            cols[n_c] = j
            n_c += 1
    if n_c == 0 or n_rows == 0:
        return 0
    k = min(n_rows, n_c)
    jwc = np.empty((n_c, n_rows))  # the nonzero columns, column-major
    for r in range(n_rows):
        for c in range(n_c):
            jwc[c, r] = jw[r, cols[c]]
    s = np.empty(k)
    vt = np.empty((n_c, k))
    thin_svd_v_nb(jwc.copy(), s, vt)
    # sigma_i u_i = J_w v_i, as rows (the SVD's own U is not formed)
    sigma_u = np.dot(vt.T, jwc)
    return _sdls_terms_nb(
        jw,
        e,
        s,
        sigma_u,
        True,
        vt,
        cols[:n_c],
        gamma,
        soft,
        dpsi,
        vr,
        n_out,
        m_out,
        term_scale,
        s_out,
    )


@numba.njit(cache=True)
def sdls_gesdd_nb(
    jw: FloatArray,
    e: FloatArray,
    gamma: float,
    soft: bool,
    dpsi: FloatArray,
    vr: FloatArray,
    n_out: FloatArray,
    m_out: FloatArray,
    term_scale: float,
    s_out: FloatArray,
) -> int:
    """`sdls_nb` from numpy's SVD of the whole ``jw`` (LAPACK dgesdd, U formed).

    `solve_ik_nb` takes this one on iterations where a DoF is held at a joint limit:
    there the locked DoF's zeroed column gets steps of round-off size from dgesdd's
    singular vectors, and their sign decides when the DoF is released (module doc).
    Its SVD and terms are e6e041f's `sdls_nb` (bit for bit), so the locks are released
    by the same rule.

    Writes the rows of ``V^T`` kept (rank r) into ``vr[:r]`` (for the null-space
    projector), ``N_i``, ``M_i`` into ``n_out[:r]``, ``m_out[:r]`` and the kept singular
    values into ``s_out[:r]``. Returns r.
    ``term_scale`` multiplies every per-term bound ``gamma_i`` (`IKConfig.term_clamp_scale`).
    The outer clamp is left to the caller (it also covers the secondary task).
    """
    n_cols = jw.shape[1]
    for j in range(n_cols):
        dpsi[j] = 0.0
    u, s, vt = np.linalg.svd(jw, full_matrices=False)
    every = np.arange(n_cols)
    return _sdls_terms_nb(
        jw, e, s, u.T, False, vt.T, every, gamma, soft, dpsi, vr, n_out, m_out, term_scale, s_out
    )


@numba.njit(cache=True)
def _sdls_terms_nb(
    jw: FloatArray,
    e: FloatArray,
    s: FloatArray,
    u_rows: FloatArray,
    u_times_sigma: bool,
    v: FloatArray,
    cols: NDArray[np.int64],
    gamma: float,
    soft: bool,
    dpsi: FloatArray,
    vr: FloatArray,
    n_out: FloatArray,
    m_out: FloatArray,
    term_scale: float,
    s_out: FloatArray,
) -> int:
    """The SDLS terms (errata Z4-Z6) of an SVD of the columns ``cols`` of ``jw`` (3K, D).

    ``s`` (k,) descending singular values; ``u_rows`` (k, 3K) row ``i`` the left singular
    vector ``u_i``, or ``sigma_i u_i`` (``= J_w v_i``) where ``u_times_sigma``; ``v``
    (len(cols), k) with ``v[c, i]`` the component of ``v_i`` on column ``cols[c]``. Adds
    each term's clamped step into ``dpsi`` (zeroed by the caller); writes the kept rows
    of ``V^T`` (zero off ``cols``) into ``vr[:r]``, ``N_i``, ``M_i`` into ``n_out[:r]``,
    ``m_out[:r]`` and ``sigma_i`` into ``s_out[:r]``. Returns the rank r. Shared by
    `sdls_nb` and `sdls_gesdd_nb`, so both SVDs give the same terms with the same
    arithmetic.
    """
    n_rows, n_cols = jw.shape
    n_eff = n_rows // 3
    n_c = cols.shape[0]
    if s.shape[0] == 0 or s[0] <= 0.0:
        return 0
    # rho[l, j]: norm of the 3-block of effector l in column j
    rho_sum = np.zeros(n_cols)
    for c in range(n_c):
        j = cols[c]
        acc = 0.0
        for ll in range(n_eff):
            a = jw[3 * ll, j]
            b = jw[3 * ll + 1, j]
            c3 = jw[3 * ll + 2, j]
            acc += math.sqrt(a * a + b * b + c3 * c3)
        rho_sum[j] = acc
    rank = 0
    for i in range(s.shape[0]):
        si = s[i]
        if si < SIGMA_CUTOFF * s[0] or si <= 0.0:
            continue
        alpha = 0.0
        n_i = 0.0
        for ll in range(n_eff):
            a = u_rows[i, 3 * ll]
            b = u_rows[i, 3 * ll + 1]
            c3 = u_rows[i, 3 * ll + 2]
            alpha += a * e[3 * ll] + b * e[3 * ll + 1] + c3 * e[3 * ll + 2]
            n_i += math.sqrt(a * a + b * b + c3 * c3)
        if u_times_sigma:
            inv_s = 1.0 / si
            alpha *= inv_s
            n_i *= inv_s
        m_i = 0.0
        for c in range(n_c):
            m_i += abs(v[c, i]) * rho_sum[cols[c]]
        m_i /= si
        g = gamma
        if n_i < m_i:
            g = gamma * n_i / m_i
        g *= term_scale
        scale = alpha / si
        mx = 0.0
        for c in range(n_c):
            ph = abs(scale * v[c, i])
            if ph > mx:
                mx = ph
        if soft:
            f = g / (g + mx)
        elif mx > g:
            f = g / mx
        else:
            f = 1.0
        for j in range(n_cols):
            vr[rank, j] = 0.0
        for c in range(n_c):
            j = cols[c]
            dpsi[j] += f * (scale * v[c, i])
            vr[rank, j] = v[c, i]
        n_out[rank] = n_i
        m_out[rank] = m_i
        s_out[rank] = si
        rank += 1
    return rank


@numba.njit(cache=True)
def free_step_nb(
    jw: FloatArray,
    vr: FloatArray,
    s: FloatArray,
    rank: int,
    qe: FloatArray,
    a: FloatArray,
    e0: FloatArray,
    z_j: float,
    lam2: float,
) -> float:
    """The step a locked DoF would take in the problem with its column back (psi units).

    ``jw`` (3K, D) is the weighted Jacobian with the locked and frozen DoFs' columns
    zeroed (``A``); ``vr[:rank]``, ``s[:rank]`` its kept right singular vectors and
    singular values; ``a`` (3K,) the locked DoF's own weighted column; ``z`` the
    secondary task's step (psi units; ``z_j`` the locked DoF's component); ``e0 = e - A
    z`` (3K,) the clamped error less the free DoFs' share of ``z``, and ``qe[i] = u_i .
    e0``. Returns component ``y`` of the damped least-squares step of ``[A a]`` towards
    ``z`` (the relaxed-pose task, as in SDLS's null-space term)::

        [x; y] = z + [A a]^T ([A a][A a]^T + lam2 I)^-1 (e - [A a] z)

    by Sherman-Morrison over ``A``'s SVD, ``p_i = u_i . a``, ``c = a - U U^T a``::

        y = z_j + (lam2 sum_i p_i (qe_i - p_i z_j) / (s_i^2 + lam2) + c . e0 - |c|^2 z_j)
                  / (lam2 (1 + sum_i p_i^2 / (s_i^2 + lam2)) + |c|^2)

    Where ``a`` has a part ``c`` outside ``A``'s range, ``y`` tends (``lam2 -> 0``) to the
    least-squares answer ``c . e / |c|^2`` (the sign of the bound's Lagrange multiplier at
    the constrained optimum, as in active-set least squares, Lawson & Hanson's NNLS);
    where ``a`` lies in it (the DoF is redundant), to the minimum-norm step plus the
    secondary task's null-space share (Greville's column update). ``lam2`` keeps ``|c|``
    of round-off size from deciding.
    """
    n_rows, n_cols = jw.shape
    # g = A^T a; p_i = u_i . a = v_i . g / s_i
    g = np.zeros(n_cols)
    aa = 0.0
    ae = 0.0
    for r in range(n_rows):
        ar = a[r]
        aa += ar * ar
        ae += ar * e0[r]
        if ar != 0.0:
            for d in range(n_cols):
                g[d] += jw[r, d] * ar
    pp = 0.0
    pq = 0.0
    num = 0.0
    den = 0.0
    for i in range(rank):
        p_i = 0.0
        for d in range(n_cols):
            p_i += vr[i, d] * g[d]
        p_i /= s[i]
        pp += p_i * p_i
        pq += p_i * qe[i]
        w = 1.0 / (s[i] * s[i] + lam2)
        num += p_i * (qe[i] - p_i * z_j) * w
        den += p_i * p_i * w
    cc = max(aa - pp, 0.0)
    ce = ae - pq
    return z_j + (lam2 * num + ce - cc * z_j) / (lam2 * (1.0 + den) + cc)


@numba.njit(cache=True)
def release_locks_nb(
    q: FloatArray,
    jac: FloatArray,
    jw: FloatArray,
    e: FloatArray,
    z: FloatArray,
    inv_mu: FloatArray,
    lower: FloatArray,
    upper: FloatArray,
    frozen: BoolArray,
    vr: FloatArray,
    s: FloatArray,
    rank: int,
    lam2: float,
    margin: float,
    locked: BoolArray,
    e0: FloatArray,
    h0: FloatArray,
    qe: FloatArray,
    a_col: FloatArray,
) -> None:
    """Release each locked DoF whose free step (`free_step_nb`) points inside by ``margin``.

    ``jac`` (3K, D) the Jacobian, ``jw`` the weighted one with the locked and frozen
    columns zeroed, ``e`` (3K,) the clamped error, ``z`` (D,) the secondary task's step
    (psi units, 0 where it is off), ``vr``, ``s``, ``rank`` the kept SVD terms of ``jw``.
    Clears ``locked[d]`` (it takes effect on the next iteration); ``e0``, ``h0``, ``qe``,
    ``a_col`` are work arrays.
    """
    n_rows, n_dofs = jw.shape
    # e0 = e - A z; qe_i = u_i . e0 = v_i . (A^T e0) / s_i
    for r in range(n_rows):
        acc = e[r]
        for d in range(n_dofs):
            acc -= jw[r, d] * z[d]
        e0[r] = acc
    for d in range(n_dofs):
        acc = 0.0
        for r in range(n_rows):
            acc += jw[r, d] * e0[r]
        h0[d] = acc
    for i in range(rank):
        acc = 0.0
        for d in range(n_dofs):
            acc += vr[i, d] * h0[d]
        qe[i] = acc / s[i]
    for d in range(n_dofs):
        if not locked[d] or frozen[d]:
            continue
        for r in range(n_rows):
            a_col[r] = jac[r, d] * inv_mu[d]
        y = free_step_nb(jw, vr, s, rank, qe, a_col, e0, z[d], lam2)
        if q[d] <= lower[d]:
            if y > margin:
                locked[d] = False
        elif q[d] >= upper[d]:
            if y < -margin:
                locked[d] = False
        else:
            locked[d] = False  # not at a limit (cannot happen: locked DoFs sit on one)


@numba.njit(cache=True)
def project_nullspace_nb(vr: FloatArray, rank: int, x: FloatArray, out: FloatArray) -> None:
    """``out = (I - V_r V_r^T) x`` with the first ``rank`` rows of ``vr`` (errata Z7)."""
    for j in range(x.shape[0]):
        out[j] = x[j]
    for i in range(rank):
        c = 0.0
        for j in range(x.shape[0]):
            c += vr[i, j] * x[j]
        for j in range(x.shape[0]):
            out[j] -= c * vr[i, j]


@numba.njit(cache=True)
def residuals_nb(targets: FloatArray, pts: FloatArray, residual: FloatArray) -> float:
    """Write each effector's distance to its target into ``residual`` (K,); return the
    largest (the stopping and stall criteria use it)."""
    worst = 0.0
    for k in range(pts.shape[0]):
        d = math.sqrt(
            (targets[k, 0] - pts[k, 0]) ** 2
            + (targets[k, 1] - pts[k, 1]) ** 2
            + (targets[k, 2] - pts[k, 2]) ** 2
        )
        residual[k] = d
        worst = max(worst, d)
    return worst


@numba.njit(cache=True)
def solve_ik_nb(
    q: FloatArray,
    kin: KinematicArrays,
    task: IKTask,
    weighting: IKWeighting,
    settings: IKSettings,
    residual: FloatArray,
    trace: FloatArray,
) -> int:
    """Algorithm 1 (corrected) for one frame; updates ``q`` (D,) in place.

    ``task`` lists the active effectors only (``K`` of them) and the ``frozen`` DoFs,
    which do not move. Writes the final distance of each effector to ``residual`` (K,)
    and per-iteration diagnostics to ``trace`` (max_iter, 4). Stops early when the
    largest error and the sum of the errors have not dropped by the share
    ``stall_fraction`` in ``stall_iter``
    steps (an unreachable target has settled; more steps only cost time). Returns the
    number of steps taken.
    """
    eff_joint, eff_point, targets, frozen = (
        task.eff_joint,
        task.eff_point,
        task.targets,
        task.frozen,
    )
    mu, lower, upper = weighting.mu, weighting.lower, weighting.upper
    gain, sec_max, dmax, gamma = settings.gain, settings.sec_max, settings.dmax, settings.gamma
    soft, tol = settings.soft, settings.tol
    max_iter, min_iter = settings.max_iter, settings.min_iter
    stall_iter, stall_fraction = settings.stall_iter, settings.stall_fraction
    n_joints = kin.parents.shape[0]
    dof_kind = kin.dof_kind
    n_dofs = q.shape[0]
    k_eff = eff_joint.shape[0]
    world = np.empty((n_joints, 4, 4))
    axis_world = np.empty((n_dofs, 3))
    pivot_world = np.empty((n_dofs, 3))
    pts = np.empty((k_eff, 3))
    jac = np.empty((3 * k_eff, n_dofs))
    jw = np.empty((3 * k_eff, n_dofs))
    e = np.empty(3 * k_eff)
    dpsi = np.empty(n_dofs)
    dphi = np.empty(n_dofs)
    dphi_p = np.empty(n_dofs)
    mh = np.empty(n_dofs)
    n_sv = min(3 * k_eff, n_dofs)
    vr = np.empty((max(n_sv, 1), n_dofs))
    n_buf = np.empty(max(n_sv, 1))
    m_buf = np.empty(max(n_sv, 1))
    s_buf = np.empty(max(n_sv, 1))
    locked = np.zeros(n_dofs, dtype=np.bool_)
    kkt = settings.kkt_release
    skip = np.empty(n_dofs, dtype=np.bool_)
    z = np.zeros(n_dofs)  # the secondary task's step (psi), locked DoFs included
    e0 = np.empty(3 * k_eff)
    h0 = np.empty(n_dofs)
    qe = np.empty(max(n_sv, 1))
    a_col = np.empty(3 * k_eff)
    live = np.empty(n_dofs, dtype=np.int64)  # the DoFs not frozen
    n_live = 0
    for d in range(n_dofs):
        if not frozen[d]:
            live[n_live] = d
            n_live += 1
    jw_live = np.empty((3 * k_eff, n_live))
    dpsi_live = np.empty(n_live)
    vr_live = np.empty((max(min(3 * k_eff, n_live), 1), n_live))
    inv_mu = 1.0 / mu
    use_secondary = gain > 0.0
    substeps = settings.substeps
    q_sub = np.empty(n_dofs)
    dphi_sub = np.empty(n_dofs)

    fk_points_jacobian_pose_nb(
        q, kin, eff_joint, eff_point, world, axis_world, pivot_world, pts, jac
    )
    err = residuals_nb(targets, pts, residual)
    it = 0
    # the stall criterion watches the largest error and the sum of the errors: the
    # largest alone stalls where one effector is out of reach while the others still
    # converge (planted feet pulled back onto their plants), the sum alone where one
    # error grows as the unreachable one shrinks
    best_err = err
    since_best = 0
    best_sum = residual.sum()
    since_best_sum = 0
    while it < max_iter and k_eff > 0:
        if err < tol and it >= min_iter:
            break
        if stall_iter > 0 and min(since_best, since_best_sum) >= stall_iter and it >= min_iter:
            break
        clamp_error_nb(pts, targets, dmax, e)
        for r in range(3 * k_eff):
            for d in range(n_dofs):
                if frozen[d] or locked[d]:
                    jw[r, d] = 0.0
                else:
                    jw[r, d] = jac[r, d] * inv_mu[d]
        use_gesdd = not settings.thin_svd
        n_locked = 0
        for d in range(n_dofs):
            if locked[d] and not frozen[d]:
                n_locked += 1
        if n_locked > 0 and not kkt:
            use_gesdd = True
        if kkt and not use_gesdd:
            # the locked columns are exact zeros: left out of the SVD like the frozen ones
            for d in range(n_dofs):
                skip[d] = frozen[d] or locked[d]
            rank = sdls_nb(
                jw, e, gamma, soft, dpsi, vr, n_buf, m_buf, settings.term_scale, skip, s_buf
            )
        elif use_gesdd and settings.thin_svd and n_live < n_dofs:
            # the frozen DoFs' zero columns are left out here too (re-planting solves
            # move the legs alone); the locked ones stay in
            for r in range(3 * k_eff):
                for c in range(n_live):
                    jw_live[r, c] = jw[r, live[c]]
            rank = sdls_gesdd_nb(
                jw_live,
                e,
                gamma,
                soft,
                dpsi_live,
                vr_live,
                n_buf,
                m_buf,
                settings.term_scale,
                s_buf,
            )
            for d in range(n_dofs):
                dpsi[d] = 0.0
            for c in range(n_live):
                dpsi[live[c]] = dpsi_live[c]
            for i in range(rank):
                for d in range(n_dofs):
                    vr[i, d] = 0.0
                for c in range(n_live):
                    vr[i, live[c]] = vr_live[i, c]
        elif use_gesdd:
            rank = sdls_gesdd_nb(
                jw, e, gamma, soft, dpsi, vr, n_buf, m_buf, settings.term_scale, s_buf
            )
        else:
            rank = sdls_nb(
                jw, e, gamma, soft, dpsi, vr, n_buf, m_buf, settings.term_scale, frozen, s_buf
            )
        if kkt and n_locked > 0:
            # a locked DoF does not move (its zeroed column's round-off in dgesdd's
            # singular vectors neither moves nor releases it: `release_locks_nb` does)
            for d in range(n_dofs):
                if locked[d]:
                    dpsi[d] = 0.0
                    for i in range(rank):
                        vr[i, d] = 0.0
        if use_secondary:
            lever_weights_nb(
                kin,
                world,
                axis_world,
                pivot_world,
                weighting.mass,
                weighting.com_local,
                weighting.planted,
                weighting.sec_mask,
                mh,
            )
            # ``substeps`` gradient steps of the task within this iteration's null space
            # (one: the paper's step), each from the pose the previous ones reached; the
            # weights and the projector stay those of this iteration's pose
            for d in range(n_dofs):
                dphi_p[d] = 0.0
                q_sub[d] = q[d]
            for _sub in range(substeps):
                secondary_task_nb(q_sub, weighting.omega, mh, gain, sec_max, dphi)
                if _sub == 0 and kkt:
                    for d in range(n_dofs):
                        z[d] = 0.0 if frozen[d] else dphi[d] * mu[d]
                for d in range(n_dofs):
                    # psi space (Z8e); a DoF held at a limit has a zeroed column, so the
                    # projector would not compensate its motion: leave it out
                    dphi[d] = 0.0 if (frozen[d] or locked[d]) else dphi[d] * mu[d]
                project_nullspace_nb(vr, rank, dphi, dphi_sub)
                for d in range(n_dofs):
                    dphi_p[d] += dphi_sub[d]
                    q_sub[d] = q[d] + dphi_p[d] * inv_mu[d]
            for d in range(n_dofs):
                dpsi[d] += dphi_p[d]
        if kkt and n_locked > 0 and rank > 0:
            release_locks_nb(
                q,
                jac,
                jw,
                e,
                z,
                inv_mu,
                lower,
                upper,
                frozen,
                vr,
                s_buf,
                rank,
                (settings.release_damping * s_buf[0]) ** 2,
                settings.release_margin,
                locked,
                e0,
                h0,
                qe,
                a_col,
            )
        # outer clamp on the sum (Buss & Kim); uniform scaling keeps the null-space part
        mx = 0.0
        for d in range(n_dofs):
            mx = max(mx, abs(dpsi[d]))
        if mx > gamma:
            f = gamma / (gamma + mx) if soft else gamma / mx
            for d in range(n_dofs):
                dpsi[d] *= f
        max_rev = 0.0
        max_pris = 0.0
        max_psi = 0.0
        for d in range(n_dofs):
            if frozen[d]:
                continue
            step = dpsi[d] * inv_mu[d]
            new = q[d] + step
            if new < lower[d]:
                new = lower[d]
                locked[d] = True
            elif new > upper[d]:
                new = upper[d]
                locked[d] = True
            elif locked[d] and step != 0.0:
                locked[d] = False  # moved back inside the limits
            taken = new - q[d]
            q[d] = new
            max_psi = max(max_psi, abs(taken * mu[d]))
            if dof_kind[d] == 1:
                max_pris = max(max_pris, abs(taken))
            else:
                max_rev = max(max_rev, abs(taken))
        if it < trace.shape[0]:
            trace[it, 0] = err
            trace[it, 1] = max_rev
            trace[it, 2] = max_psi
            trace[it, 3] = max_pris
        fk_points_jacobian_pose_nb(
            q, kin, eff_joint, eff_point, world, axis_world, pivot_world, pts, jac
        )
        err = residuals_nb(targets, pts, residual)
        if err < best_err * (1.0 - stall_fraction):
            best_err = err
            since_best = 0
        else:
            since_best += 1
        total = residual.sum()
        if total < best_sum * (1.0 - stall_fraction):
            best_sum = total
            since_best_sum = 0
        else:
            since_best_sum += 1
        it += 1
    return it


# ------------------------------------------------------------------ Python helpers


def clamp_max_abs(w: ArrayLike, d: float) -> FloatArray:
    """ClampMaxAbs (errata Z6): ``w`` if ``max|w| <= d``, else ``w d / max|w|``.

    Parameters
    ----------
    w : array_like, shape (n,)
    d : float
        Bound, >= 0.
    """
    out = np.array(w, dtype=float).ravel()
    clamp_max_abs_nb(out, float(d))
    return out


def clamp_target_error(s_mm: ArrayLike, t_mm: ArrayLike, dmax_mm: float) -> FloatArray:
    """Per-effector clamped error (errata Z2), shape (3K,) from ``s``, ``t`` of shape (K, 3)."""
    s = np.ascontiguousarray(s_mm, dtype=float)
    t = np.ascontiguousarray(t_mm, dtype=float)
    if s.ndim != 2 or s.shape[1] != 3 or t.shape != s.shape:
        raise ShapeError(
            f"clamp_target_error: expected s and t of equal shape (K, 3), found "
            f"{s.shape} and {t.shape}"
        )
    out = np.empty(s.size)
    clamp_error_nb(s, t, float(dmax_mm), out)
    return out


@dataclass
class SDLSStep:
    """One SDLS response (diagnostics for tests).

    Attributes
    ----------
    dpsi : ndarray (D,)  per-term clamped sum, before the outer clamp
    v_r : ndarray (r, D)  kept right singular vectors
    n : ndarray (r,)  N_i (Z4)
    m : ndarray (r,)  M_i (Z5)
    """

    dpsi: FloatArray
    v_r: FloatArray
    n: FloatArray
    m: FloatArray


def sdls_response(
    jw: ArrayLike,
    e: ArrayLike,
    gamma_rad: float = DEFAULT_GAMMA_RAD,
    soft: bool = False,
    term_clamp_scale: float = 1.0,
) -> SDLSStep:
    """SDLS response of a weighted Jacobian ``jw`` (3K, D) to an error ``e`` (3K,).

    ``term_clamp_scale`` multiplies the per-term bounds (`IKConfig.term_clamp_scale`)."""
    a = np.ascontiguousarray(jw, dtype=float)
    ev = np.ascontiguousarray(e, dtype=float)
    if a.ndim != 2 or a.shape[0] % 3 or ev.shape != (a.shape[0],):
        raise ShapeError(
            f"sdls_response: expected jw (3K, D) and e (3K,), found {a.shape}, {ev.shape}"
        )
    n_sv = max(min(a.shape), 1)
    dpsi = np.empty(a.shape[1])
    vr = np.empty((n_sv, a.shape[1]))
    nb = np.empty(n_sv)
    mb = np.empty(n_sv)
    sb = np.empty(n_sv)
    skip = ~np.any(a != 0.0, axis=0)  # zero columns (frozen DoFs)
    r = sdls_nb(
        a, ev, float(gamma_rad), bool(soft), dpsi, vr, nb, mb, float(term_clamp_scale), skip, sb
    )
    return SDLSStep(dpsi, vr[:r].copy(), nb[:r].copy(), mb[:r].copy())


def nullspace_projector(jw: ArrayLike) -> FloatArray:
    """Exact projector ``P = I - V_r V_r^T`` (D, D) onto the null space of ``jw`` (errata Z7)."""
    step = sdls_response(jw, np.zeros(np.shape(jw)[0]))
    d = step.v_r.shape[1]
    return np.eye(d) - step.v_r.T @ step.v_r


def arm_length_mm(skeleton: Skeleton) -> float:
    """Rest length of the left arm, shoulder to the end of the hand segment (mm).

    Upper arm + forearm + hand segments of `mocapkit.skeleton.limbs.arm` (730 mm for
    Table 1); 0.1 of it is the default target clamp ``D_max``.
    """
    if not limbs.has_limb(skeleton, "left_arm"):
        raise ShapeError(
            f"skeleton {skeleton.name!r} has no canonical left arm "
            "(left_shoulder, left_elbow, left_wrist); set IKConfig.dmax_mm explicitly"
        )
    total = limbs.limb_length_mm(skeleton, limbs.arm(skeleton, "left"), to_tip=True)
    if total <= 0:
        raise ShapeError(
            f"skeleton {skeleton.name!r}: the left arm has zero length; "
            "set IKConfig.dmax_mm explicitly"
        )
    return total


def leg_length_mm(skeleton: Skeleton) -> float:
    """Rest length of the left leg, hip joint to ankle (mm); arm length if there are no legs.

    The reference length ``L`` of the prismatic root DoFs (module doc). An upper-body
    model (``azad14``) has no legs; its arm length is the nearest stand-in for the
    scale of the body's motion.
    """
    if limbs.has_limb(skeleton, "left_leg"):
        return limbs.limb_length_mm(skeleton, limbs.leg(skeleton, "left"))
    return arm_length_mm(skeleton)


def dof_weights(
    skeleton: Skeleton,
    planted_joints: Sequence[str] | None = None,
    prismatic_length_mm: float | None = None,
) -> FloatArray:
    """Cost weights ``mu`` (D,) of the weighted Jacobian (recipe Z, errata Z3; see module doc).

    ``mu_j = sqrt(m_j / m_min)`` over revolute and ball DoFs (min 1); prismatic DoFs
    get ``sqrt(m_j / m_min) / L`` (per mm) with ``L = prismatic_length_mm`` or the leg length.
    ``planted_joints`` defaults to the ankles (`mocapkit.ik.secondary.planted_feet`).
    """
    if planted_joints is None:
        planted_joints = planted_feet(skeleton)
    m = carried_mass_planted(skeleton, planted_joints)
    rot = skeleton.dof_kind != PRISMATIC
    positive = m[rot & (m > 0)]
    if positive.size == 0:
        raise ShapeError(
            f"skeleton {skeleton.name!r}: no rotational DoF carries mass; "
            "cannot weight the Jacobian"
        )
    m_min = float(positive.min())
    mu = np.sqrt(np.maximum(m, m_min) / m_min)
    length = leg_length_mm(skeleton) if prismatic_length_mm is None else float(prismatic_length_mm)
    if not length > 0:
        raise ConfigError(f"prismatic_length_mm: expected a positive length, found {length}")
    mu = np.where(rot, mu, mu / length)
    return mu


def canonical_effector(skeleton: Skeleton, name: str) -> Effector:
    """The effector ``name`` (one of `EFFECTOR_CANONICAL`) at its canonical point.

    ``head`` is the canonical head point, ``left_hand``/``right_hand`` the wrists,
    ``left_foot``/``right_foot`` the ankles (Zhang et al. 2011 §4: head, hands, feet).

    Raises
    ------
    UnknownNameError
        For another name, or a skeleton without that canonical point (no legs).
    """
    if name not in EFFECTOR_CANONICAL:
        raise unknown_name("effector", name, EFFECTOR_CANONICAL)
    cname = EFFECTOR_CANONICAL[name]
    if cname not in skeleton.canonical:
        raise unknown_name(
            "canonical joint", cname, skeleton.canonical, f"skeleton {skeleton.name!r} ({name})"
        )
    joint, point = skeleton.canonical[cname]
    return Effector(name, joint, (float(point[0]), float(point[1]), float(point[2])))


def default_effectors(skeleton: Skeleton) -> tuple[Effector, ...]:
    """The effectors of the paper: head centre, the wrists and the ankles the skeleton has.

    Five on ``zhang21``; head and both hands on an upper-body model (``azad14``).
    """
    names = ["head"]
    names += [f"{arm.side}_hand" for arm in limbs.limbs_present(skeleton, "arm")]
    names += [f"{lg.side}_foot" for lg in limbs.limbs_present(skeleton, "leg")]
    return tuple(canonical_effector(skeleton, n) for n in names)


class SDLSSolver:
    """Warm-startable SDLS IK on one skeleton and a fixed list of effectors.

    Parameters
    ----------
    skeleton : Skeleton
    effectors : sequence of Effector, optional
        Defaults to `default_effectors` (head, hands, feet).
    config : IKConfig
    planted_joints : sequence of str, optional
        Joints held on the ground (affects mass weights, Z8b); by default the ankles
        of the legs the skeleton has (`mocapkit.ik.secondary.planted_feet`).
    omega : array_like, shape (D,), optional
        Relaxed pose for the secondary task.
    """

    def __init__(
        self,
        skeleton: Skeleton,
        effectors: Sequence[Effector] | None = None,
        config: IKConfig | None = None,
        planted_joints: Sequence[str] | None = None,
        omega: ArrayLike | None = None,
    ) -> None:
        self.skeleton = skeleton
        self.config = config or IKConfig()
        self.effectors = tuple(effectors) if effectors is not None else default_effectors(skeleton)
        if not self.effectors:
            raise ConfigError("SDLSSolver: expected at least one effector, found none")
        names = [e.name for e in self.effectors]
        if len(set(names)) != len(names):
            raise ConfigError(f"SDLSSolver: effector names must be unique, found {names}")
        if planted_joints is None:
            planted_joints = planted_feet(skeleton)
        planted = tuple(p for p in planted_joints if p in skeleton.joint_names)
        self.planted_joints = planted
        self.secondary = SecondaryTask(skeleton, planted, omega)
        self.mu = dof_weights(skeleton, planted, self.config.prismatic_length_mm)
        self.dmax_mm = (
            self.config.dmax_mm
            if self.config.dmax_mm is not None
            else 0.1 * arm_length_mm(skeleton)
        )
        self._kin = kinematic_arrays(skeleton)
        self._eff_joint = np.array(
            [skeleton.joint_index(e.joint) for e in self.effectors], dtype=np.int64
        )
        self._eff_point = np.array([e.point_mm for e in self.effectors], dtype=float).reshape(-1, 3)
        self._lower = np.ascontiguousarray(skeleton.lower)
        self._upper = np.ascontiguousarray(skeleton.upper)
        sec = self.secondary
        self._weighting = IKWeighting(
            mu=self.mu,
            lower=self._lower,
            upper=self._upper,
            omega=sec.omega,
            sec_mask=sec.mask,
            planted=sec.planted,
            mass=sec.mass,
            com_local=sec.com_local,
        )
        cfg = self.config
        self._settings = IKSettings(
            gain=float(cfg.secondary_gain),
            sec_max=float(min(cfg.secondary_max_step_rad, cfg.gamma_rad)),
            dmax=float(self.dmax_mm),
            gamma=float(cfg.gamma_rad),
            soft=cfg.clamp == "soft",
            tol=float(cfg.tol_mm),
            max_iter=int(cfg.max_iterations),
            min_iter=int(cfg.min_iterations),
            stall_iter=int(cfg.stall_iterations),
            stall_fraction=float(cfg.stall_fraction),
            substeps=int(cfg.relax_substeps),
            term_scale=float(cfg.term_clamp_scale),
            thin_svd=cfg.svd == "gesvd",
            kkt_release=cfg.lock_release == "kkt",
            release_margin=float(cfg.release_margin),
            release_damping=float(cfg.release_damping),
        )

    @property
    def effector_names(self) -> tuple[str, ...]:
        """Names of the effectors, in the order targets are given."""
        return tuple(e.name for e in self.effectors)

    def effector_index(self, name: str) -> int:
        """Index of an effector by name."""
        try:
            return self.effector_names.index(name)
        except ValueError:
            raise unknown_name("effector", name, self.effector_names, "SDLSSolver") from None

    def with_points(self, points_mm: ArrayLike) -> SDLSSolver:
        """A solver whose effector points (marker offsets in the joint frames) are replaced.

        Parameters
        ----------
        points_mm : array_like, shape (E, 3)
        """
        pts = np.asarray(points_mm, dtype=float)
        if pts.shape != (len(self.effectors), 3) or not np.all(np.isfinite(pts)):
            raise ShapeError(
                f"effector points: expected finite shape ({len(self.effectors)}, 3), "
                f"found {pts.shape}"
            )
        effs = [
            Effector(e.name, e.joint, (float(p[0]), float(p[1]), float(p[2])))
            for e, p in zip(self.effectors, pts, strict=True)
        ]
        return SDLSSolver(
            self.skeleton, effs, self.config, self.planted_joints, self.secondary.omega
        )

    def effector_positions(self, q: ArrayLike) -> FloatArray:
        """World positions (E, 3) of the effectors at pose ``q`` (D,)."""
        pts, _ = points_and_jacobian(self.skeleton, q, self._eff_joint, self._eff_point)
        return pts

    def weighted_jacobian(self, q: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Effector positions (E, 3), Jacobian ``J`` (3E, D) and ``J_w = J diag(mu)^-1``."""
        pts, jac = points_and_jacobian(self.skeleton, q, self._eff_joint, self._eff_point)
        return pts, jac, jac / self.mu[None, :]

    def solve(
        self,
        q0: ArrayLike,
        targets_mm: ArrayLike,
        active: ArrayLike | None = None,
        frozen: ArrayLike | None = None,
        record_trace: bool = False,
    ) -> IKResult:
        """Run the IK loop from ``q0`` (warm start).

        Parameters
        ----------
        q0 : array_like, shape (D,)
            Start pose (rad, mm); clipped into the limits.
        targets_mm : array_like, shape (E, 3)
            Target of each effector (world, mm); rows of inactive effectors are ignored
            and may be NaN.
        active : array_like of bool, shape (E,), optional
            Effectors in the task (default: those with finite targets).
        frozen : array_like of bool, shape (D,), optional
            DoFs held fixed.
        record_trace : bool
            Keep per-iteration diagnostics in the result.
        """
        sk = self.skeleton
        q = np.ascontiguousarray(np.asarray(q0, dtype=float).copy())
        sk.check_q(q, "q0")
        if q.shape != (sk.n_dofs,):
            raise ShapeError(f"q0: expected shape ({sk.n_dofs},), found {q.shape}")
        q = np.clip(q, self._lower, self._upper)
        t = np.asarray(targets_mm, dtype=float)
        n_eff = len(self.effectors)
        if t.shape != (n_eff, 3):
            raise ShapeError(
                f"targets_mm: expected shape ({n_eff}, 3) for effectors "
                f"{list(self.effector_names)}, found {t.shape}"
            )
        finite = np.all(np.isfinite(t), axis=1)
        act = finite if active is None else np.asarray(active, dtype=bool) & finite
        if act.shape != (n_eff,):
            raise ShapeError(f"active: expected shape ({n_eff},), found {act.shape}")
        frz = (
            np.zeros(sk.n_dofs, dtype=bool)
            if frozen is None
            else np.array(frozen, dtype=bool, order="C")  # a fresh writable array: one
        )  # kernel signature, whatever flags the caller's array has
        if frz.shape != (sk.n_dofs,):
            raise ShapeError(f"frozen: expected shape ({sk.n_dofs},), found {frz.shape}")
        idx = np.flatnonzero(act)
        cfg = self.config
        residual = np.full(len(idx), np.nan)
        trace = np.zeros((cfg.max_iterations if record_trace else 0, 4))
        task = IKTask(
            eff_joint=np.ascontiguousarray(self._eff_joint[idx]),
            eff_point=np.ascontiguousarray(self._eff_point[idx]),
            targets=np.ascontiguousarray(t[idx]),
            frozen=frz,
        )
        n_it = solve_ik_nb(q, self._kin, task, self._weighting, self._settings, residual, trace)
        res_all = np.full(n_eff, np.nan)
        res_all[idx] = residual
        converged = bool(len(idx) == 0 or np.all(residual < cfg.tol_mm))
        return IKResult(
            q=q,
            iterations=int(n_it),
            residual_mm=res_all,
            converged=converged,
            trace=trace[:n_it].copy() if record_trace else None,
        )


__all__ = [
    "DEFAULT_GAMMA_RAD",
    "EFFECTOR_CANONICAL",
    "REVOLUTE",
    "Effector",
    "IKConfig",
    "IKResult",
    "IKSettings",
    "IKTask",
    "IKWeighting",
    "SDLSSolver",
    "SDLSStep",
    "arm_length_mm",
    "canonical_effector",
    "clamp_max_abs",
    "clamp_target_error",
    "default_effectors",
    "dof_weights",
    "leg_length_mm",
    "nullspace_projector",
    "sdls_response",
]
