"""Fewer Jacobian rows with the same SVD: each rigid set of effectors' rows reduced to six.

Effectors fixed to one joint (a marker set's centre and its member markers) move as one
rigid body: for every DoF, the velocity of effector ``k`` is ``v_c + omega x r_k``, with
``r_k`` its offset from the set's centroid. Their 3m rows of ``J_w`` are therefore
``A B``, with ``A`` (3m, 6) the rows ``[I, -[r_k]x]`` and ``B`` (6, D) the body's
velocity. With ``Q`` (3m, 6) an orthonormal basis of the range of ``A``,
``Q Q^T J_set = J_set``, so the six rows ``Q^T J_set`` have the same Gram matrix
``J_set^T J_set``: the stacked rows have the singular values and right singular vectors
of ``J_w`` (those of the zero singular values aside), from a smaller SVD. The SDLS terms
(`mocapkit.ik.sdls_step`) take ``alpha_i``, ``N_i`` and ``M_i`` from the whole ``J_w``
and ``v_i``, so their per-effector norms keep their meaning. Sets of fewer than three
effectors, or whose points are (nearly) collinear, keep their rows.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: A set is reduced only where each of its six basis columns keeps at least this share
#: of its norm after the projections (points far enough from a line).
MIN_SHARE = 1e-6


@numba.njit(cache=True)
def rigid_sets_nb(eff_joint: IntArray) -> tuple[IntArray, IntArray]:
    """The effectors grouped by joint: ``order`` (K,) effector indices, sets of three
    or more first, each set's members together; ``bounds`` (n_sets + 1,) where each of
    those sets starts in ``order`` (the effectors after ``bounds[-1]`` keep their rows)."""
    k_eff = eff_joint.shape[0]
    order = np.empty(k_eff, dtype=np.int64)
    taken = np.zeros(k_eff, dtype=np.bool_)
    bounds = np.zeros(k_eff + 1, dtype=np.int64)
    n_sets = 0
    pos = 0
    for a in range(k_eff):
        if taken[a]:
            continue
        count = 0
        for b in range(a, k_eff):
            if eff_joint[b] == eff_joint[a]:
                count += 1
        if count < 3:
            continue
        for b in range(a, k_eff):
            if eff_joint[b] == eff_joint[a]:
                order[pos] = b
                taken[b] = True
                pos += 1
        n_sets += 1
        bounds[n_sets] = pos
    for a in range(k_eff):
        if not taken[a]:
            order[pos] = a
            pos += 1
    return order, bounds[: n_sets + 1].copy()


def no_sets(n_eff: int) -> tuple[IntArray, IntArray]:
    """`rigid_sets_nb`'s answer with no rigid set: every effector keeps its rows."""
    return np.arange(n_eff, dtype=np.int64), np.zeros(1, dtype=np.int64)


@numba.njit(cache=True)
def _set_basis_nb(pts: FloatArray, members: IntArray, q: FloatArray) -> bool:
    """Orthonormal basis ``q`` (3m, 6) of the rigid velocities of the points
    ``pts[members]``; False where the points are too near a line for six."""
    m = members.shape[0]
    cx = 0.0
    cy = 0.0
    cz = 0.0
    for k in range(m):
        cx += pts[members[k], 0]
        cy += pts[members[k], 1]
        cz += pts[members[k], 2]
    cx /= m
    cy /= m
    cz /= m
    for k in range(m):
        rx = pts[members[k], 0] - cx
        ry = pts[members[k], 1] - cy
        rz = pts[members[k], 2] - cz
        for i in range(3):
            for j in range(6):
                q[3 * k + i, j] = 0.0
            q[3 * k + i, i] = 1.0
        # -[r]x: the velocity omega x r = -[r]x omega
        q[3 * k, 4] = -rz
        q[3 * k, 5] = ry
        q[3 * k + 1, 3] = rz
        q[3 * k + 1, 5] = -rx
        q[3 * k + 2, 3] = -ry
        q[3 * k + 2, 4] = rx
    n_rows = 3 * m
    # Gram-Schmidt, each column projected twice (CGS2: orthonormal to round-off)
    for j in range(6):
        first = 0.0
        for r in range(n_rows):
            first += q[r, j] * q[r, j]
        for _pass in range(2):
            for i in range(j):
                dot = 0.0
                for r in range(n_rows):
                    dot += q[r, i] * q[r, j]
                for r in range(n_rows):
                    q[r, j] -= dot * q[r, i]
        norm = 0.0
        for r in range(n_rows):
            norm += q[r, j] * q[r, j]
        if norm <= (MIN_SHARE * MIN_SHARE) * first or norm == 0.0:
            return False
        inv = 1.0 / math.sqrt(norm)
        for r in range(n_rows):
            q[r, j] *= inv
    return True


@numba.njit(cache=True)
def rigid_rows_nb(
    jw: FloatArray, pts: FloatArray, order: IntArray, bounds: IntArray, cols: IntArray
) -> FloatArray:
    """Rows of the columns ``cols`` of ``jw`` (3K, D) with the same Gram matrix, in
    column-major order: ``out`` (len(cols), n), ``out[c, r]`` the entry of row ``r``.

    Six rows for each rigid set of `rigid_sets_nb` (``Q^T J_set``, module doc), the
    other effectors' three rows as they are. ``pts`` (K, 3): the effectors' world
    positions.
    """
    n_c = cols.shape[0]
    n_sets = bounds.shape[0] - 1
    basis = np.empty((3 * order.shape[0], 6))  # rows 3 pos .. 3 pos + 2: order[pos]
    reduced = np.zeros(n_sets, dtype=np.bool_)
    n = 3 * (order.shape[0] - bounds[n_sets])
    for g in range(n_sets):
        lo, hi = bounds[g], bounds[g + 1]
        reduced[g] = _set_basis_nb(pts, order[lo:hi], basis[3 * lo : 3 * hi])
        n += 6 if reduced[g] else 3 * (hi - lo)
    out = np.zeros((n_c, n))
    r = 0
    for g in range(n_sets):
        lo, hi = bounds[g], bounds[g + 1]
        if reduced[g]:
            for pos in range(lo, hi):
                for i in range(3):
                    row = 3 * order[pos] + i
                    for c in range(n_c):
                        x = jw[row, cols[c]]
                        if x != 0.0:
                            for j in range(6):
                                out[c, r + j] += basis[3 * pos + i, j] * x
            r += 6
        else:
            for pos in range(lo, hi):
                for i in range(3):
                    for c in range(n_c):
                        out[c, r] = jw[3 * order[pos] + i, cols[c]]
                    r += 1
    for pos in range(bounds[n_sets], order.shape[0]):
        for i in range(3):
            for c in range(n_c):
                out[c, r] = jw[3 * order[pos] + i, cols[c]]
            r += 1
    return out


__all__ = ["MIN_SHARE", "no_sets", "rigid_rows_nb", "rigid_sets_nb"]
