"""A data-driven prior on arm directions in the body frame (beyond Mamania et al. 2004).

Under near-orthography an arm mirrored through the image plane is as smooth as the true
one, so eq. 3 cannot tell them apart and the joint limits break the tie only where the
mirror is anatomically impossible. Real motion tells more: some arm postures are common
(arms hanging, reaching forwards and sideways) and others rare (the upper arm far
behind the back with the forearm folded forwards). This module scores each candidate
pose by how rare its arms are in captured motion.

Features. The body frame of a pose is that of `mocapkit.tracking.mono.priors` (and
`stick.BACKWARD`): up = minus the trunk (neck -> pelvis), right = right shoulder minus
left shoulder made orthogonal to up, forward = up x right. Per arm the feature is the
unit upper arm and the unit forearm in that frame, six numbers
``(u_right, u_up, u_fwd, f_right, f_up, f_fwd)``; the left arm is mirrored into a right
arm (its ``right`` components negated), so one density serves both arms.

Density. A Gaussian mixture in those six numbers (`ArmPrior`), fitted by EM
(`fit_arm_prior`) on motion-capture clips. The cost of an arm is its negative
log-density above the densest point of the mixture (the largest density among the
component means), clipped at ``cap`` nats, so that a posture unseen in the training
clips costs a bounded amount instead of ruling a pose out (the limits do that). The
pose's cost is the sum over its two arms (`ArmPrior.cost`); `MonoConfig.arm_prior_weight`
turns nats into the units of eq. 3.

The shipped table (`mocapkit.tracking.mono.arm_prior_table`) is fitted by
``tools/mono_fit_arm_prior.py`` on the project's tuning clips, so the report clips stay
unseen (its provenance is in that module's docstring): 12 components, 0.03 added to each
covariance's diagonal. Both were chosen by leave-one-clip-out log-likelihood on the
fitting clips; with a floor of 1e-3 the density was so narrow that unseen clips' true
arms cost the full cap in most frames.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ConfigError, ShapeError
from mocapkit.tracking.mono.stick import StickModel

FloatArray = NDArray[np.float64]

#: Feature size per arm: unit upper arm and unit forearm in the body frame.
ARM_FEATURES = 6

#: Joints the features read (canonical names; the links of `arm_features`' docstring).
_ARM_JOINTS = (
    "neck",
    "pelvis",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "left_wrist",
    "right_elbow",
    "right_wrist",
)


def arm_features(model: StickModel, positions: ArrayLike) -> FloatArray:
    """Upper arm and forearm directions of both arms in the body frame (N, 2, 6).

    Parameters
    ----------
    model : StickModel
        Needs the joints of the links ``trunk``, ``left_clavicle``, ``right_clavicle``
        and per side ``<side>_upper_arm``, ``<side>_forearm``.
    positions : (N, K, 3) float
        Poses (any right-handed frame; mm or px).

    Returns
    -------
    (N, 2, 6) float
        Arm 0 is the left arm mirrored (right components negated), arm 1 the right arm;
        per arm ``(u_right, u_up, u_fwd, f_right, f_up, f_fwd)`` of the unit upper arm u
        and unit forearm f. NaN where a link is unknown.
    """
    p = np.asarray(positions, dtype=float)
    if p.ndim != 3 or p.shape[1:] != (model.n_joints, 3):
        raise ShapeError(
            f"arm_features: expected positions (N, {model.n_joints}, 3), found {p.shape}"
        )
    names = model.joint_names
    j = [names.index(n) for n in _ARM_JOINTS]
    neck, pelvis, ls, rs = (p[:, i] for i in j[:4])
    with np.errstate(invalid="ignore", divide="ignore"):
        up = neck - pelvis
        up /= np.sqrt(np.sum(up * up, axis=-1, keepdims=True))
        right = rs - ls  # right clavicle minus left clavicle
        right -= np.sum(right * up, axis=-1, keepdims=True) * up
        right /= np.sqrt(np.sum(right * right, axis=-1, keepdims=True))
        fwd = np.empty_like(up)  # up x right
        fwd[:, 0] = up[:, 1] * right[:, 2] - up[:, 2] * right[:, 1]
        fwd[:, 1] = up[:, 2] * right[:, 0] - up[:, 0] * right[:, 2]
        fwd[:, 2] = up[:, 0] * right[:, 1] - up[:, 1] * right[:, 0]
        frame = np.stack([right, up, fwd], axis=2)  # (N, 3, 3): columns are the axes
        # upper arm, forearm of the left arm, then of the right arm
        d = p[:, j[4:8]] - p[:, [j[2], j[4], j[3], j[6]]]  # (N, 4, 3)
        d /= np.sqrt(np.sum(d * d, axis=-1, keepdims=True))
        out = np.matmul(d, frame).reshape(p.shape[0], 2, ARM_FEATURES)
    out[:, 0, 0] *= -1.0
    out[:, 0, 3] *= -1.0
    return out


@dataclass(frozen=True, eq=False)
class ArmPrior:
    """Gaussian mixture over the arm features (see the module docstring).

    Attributes
    ----------
    weights : (M,) float
        Mixture weights (sum 1).
    means : (M, 6) float
    covariances : (M, 6, 6) float
        Symmetric positive definite.
    cap : float
        Largest cost of one arm (nats above the densest point).
    """

    weights: FloatArray
    means: FloatArray
    covariances: FloatArray
    cap: float = 10.0
    _chol_inv: FloatArray = field(init=False, repr=False)  # (M, 6, 6) inverse Cholesky factors
    _whiten: FloatArray = field(init=False, repr=False)  # (6, 6 M): x @ W = all C_m^-1 x at once
    _offset: FloatArray = field(init=False, repr=False)  # (6 M,): all C_m^-1 mu_m
    _log_norm: FloatArray = field(init=False, repr=False)  # (M,) log weight + Gaussian constant
    _log_peak: float = field(init=False, repr=False)  # largest log-density among the means

    def __post_init__(self) -> None:
        w = np.asarray(self.weights, dtype=float)
        mu = np.asarray(self.means, dtype=float)
        cov = np.asarray(self.covariances, dtype=float)
        m = w.shape[0]
        if w.ndim != 1 or mu.shape != (m, ARM_FEATURES) or cov.shape != (m, 6, 6):
            raise ShapeError(
                f"ArmPrior: expected weights (M,), means (M, 6), covariances (M, 6, 6), "
                f"found {w.shape}, {mu.shape}, {cov.shape}"
            )
        if m == 0 or np.any(w < 0) or not np.isclose(w.sum(), 1.0):
            raise ConfigError(f"ArmPrior: expected M >= 1 weights >= 0 summing to 1, found {w}")
        if not self.cap > 0:
            raise ConfigError(f"ArmPrior.cap: expected > 0 nats, found {self.cap}")
        chol = np.linalg.cholesky(cov)  # raises LinAlgError when not positive definite
        object.__setattr__(self, "weights", w)
        object.__setattr__(self, "means", mu)
        object.__setattr__(self, "covariances", cov)
        ci = np.linalg.inv(chol)
        object.__setattr__(self, "_chol_inv", ci)
        object.__setattr__(self, "_whiten", ci.reshape(-1, ARM_FEATURES).T.copy())
        object.__setattr__(self, "_offset", np.einsum("mij,mj->mi", ci, mu).ravel())
        log_det = 2.0 * np.log(np.diagonal(chol, axis1=1, axis2=2)).sum(axis=1)
        object.__setattr__(
            self, "_log_norm", np.log(w) - 0.5 * (ARM_FEATURES * np.log(2 * np.pi) + log_det)
        )
        object.__setattr__(self, "_log_peak", float(np.max(self.log_density(mu))))

    def log_density(self, features: ArrayLike) -> FloatArray:
        """Log-density of features (..., 6) under the mixture (...,); NaN stays NaN."""
        x = np.asarray(features, dtype=float)
        if x.shape[-1] != ARM_FEATURES:
            raise ShapeError(f"ArmPrior.log_density: expected (..., 6), found {x.shape}")
        # C_m^-1 (x - mu_m) for every component in one product (the tracker calls this
        # for every surviving pose of every frame)
        z = (x @ self._whiten - self._offset).reshape(x.shape[:-1] + self.means.shape)
        comp = self._log_norm - 0.5 * np.sum(z * z, axis=-1)
        top = np.max(comp, axis=-1, keepdims=True)
        return np.asarray(top[..., 0] + np.log(np.sum(np.exp(comp - top), axis=-1)), dtype=float)

    def arm_cost(self, features: ArrayLike) -> FloatArray:
        """Nats below the densest point, clipped to ``[0, cap]`` (...,); NaN costs 0."""
        x = np.asarray(features, dtype=float)
        if x.shape[-1] != ARM_FEATURES:
            raise ShapeError(f"ArmPrior.arm_cost: expected (..., 6), found {x.shape}")
        # the density without log-sum-exp's shift: the terms are at most exp(max
        # _log_norm) (no overflow), and where all underflow the cost is the cap anyway
        z = (x @ self._whiten - self._offset).reshape(x.shape[:-1] + self.means.shape)
        dens = np.exp(self._log_norm - 0.5 * np.einsum("...i,...i->...", z, z)).sum(axis=-1)
        with np.errstate(divide="ignore"):
            c = self._log_peak - np.log(dens)
        return np.asarray(np.nan_to_num(np.clip(c, 0.0, self.cap), nan=0.0), dtype=float)

    def cost(self, model: StickModel, positions: ArrayLike) -> FloatArray:
        """Sum over both arms of `arm_cost` for each pose (N,)."""
        return np.asarray(self.arm_cost(arm_features(model, positions)).sum(axis=1), dtype=float)


def fit_arm_prior(
    features: ArrayLike,
    n_components: int,
    rng: np.random.Generator,
    iterations: int = 200,
    regularisation: float = 1e-3,
    cap: float = 10.0,
) -> ArmPrior:
    """Fit `ArmPrior` by expectation-maximisation.

    Parameters
    ----------
    features : (S, 6) float
        Arm features (`arm_features`, both arms pooled); rows with NaN are dropped.
    n_components : int
    rng : numpy.random.Generator
        Picks the initial means (k-means++ seeding).
    iterations : int
        EM steps (stops early when the mean log-likelihood gains under 1e-7).
    regularisation : float
        Added to each covariance's diagonal (unit vectors: 1e-3 is 0.03 in std).
    cap : float
        `ArmPrior.cap`.
    """
    x = np.asarray(features, dtype=float)
    if x.ndim != 2 or x.shape[1] != ARM_FEATURES:
        raise ShapeError(f"fit_arm_prior: expected features (S, 6), found {x.shape}")
    x = x[np.isfinite(x).all(axis=1)]
    m = int(n_components)
    if m < 1 or x.shape[0] < 10 * m:
        raise ConfigError(
            f"fit_arm_prior: expected >= 1 component and >= 10 samples per component, "
            f"found {m} components and {x.shape[0]} samples"
        )
    # k-means++ seeding of the means
    means = [x[rng.integers(x.shape[0])]]
    for _ in range(1, m):
        d2 = np.min(((x[:, None, :] - np.array(means)[None]) ** 2).sum(-1), axis=1)
        means.append(x[rng.choice(x.shape[0], p=d2 / d2.sum())])
    mu = np.array(means)
    cov = np.repeat((np.cov(x.T) + regularisation * np.eye(6))[None], m, axis=0)
    w = np.full(m, 1.0 / m)
    last = -np.inf
    for _ in range(iterations):
        prior = ArmPrior(w, mu, cov, cap)
        d = x[:, None, :] - mu
        z = np.einsum("mij,smj->smi", prior._chol_inv, d)
        comp = prior._log_norm - 0.5 * np.sum(z * z, axis=-1)
        top = comp.max(axis=1, keepdims=True)
        ll = top[:, 0] + np.log(np.exp(comp - top).sum(axis=1))
        resp = np.exp(comp - ll[:, None])  # (S, M)
        nk = resp.sum(axis=0) + 1e-12
        w = nk / nk.sum()
        mu = (resp.T @ x) / nk[:, None]
        d = x[:, None, :] - mu
        cov = np.einsum("sm,smi,smj->mij", resp, d, d) / nk[:, None, None]
        cov += regularisation * np.eye(6)
        mean_ll = float(ll.mean())
        if mean_ll - last < 1e-7:
            break
        last = mean_ll
    return ArmPrior(w, mu, cov, cap)


def default_arm_prior() -> ArmPrior:
    """The shipped prior (`mocapkit.tracking.mono.arm_prior_table`)."""
    from mocapkit.tracking.mono import arm_prior_table as t

    return ArmPrior(np.array(t.WEIGHTS), np.array(t.MEANS), np.array(t.COVARIANCES), t.CAP)
