"""The rigid sets' fewer rows (`mocapkit.ik.rigid_rows`): the same Gram matrix, so the
same SDLS response (Buss & Kim 2005; Zhang et al. 2011 §4, errata Z4-Z6) as from every
row. A solver with marker-set members: `test_sdls_svd`."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.ik.config import DEFAULT_GAMMA_RAD
from mocapkit.ik.effectors import Effector, default_effectors
from mocapkit.ik.rigid_rows import no_sets, rigid_rows_nb, rigid_sets_nb
from mocapkit.ik.sdls import SDLSSolver
from mocapkit.ik.sdls_step import SIGMA_CUTOFF, sdls_gesdd_nb, sdls_nb
from mocapkit.skeleton import PRISMATIC, load_preset
from mocapkit.skeleton.kinematics import points_and_jacobian


@pytest.fixture(scope="module")
def skel():
    return load_preset("zhang21")


def _pose(skel, rng, scale=0.4):
    q = np.where(skel.dof_kind != PRISMATIC, rng.normal(0.0, scale, skel.n_dofs), 0.0)
    return np.clip(q, skel.lower, skel.upper)


def _set_effectors(skel, rng):
    """The default effectors, then three members around each of head and hands (the
    hybrid's marker sets): sets of four on three joints, the feet alone."""
    base = default_effectors(skel)
    members = []
    for e in base[:3]:
        for m in range(3):
            p = np.add(e.point_mm, rng.normal(0.0, 50.0, 3))
            members.append(Effector(f"{e.name}/{m}", e.joint, (p[0], p[1], p[2])))
    return [*base, *members]


def _jacobian(skel, solver, q):
    pts, jac = points_and_jacobian(skel, q, solver._eff_joint, solver._eff_point)
    return np.ascontiguousarray(pts), np.ascontiguousarray(jac / solver.mu[None, :])


def _reference(jw, e, gamma=DEFAULT_GAMMA_RAD):
    """SDLS (hard clamps per term, no outer clamp) from numpy's SVD of every row."""
    u, s, vt = np.linalg.svd(jw, full_matrices=False)
    k = jw.shape[0] // 3
    rho = np.linalg.norm(jw.reshape(k, 3, -1), axis=1).sum(axis=0)
    dpsi = np.zeros(jw.shape[1])
    ns = []
    for i in range(len(s)):
        if s[i] < SIGMA_CUTOFF * s[0]:
            continue
        n_i = np.linalg.norm(u[:, i].reshape(k, 3), axis=1).sum()
        m_i = (np.abs(vt[i]) * rho).sum() / s[i]
        g = gamma * min(1.0, n_i / m_i)
        phi = (u[:, i] @ e) / s[i] * vt[i]
        mx = np.abs(phi).max()
        dpsi += phi * (g / mx if mx > g else 1.0)
        ns.append(n_i)
    return dpsi, np.array(ns)


def test_sets_are_the_joints_with_three_or_more_effectors():
    order, bounds = rigid_sets_nb(np.array([5, 7, 5, 9, 7, 5, 7, 7, 2], dtype=np.int64))
    assert bounds.tolist() == [0, 3, 7]
    assert order.tolist() == [0, 2, 5, 1, 4, 6, 7, 3, 8]
    order, bounds = rigid_sets_nb(np.array([1, 2, 1], dtype=np.int64))
    assert bounds.tolist() == [0] and sorted(order.tolist()) == [0, 1, 2]


def test_fewer_rows_same_gram_matrix(skel, rng):
    solver = SDLSSolver(skel, _set_effectors(skel, rng))
    sets = rigid_sets_nb(solver._eff_joint)
    for _ in range(5):
        pts, jw = _jacobian(skel, solver, _pose(skel, rng))
        cols = np.arange(jw.shape[1], dtype=np.int64)
        rows = rigid_rows_nb(jw, pts, sets[0], sets[1], cols).T
        assert rows.shape == (3 * 6 + 2 * 3, jw.shape[1])  # three sets of four, two feet
        np.testing.assert_allclose(rows.T @ rows, jw.T @ jw, rtol=0, atol=1e-12 * (jw**2).max())
        s_all = np.linalg.svd(jw, compute_uv=False)
        s_rows = np.linalg.svd(rows, compute_uv=False)
        np.testing.assert_allclose(s_rows, s_all[:24], rtol=0, atol=1e-12 * s_all[0])
        assert np.all(s_all[24:] < SIGMA_CUTOFF * s_all[0])  # the rows left out: none


def test_collinear_set_keeps_its_rows(skel, rng):
    """Points on a line have only five rigid velocities: their rows are kept as they are."""
    e = default_effectors(skel)[1]
    line = [Effector(f"m{k}", e.joint, (10.0 * k, 20.0 * k, -5.0 * k)) for k in range(4)]
    solver = SDLSSolver(skel, line)
    sets = rigid_sets_nb(solver._eff_joint)
    pts, jw = _jacobian(skel, solver, _pose(skel, rng))
    rows = rigid_rows_nb(jw, pts, sets[0], sets[1], np.arange(jw.shape[1], dtype=np.int64)).T
    kept = [3 * k + i for k in sets[0] for i in range(3)]
    np.testing.assert_array_equal(rows, jw[kept])


@pytest.mark.parametrize("kernel", ["gesvd", "gesdd"])
def test_sdls_from_fewer_rows_equals_every_row(skel, rng, kernel):
    """Both SVD kernels with the sets: the response, N_i and rank of the reference from
    every row (a locked DoF's zero column included for dgesdd)."""
    solver = SDLSSolver(skel, _set_effectors(skel, rng))
    sets = rigid_sets_nb(solver._eff_joint)
    d = skel.n_dofs
    for _ in range(5):
        pts, jw = _jacobian(skel, solver, _pose(skel, rng))
        jw[:, rng.choice(d, 2, replace=False)] = 0.0
        e = rng.normal(0.0, 40.0, jw.shape[0])
        dpsi, vr = np.empty(d), np.empty((d, d))
        n, m, s = np.empty(d), np.empty(d), np.empty(d)
        if kernel == "gesvd":
            r = sdls_nb(jw, e, DEFAULT_GAMMA_RAD, False, dpsi, vr, n, m, 1.0,
                        np.zeros(d, dtype=bool), s, pts, sets)  # fmt: skip
        else:
            r = sdls_gesdd_nb(jw, e, DEFAULT_GAMMA_RAD, False, dpsi, vr, n, m, 1.0, s, pts, sets)
        ref, n_ref = _reference(jw, e)
        assert r == len(n_ref)
        np.testing.assert_allclose(dpsi, ref, rtol=0, atol=1e-9 * np.abs(ref).max())
        np.testing.assert_allclose(n[:r], n_ref, rtol=1e-9)


def test_no_sets_is_every_row(skel, rng):
    solver = SDLSSolver(skel, _set_effectors(skel, rng))
    pts, jw = _jacobian(skel, solver, _pose(skel, rng))
    order, bounds = no_sets(len(solver.effectors))
    rows = rigid_rows_nb(jw, pts, order, bounds, np.arange(skel.n_dofs, dtype=np.int64))
    np.testing.assert_array_equal(rows.T, jw)
