"""Errata tests for Zhang et al. 2011 §4 (Z1-Z8, Z13): Jacobian, clamps, SDLS, null space."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mocapkit.errors import ConfigError, ShapeError, UnknownNameError
from mocapkit.ik.config import DEFAULT_GAMMA_RAD, IKConfig
from mocapkit.ik.sdls import SDLSSolver
from mocapkit.ik.sdls_step import (
    clamp_max_abs,
    clamp_target_error,
    nullspace_projector,
    sdls_response,
)
from mocapkit.ik.weights import arm_length_mm, dof_weights
from mocapkit.skeleton import PRISMATIC, load_preset


@pytest.fixture(scope="module")
def skel():
    return load_preset("zhang21")


@pytest.fixture(scope="module")
def solver(skel):
    return SDLSSolver(skel)


def random_upper_pose(skel, rng, scale=0.4):
    """A random pose with legs straight and the root at rest (so the feet stay put)."""
    q = np.zeros(skel.n_dofs)
    for d, name in enumerate(skel.dof_names):
        if skel.dof_kind[d] == PRISMATIC or "hip" in name or "knee" in name:
            continue
        q[d] = rng.normal(0.0, scale)
    return np.clip(q, skel.lower, skel.upper)


def test_table1_dof_count_and_mass(skel):
    rot = skel.dof_kind != PRISMATIC
    assert int(rot.sum()) == 21
    assert skel.total_mass_kg == pytest.approx(80.67, abs=1e-9)
    assert arm_length_mm(skel) == pytest.approx(730.0)
    assert SDLSSolver(skel).dmax_mm == pytest.approx(73.0)


def test_jacobian_matches_central_differences(skel, solver, rng):
    q = random_upper_pose(skel, rng)
    q[:3] = [10.0, -20.0, -30.0]
    _, jac, jw = solver.weighted_jacobian(q)
    for d in range(skel.n_dofs):
        h = 1e-3 if skel.dof_kind[d] == PRISMATIC else 1e-6
        qp, qm = q.copy(), q.copy()
        qp[d] += h
        qm[d] -= h
        num = (solver.effector_positions(qp) - solver.effector_positions(qm)).ravel() / (2 * h)
        scale = max(np.abs(jac[:, d]).max(), 1.0)
        assert np.abs(num - jac[:, d]).max() < 1e-6 * scale, skel.dof_names[d]
    dpsi = rng.normal(size=skel.n_dofs)
    np.testing.assert_allclose(jw @ dpsi, jac @ (dpsi / solver.mu), rtol=1e-12, atol=1e-9)


def test_weights_normalised_and_prismatic_scaled(skel):
    mu = dof_weights(skel)
    rot = skel.dof_kind != PRISMATIC
    assert mu[rot].min() == pytest.approx(1.0)
    # elbows carry the least mass; the root translation is made per-mm by the leg length
    assert mu[skel.dof_index("l_elbow_flexion")] == pytest.approx(1.0)
    leg = 386.0 + 550.0
    assert mu[0] * leg == pytest.approx(math.sqrt(skel.total_mass_kg / (1.31 + 0.52)))


def test_clamp_max_abs_only_shrinks_and_is_idempotent(rng):
    for _ in range(200):
        w = rng.normal(size=7) * rng.uniform(0.01, 10)
        d = rng.uniform(0.0, 3.0)
        c = clamp_max_abs(w, d)
        assert np.abs(c).max() <= max(d, 0.0) + 1e-12
        assert np.abs(c).max() <= np.abs(w).max() + 1e-15
        np.testing.assert_array_equal(clamp_max_abs(c, d), c)
        if np.abs(w).max() <= d:
            np.testing.assert_array_equal(c, w)
        else:  # direction kept
            np.testing.assert_allclose(c / np.abs(c).max(), w / np.abs(w).max())


def test_target_clamp_is_per_effector():
    s = np.zeros((3, 3))
    t = np.array([[10.0, 0, 0], [0, 300.0, 0], [0, 0, 73.0]])
    e = clamp_target_error(s, t, 73.0).reshape(3, 3)
    np.testing.assert_allclose(e[0], [10.0, 0, 0])  # near target kept whole (not rescaled)
    np.testing.assert_allclose(e[1], [0, 73.0, 0])  # far target shortened to D_max
    np.testing.assert_allclose(e[2], [0, 0, 73.0])


def test_sdls_n_in_range_and_damping_bounded(skel, solver, rng):
    k = len(solver.effectors)
    for _ in range(20):
        q = random_upper_pose(skel, rng, 0.8)
        _, _, jw = solver.weighted_jacobian(q)
        e = rng.normal(size=3 * k) * 50
        step = sdls_response(jw, e)
        assert np.all(step.n >= 1.0 - 1e-9)
        assert np.all(step.n <= math.sqrt(k) + 1e-9)
        assert np.all(step.m > 0)
        # every term is clamped to gamma_i <= Gamma, so the sum is bounded by r Gamma
        assert np.abs(step.dpsi).max() <= len(step.n) * DEFAULT_GAMMA_RAD + 1e-9


def test_nullspace_projector_exact(skel, solver, rng):
    q = random_upper_pose(skel, rng)
    _, _, jw = solver.weighted_jacobian(q)
    p = nullspace_projector(jw)
    np.testing.assert_allclose(p @ p, p, atol=1e-12)
    np.testing.assert_allclose(p, p.T, atol=1e-12)
    for _ in range(10):
        x = rng.normal(size=skel.n_dofs)
        assert np.linalg.norm(jw @ (p @ x)) < 1e-10 * np.linalg.norm(x) * np.linalg.norm(jw, 2)


def test_nullspace_drift_is_second_order(skel, solver, rng):
    q = random_upper_pose(skel, rng)
    _, _, jw = solver.weighted_jacobian(q)
    p = nullspace_projector(jw)
    x = p @ rng.normal(size=skel.n_dofs)
    x /= np.abs(x).max()
    s0 = solver.effector_positions(q)

    def drift(eps):
        return np.abs(solver.effector_positions(q + eps * x / solver.mu) - s0).max()

    ratio = drift(0.02) / drift(0.01)
    assert 3.6 < ratio < 4.4


@pytest.mark.parametrize("clamp", ["hard", "soft"])
def test_fk_targets_reached(skel, rng, clamp):
    solver = SDLSSolver(skel, config=IKConfig(clamp=clamp))
    q0 = solver.secondary.omega
    n_trials, reached = 60, 0
    for _ in range(n_trials):
        qt = random_upper_pose(skel, rng)
        res = solver.solve(q0, solver.effector_positions(qt), record_trace=True)
        reached += res.converged
        assert res.trace is not None
        assert np.all(res.trace[:, 1] <= DEFAULT_GAMMA_RAD + 1e-12)  # revolute steps
        assert np.all(res.trace[:, 2] <= DEFAULT_GAMMA_RAD + 1e-12)  # weighted steps
        assert np.all(res.trace[:, 3] <= DEFAULT_GAMMA_RAD * solver.mu[0] ** -1 + 1e-9)
        assert np.all(res.q >= skel.lower) and np.all(res.q <= skel.upper)
    assert reached >= 0.95 * n_trials


@pytest.mark.parametrize("clamp", ["hard", "soft"])
def test_unreachable_target_settles(skel, clamp):
    # the loop's own dynamics over 300 steps (the early stop on a stall is off)
    cfg = IKConfig(max_iterations=300, clamp=clamp, stall_iterations=0)
    solver = SDLSSolver(skel, config=cfg)
    q0 = solver.secondary.omega
    targets = solver.effector_positions(q0)
    hand = solver.effector_index("right_hand")
    targets[hand] += [2500.0, 0.0, 0.0]
    res = solver.solve(q0, targets, record_trace=True)
    assert not res.converged and res.iterations == 300
    assert res.trace is not None
    tail = res.trace[-50:]
    # settled, no oscillation: over the last 50 iterations the worst error varies by
    # under 1 % and every step is at least 20 times below Gamma (a flip-flopping
    # solver would keep taking steps of order Gamma)
    assert np.ptp(tail[:, 0]) < 0.01 * tail[:, 0].mean()
    assert tail[:, 1].max() < DEFAULT_GAMMA_RAD / 20
    # and it got as close as it could: the hand moved towards the target
    start = solver.effector_positions(q0)[hand]
    end = solver.effector_positions(res.q)[hand]
    assert end[0] - start[0] > 500.0


@pytest.mark.parametrize("clamp", ["hard", "soft"])
def test_unreachable_target_stops_early_once_settled(skel, clamp):
    full = SDLSSolver(skel, config=IKConfig(max_iterations=300, clamp=clamp, stall_iterations=0))
    early = SDLSSolver(
        skel,
        config=IKConfig(max_iterations=300, clamp=clamp, stall_iterations=35, stall_fraction=0.005),
    )
    q0 = full.secondary.omega
    targets = full.effector_positions(q0)
    hand = full.effector_index("right_hand")
    targets[hand] += [2500.0, 0.0, 0.0]
    a = full.solve(q0, targets)
    b = early.solve(q0, targets)
    assert b.iterations < 0.7 * a.iterations
    # it stopped where the full run also ends up: within 1 % of the settled error
    assert b.residual_mm[hand] == pytest.approx(a.residual_mm[hand], rel=0.01)


def test_warm_start_tracks_in_about_one_iteration(skel, solver):
    n = 50
    t = np.arange(n) / 50.0
    q = np.tile(solver.secondary.omega, (n, 1))
    for d, name in enumerate(skel.dof_names):
        if "shoulder" in name or "elbow" in name:
            q[:, d] += 0.5 * np.sin(2 * np.pi * 0.5 * t + d) + 0.4
    q = np.clip(q, skel.lower, skel.upper)
    qc = q[0].copy()
    iters = []
    for i in range(n):
        res = solver.solve(qc, solver.effector_positions(q[i]))
        assert res.converged
        qc = res.q
        iters.append(res.iterations)
    assert np.mean(iters) < 3


def test_inactive_and_frozen(skel, solver, rng):
    q0 = solver.secondary.omega
    qt = random_upper_pose(skel, rng)
    targets = solver.effector_positions(qt)
    targets[solver.effector_index("left_hand")] = np.nan
    frozen = np.zeros(skel.n_dofs, dtype=bool)
    frozen[skel.dof_index("l_elbow_flexion")] = True
    res = solver.solve(q0, targets, frozen=frozen)
    assert np.isnan(res.residual_mm[solver.effector_index("left_hand")])
    assert res.q[skel.dof_index("l_elbow_flexion")] == q0[skel.dof_index("l_elbow_flexion")]


def test_bad_inputs_raise(skel, solver):
    with pytest.raises(ShapeError, match="targets_mm: expected shape"):
        solver.solve(solver.secondary.omega, np.zeros((2, 3)))
    with pytest.raises(ShapeError, match="q0"):
        solver.solve(np.zeros(3), np.zeros((5, 3)))
    with pytest.raises(ConfigError, match="secondary_gain"):
        IKConfig(secondary_gain=5.0)
    with pytest.raises(ConfigError, match="clamp"):
        IKConfig(clamp="medium")
    with pytest.raises(UnknownNameError, match="effector"):
        solver.effector_index("tail")
