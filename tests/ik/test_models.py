"""The SDLS IK on models other than ``zhang21``: ``azad14`` (ball joints, no legs,
prismatic shoulder offsets), with effectors, planted joints and the relaxed pose found
through canonical names."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import UnknownNameError
from mocapkit.ik.config import DEFAULT_GAMMA_RAD, IKConfig
from mocapkit.ik.effectors import Effector, canonical_effector, default_effectors
from mocapkit.ik.sdls import SDLSSolver
from mocapkit.ik.secondary import planted_feet, relaxed_pose
from mocapkit.ik.weights import arm_length_mm, dof_weights, leg_length_mm
from mocapkit.skeleton import BALL, PRISMATIC, joint_positions, limbs, load_preset


def random_azad_pose(sk, rng):  # type: ignore[no-untyped-def]
    """Torso moved and tilted a little, arms anywhere in their ranges around the relaxed pose."""
    q = relaxed_pose(sk)
    root = sk.dof_joint == 0
    rot = sk.dof_kind != PRISMATIC
    q[root & ~rot] = rng.normal(0.0, 50.0, int((root & ~rot).sum()))
    q[root & rot] = rng.normal(0.0, 0.2, int((root & rot).sum()))
    q[~root & rot] += rng.normal(0.0, 0.6, int((~root & rot).sum()))
    q[~root & ~rot] = rng.normal(0.0, 20.0, int((~root & ~rot).sum()))
    return np.clip(q, sk.lower, sk.upper)


def test_zhang21_defaults_are_the_papers_five_effectors_and_feet() -> None:
    sk = load_preset("zhang21")
    effs = default_effectors(sk)
    assert effs == (
        Effector("head", "head", (0.0, 0.0, 50.0)),
        Effector("left_hand", "l_hand"),
        Effector("right_hand", "r_hand"),
        Effector("left_foot", "l_foot"),
        Effector("right_foot", "r_foot"),
    )
    assert planted_feet(sk) == ("l_foot", "r_foot")
    np.testing.assert_array_equal(dof_weights(sk), dof_weights(sk, ("l_foot", "r_foot")))


def test_azad14_has_no_feet_and_falls_back_to_the_arm_length() -> None:
    sk = load_preset("azad14")
    solver = SDLSSolver(sk)
    assert solver.effector_names == ("head", "left_hand", "right_hand")
    assert solver.planted_joints == ()
    assert not solver.secondary.planted.any()
    # upper arm 300 + forearm 270 (the hand is the forearm's end point)
    assert arm_length_mm(sk) == pytest.approx(570.0)
    assert leg_length_mm(sk) == pytest.approx(570.0)
    assert solver.dmax_mm == pytest.approx(57.0)
    rot = sk.dof_kind != PRISMATIC
    assert solver.mu[rot].min() == pytest.approx(1.0)
    assert np.all(np.isfinite(solver.mu)) and np.all(solver.mu > 0)
    with pytest.raises(UnknownNameError, match="left_ankle"):
        canonical_effector(sk, "left_foot")
    with pytest.raises(UnknownNameError, match="expected one of: head, left_foot, left_hand"):
        canonical_effector(sk, "tail")


@pytest.mark.parametrize("name", ["zhang21", "azad14", "upper_stick"])
def test_relaxed_elbow_bends_forward_by_15_degrees_in_every_model(name: str) -> None:
    # zhang21 flexes +15 deg about +x, azad14 -15 deg about -x (theta_4 <= 0): the same bend
    sk = load_preset(name)
    omega = relaxed_pose(sk)
    p = joint_positions(sk, omega)
    for side in limbs.SIDES:
        arm = limbs.arm(sk, side)
        upper = p[arm.middle] - p[arm.root]
        fore = p[arm.end] - p[arm.middle]
        cos = upper @ fore / (np.linalg.norm(upper) * np.linalg.norm(fore))
        assert np.degrees(np.arccos(cos)) == pytest.approx(15.0)
        assert fore[1] > 0  # towards +Y, where every preset's subject faces
    elbows = np.concatenate([limbs.flexion_dofs(sk, a)[0] for a in limbs.limbs_present(sk, "arm")])
    others = np.setdiff1d(np.arange(sk.n_dofs), elbows)
    assert np.all(omega[others] == 0)


def test_azad14_jacobian_matches_central_differences(rng: np.random.Generator) -> None:
    sk = load_preset("azad14", ("adaptive_shoulder",))
    assert np.any(sk.dof_kind == BALL) and np.sum(sk.dof_kind == PRISMATIC) == 9
    solver = SDLSSolver(sk)
    for _ in range(3):
        q = random_azad_pose(sk, rng)
        _, jac, jw = solver.weighted_jacobian(q)
        for d in range(sk.n_dofs):
            h = 1e-3 if sk.dof_kind[d] == PRISMATIC else 1e-6
            qp, qm = q.copy(), q.copy()
            qp[d] += h
            qm[d] -= h
            num = (solver.effector_positions(qp) - solver.effector_positions(qm)).ravel() / (2 * h)
            scale = max(np.abs(jac[:, d]).max(), 1.0)
            assert np.abs(num - jac[:, d]).max() < 1e-6 * scale, sk.dof_names[d]
        np.testing.assert_allclose(jw, jac / solver.mu[None, :], rtol=1e-15)


@pytest.mark.parametrize("clamp", ["hard", "soft"])
def test_azad14_fk_targets_reached(rng: np.random.Generator, clamp: str) -> None:
    sk = load_preset("azad14")
    solver = SDLSSolver(sk, config=IKConfig(clamp=clamp))
    q0 = solver.secondary.omega
    n_trials, reached = 50, 0
    for _ in range(n_trials):
        qt = random_azad_pose(sk, rng)
        res = solver.solve(q0, solver.effector_positions(qt), record_trace=True)
        reached += res.converged and bool(np.all(res.residual_mm < 1.0))
        assert res.trace is not None
        assert np.all(res.trace[:, 2] <= DEFAULT_GAMMA_RAD + 1e-12)  # weighted steps
        assert np.all(res.q >= sk.lower) and np.all(res.q <= sk.upper)
    assert reached >= 0.95 * n_trials
