"""Prioritized fusion of the edge and distance cues (Azad et al. 2008 §IV, Algorithm 1; errata A10).

Per particle, with the edge error ``e_g`` (eq. (1), averaged over the views) and the
raw squared hand distance ``e_d`` (mm^2):

1. inside the minimum radius (``e_d < t_d^2``) the distance error is set to 0,
   outside it the edge error is set to its maximum 1;
2. ``e_d := s_d e_d / e_d^(t-1)`` with ``e_d^(t-1)`` the **raw** squared distance of
   the previous frame's estimate, floored at ``t_d^2`` (errata A10: the value after
   step 3 is 0 whenever the last estimate was inside, and the paper would divide by
   it);
3. ``e_d`` is capped at 50 (the algorithm's reading; errata A10 lets one choose
   between capping ``e_d`` and capping the whole exponent: capping ``e_d`` keeps the
   edge term intact, and with ``s_g = 10`` the exponent never exceeds 60, far from
   underflow);
4. ``pi = exp(-(e_d + s_g e_g))``.

Hence any particle inside ``t_d`` (``pi >= exp(-s_g)`` because ``e_g <= 1``) outweighs
any particle outside it (``pi = exp(-(e_d + s_g))`` with ``e_d > 0``), the property
the tests check. ``conventional=True`` instead multiplies the two likelihoods
(``exp(-(s_d e_d / e_d^(t-1) + s_g e_g))`` with the same cap), the fusion §IV compares
against, for ablations.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import ConfigError

FloatArray = NDArray[np.float64]


class FusionParams(NamedTuple):
    """Constants of Algorithm 1 (paper values as defaults via `default_fusion`).

    Attributes
    ----------
    s_g, s_d : float
        Weights of the edge and distance errors (``1 / (2 sigma^2)``; paper: 10 and 10).
    t_d_mm : float
        Minimum radius (paper: 30 mm).
    cap : float
        Cap of the normalised distance error (paper: 50).
    conventional : bool
        Multiply the cues instead of prioritizing (ablation).
    """

    s_g: float
    s_d: float
    t_d_mm: float
    cap: float
    conventional: bool


def default_fusion(conventional: bool = False) -> FusionParams:
    """The paper's constants: ``s_g = s_d = 10``, ``t_d = 30 mm``, cap 50."""
    return FusionParams(10.0, 10.0, 30.0, 50.0, conventional)


def check_fusion(params: FusionParams) -> FusionParams:
    """Refuse non-positive or non-finite constants."""
    for name in ("s_g", "s_d", "t_d_mm", "cap"):
        v = float(getattr(params, name))
        if not (v > 0 and math.isfinite(v)):
            raise ConfigError(f"FusionParams.{name}: expected a positive number, found {v}")
    return params


@numba.njit(cache=True, fastmath=False)
def fused_weight_nb(
    edge_error: float, dist_sq_mm2: float, prev_dist_sq_mm2: float, params: FusionParams
) -> float:
    """Algorithm 1 for one particle: its weight ``pi`` (module notes).

    Parameters
    ----------
    edge_error : float
        ``e_g`` in [0, 1] (view average of eq. (1)).
    dist_sq_mm2 : float
        Raw ``|p_h - f_d(s)|^2``; NaN when no hand is measured (distance cue off:
        every particle counts as inside the radius).
    prev_dist_sq_mm2 : float
        Raw squared distance of the previous estimate (floored at ``t_d^2`` here).
    params : FusionParams
    """
    t2 = params.t_d_mm * params.t_d_mm
    e_g = edge_error
    e_d = dist_sq_mm2
    if not (e_d == e_d):  # NaN: no measurement
        e_d = 0.0
    elif not params.conventional:
        if e_d < t2:
            e_d = 0.0
        else:
            e_g = 1.0
    prev = prev_dist_sq_mm2 if prev_dist_sq_mm2 > t2 else t2  # errata A10 (NaN -> t2 too)
    e_d = params.s_d * e_d / prev
    if e_d > params.cap:
        e_d = params.cap
    return math.exp(-(e_d + params.s_g * e_g))


@numba.njit(cache=True, fastmath=False)
def fused_weights_nb(
    edge_error: FloatArray,
    dist_sq_mm2: FloatArray,
    prev_dist_sq_mm2: float,
    params: FusionParams,
    out: FloatArray,
) -> None:
    """`fused_weight_nb` over a particle batch: ``out[i]`` for arrays (N,)."""
    for i in range(edge_error.shape[0]):
        out[i] = fused_weight_nb(edge_error[i], dist_sq_mm2[i], prev_dist_sq_mm2, params)


__all__ = [
    "FusionParams",
    "check_fusion",
    "default_fusion",
    "fused_weight_nb",
    "fused_weights_nb",
]
