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
cycle between release and clip (`git log -p docs/design-notes/hybrid.md`). With ``"gesvd"`` both
SVDs are taken of fewer rows: the rows of the effectors fixed to one joint (a marker
set and its members) reduced to six with the same singular values and V
(`mocapkit.ik.rigid_rows`).

The pieces, one concept a file: `mocapkit.ik.config` (`IKConfig`, `IKResult`),
`mocapkit.ik.effectors` (named effector points), `mocapkit.ik.weights` (the weights
``mu``), `mocapkit.ik.sdls_step` (one SDLS step, steps 2-5 and 6's projector),
`mocapkit.ik.solve` (the compiled loop of one frame), `mocapkit.ik.rigid_rows` (the
rigid sets' fewer rows), `mocapkit.ik.secondary` (the
relaxed-pose task) and `mocapkit.ik.lapack` (dgesvd for compiled code); this module holds
the solver object that binds them to a skeleton.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ConfigError, ShapeError, unknown_name
from mocapkit.ik.config import IKConfig, IKResult
from mocapkit.ik.effectors import Effector, default_effectors
from mocapkit.ik.secondary import SecondaryTask, planted_feet
from mocapkit.ik.solve import IKSettings, IKTask, IKWeighting, solve_ik_nb
from mocapkit.ik.weights import arm_length_mm, dof_weights
from mocapkit.skeleton.kinematics import kinematic_arrays, points_and_jacobian
from mocapkit.skeleton.model import Skeleton

FloatArray = NDArray[np.float64]


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
        self.mu = dof_weights(skeleton, planted)
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
        #: DoFs whose limits leave them no range (``zhang21``'s root pitch and roll): held
        #: fixed in every solve, as if frozen. Left free, the first step moves them, the
        #: clamp locks them, and a locked DoF sends every later iteration to the SVD with
        #: U (`mocapkit.ik.solve`), which waits for a release that cannot come.
        self._fixed = self._lower == self._upper
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
            keep_best=bool(cfg.stall_keep_best),
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
        finite = np.isfinite(t).all(axis=1)
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
        frz |= self._fixed
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
        converged = bool(len(idx) == 0 or (residual < cfg.tol_mm).all())
        return IKResult(
            q=q,
            iterations=int(n_it),
            residual_mm=res_all,
            converged=converged,
            trace=trace[:n_it].copy() if record_trace else None,
        )


__all__ = ["Effector", "IKConfig", "IKResult", "SDLSSolver"]
