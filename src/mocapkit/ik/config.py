"""Settings and result of the SDLS solver (`mocapkit.ik.sdls.SDLSSolver`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import ConfigError

FloatArray = NDArray[np.float64]

#: Buss's released code uses 45 deg for the global bound Gamma (errata Z6).
DEFAULT_GAMMA_RAD = math.radians(45.0)


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
    stall_keep_best : bool
        With a stall stop: end on the iterate where the sum of the errors was smallest.
        Where marker noise leaves every solve short of ``tol_mm``, the
        scaled iterations reach the least-squares valley in 5-10 steps and then chatter
        (the largest error jumping between 3.6 and 10 mm on a balance restore), so the
        step the iteration cap happens to end on is no better than the one where the
        errors stopped dropping.
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
        the lock. Both SVDs take six rows for each set of three or more effectors on
        one joint (`mocapkit.ik.rigid_rows`). Trajectories differ from ``"gesdd"`` by
        round-off, which the chaotic cases amplify (docs/design-notes/hybrid.md).
    """

    gamma_rad: float = DEFAULT_GAMMA_RAD
    dmax_mm: float | None = None
    tol_mm: float = 1.0
    max_iterations: int = 100
    min_iterations: int = 1
    stall_iterations: int = 0
    stall_fraction: float = 0.005
    stall_keep_best: bool = False
    secondary_gain: float = 0.3
    secondary_max_step_rad: float = 0.05
    clamp: str = "hard"
    relax_substeps: int = 1
    term_clamp_scale: float = 1.0
    svd: str = "gesdd"

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
        if self.stall_keep_best and self.stall_iterations == 0:
            raise ConfigError(
                "IKConfig.stall_keep_best: expected a stall stop (stall_iterations >= 1), "
                "found stall_iterations=0"
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


__all__ = ["DEFAULT_GAMMA_RAD", "IKConfig", "IKResult"]
