"""The SDLS response from LAPACK's dgesvd without U, over the nonzero columns only.

`mocapkit.ik.sdls.sdls_nb` forms no left singular vectors (``u_i = J_w v_i / sigma_i``)
and leaves the zero columns of frozen or locked DoFs out of the SVD; both must give the
SDLS of Buss & Kim 2005 (Zhang et al. 2011 §4, errata Z4-Z6) as written with numpy's
full SVD.
"""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.ik.config import DEFAULT_GAMMA_RAD, IKConfig
from mocapkit.ik.effectors import Effector, default_effectors
from mocapkit.ik.lapack import thin_svd_v_nb
from mocapkit.ik.sdls import SDLSSolver
from mocapkit.ik.sdls_step import SIGMA_CUTOFF, nullspace_projector, sdls_response
from mocapkit.skeleton import PRISMATIC, load_preset
from mocapkit.skeleton.kinematics import points_and_jacobian


@pytest.fixture(scope="module")
def skel():
    return load_preset("zhang21")


def _pose(skel, rng, scale=0.5):
    q = np.zeros(skel.n_dofs)
    for d in range(skel.n_dofs):
        if skel.dof_kind[d] != PRISMATIC:
            q[d] = rng.normal(0.0, scale)
    return np.clip(q, skel.lower, skel.upper)


def _reference_sdls(jw, e, gamma, term_scale=1.0):
    """SDLS (hard clamps per term, no outer clamp) from numpy's SVD with its own U."""
    u, s, vt = np.linalg.svd(jw, full_matrices=False)
    k = jw.shape[0] // 3
    rho = np.linalg.norm(jw.reshape(k, 3, -1), axis=1).sum(axis=0)  # (D,)
    dpsi = np.zeros(jw.shape[1])
    ns, ms = [], []
    for i in range(len(s)):
        if s[i] < SIGMA_CUTOFF * s[0] or s[i] <= 0:
            continue
        n_i = np.linalg.norm(u[:, i].reshape(k, 3), axis=1).sum()
        m_i = (np.abs(vt[i]) * rho).sum() / s[i]
        g = gamma * min(1.0, n_i / m_i) * term_scale
        phi = (u[:, i] @ e) / s[i] * vt[i]
        mx = np.abs(phi).max()
        dpsi += phi * (g / mx if mx > g else 1.0)
        ns.append(n_i)
        ms.append(m_i)
    return dpsi, np.array(ns), np.array(ms)


def _tall_jacobian(skel, rng):
    """A (42, 24) weighted Jacobian: 14 effector points, as many rows as the hybrid's sets."""
    solver = SDLSSolver(skel)
    q = _pose(skel, rng)
    joints = rng.choice(skel.n_joints, 14, replace=True)
    points = rng.normal(0.0, 60.0, (14, 3))
    _, jac = points_and_jacobian(skel, q, np.asarray(joints, dtype=np.int64), points)
    return jac / solver.mu[None, :]


def test_thin_svd_matches_numpy(skel, rng):
    jw = _tall_jacobian(skel, rng)
    n_rows, n_cols = jw.shape
    k = min(n_rows, n_cols)
    s = np.empty(k)
    vt = np.empty((n_cols, k))
    thin_svd_v_nb(np.ascontiguousarray(jw.T), s, vt)
    s_ref = np.linalg.svd(jw, compute_uv=False)
    np.testing.assert_allclose(s, s_ref, rtol=1e-12, atol=1e-12 * s_ref[0])
    # V orthonormal and J_w V = U S with U orthonormal on the terms above the cut-off
    np.testing.assert_allclose(vt.T @ vt, np.eye(k), atol=1e-12)
    keep = s > 1e-8 * s[0]
    u = (jw @ vt[:, keep]) / s[keep]
    np.testing.assert_allclose(u.T @ u, np.eye(int(keep.sum())), atol=1e-9)


@pytest.mark.parametrize("term_scale", [1.0, 3.0])
def test_sdls_response_equals_full_svd_reference(skel, rng, term_scale):
    for _ in range(10):
        jw = _tall_jacobian(skel, rng)
        e = rng.normal(0.0, 40.0, jw.shape[0])
        got = sdls_response(jw, e, term_clamp_scale=term_scale)
        ref, n_ref, m_ref = _reference_sdls(jw, e, DEFAULT_GAMMA_RAD, term_scale)
        np.testing.assert_allclose(got.dpsi, ref, rtol=0, atol=1e-9 * np.abs(ref).max())
        np.testing.assert_allclose(got.n, n_ref, rtol=1e-9)
        np.testing.assert_allclose(got.m, m_ref, rtol=1e-9)


def test_zero_columns_are_left_out_of_the_svd(skel, rng):
    """Frozen DoFs (zero columns): the same response as the SVD of the other columns,
    nothing on the frozen DoFs, and their projector rows those of the identity."""
    for _ in range(10):
        jw = _tall_jacobian(skel, rng)
        zero = rng.choice(jw.shape[1], 7, replace=False)
        jw[:, zero] = 0.0
        live = np.setdiff1d(np.arange(jw.shape[1]), zero)
        e = rng.normal(0.0, 40.0, jw.shape[0])
        got = sdls_response(jw, e)
        ref_live, n_live, _ = _reference_sdls(jw[:, live], e, DEFAULT_GAMMA_RAD)
        assert np.all(got.dpsi[zero] == 0.0)
        np.testing.assert_allclose(
            got.dpsi[live], ref_live, rtol=0, atol=1e-9 * np.abs(ref_live).max()
        )
        # the same terms kept as from the live columns alone (no null vector of a zero column)
        np.testing.assert_allclose(got.n, n_live, rtol=1e-9)
        p = nullspace_projector(jw)
        np.testing.assert_allclose(p[zero][:, zero], np.eye(len(zero)), atol=1e-12)
        np.testing.assert_allclose(p[zero][:, live], 0.0, atol=1e-12)
        np.testing.assert_allclose(jw @ p, 0.0, atol=1e-9 * np.abs(jw).max())


def test_all_zero_jacobian_gives_no_step():
    step = sdls_response(np.zeros((6, 5)), np.ones(6))
    assert np.all(step.dpsi == 0.0)
    assert step.v_r.shape == (0, 5)


@pytest.mark.parametrize("members", [0, 3])
def test_gesvd_solver_reaches_fk_targets_like_gesdd(skel, rng, members):
    """`IKConfig.svd` "gesvd" (the tracker's): FK targets from a pose 0.3 rad away are
    reached wherever the default SVD reaches them (without members: exactly there), and
    the largest errors are as near. With ``members`` effectors around each of head and
    hands (the hybrid's marker sets), its SVDs take the rigid sets' fewer rows
    (`mocapkit.ik.rigid_rows`), the default's every row; joint limits lock and release
    DoFs on the way."""
    effs = list(default_effectors(skel))
    for e in effs[:3]:
        for m in range(members):
            p = np.add(e.point_mm, rng.normal(0.0, 50.0, 3))
            effs.append(Effector(f"{e.name}/{m}", e.joint, (p[0], p[1], p[2])))
    plain = SDLSSolver(skel, effs)
    thin = SDLSSolver(skel, effs, config=IKConfig(svd="gesvd"))
    worst = []
    for _ in range(8):
        q_true = _pose(skel, rng, 0.4)
        targets = plain.effector_positions(q_true)
        start = np.clip(q_true + rng.normal(0.0, 0.3, skel.n_dofs), skel.lower, skel.upper)
        start[:3] = q_true[:3]
        a = plain.solve(start, targets)
        b = thin.solve(start, targets)
        if members == 0:
            assert b.converged == a.converged
        if a.converged:
            assert np.nanmax(b.residual_mm) < thin.config.tol_mm
        worst.append((np.nanmax(a.residual_mm), np.nanmax(b.residual_mm)))
    # the poses neither reaches: errors of a few mm, as near on the whole
    np.testing.assert_allclose(np.median(worst, axis=0)[1], np.median(worst, axis=0)[0], rtol=0.25)


def test_gesvd_frozen_dofs_do_not_move(skel, rng):
    thin = SDLSSolver(skel, config=IKConfig(svd="gesvd"))
    q0 = _pose(skel, rng, 0.3)
    targets = thin.effector_positions(_pose(skel, rng, 0.3))
    frozen = np.zeros(skel.n_dofs, dtype=bool)
    frozen[rng.choice(skel.n_dofs, 8, replace=False)] = True
    res = thin.solve(q0, targets, frozen=frozen)
    np.testing.assert_array_equal(res.q[frozen], np.clip(q0, skel.lower, skel.upper)[frozen])
    assert res.iterations > 1


def test_svd_setting_is_checked():
    with pytest.raises(ConfigError, match="IKConfig.svd"):
        IKConfig(svd="eigh")


def test_dofs_without_range_are_held_as_frozen(skel, rng):
    """DoFs whose limits leave no range (the hybrid model's root pitch and roll; here two
    of the trunk's) stay at their value and the solve is the one with them frozen: they
    never take a step that the limit clamp would turn into a lock."""
    lower, upper = skel.lower.copy(), skel.upper.copy()
    fixed = np.array([skel.dof_index("spine1_flexion"), skel.dof_index("neck_lateral")])
    lower[fixed] = upper[fixed] = 0.0
    skel = skel.replace(lower=lower, upper=upper)
    solver = SDLSSolver(skel, config=IKConfig(svd="gesvd"))
    frozen = np.zeros(skel.n_dofs, dtype=bool)
    frozen[fixed] = True
    for _ in range(5):
        q_true = _pose(skel, rng, 0.4)
        targets = solver.effector_positions(q_true)
        start = np.clip(q_true + rng.normal(0.0, 0.3, skel.n_dofs), skel.lower, skel.upper)
        res = solver.solve(start, targets)
        assert np.all(res.q[fixed] == skel.lower[fixed])
        np.testing.assert_array_equal(res.q, solver.solve(start, targets, frozen=frozen).q)
        assert np.nanmax(res.residual_mm) < np.nanmax(
            np.linalg.norm(solver.effector_positions(start) - targets, axis=1)
        )
