"""The compiled IK loop of one frame (Algorithm 1 of Zhang et al. 2011, corrected)."""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
from numpy.typing import NDArray

from mocapkit.ik.rigid_rows import rigid_sets_nb
from mocapkit.ik.sdls_step import (
    clamp_error_nb,
    project_nullspace_nb,
    residuals_nb,
    sdls_gesdd_nb,
    sdls_nb,
    used_columns_nb,
)
from mocapkit.ik.secondary import lever_weights_nb, secondary_task_nb
from mocapkit.skeleton.kinematics import KinematicArrays, fk_points_jacobian_pose_nb

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


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
    keep_best : bool
        With ``stall_iter``: the solve ends on the iterate where the sum of the errors
        was smallest (`IKConfig.stall_keep_best`).
    substeps : int
        Gradient steps of the secondary task per iteration (`IKConfig.relax_substeps`).
    term_scale : float
        Factor on the per-term SDLS bounds (`IKConfig.term_clamp_scale`).
    thin_svd : bool
        `sdls_nb` where no DoF is locked (`IKConfig.svd` ``"gesvd"``), else `sdls_gesdd_nb`.
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
    keep_best: bool = False


class _Buffers(NamedTuple):
    """Work arrays of one solve, allocated once (`_buffers_nb`)."""

    jw: FloatArray
    dpsi: FloatArray
    vr: FloatArray
    n: FloatArray
    m: FloatArray
    s: FloatArray
    dpsi_live: FloatArray
    vr_live: FloatArray
    mh: FloatArray
    dphi: FloatArray
    dphi_p: FloatArray
    dphi_sub: FloatArray
    q_sub: FloatArray


@numba.njit(cache=True)
def _buffers_nb(k_eff: int, n_dofs: int, n_live: int) -> _Buffers:
    """The work arrays for ``k_eff`` effectors, ``n_dofs`` DoFs of which ``n_live`` move."""
    n_sv = max(min(3 * k_eff, n_dofs), 1)
    return _Buffers(
        np.empty((3 * k_eff, n_dofs)),
        np.empty(n_dofs),
        np.empty((n_sv, n_dofs)),
        np.empty(n_sv),
        np.empty(n_sv),
        np.empty(n_sv),
        np.empty(n_live),
        np.empty((max(min(3 * k_eff, n_live), 1), n_live)),
        np.empty(n_dofs),
        np.empty(n_dofs),
        np.empty(n_dofs),
        np.empty(n_dofs),
        np.empty(n_dofs),
    )


@numba.njit(cache=True)
def _sdls_step_nb(
    jac: FloatArray,
    inv_mu: FloatArray,
    frozen: BoolArray,
    locked: BoolArray,
    e: FloatArray,
    settings: IKSettings,
    bufs: _Buffers,
    pts: FloatArray,
    sets: tuple[NDArray[np.int64], NDArray[np.int64]],
) -> int:
    """Steps 3-5 of one iteration: the weighted Jacobian and its SDLS response ``bufs.dpsi``.

    Frozen and locked DoFs get zero columns. The SVD routine is chosen by
    `IKSettings.thin_svd` and the locks (module doc of `mocapkit.ik.sdls`): dgesdd of the
    whole ``J_w`` (with ``thin_svd``: of its columns not frozen, less those that are zero
    without a lock) while a DoF is locked, else dgesvd without U. With ``thin_svd`` both
    take the SVD of the rigid sets' fewer rows (``sets`` of `rigid_sets_nb`, ``pts`` the
    effectors' positions; `mocapkit.ik.rigid_rows`). Returns the rank; the kept right
    singular vectors are in ``bufs.vr``.
    """
    jw, dpsi, vr = bufs.jw, bufs.dpsi, bufs.vr
    n_rows, n_dofs = jw.shape
    gamma, soft, scale = settings.gamma, settings.soft, settings.term_scale
    for r in range(n_rows):
        for d in range(n_dofs):
            if frozen[d] or locked[d]:
                jw[r, d] = 0.0
            else:
                jw[r, d] = jac[r, d] * inv_mu[d]
    use_gesdd = not settings.thin_svd
    for d in range(n_dofs):
        if locked[d] and not frozen[d]:
            use_gesdd = True
    if use_gesdd and settings.thin_svd:
        # the frozen DoFs' zero columns are left out here too (re-planting solves move
        # the legs alone), and so are the columns that are zero without a lock (the
        # legs where the feet are free); the locked ones stay in
        cols, n_use = used_columns_nb(jw, frozen, locked)
        if n_use < n_dofs:
            jw_live = np.empty((n_rows, n_use))
            for r in range(n_rows):
                for c in range(n_use):
                    jw_live[r, c] = jw[r, cols[c]]
            dpsi_live, vr_live = bufs.dpsi_live[:n_use], bufs.vr_live[:, :n_use]
            rank = sdls_gesdd_nb(
                jw_live, e, gamma, soft, dpsi_live, vr_live, bufs.n, bufs.m, scale, bufs.s,
                pts, sets,
            )  # fmt: skip
            for d in range(n_dofs):
                dpsi[d] = 0.0
            for c in range(n_use):
                dpsi[cols[c]] = dpsi_live[c]
            for i in range(rank):
                for d in range(n_dofs):
                    vr[i, d] = 0.0
                for c in range(n_use):
                    vr[i, cols[c]] = vr_live[i, c]
            return rank
    if use_gesdd:
        # the paper's solver (``svd="gesdd"``) takes every row, as before the rigid sets
        every = (sets[0], np.zeros(1, dtype=np.int64)) if not settings.thin_svd else sets
        return sdls_gesdd_nb(
            jw, e, gamma, soft, dpsi, vr, bufs.n, bufs.m, scale, bufs.s, pts, every
        )
    return sdls_nb(jw, e, gamma, soft, dpsi, vr, bufs.n, bufs.m, scale, frozen, bufs.s, pts, sets)


@numba.njit(cache=True)
def _relax_nb(
    q: FloatArray,
    kin: KinematicArrays,
    frames: tuple[FloatArray, FloatArray, FloatArray],
    weighting: IKWeighting,
    settings: IKSettings,
    frozen: BoolArray,
    locked: BoolArray,
    rank: int,
    inv_mu: FloatArray,
    bufs: _Buffers,
) -> None:
    """Step 6: the secondary task's step, projected into the null space, added to ``bufs.dpsi``.

    ``settings.substeps`` gradient steps of the task within this iteration's null space
    (one: the paper's step), each from the pose the previous ones reached; the weights
    and the projector stay those of this iteration's pose.
    """
    world, axis_world, pivot_world = frames
    mu, mh, dphi, dphi_p = weighting.mu, bufs.mh, bufs.dphi, bufs.dphi_p
    q_sub, dphi_sub = bufs.q_sub, bufs.dphi_sub
    n_dofs = q.shape[0]
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
    for d in range(n_dofs):
        dphi_p[d] = 0.0
        q_sub[d] = q[d]
    for _sub in range(settings.substeps):
        secondary_task_nb(q_sub, weighting.omega, mh, settings.gain, settings.sec_max, dphi)
        for d in range(n_dofs):
            # psi space (Z8e); a DoF held at a limit has a zeroed column, so the
            # projector would not compensate its motion: leave it out
            dphi[d] = 0.0 if (frozen[d] or locked[d]) else dphi[d] * mu[d]
        project_nullspace_nb(bufs.vr, rank, dphi, dphi_sub)
        for d in range(n_dofs):
            dphi_p[d] += dphi_sub[d]
            q_sub[d] = q[d] + dphi_p[d] * inv_mu[d]
    for d in range(n_dofs):
        bufs.dpsi[d] += dphi_p[d]


@numba.njit(cache=True)
def _take_step_nb(
    q: FloatArray,
    dpsi: FloatArray,
    weighting: IKWeighting,
    settings: IKSettings,
    frozen: BoolArray,
    locked: BoolArray,
    dof_kind: NDArray[np.int64],
    inv_mu: FloatArray,
    stats: FloatArray,
) -> None:
    """Step 7: the outer clamp of ``dpsi``, ``q += dpsi / mu`` clipped into the limits.

    A DoF clipped at a limit is locked; a locked DoF that steps back inside is released.
    Writes the largest step taken over revolute DoFs (rad), in psi units and over
    prismatic DoFs (mm) to ``stats`` (3,).
    """
    gamma = settings.gamma
    mu, lower, upper = weighting.mu, weighting.lower, weighting.upper
    n_dofs = q.shape[0]
    # outer clamp on the sum (Buss & Kim); uniform scaling keeps the null-space part
    mx = 0.0
    for d in range(n_dofs):
        mx = max(mx, abs(dpsi[d]))
    if mx > gamma:
        f = gamma / (gamma + mx) if settings.soft else gamma / mx
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
    stats[0] = max_rev
    stats[1] = max_psi
    stats[2] = max_pris


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
    ``stall_fraction`` in ``stall_iter`` steps (an unreachable target has settled; more
    steps only cost time); with ``keep_best`` the solve ends on the iterate where the
    sum of the errors was smallest. Returns the number of steps taken.
    """
    eff_joint, eff_point, targets, frozen = (
        task.eff_joint,
        task.eff_point,
        task.targets,
        task.frozen,
    )
    tol, min_iter = settings.tol, settings.min_iter
    stall_iter, stall_fraction = settings.stall_iter, settings.stall_fraction
    n_dofs = q.shape[0]
    k_eff = eff_joint.shape[0]
    frames = (np.empty((kin.parents.shape[0], 4, 4)), np.empty((n_dofs, 3)), np.empty((n_dofs, 3)))
    pts = np.empty((k_eff, 3))
    jac = np.empty((3 * k_eff, n_dofs))
    e = np.empty(3 * k_eff)
    locked = np.zeros(n_dofs, dtype=np.bool_)
    n_live = 0  # the DoFs not frozen
    for d in range(n_dofs):
        if not frozen[d]:
            n_live += 1
    bufs = _buffers_nb(k_eff, n_dofs, n_live)
    sets = rigid_sets_nb(eff_joint)
    inv_mu = 1.0 / weighting.mu
    stats = np.empty(3)

    fk_points_jacobian_pose_nb(
        q, kin, eff_joint, eff_point, frames[0], frames[1], frames[2], pts, jac
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
    keep_best = settings.keep_best and stall_iter > 0
    q_best = q.copy()
    residual_best = residual.copy()
    sum_best = residual.sum()
    while it < settings.max_iter and k_eff > 0:
        if err < tol and it >= min_iter:
            break
        if stall_iter > 0 and min(since_best, since_best_sum) >= stall_iter and it >= min_iter:
            break
        clamp_error_nb(pts, targets, settings.dmax, e)
        rank = _sdls_step_nb(jac, inv_mu, frozen, locked, e, settings, bufs, pts, sets)
        if settings.gain > 0.0:
            _relax_nb(q, kin, frames, weighting, settings, frozen, locked, rank, inv_mu, bufs)
        _take_step_nb(
            q, bufs.dpsi, weighting, settings, frozen, locked, kin.dof_kind, inv_mu, stats
        )
        if it < trace.shape[0]:
            trace[it, 0] = err
            trace[it, 1] = stats[0]
            trace[it, 2] = stats[1]
            trace[it, 3] = stats[2]
        fk_points_jacobian_pose_nb(
            q, kin, eff_joint, eff_point, frames[0], frames[1], frames[2], pts, jac
        )
        err = residuals_nb(targets, pts, residual)
        if keep_best and residual.sum() < sum_best:
            sum_best = residual.sum()
            q_best[:] = q
            residual_best[:] = residual
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
    if keep_best and residual.sum() > sum_best:
        q[:] = q_best
        residual[:] = residual_best
    return it


__all__ = ["IKSettings", "IKTask", "IKWeighting", "solve_ik_nb"]
