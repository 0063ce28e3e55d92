"""Releasing a DoF locked at a joint limit by the active-set rule (`IKConfig.lock_release`).

With ``"kkt"`` a locked DoF's column is left out of the SVD and the DoF is released when
the step the problem with its column back wants for it (`free_step_nb`) points inside
the range; the solves then no longer rest on round-off (docs/hybrid.md, Speed).
"""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.ik.sdls import IKConfig, SDLSSolver, free_step_nb, release_locks_nb
from mocapkit.skeleton import PRISMATIC, load_preset


@pytest.fixture(scope="module")
def skel():
    return load_preset("zhang21")


def _svd_terms(jw):
    """Kept right singular vectors (rows), singular values and U of ``jw``."""
    u, s, vt = np.linalg.svd(jw, full_matrices=False)
    keep = s > 1e-10 * s[0]
    return vt[keep].copy(), s[keep].copy(), u[:, keep]


def _direct_free_step(jw_free, j, e, z, lam2):
    """Component ``j`` of ``z + J^T (J J^T + lam2 I)^-1 (e - J z)`` (J with column j)."""
    m = jw_free @ jw_free.T + lam2 * np.eye(jw_free.shape[0])
    return float((z + jw_free.T @ np.linalg.solve(m, e - jw_free @ z))[j])


def _free_step(jw_free, j, e, z, lam2):
    """`free_step_nb` for column ``j`` of ``jw_free`` (the others as ``A``)."""
    jw = jw_free.copy()
    a = jw[:, j].copy()
    jw[:, j] = 0.0
    zc = z.copy()
    zc[j] = 0.0
    e0 = e - jw @ zc
    vr, s, u = _svd_terms(jw)
    qe = u.T @ e0
    return free_step_nb(jw, vr, s, len(s), qe, a, e0, float(z[j]), lam2)


@pytest.mark.parametrize(("rows", "cols"), [(12, 5), (6, 9)])
def test_free_step_is_the_damped_step_of_the_problem_with_the_column_back(rng, rows, cols):
    """Against the damped least-squares step written out, with a column outside the
    others' range (12 x 5) and one inside it (6 x 9: the DoF is redundant)."""
    for _ in range(5):
        jw = rng.normal(size=(rows, cols)) * rng.uniform(0.1, 10.0, cols)
        e = rng.normal(size=rows) * 10.0
        z = rng.normal(size=cols) * 0.05
        for lam2 in (1e-2, 1.0, 100.0):
            for j in (0, cols - 1):
                got = _free_step(jw, j, e, z, lam2)
                want = _direct_free_step(jw, j, e, z, lam2)
                assert got == pytest.approx(want, rel=1e-8, abs=1e-12)


def test_free_step_tends_to_the_active_set_multiplier_and_to_greville(rng):
    jw = rng.normal(size=(12, 5))
    e = rng.normal(size=12)
    z = np.zeros(5)
    # a column with a part outside the others' range: c . e / |c|^2 (the sign of the
    # bound's multiplier at the constrained least-squares optimum)
    u, _, _ = np.linalg.svd(np.delete(jw, 2, axis=1), full_matrices=False)
    c = jw[:, 2] - u @ (u.T @ jw[:, 2])
    assert _free_step(jw, 2, e, z, 1e-12) == pytest.approx(c @ e / (c @ c), rel=1e-6)
    # a redundant column (a combination of the others) with the secondary task's step:
    # the minimum-norm least-squares step plus the null-space share of z
    jw[:, 4] = jw[:, :4] @ np.array([0.5, -1.0, 0.25, 2.0])
    jw = jw[:6]
    e = e[:6]
    z = rng.normal(size=5) * 0.1
    pinv = np.linalg.pinv(jw)
    want = (pinv @ e + (np.eye(5) - pinv @ jw) @ z)[4]
    # (the damping, 1e-4 sigma_1 as in the solver, keeps the round-off of c ~ 1e-16 |a|
    # from deciding; it moves the step by about lam2 / sigma_min^2)
    assert _free_step(jw, 4, e, z, 1e-8) == pytest.approx(want, rel=1e-6)


@pytest.mark.parametrize("side", ["lower", "upper"])
def test_a_locked_dof_is_released_exactly_when_its_free_step_points_inside(rng, side):
    jac = rng.normal(size=(9, 4)) * 10.0
    inv_mu = np.ones(4)
    lower = np.full(4, -1.0)
    upper = np.full(4, 1.0)
    q = np.zeros(4)
    q[3] = lower[3] if side == "lower" else upper[3]
    frozen = np.zeros(4, dtype=bool)
    jw = jac.copy()
    jw[:, 3] = 0.0
    vr, s, u = _svd_terms(jw)
    c = jac[:, 3] - u @ (u.T @ jac[:, 3])
    inward = 1.0 if side == "lower" else -1.0
    margin = 1e-3
    # e = t c: the free problem wants the locked DoF to move by t (to 1e-9, the damping)
    for t, released in [(2e-3, True), (5e-4, False), (-2e-3, False), (0.0, False)]:
        e = inward * t * c
        locked = np.array([False, False, False, True])
        work = [np.empty(9), np.empty(4), np.empty(len(s)), np.empty(9)]
        release_locks_nb(
            q, jac, jw, e, np.zeros(4), inv_mu, lower, upper, frozen, vr, s, len(s),
            1e-12 * s[0] ** 2, margin, locked, *work,
        )  # fmt: skip
        assert locked[3] == (not released), t


def _upper_pose(skel, rng, scale=0.4):
    q = np.zeros(skel.n_dofs)
    for d, name in enumerate(skel.dof_names):
        if skel.dof_kind[d] == PRISMATIC or "hip" in name or "knee" in name:
            continue
        q[d] = rng.normal(0.0, scale)
    return np.clip(q, skel.lower, skel.upper)


@pytest.mark.parametrize(
    "config",
    [
        IKConfig(lock_release="kkt"),
        IKConfig(
            lock_release="kkt", svd="gesvd", max_iterations=30, term_clamp_scale=3.0,
            relax_substeps=3,
        ),
    ],
    ids=["plain", "tracking"],
)  # fmt: skip
def test_kkt_solves_do_not_rest_on_round_off(skel, config):
    """Targets moved by 1e-9 mm move the solution by about 1e-9 rad, not by a branch.

    (With ``"roundoff"`` the same 20 problems move by a median 0.18 rad, 34 mm at most:
    every lock's release there is a coin toss of round-off.)"""
    rng = np.random.default_rng(5)
    solver = SDLSSolver(skel, config=config)
    moved = []
    for _ in range(20):
        q_true = _upper_pose(skel, rng)
        targets = solver.effector_positions(q_true) + rng.normal(0.0, 5.0, (5, 3))
        noise = rng.normal(0.0, 0.3, skel.n_dofs) * (skel.dof_kind != PRISMATIC)
        start = np.clip(q_true + noise, skel.lower, skel.upper)
        a = solver.solve(start, targets)
        b = solver.solve(start, targets + 1e-9)
        moved.append(np.max(np.abs(a.q - b.q)))
    moved_arr = np.array(moved)
    assert np.sum(moved_arr < 1e-7) >= 18
    assert np.max(moved_arr) < 1e-3


def test_kkt_scaled_solver_reaches_fk_targets(skel):
    """The 10-in-1 solver of test_sdls_scaled reaches every FK target with the rule
    (with locks never released it missed 9 of 10)."""
    rng = np.random.default_rng(20261121)
    plain = SDLSSolver(skel)
    fast = SDLSSolver(
        skel, config=IKConfig(term_clamp_scale=10.0, relax_substeps=10, lock_release="kkt")
    )
    for _ in range(10):
        q_true = _upper_pose(skel, rng)
        targets = plain.effector_positions(q_true)
        noise = rng.normal(0.0, 0.3, skel.n_dofs) * (skel.dof_kind != PRISMATIC)
        start = np.clip(q_true + noise, skel.lower, skel.upper)
        start[:3] = q_true[:3]
        b = fast.solve(start, targets)
        assert b.converged and b.iterations <= 25


def test_lock_release_settings_are_checked():
    with pytest.raises(ConfigError, match=r"expected 'roundoff' or 'kkt', found 'sign'"):
        IKConfig(lock_release="sign")
    with pytest.raises(ConfigError, match=r"release_margin >= 0 and release_damping > 0"):
        IKConfig(release_margin=-1.0)
    with pytest.raises(ConfigError, match=r"release_margin >= 0 and release_damping > 0"):
        IKConfig(release_damping=0.0)
