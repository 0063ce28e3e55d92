"""The compiled Nelder-Mead gives SciPy's iterates, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit
from scipy.optimize import Bounds, minimize

from mocapkit.ik.nelder_mead import initial_simplex, nelder_mead_nb


@njit(cache=True)
def _rosenbrock(x, a, b):
    return (a - x[0]) ** 2 + b * (x[1] - x[0] ** 2) ** 2 + 0.5 * (x[2] - x[1]) ** 2


@njit(cache=True)
def _bowl(x, a, b):
    return np.sum((x - a) ** 2 * b) + 0.1 * np.sin(3.0 * x[0])


@pytest.mark.parametrize("which", ["rosenbrock", "bowl_bounded", "tiny_budget"])
def test_nelder_mead_nb_reproduces_scipy(which, rng):
    if which == "rosenbrock":
        fun, a, b = _rosenbrock, 1.0, 100.0
        x0 = np.array([-1.2, 1.0, 0.3])
        lb, ub = np.full(3, -np.inf), np.full(3, np.inf)
        maxfev = 2000
    else:
        fun, a, b = _bowl, rng.uniform(-1, 1, 4), rng.uniform(0.5, 3.0, 4)
        x0 = rng.uniform(-0.5, 0.5, 4)
        lb, ub = np.full(4, -0.6), np.array([0.2, 0.9, 0.4, 0.45])
        maxfev = 300 if which == "bowl_bounded" else 23
    sim = initial_simplex(np.clip(x0, lb, ub), 0.1)
    res = minimize(
        lambda x: fun(x, a, b),
        np.clip(x0, lb, ub),
        method="Nelder-Mead",
        bounds=None if which == "rosenbrock" else Bounds(lb, ub),
        options={"initial_simplex": sim, "xatol": 1e-6, "fatol": 1e-8, "maxfev": maxfev},
    )
    x, fx, nfev, _nit, converged = nelder_mead_nb(fun, a, b, sim, lb, ub, 1e-6, 1e-8, maxfev)
    np.testing.assert_array_equal(x, res.x)
    assert fx == res.fun
    assert nfev == res.nfev
    assert converged == (res.status == 0)
