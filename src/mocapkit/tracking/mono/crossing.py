"""Transitions pruned where a link would cross the image plane faster than a frame allows.

Each link seen in the image has two 3-D configurations, its child in front of or behind
its parent (`mocapkit.tracking.mono.flips`). Switching between them is free for the
image, and it is physical only where the link passes through the image plane: there its
depth offset (the link's component along the child's viewing ray) is near zero and both
configurations coincide. A switch while the offset is large moves the child in depth by
twice that offset in one frame, which no image motion shows: the pose pops.

`crossing_pruned` marks the transitions between two frames' candidate poses in which a
link's depth offset changes sign by more than ``allow_mm`` (what depth may change in a
frame unseen, `mocapkit.tracking.base.UNSEEN_SPEED_MM_S` times the frame time) plus
``factor`` times the link's step across the viewing ray (its image motion relative to
its parent; the hybrid re-plant's 1.5). The pose graph gives them an infinite weight, as
the paper prunes poses past the joint limits, so the decoder switches a link's
configuration where it is near the image plane or where the image moves enough to carry
the switch; where no transition into a frame survives, the graph keeps them all for that
frame (`mocapkit.tracking.mono.graph.PoseGraph`) and the frame's ``pruned_all`` says so.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ShapeError

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]


@nb.njit(cache=True)
def _crossings(
    va: FloatArray,
    vb: FloatArray,
    da: FloatArray,
    db: FloatArray,
    ea: FloatArray,
    eb: FloatArray,
    ub: FloatArray,
    links: IntArray,
    allow_mm: float,
    factor: float,
) -> BoolArray:
    na, nbs = va.shape[0], vb.shape[0]
    out = np.zeros((na, nbs), dtype=np.bool_)
    for i in range(na):
        for j in range(nbs):
            for k in links:
                if not da[i, k] * db[j, k] < 0.0:
                    continue  # same side of the image plane, on it, or unseen (NaN)
                sx = vb[j, k, 0] - va[i, k, 0]
                sy = vb[j, k, 1] - va[i, k, 1]
                sz = vb[j, k, 2] - va[i, k, 2]
                along = sx * ub[j, k, 0] + sy * ub[j, k, 1] + sz * ub[j, k, 2]
                across = np.sqrt(max(sx * sx + sy * sy + sz * sz - along * along, 0.0))
                if ea[i, k] + eb[j, k] > allow_mm + factor * across:
                    out[i, j] = True
                    break
    return out


def _rays(positions: FloatArray, child: IntArray, perspective: bool) -> FloatArray:
    """Unit viewing direction (N, L, 3) at each link's child: through the camera's centre
    (perspective), or the optical axis z (orthographic, weak perspective)."""
    if not perspective:
        out = np.zeros((positions.shape[0], child.shape[0], 3))
        out[..., 2] = 1.0
        return out
    c = positions[:, child]
    n = np.linalg.norm(c, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.asarray(c / n)


def crossing_pruned(
    positions_a: ArrayLike,
    positions_b: ArrayLike,
    parent: ArrayLike,
    child: ArrayLike,
    links: ArrayLike,
    allow_mm: float,
    factor: float,
    perspective: bool = True,
    tolerance: ArrayLike = 0.0,
) -> BoolArray:
    """(Na, Nb) True where a transition moves a link through the image plane too fast.

    For each link of ``links`` its depth offset is the link vector (child minus parent)
    along the child's viewing ray, in each frame. A transition is pruned where, for some
    such link, the offset changes sign (one configuration to the other) and the least
    offsets the image allows on either side (with the link's length uncertain by the
    share ``tolerance``: near the image plane a length a few per cent off moves the
    offset a lot) sum to more than ``allow_mm + factor * across``, ``across`` being the
    link vector's change across the ray (what the image shows of its motion).

    Parameters
    ----------
    positions_a, positions_b : (Na, K, 3), (Nb, K, 3) float
        Candidate joints of frames k and k + 1 (camera frame, mm); NaN joints are unseen
        and prune nothing.
    parent, child : (L,) int
        Each link's joints.
    links : (M,) int
        The links tested.
    allow_mm : float
        Depth change a frame allows unseen.
    factor : float
        Share of the image step a depth step may exceed it by.
    perspective : bool
        Rays through the camera's centre; False: along z.
    tolerance : float or (L,) float
        Share by which each link's length is uncertain.
    """
    a = np.ascontiguousarray(positions_a, dtype=float)
    b = np.ascontiguousarray(positions_b, dtype=float)
    if a.ndim != 3 or b.ndim != 3 or a.shape[1:] != b.shape[1:] or a.shape[2] != 3:
        raise ShapeError(
            f"crossing_pruned: expected (Na, K, 3) and (Nb, K, 3) joints, found {a.shape}, "
            f"{b.shape}"
        )
    p = np.asarray(parent, dtype=np.int64)
    c = np.asarray(child, dtype=np.int64)
    sel = np.ascontiguousarray(links, dtype=np.int64)
    va, vb = a[:, c] - a[:, p], b[:, c] - b[:, p]
    ub = _rays(b, c, perspective)
    da = np.einsum("nli,nli->nl", va, _rays(a, c, perspective))  # depth offsets
    db = np.einsum("nli,nli->nl", vb, ub)
    tol = np.asarray(tolerance, dtype=float)
    ea, eb = _least_offset(va, da, tol), _least_offset(vb, db, tol)
    return np.asarray(_crossings(va, vb, da, db, ea, eb, ub, sel, float(allow_mm), float(factor)))


def _least_offset(vectors: FloatArray, offsets: FloatArray, tolerance: FloatArray) -> FloatArray:
    """The smallest depth offset (N, L) the image allows each link if its length is
    uncertain by the share ``tolerance`` (L,): ``sqrt(d^2 - |v|^2 (1 - (1 - t)^2))``,
    0 where the link may lie in the image plane."""
    n2 = np.einsum("nli,nli->nl", vectors, vectors)
    shrink = 1.0 - (1.0 - np.asarray(tolerance, dtype=float)) ** 2
    return np.asarray(np.sqrt(np.maximum(offsets * offsets - n2 * shrink, 0.0)))


@dataclass(frozen=True)
class CrossingBound:
    """`crossing_pruned` as a pose graph's pruning of transitions.

    Attributes
    ----------
    parent, child : (L,) int
        The graph's links.
    links : (M,) int
        The links whose crossings are bounded.
    speed_mm_s : float
        Depth speed allowed unseen (``allow_mm`` per second).
    factor : float
    perspective : bool
    tolerance : (L,) float
        Share by which each link's length is uncertain.
    """

    parent: IntArray
    child: IntArray
    links: IntArray
    speed_mm_s: float
    factor: float
    perspective: bool
    tolerance: FloatArray

    def pruned(self, positions_a: ArrayLike, positions_b: ArrayLike, dt_s: float) -> BoolArray:
        """The transitions pruned (Na, Nb) between two frames ``dt_s`` apart."""
        return crossing_pruned(
            positions_a,
            positions_b,
            self.parent,
            self.child,
            self.links,
            self.speed_mm_s * dt_s,
            self.factor,
            self.perspective,
            self.tolerance,
        )


__all__ = ["CrossingBound", "crossing_pruned"]
