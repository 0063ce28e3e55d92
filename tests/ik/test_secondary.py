"""Errata Z8/Z13: the relaxed-pose secondary task and its carried-mass, lever-arm weights."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ShapeError
from mocapkit.ik.config import IKConfig
from mocapkit.ik.sdls import SDLSSolver
from mocapkit.ik.secondary import (
    SecondaryTask,
    carried_mass_planted,
    relaxed_pose,
    secondary_mask,
)
from mocapkit.skeleton import load_preset, subtree_mass


@pytest.fixture(scope="module")
def skel():
    return load_preset("zhang21")


def test_relaxed_pose(skel):
    omega = relaxed_pose(skel)
    assert omega[skel.dof_index("l_elbow_flexion")] == pytest.approx(np.radians(15))
    assert omega[skel.dof_index("r_elbow_flexion")] == pytest.approx(np.radians(15))
    others = [d for d, n in enumerate(skel.dof_names) if "elbow" not in n]
    assert np.all(omega[others] == 0)


def test_root_left_out_and_planted_complement(skel):
    mask = secondary_mask(skel)
    assert not mask[:3].any() and mask[3:].all()
    m = carried_mass_planted(skel, ("l_foot", "r_foot"))
    sub = subtree_mass(skel)
    knee = skel.dof_index("l_knee_flexion")
    assert m[knee] == pytest.approx(skel.total_mass_kg - sub[skel.joint_index("l_tibia")])
    elbow = skel.dof_index("l_elbow_flexion")
    assert m[elbow] == pytest.approx(1.31 + 0.52)


def test_lever_arm_zero_for_vertical_axis(skel):
    task = SecondaryTask(skel)
    q = relaxed_pose(skel)
    w = task.weights(q)
    # arms hanging: the shoulder rotation axis is vertical, so gravity exerts no torque about it
    assert w[skel.dof_index("l_shoulder_rotation")] == pytest.approx(0.0, abs=1e-9)
    q2 = q.copy()
    q2[skel.dof_index("l_shoulder_flexion")] = np.radians(90)  # arm forward: big lever
    assert task.weights(q2)[skel.dof_index("l_shoulder_flexion")] > 1000.0
    assert np.all(w[:3] == 0)


def test_step_is_clamped_and_descends(skel):
    task = SecondaryTask(skel)
    q = relaxed_pose(skel)
    q[skel.dof_index("l_shoulder_flexion")] = 1.2
    q[skel.dof_index("spine1_flexion")] = 0.3
    step = task.step(q, gain=0.3, gamma_rad=0.05)
    assert np.abs(step).max() <= 0.05 + 1e-15
    assert step[skel.dof_index("l_shoulder_flexion")] < 0
    assert task.cost(q + 0.1 * step) < task.cost(q)


def test_secondary_lowers_cost_once_targets_met(skel, rng):
    solver = SDLSSolver(skel, config=IKConfig(secondary_gain=0.3))
    plain = SDLSSolver(skel, config=IKConfig(secondary_gain=0.0))
    q_true = relaxed_pose(skel)
    for name, val in [
        ("r_shoulder_flexion", 0.9),
        ("r_elbow_flexion", 1.0),
        ("l_shoulder_abduction", 0.6),
        ("spine2_flexion", 0.2),
    ]:
        q_true[skel.dof_index(name)] = val
    targets = solver.effector_positions(q_true)
    # a valid but tense solution: reach the targets without the secondary task from a bent start
    start = q_true + rng.normal(0.0, 0.25, skel.n_dofs) * (np.arange(skel.n_dofs) >= 3)
    start = np.clip(start, skel.lower, skel.upper)
    q = plain.solve(start, targets).q
    cost0 = solver.secondary.cost(q)
    for _ in range(60):  # frames of a warm-started sequence with still targets
        res = solver.solve(q, targets)
        q = res.q
        assert res.converged
    assert solver.secondary.cost(q) < 0.8 * cost0


def test_bad_omega(skel):
    with pytest.raises(ShapeError, match="omega: expected the relaxed pose"):
        SecondaryTask(skel, omega=np.zeros(3))
