"""One SDLS step (Buss & Kim 2005, errata Z2-Z7): compiled kernels and their Python entry points."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ShapeError
from mocapkit.ik.config import DEFAULT_GAMMA_RAD
from mocapkit.ik.lapack import thin_svd_v_nb
from mocapkit.ik.rigid_rows import no_sets, rigid_rows_nb
from mocapkit.ik.secondary import clamp_max_abs_nb

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]

#: Singular values below this fraction of the largest are ignored (errata Z6).
SIGMA_CUTOFF = 1e-10


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
def used_columns_nb(jw: FloatArray, skip: BoolArray, keep: BoolArray) -> tuple[IntArray, int]:
    """The columns of ``jw`` (3K, D) an SVD takes, in order: those not ``skip``ped that
    have a nonzero entry or are marked ``keep``. Returns ``cols`` (D,) and how many of
    its first entries are used."""
    n_rows, n_cols = jw.shape
    cols = np.empty(n_cols, dtype=np.int64)
    n_c = 0
    for j in range(n_cols):
        if skip[j]:
            continue
        use = keep[j]
        for r in range(n_rows):
            if use:
                break
            use = jw[r, j] != 0.0
        if use:
            cols[n_c] = j
            n_c += 1
    return cols, n_c


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
    pts: FloatArray,
    sets: tuple[NDArray[np.int64], NDArray[np.int64]],
) -> int:
    """SDLS response ``dpsi`` (D,) of ``jw`` (3K, D) to the error ``e`` (3K,), per-term clamped.

    Writes the rows of ``V^T`` kept (rank r) into ``vr[:r]`` (for the null-space
    projector), ``N_i``, ``M_i`` into ``n_out[:r]``, ``m_out[:r]`` and the kept singular
    values into ``s_out[:r]``. Returns r.
    ``term_scale`` multiplies every per-term bound ``gamma_i`` (`IKConfig.term_clamp_scale`).
    ``skip`` (D,) marks zero columns to leave out of the SVD (frozen DoFs); columns
    found to be zero are left out too. Their ``dpsi`` and ``vr`` entries are exactly 0.
    The SVD is LAPACK's dgesvd without U (`thin_svd_v_nb`) of the rows of
    `mocapkit.ik.rigid_rows.rigid_rows_nb`: six a rigid set of effectors (``sets``:
    ``order`` and ``bounds`` of `rigid_sets_nb`; ``pts`` (K, 3) the effectors'
    positions), the same singular values and V. ``u_i = J_w v_i / sigma_i``, from the
    whole ``J_w``, gives ``alpha_i`` and ``N_i``.
    The outer clamp is left to the caller (it also covers the secondary task).
    """
    n_rows, n_cols = jw.shape
    for j in range(n_cols):
        dpsi[j] = 0.0
    # the columns ``skip`` (frozen DoFs: zero) add only zero singular values (below
    # the cut-off) and null vectors, so the SVD is taken of the others alone. Their
    # ``dpsi`` is then exactly 0; for a DoF locked at a joint limit that would keep it
    # locked for good, so `solve_ik_nb` takes `sdls_gesdd_nb` on such iterations.
    # Columns that are zero for another reason (the legs' DoFs in a solve with the feet
    # free: no effector below the pelvis) are left out the same way: half the columns
    # of a re-plant's feet-free solves, whose SVD then costs about half as much
    cols, n_c = used_columns_nb(jw, skip, np.zeros(n_cols, dtype=np.bool_))
    if n_c == 0 or n_rows == 0:
        return 0
    jwc = np.empty((n_c, n_rows))  # the nonzero columns, column-major
    for r in range(n_rows):
        for c in range(n_c):
            jwc[c, r] = jw[r, cols[c]]
    rows = rigid_rows_nb(jw, pts, sets[0], sets[1], cols[:n_c])
    k = min(rows.shape[1], n_c)
    s = np.empty(k)
    vt = np.empty((n_c, k))
    thin_svd_v_nb(rows, s, vt)
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
    pts: FloatArray,
    sets: tuple[NDArray[np.int64], NDArray[np.int64]],
) -> int:
    """`sdls_nb` from numpy's SVD of the whole ``jw`` (LAPACK dgesdd, U formed).

    `solve_ik_nb` takes this one on iterations where a DoF is held at a joint limit:
    there the locked DoF's zeroed column gets steps of round-off size from dgesdd's
    singular vectors, and their sign decides when the DoF is released (module doc).
    Its SVD and terms are e6e041f's `sdls_nb` (bit for bit), so the locks are released
    by the same rule.

    Where ``sets`` (`mocapkit.ik.rigid_rows.rigid_sets_nb`; ``pts`` (K, 3) the effectors'
    positions) has rigid sets of effectors, the SVD is that of their fewer rows
    (`rigid_rows_nb`, every column: a locked DoF's zero column keeps its round-off) and
    ``u_i = J_w v_i / sigma_i`` comes from the whole ``J_w``, as in `sdls_nb`.

    Writes the rows of ``V^T`` kept (rank r) into ``vr[:r]`` (for the null-space
    projector), ``N_i``, ``M_i`` into ``n_out[:r]``, ``m_out[:r]`` and the kept singular
    values into ``s_out[:r]``. Returns r.
    ``term_scale`` multiplies every per-term bound ``gamma_i`` (`IKConfig.term_clamp_scale`).
    The outer clamp is left to the caller (it also covers the secondary task).
    """
    n_cols = jw.shape[1]
    for j in range(n_cols):
        dpsi[j] = 0.0
    every = np.arange(n_cols)
    if sets[1].shape[0] > 1:
        rows = rigid_rows_nb(jw, pts, sets[0], sets[1], every)
        _, s, vt = np.linalg.svd(rows.T, full_matrices=False)
        sigma_u = np.dot(vt, jw.T)  # row i: sigma_i u_i = J_w v_i
        return _sdls_terms_nb(
            jw, e, s, sigma_u, True, vt.T, every, gamma, soft, dpsi, vr, n_out, m_out,
            term_scale, s_out,
        )  # fmt: skip
    u, s, vt = np.linalg.svd(jw, full_matrices=False)
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
    n_eff = a.shape[0] // 3
    r = sdls_nb(
        a,
        ev,
        float(gamma_rad),
        bool(soft),
        dpsi,
        vr,
        nb,
        mb,
        float(term_clamp_scale),
        skip,
        sb,
        np.zeros((n_eff, 3)),
        no_sets(n_eff),
    )
    return SDLSStep(dpsi, vr[:r].copy(), nb[:r].copy(), mb[:r].copy())


def nullspace_projector(jw: ArrayLike) -> FloatArray:
    """Exact projector ``P = I - V_r V_r^T`` (D, D) onto the null space of ``jw`` (errata Z7)."""
    step = sdls_response(jw, np.zeros(np.shape(jw)[0]))
    d = step.v_r.shape[1]
    return np.eye(d) - step.v_r.T @ step.v_r


__all__ = [
    "SIGMA_CUTOFF",
    "SDLSStep",
    "clamp_error_nb",
    "clamp_max_abs",
    "clamp_target_error",
    "nullspace_projector",
    "project_nullspace_nb",
    "residuals_nb",
    "sdls_gesdd_nb",
    "sdls_nb",
    "sdls_response",
    "used_columns_nb",
]
