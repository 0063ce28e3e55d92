"""Balance heuristic (Zhang §5.3, errata Z12): spine bow keeps the CoG over the feet."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.ik.sdls import SDLSSolver
from mocapkit.skeleton import load_preset
from mocapkit.tracking.balance import (
    BalanceConfig,
    balance_pose,
    calibrate_balance,
    cog_offset_mm,
    support_points,
)


@pytest.fixture(scope="module")
def setup():
    sk = load_preset("zhang21")
    solver = SDLSSolver(sk)
    model = calibrate_balance(solver)
    return sk, solver, model


def squat(solver, depths):
    """IK poses of a squat: head and hands go down by dh (head a little forward), feet planted."""
    q0 = solver.secondary.omega.copy()
    s0 = solver.effector_positions(q0)
    q = q0.copy()
    for dh in depths:
        t = s0.copy()
        t[:3, 2] += dh
        t[0, 1] -= 0.2 * dh
        q = solver.solve(q, t).q
        yield q, t


def test_tau_zero_at_rest_and_sign(setup):
    sk, solver, model = setup
    np.testing.assert_array_equal(model.taus(0.0), 0.0)
    # a squat (dh < 0) asks for forward flexion, so p < 0 (errata Z12)
    assert np.all(model.p_rad_per_mm < 0)
    q0 = solver.secondary.omega
    res = balance_pose(
        solver,
        q0,
        solver.effector_positions(q0),
        q0[2],
        support_points(sk, q0),
        model,
        BalanceConfig(mode="proportional"),
    )
    np.testing.assert_array_equal(res.taus, 0.0)


@pytest.mark.parametrize("mode", ["proportional", "solve"])
def test_squat_keeps_markers_and_improves_balance(setup, mode):
    sk, solver, model = setup
    q0 = solver.secondary.omega
    support = support_points(sk, q0)
    cfg = BalanceConfig(mode=mode)
    worst_off, worst_on, inside = 0.0, 0.0, 0
    depths = np.linspace(-20.0, -300.0, 12)
    for q, t in squat(solver, depths):
        cog, back, front = cog_offset_mm(sk, q, support)
        worst_off = max(worst_off, cog - front, back - cog)
        res = balance_pose(solver, q, t, q0[2], support, model, cfg)
        # head and hands stay on their markers (Z12): within twice the IK tolerance
        assert np.nanmax(res.residual_mm) <= 2.0 * solver.config.tol_mm
        cog, back, front = cog_offset_mm(sk, res.q, support)
        worst_on = max(worst_on, cog - front, back - cog)
        inside += back <= cog <= front
    assert worst_off > 50.0  # without the heuristic the squat falls forward out of the box
    assert worst_on < worst_off
    if mode == "solve":
        # markers come first (Z12): where head and hands cannot be restored under the
        # needed bow, the bow is halved and the CoG may leave the box (1 of 12 here)
        assert inside >= 0.9 * len(depths)


def test_bad_config():
    with pytest.raises(ConfigError, match="BalanceConfig.mode"):
        BalanceConfig(mode="tilt")
