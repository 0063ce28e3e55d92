"""Iterations that do the work of several: scaled SDLS term bounds and relaxation sub-steps.

`IKConfig.term_clamp_scale` and `IKConfig.relax_substeps` (the hybrid tracker's default
takes 10 of each, with 10 iterations a solve instead of 100).
"""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.ik.config import IKConfig
from mocapkit.ik.sdls import SDLSSolver
from mocapkit.ik.sdls_step import clamp_max_abs, nullspace_projector, sdls_response
from mocapkit.skeleton import PRISMATIC, load_preset


@pytest.fixture(scope="module")
def skel():
    return load_preset("zhang21")


def _upper_pose(skel, rng, scale=0.4):
    q = np.zeros(skel.n_dofs)
    for d, name in enumerate(skel.dof_names):
        if skel.dof_kind[d] == PRISMATIC or "hip" in name or "knee" in name:
            continue
        q[d] = rng.normal(0.0, scale)
    return np.clip(q, skel.lower, skel.upper)


@pytest.mark.parametrize("m", [2, 5, 10])
def test_scaled_term_bounds_equal_m_linearised_iterations(skel, rng, m):
    """One response with bounds ``m gamma_i`` equals ``m`` responses on the same Jacobian
    with the error updated linearly (``e <- e - J_w dpsi``) in between (hard clamp)."""
    solver = SDLSSolver(skel)
    for _ in range(5):
        q = _upper_pose(skel, rng)
        _, _, jw = solver.weighted_jacobian(q)
        e = rng.normal(0.0, 40.0, size=jw.shape[0])
        total = np.zeros(jw.shape[1])
        e_now = e.copy()
        for _ in range(m):
            step = sdls_response(jw, e_now).dpsi
            total += step
            e_now = e_now - jw @ step
        once = sdls_response(jw, e, term_clamp_scale=m).dpsi
        np.testing.assert_allclose(once, total, rtol=0, atol=1e-9 * np.abs(total).max())
        # not trivially so: some term is bounded at m = 1 (a single plain step falls short)
        assert np.abs(sdls_response(jw, e).dpsi * m - total).max() > 1e-6


@pytest.mark.parametrize("m", [1, 4])
def test_relax_substeps_equal_repeated_projected_gradient_steps(skel, rng, m):
    """One iteration with ``relax_substeps = m``, targets already met (no primary step):
    ``m`` gradient steps of the relaxed-pose task (Z8), each from the pose the previous
    ones reached, with the weights and the projector of the iteration's pose."""
    cfg = IKConfig(max_iterations=1, min_iterations=1, relax_substeps=m)
    solver = SDLSSolver(skel, config=cfg)
    q0 = _upper_pose(skel, rng, scale=0.3)
    targets = solver.effector_positions(q0)
    got = solver.solve(q0, targets).q

    sec = solver.secondary
    mh = sec.weights(q0)
    w = mh / mh.max()
    mu = solver.mu
    _, _, jw = solver.weighted_jacobian(q0)
    p = nullspace_projector(jw)
    acc = np.zeros(skel.n_dofs)
    q_sub = q0.copy()
    sec_max = min(cfg.secondary_max_step_rad, cfg.gamma_rad)
    for _ in range(m):
        dphi = clamp_max_abs(-2.0 * cfg.secondary_gain * w * (q_sub - sec.omega), sec_max)
        acc += p @ (dphi * mu)
        q_sub = q0 + acc / mu
    dpsi = clamp_max_abs(acc, cfg.gamma_rad)
    want = np.clip(q0 + dpsi / mu, skel.lower, skel.upper)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    # the task's weighted distance to the relaxed pose falls, and further with more steps
    one = SDLSSolver(skel, config=IKConfig(max_iterations=1, min_iterations=1))
    dist = lambda q: float(np.sum(w * (mu * (q - sec.omega)) ** 2))  # noqa: E731
    assert dist(got) < dist(q0)
    if m > 1:
        assert dist(got) < dist(one.solve(q0, targets).q)


def test_scaled_solver_reaches_fk_targets_in_fewer_iterations(skel, rng):
    """FK targets from a pose 0.3 rad away (10 problems): the scaled solver (10 and 10,
    at most 100 iterations) reaches the tolerance on every one, never in more iterations
    than the plain solver, which runs out of iterations on some (the flat valley)."""
    plain = SDLSSolver(skel)
    fast = SDLSSolver(skel, config=IKConfig(term_clamp_scale=10.0, relax_substeps=10))
    n_plain_capped = 0
    for _ in range(10):
        q_true = _upper_pose(skel, rng)
        targets = plain.effector_positions(q_true)
        noise = rng.normal(0.0, 0.3, skel.n_dofs) * (skel.dof_kind != PRISMATIC)
        start = np.clip(q_true + noise, skel.lower, skel.upper)
        start[:3] = q_true[:3]
        a = plain.solve(start, targets)
        b = fast.solve(start, targets)
        assert b.converged
        assert np.nanmax(b.residual_mm) < plain.config.tol_mm
        assert b.iterations <= a.iterations
        n_plain_capped += a.iterations == plain.config.max_iterations
    assert n_plain_capped >= 1


def test_scaled_settings_are_checked():
    with pytest.raises(ConfigError, match="relax_substeps >= 1"):
        IKConfig(relax_substeps=0)
    with pytest.raises(ConfigError, match="term_clamp_scale >= 1"):
        IKConfig(term_clamp_scale=0.5)
