"""The arm re-seed's seeds and its choice among their solves (`HybridTracker._reseed_lost_arms`).

An arm driven into its joint limits can stay there on the wrong branch, its hand set
hundreds of mm off. Solved again from the relaxed pose alone, it came back on whatever
branch that pose leads to: on the real tennis serve the left elbow went 250-370 mm in
one frame (18.6 m/s against 2.1 m/s for its marker). Here the arm is solved from several
seeds: the relaxed arm and the current arm swivelled about its shoulder-wrist axis
(`mocapkit.ik.swivel.swivel_arm`: the wrist stays, the elbow goes round the circle) every
``360 / SWIVEL_SEEDS`` deg. Their solves that fit the hand set as well as the best one
(within a tolerance: the marker noise) reach it on different branches, and the one whose
elbow moved least is kept: the smallest jump the markers allow.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ShapeError
from mocapkit.ik.swivel import swivel_arm
from mocapkit.skeleton.limbs import arm
from mocapkit.skeleton.model import Skeleton

FloatArray = NDArray[np.float64]

#: Seeds on the swivel circle, the current arm's own angle included (it is the pose the
#: re-seed starts from, so it is left out): every 45 deg. The only count tried.
SWIVEL_SEEDS = 8


def arm_seeds(
    skeleton: Skeleton, q: ArrayLike, side: str, relaxed_q: ArrayLike
) -> list[FloatArray]:
    """Start poses of a re-seed of one arm: ``q`` with the arm's DoFs at ``relaxed_q``'s,
    then ``q`` with the arm swivelled by ``k * 2 pi / SWIVEL_SEEDS`` (k = 1 ..
    ``SWIVEL_SEEDS - 1``), clipped to the joint limits. An arm whose wrist lies on its
    shoulder has no swivel axis: the relaxed seed alone."""
    qa = np.asarray(q, dtype=float)
    dofs = arm(skeleton, side).dofs
    relaxed = qa.copy()
    relaxed[dofs] = np.asarray(relaxed_q, dtype=float)[dofs]
    seeds = [relaxed]
    for k in range(1, SWIVEL_SEEDS):
        try:
            turned = swivel_arm(skeleton, qa, side, 2.0 * math.pi * k / SWIVEL_SEEDS)
        except ShapeError:
            return seeds
        seeds.append(np.clip(turned, skeleton.lower, skeleton.upper))
    return seeds


def nearest_fit(fit_mm: ArrayLike, move_mm: ArrayLike, tol_mm: float) -> int:
    """Index of the candidate that moves least (``move_mm``) among those whose fit
    (``fit_mm``, distance to the set) is within ``tol_mm`` of the best."""
    fit = np.asarray(fit_mm, dtype=float)
    move = np.asarray(move_mm, dtype=float)
    if fit.shape != move.shape or fit.ndim != 1 or fit.size == 0:
        raise ShapeError(
            f"nearest_fit: expected two equal non-empty 1-D arrays, found {fit.shape} and "
            f"{move.shape}"
        )
    good = fit <= np.min(fit) + tol_mm
    return int(np.flatnonzero(good)[np.argmin(move[good])])


__all__ = ["SWIVEL_SEEDS", "arm_seeds", "nearest_fit"]
