"""Edge weights of the pose graph: link angular velocity and acceleration (errata M1-M4).

Mamania et al. (2004, §4.3.2) weigh transitions by the links' angular accelerations:

- eq. 1 prints ``omega = AB x V_AB``. For a link vector r of fixed length, r' = omega x r
  gives ``omega = r x r' / |r|^2`` (errata M1): the printed form scales with |r|^2, so
  long links dominate. Over one frame the exact value is the unit axis of r_k x r_{k+1}
  times the angle between them over dt (`angular_velocity`); `angular_velocity_literal`
  keeps the printed formula for comparison.
- eq. 2: the acceleration is (omega_{k+1,k+2} - omega_{k,k+1}) / dt (errata M2, not
  delta t); eq. 3 sums its norm over links and couples three frames (errata M3), so it
  needs pair states (`mocapkit.tracking.mono.viterbi.pair_viterbi`).
- eq. 4-5 need the previous velocity: ``e = A_{k+2} - 2 A_{k+1} + A_k`` (errata M4), a
  second-order weight ``sum_A |e_A|`` (`joint_acceleration_cost`).

A first-order weight for plain Viterbi is the summed rotation angle of the links per
second (`rotation_cost`), the magnitude of the corrected omega.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ShapeError

FloatArray = NDArray[np.float64]


def angular_velocity(r0: ArrayLike, r1: ArrayLike, dt_s: float) -> FloatArray:
    """Corrected angular velocity (rad/s) of link vectors r0 -> r1 over ``dt_s`` (errata M1).

    ``axis(r0 x r1) * atan2(|r0 x r1|, r0 . r1) / dt``; zero for parallel vectors, an
    arbitrary axis perpendicular to r0 for opposite ones.

    Parameters
    ----------
    r0, r1 : (..., 3) float
    dt_s : float
    """
    a = np.asarray(r0, dtype=float)
    b = np.asarray(r1, dtype=float)
    if a.shape[-1:] != (3,) or b.shape[-1:] != (3,):
        raise ShapeError(f"angular_velocity: expected (..., 3) vectors, found {a.shape}, {b.shape}")
    a2, b2 = np.broadcast_arrays(a, b)
    return np.asarray(_omega_nd(np.ascontiguousarray(a2), np.ascontiguousarray(b2), 1.0 / dt_s))


def angular_velocity_literal(r0: ArrayLike, r1: ArrayLike, dt_s: float) -> FloatArray:
    """Eq. 1 as printed: ``r0 x (r1 - r0) / dt`` (scales with |r|^2; kept for comparison)."""
    a = np.asarray(r0, dtype=float)
    b = np.asarray(r1, dtype=float)
    return np.cross(a, (b - a) / dt_s)


@nb.njit(cache=True)
def _omega(r0: FloatArray, r1: FloatArray, inv_dt: float, out: FloatArray) -> None:
    cx = r0[1] * r1[2] - r0[2] * r1[1]
    cy = r0[2] * r1[0] - r0[0] * r1[2]
    cz = r0[0] * r1[1] - r0[1] * r1[0]
    s = np.sqrt(cx * cx + cy * cy + cz * cz)
    c = r0[0] * r1[0] + r0[1] * r1[1] + r0[2] * r1[2]
    n0 = np.sqrt(r0[0] * r0[0] + r0[1] * r0[1] + r0[2] * r0[2])
    n1 = np.sqrt(r1[0] * r1[0] + r1[1] * r1[1] + r1[2] * r1[2])
    if s <= 1e-12 * n0 * n1:
        if c >= 0.0:
            out[:] = 0.0
            return
        # opposite vectors: half a turn about any axis perpendicular to r0
        ax = (
            np.array([0.0, -r0[2], r0[1]])
            if abs(r0[0]) < 0.9 * n0
            else np.array([-r0[1], r0[0], 0.0])
        )
        ax = ax / np.sqrt(ax @ ax)
        out[:] = ax * (np.pi * inv_dt)
        return
    ang = np.arctan2(s, c) * inv_dt / s
    out[0] = cx * ang
    out[1] = cy * ang
    out[2] = cz * ang


@nb.njit(cache=True)
def _omega_nd(a: FloatArray, b: FloatArray, inv_dt: float) -> FloatArray:
    fa = np.ascontiguousarray(a).reshape(-1, 3)
    fb = np.ascontiguousarray(b).reshape(-1, 3)
    out = np.zeros_like(fa)
    for i in range(fa.shape[0]):
        _omega(fa[i], fb[i], inv_dt, out[i])
    return out.reshape(a.shape)


@nb.njit(cache=True)
def _pair_omegas(va: FloatArray, vb: FloatArray, inv_dt: float) -> tuple[FloatArray, FloatArray]:
    """omega (Na, Nb, L, 3) and summed |omega| (Na, Nb) from (Na, L, 3), (Nb, L, 3)."""
    na, nl = va.shape[0], va.shape[1]
    nbs = vb.shape[0]
    out = np.zeros((na, nbs, nl, 3))
    rot = np.zeros((na, nbs))
    for i in range(na):
        for j in range(nbs):
            acc = 0.0
            for k in range(nl):
                ax, ay, az = va[i, k, 0], va[i, k, 1], va[i, k, 2]
                bx, by, bz = vb[j, k, 0], vb[j, k, 1], vb[j, k, 2]
                if np.isnan(ax) or np.isnan(bx):
                    continue  # an unseen link adds nothing
                cx = ay * bz - az * by
                cy = az * bx - ax * bz
                cz = ax * by - ay * bx
                sn = np.sqrt(cx * cx + cy * cy + cz * cz)
                c = ax * bx + ay * by + az * bz
                if sn <= 1e-12 * np.sqrt(
                    (ax * ax + ay * ay + az * az) * (bx * bx + by * by + bz * bz)
                ):
                    if c < 0.0:  # opposite: half a turn about some perpendicular axis
                        _omega(va[i, k], vb[j, k], inv_dt, out[i, j, k])
                        acc += np.pi * inv_dt
                    continue
                ang = np.arctan2(sn, c) * inv_dt
                f = ang / sn
                out[i, j, k, 0] = cx * f
                out[i, j, k, 1] = cy * f
                out[i, j, k, 2] = cz * f
                acc += ang
            rot[i, j] = acc
    return out, rot


def pair_omegas(vectors_a: ArrayLike, vectors_b: ArrayLike, dt_s: float) -> FloatArray:
    """Corrected omega (Na, Nb, L, 3) of every link between every pair of candidate poses.

    Parameters
    ----------
    vectors_a : (Na, L, 3) float
        Link vectors of the candidates of frame k (NaN for unseen links: omega 0).
    vectors_b : (Nb, L, 3) float
        Link vectors of the candidates of frame k + 1.
    dt_s : float
    """
    a = np.ascontiguousarray(vectors_a, dtype=float)
    b = np.ascontiguousarray(vectors_b, dtype=float)
    if a.ndim != 3 or b.ndim != 3 or a.shape[1:] != b.shape[1:] or a.shape[2] != 3:
        raise ShapeError(
            f"pair_omegas: expected (Na, L, 3) and (Nb, L, 3), found {a.shape}, {b.shape}"
        )
    return np.asarray(_pair_omegas(a, b, 1.0 / dt_s)[0])


def pair_omegas_and_rotation(
    vectors_a: ArrayLike, vectors_b: ArrayLike, dt_s: float
) -> tuple[FloatArray, FloatArray]:
    """`pair_omegas` and its `rotation_cost` in one pass."""
    a = np.ascontiguousarray(vectors_a, dtype=float)
    b = np.ascontiguousarray(vectors_b, dtype=float)
    if a.ndim != 3 or b.ndim != 3 or a.shape[1:] != b.shape[1:] or a.shape[2] != 3:
        raise ShapeError(
            f"pair_omegas: expected (Na, L, 3) and (Nb, L, 3), found {a.shape}, {b.shape}"
        )
    w, r = _pair_omegas(a, b, 1.0 / dt_s)
    return np.asarray(w), np.asarray(r)


def rotation_cost(omegas: ArrayLike) -> FloatArray:
    """First-order weight (Na, Nb): summed |omega| over links (rad/s) from `pair_omegas`."""
    w = np.asarray(omegas, dtype=float)
    return np.asarray(np.sqrt((w * w).sum(axis=-1)).sum(axis=-1))


@nb.njit(cache=True)
def _acc_cost(wa: FloatArray, wb: FloatArray, inv_dt: float) -> FloatArray:
    ni, nj, nl = wa.shape[0], wa.shape[1], wa.shape[2]
    nm = wb.shape[1]
    out = np.zeros((ni, nj, nm))
    for i in range(ni):
        for j in range(nj):
            for m in range(nm):
                acc = 0.0
                for k in range(nl):
                    dx = wb[j, m, k, 0] - wa[i, j, k, 0]
                    dy = wb[j, m, k, 1] - wa[i, j, k, 1]
                    dz = wb[j, m, k, 2] - wa[i, j, k, 2]
                    acc += np.sqrt(dx * dx + dy * dy + dz * dz)
                out[i, j, m] = acc * inv_dt
    return out


def acceleration_cost(omegas_a: ArrayLike, omegas_b: ArrayLike, dt_s: float) -> FloatArray:
    """Eq. 3 with errata M1-M2: (Ni, Nj, Nm) summed |alpha| over links (rad/s^2).

    Parameters
    ----------
    omegas_a : (Ni, Nj, L, 3)
        `pair_omegas` between frames k and k + 1.
    omegas_b : (Nj, Nm, L, 3)
        `pair_omegas` between frames k + 1 and k + 2.
    dt_s : float
        The time between the two omegas' midpoints (one frame for an even rate).
    """
    a = np.ascontiguousarray(omegas_a, dtype=float)
    b = np.ascontiguousarray(omegas_b, dtype=float)
    if a.ndim != 4 or b.ndim != 4 or a.shape[1] != b.shape[0] or a.shape[2:] != b.shape[2:]:
        raise ShapeError(
            f"acceleration_cost: expected (Ni, Nj, L, 3) and (Nj, Nm, L, 3), found {a.shape}, "
            f"{b.shape}"
        )
    return np.asarray(_acc_cost(a, b, 1.0 / dt_s))


@nb.njit(cache=True)
def _acc_min(
    cost: FloatArray, wa: FloatArray, wb: FloatArray, inv_dt: float
) -> tuple[FloatArray, NDArray[np.int64]]:
    ni, nj, nl = wa.shape[0], wa.shape[1], wa.shape[2]
    nm = wb.shape[1]
    best = np.full((nj, nm), np.inf)
    back = np.zeros((nj, nm), dtype=np.int64)
    wj = np.empty((ni, nl, 3))
    for j in range(nj):
        order = np.argsort(cost[:, j], kind="mergesort")  # cheapest first, ties by index
        for i in range(ni):
            wj[i] = wa[i, j]
        for m in range(nm):
            b = np.inf
            arg = 0
            for r in range(ni):
                i = order[r]
                c = cost[i, j]
                if c > b or (c == b and i > arg):
                    break  # sorted: every later i starts at least as high
                acc = 0.0
                lost = False
                for k in range(nl):
                    dx = wb[j, m, k, 0] - wj[i, k, 0]
                    dy = wb[j, m, k, 1] - wj[i, k, 1]
                    dz = wb[j, m, k, 2] - wj[i, k, 2]
                    acc += np.sqrt(dx * dx + dy * dy + dz * dz)
                    t = c + acc * inv_dt
                    if t > b or (t == b and i > arg):
                        lost = True  # the partial sum only grows: i cannot win
                        break
                if lost:
                    continue
                tot = c + acc * inv_dt
                if tot < b or (tot == b and i < arg):
                    b = tot
                    arg = i
            best[j, m] = b
            back[j, m] = arg
    return best, back


def acceleration_min(
    pair_cost: ArrayLike, omegas_a: ArrayLike, omegas_b: ArrayLike, dt_s: float
) -> tuple[FloatArray, NDArray[np.int64]]:
    """Minimum over i of ``pair_cost[i, j] + acceleration_cost(...)[i, j, m]`` and its argmin.

    The pair-state Viterbi step over eq. 3 without the (Ni, Nj, Nm) array: for each
    (j, m) the candidates i are scanned cheapest ``pair_cost[i, j]`` first; the scan
    stops at the first i whose pair cost alone exceeds the best so far, and an i is
    dropped as soon as its cost plus its partial sum over links exceeds it (the sum
    only grows).
    The result equals ``tot = pair_cost[:, :, None] + acceleration_cost(...)``,
    ``tot.min(axis=0)``, ``tot.argmin(axis=0)`` exactly (same sums in the same order,
    ties to the first i).

    Parameters
    ----------
    pair_cost : (Ni, Nj) float
        Best path cost ending in each pair state (i, j).
    omegas_a, omegas_b, dt_s
        As `acceleration_cost`.

    Returns
    -------
    best : (Nj, Nm) float
    back : (Nj, Nm) int
    """
    c = np.ascontiguousarray(pair_cost, dtype=float)
    a = np.ascontiguousarray(omegas_a, dtype=float)
    b = np.ascontiguousarray(omegas_b, dtype=float)
    if (
        a.ndim != 4
        or b.ndim != 4
        or a.shape[1] != b.shape[0]
        or a.shape[2:] != b.shape[2:]
        or c.shape != a.shape[:2]
    ):
        raise ShapeError(
            f"acceleration_min: expected (Ni, Nj), (Ni, Nj, L, 3) and (Nj, Nm, L, 3), found "
            f"{c.shape}, {a.shape}, {b.shape}"
        )
    best, back = _acc_min(c, a, b, 1.0 / dt_s)
    return np.asarray(best), np.asarray(back)


def joint_acceleration_cost(
    pos_a: ArrayLike, pos_b: ArrayLike, pos_c: ArrayLike, dt_s: float
) -> FloatArray:
    """Eq. 4-5 with errata M4: (Ni, Nj, Nm) sum over joints |A_c - 2 A_b + A_a| / dt^2.

    Parameters
    ----------
    pos_a, pos_b, pos_c : (Ni, K, 3), (Nj, K, 3), (Nm, K, 3)
        Candidate joint positions of three consecutive frames (NaN joints add nothing).
    dt_s : float
    """
    a = np.asarray(pos_a, dtype=float)[:, None, None]
    b = np.asarray(pos_b, dtype=float)[None, :, None]
    c = np.asarray(pos_c, dtype=float)[None, None, :]
    e = np.linalg.norm(c - 2.0 * b + a, axis=-1)
    return np.asarray(np.nansum(e, axis=-1) / dt_s**2)
