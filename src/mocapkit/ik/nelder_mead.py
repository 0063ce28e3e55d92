"""Downhill simplex (Nelder & Mead 1965) compiled with Numba, with SciPy's exact semantics.

A transcription of ``scipy.optimize.minimize(method="Nelder-Mead")`` (non-adaptive
coefficients, bounds by reflection then clipping of the initial simplex and clipping
of every trial point, the same stopping tests on ``xatol``/``fatol``/``maxfev``):
given the same cost and initial simplex it visits the same iterates, bit for bit
(tested). It exists because SciPy's pure-Python loop costs tens of microseconds per
evaluation, about ten times a compiled image cost, which would break a tracker's frame
budget. Used by the arm refinement (Zhang et al. 2011 §5.2, recipe Z step 4) and meant
for the other markerless trackers' local searches. It lives with the IK because it is a
pose solver over joint parameters that any tracker layer above may call.

Caching. A jitted function that receives another dispatcher as an argument cannot be
cached: the dispatcher's type differs in every process, so Numba saves a new entry
each run and never finds it again (numba issue #9237), and a cached caller that passes
one is refused as "uses dynamic globals". The simplex logic therefore lives once, in
`nelder_mead_core`, inlined at the IR level (``inline="always"``) into each caller
before typing: a production caller is a cached ``@njit(cache=True)`` function in its own
module that calls ``nelder_mead_core(its_cost, a, b, ...)`` with its cost as a
module-level global (e.g. `mocapkit.tracking.hybrid.arm_refinement.nelder_mead_arm_nb`).
`nelder_mead_nb` takes any cost as an argument and is compiled anew in every process.
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def initial_simplex(x0: FloatArray, step_rad: float) -> FloatArray:
    """Recipe Z step 4: ``x0`` and ``x0 + step * e_k`` for each DoF, shape (N + 1, N)."""
    n = x0.shape[0]
    sim = np.repeat(x0[None, :], n + 1, axis=0)
    sim[1:] += step_rad * np.eye(n)
    return sim


@numba.njit(cache=True)
def _sort_simplex(sim: FloatArray, fsim: FloatArray) -> None:
    """Stable sort of the vertices by value (insertion sort: SciPy's argsort on <= 16
    items is an insertion sort too, so ties keep the same order)."""
    n = fsim.shape[0]
    row = np.empty(sim.shape[1])
    for i in range(1, n):
        f = fsim[i]
        _row_to(sim, i, row)
        j = i - 1
        while j >= 0 and fsim[j] > f:
            fsim[j + 1] = fsim[j]
            _row_to(sim, j, sim[j + 1])
            j -= 1
        fsim[j + 1] = f
        _to_row(row, sim, j + 1)


# Element loops for the row copies of the simplex: slice assignment (``a[:] = b``)
# compiles to a broadcasting check with a formatted error path, several times the
# code of the loop, in every one of the dozen places the search copies a vertex.
# Plain calls, not ``inline="always"``: Numba's IR inlining re-runs its front end per
# call site (the search compiled in ~8 s instead of ~3 s), and LLVM inlines them anyway.
@numba.njit(cache=True)
def _row_to(m: FloatArray, i: int, out: FloatArray) -> None:
    """``out[:] = m[i]``."""
    for j in range(out.shape[0]):
        out[j] = m[i, j]


@numba.njit(cache=True)
def _to_row(v: FloatArray, m: FloatArray, i: int) -> None:
    """``m[i] = v``."""
    for j in range(v.shape[0]):
        m[i, j] = v[j]


@numba.njit(cache=True)
def _vec_to(v: FloatArray, out: FloatArray) -> None:
    """``out[:] = v``."""
    for j in range(v.shape[0]):
        out[j] = v[j]


@numba.njit(cache=True)
def clip_nb(x: FloatArray, lb: FloatArray, ub: FloatArray) -> None:
    """Clip ``x`` into ``[lb, ub]`` in place."""
    for i in range(x.shape[0]):
        x[i] = min(max(x[i], lb[i]), ub[i])


@numba.njit(inline="always")
def nelder_mead_core(
    fun: Any,
    a: Any,
    b: Any,
    initial_simplex: FloatArray,
    lb: FloatArray,
    ub: FloatArray,
    xatol: float,
    fatol: float,
    maxfev: int,
) -> tuple[FloatArray, float, int, int, bool]:
    """Downhill simplex with SciPy's semantics; see `nelder_mead_nb` (never called from Python).

    Scalar loops throughout: NumPy array expressions here multiply the generated code
    (and compile time) several-fold. Each loop computes, element by element, the same
    expression in the same order as the SciPy line it transcribes (quoted), so the
    iterates are bit-identical.
    """
    rho = 1.0
    chi = 2.0
    psi = 0.5
    sigma = 0.5
    n = initial_simplex.shape[1]
    sim = initial_simplex.copy()
    # SciPy: reflect vertices above the upper bound into the interior, then clip
    for i in range(n + 1):
        for j in range(n):
            if sim[i, j] > ub[j]:
                sim[i, j] = 2.0 * ub[j] - sim[i, j]
            sim[i, j] = min(max(sim[i, j], lb[j]), ub[j])
    fsim = np.full(n + 1, np.inf)
    xt = np.empty(n)  # SciPy hands the cost a copy of the point
    nfev = 0
    for k in range(n + 1):
        if nfev >= maxfev:
            break
        _row_to(sim, k, xt)
        fsim[k] = fun(xt, a, b)
        nfev += 1
    _sort_simplex(sim, fsim)
    iterations = 1
    converged = False
    xbar = np.empty(n)
    xr = np.empty(n)
    xe = np.empty(n)
    xc = np.empty(n)
    while nfev < maxfev:
        # convergence test, as SciPy's: max |sim[1:] - sim[0]| <= xatol and
        # max |fsim[0] - fsim[1:]| <= fatol
        dx = 0.0
        df = 0.0
        for i in range(1, n + 1):
            for j in range(n):
                dx = max(dx, abs(sim[i, j] - sim[0, j]))
            df = max(df, abs(fsim[0] - fsim[i]))
        if dx <= xatol and df <= fatol:
            converged = True
            break
        # "xbar = np.add.reduce(sim[:-1], 0) / N": row after row, as NumPy's axis-0 reduce
        for j in range(n):
            acc = sim[0, j]
            for i in range(1, n):
                acc += sim[i, j]
            xbar[j] = acc / n
        # "xr = (1 + rho) * xbar - rho * sim[-1]"
        for j in range(n):
            xr[j] = (1 + rho) * xbar[j] - rho * sim[n, j]
        clip_nb(xr, lb, ub)
        _vec_to(xr, xt)
        fxr = fun(xt, a, b)
        nfev += 1
        doshrink = False
        if fxr < fsim[0]:
            if nfev >= maxfev:
                break
            # "xe = (1 + rho * chi) * xbar - rho * chi * sim[-1]"
            for j in range(n):
                xe[j] = (1 + rho * chi) * xbar[j] - rho * chi * sim[n, j]
            clip_nb(xe, lb, ub)
            _vec_to(xe, xt)
            fxe = fun(xt, a, b)
            nfev += 1
            if fxe < fxr:
                _to_row(xe, sim, n)
                fsim[n] = fxe
            else:
                _to_row(xr, sim, n)
                fsim[n] = fxr
        elif fxr < fsim[n - 1]:
            _to_row(xr, sim, n)
            fsim[n] = fxr
        else:
            if nfev >= maxfev:
                break
            if fxr < fsim[n]:
                # outside contraction: "xc = (1 + psi * rho) * xbar - psi * rho * sim[-1]"
                for j in range(n):
                    xc[j] = (1 + psi * rho) * xbar[j] - psi * rho * sim[n, j]
                clip_nb(xc, lb, ub)
                _vec_to(xc, xt)
                fxc = fun(xt, a, b)
                nfev += 1
                if fxc <= fxr:
                    _to_row(xc, sim, n)
                    fsim[n] = fxc
                else:
                    doshrink = True
            else:
                # inside contraction: "xcc = (1 - psi) * xbar + psi * sim[-1]"
                for j in range(n):
                    xc[j] = (1 - psi) * xbar[j] + psi * sim[n, j]
                clip_nb(xc, lb, ub)
                _vec_to(xc, xt)
                fxcc = fun(xt, a, b)
                nfev += 1
                if fxcc < fsim[n]:
                    _to_row(xc, sim, n)
                    fsim[n] = fxcc
                else:
                    doshrink = True
            if doshrink:
                for i in range(1, n + 1):
                    # "sim[j] = sim[0] + sigma * (sim[j] - sim[0])", then clipped
                    for j in range(n):
                        sim[i, j] = sim[0, j] + sigma * (sim[i, j] - sim[0, j])
                    clip_nb(sim[i], lb, ub)
                    if nfev >= maxfev:
                        # SciPy: the vertex has moved but its value is stale
                        break
                    _row_to(sim, i, xt)
                    fsim[i] = fun(xt, a, b)
                    nfev += 1
        iterations += 1
        _sort_simplex(sim, fsim)
    _sort_simplex(sim, fsim)
    return sim[0].copy(), fsim[0], nfev, iterations, converged


# not cache=True: a dispatcher argument defeats the on-disk cache (notes above) and
# would only add a new cache entry per process
@numba.njit
def nelder_mead_nb(
    fun: Any,
    a: Any,
    b: Any,
    initial_simplex: FloatArray,
    lb: FloatArray,
    ub: FloatArray,
    xatol: float,
    fatol: float,
    maxfev: int,
) -> tuple[FloatArray, float, int, int, bool]:
    """Downhill simplex with SciPy's semantics (``adaptive=False``, bounds by clipping).

    Generic in the cost; compiled anew in every process (a function argument defeats
    Numba's cache; module notes). Cached production callers inline `nelder_mead_core`
    with their cost as a global instead.

    Parameters
    ----------
    fun : numba-compiled callable ``fun(x, a, b) -> float``
    a, b : any
        Extra arguments passed to ``fun``.
    initial_simplex : ndarray, shape (N + 1, N)
    lb, ub : ndarray, shape (N,)
        Bounds (``-inf``/``inf`` for none).
    xatol, fatol : float
        Stop when every vertex is within ``xatol`` of the best in every coordinate and
        every value within ``fatol`` of the best value.
    maxfev : int
        Evaluation budget.

    Returns
    -------
    x : ndarray (N,)
    fx : float
    nfev : int
    nit : int
    converged : bool
        Stopped on the tolerances.
    """
    return nelder_mead_core(fun, a, b, initial_simplex, lb, ub, xatol, fatol, maxfev)


__all__ = ["clip_nb", "initial_simplex", "nelder_mead_core", "nelder_mead_nb"]
