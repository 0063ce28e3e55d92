"""Smoothing poses across an Euler branch switch (`mocapkit.skeleton.smoothing`)."""

from __future__ import annotations

from functools import partial

import numpy as np
from scipy.signal import butter, filtfilt

from mocapkit.skeleton.kinematics import joint_positions
from mocapkit.skeleton.presets import load_preset
from mocapkit.skeleton.smoothing import euler_groups, filter_poses


def _skeleton():
    return load_preset("zhang21")


def _other_branch(q, groups):
    out = q.copy()
    for a, b, c in groups:
        out[..., a] += np.pi
        out[..., b] = np.pi - out[..., b]
        out[..., c] += np.pi
    return out


def test_euler_groups_are_the_three_dof_orthogonal_joints():
    sk = _skeleton()
    groups = euler_groups(sk)
    names = {sk.dof_names[g[0]] for g in groups}
    assert {"l_shoulder_flexion", "r_shoulder_flexion", "l_hip_flexion"} <= names
    for g in groups:
        assert len({int(sk.dof_joint[i]) for i in g}) == 1
        axes = sk.dof_axis[list(g)]
        np.testing.assert_allclose(np.abs(axes @ axes.T), np.eye(3), atol=1e-12)


def test_identity_filter_returns_the_poses_on_either_branch():
    sk = _skeleton()
    rng = np.random.default_rng(3)
    q = rng.uniform(-1.2, 1.2, (8, sk.n_dofs))
    alt = _other_branch(q, euler_groups(sk))
    np.testing.assert_allclose(joint_positions(sk, alt), joint_positions(sk, q), atol=1e-9)
    np.testing.assert_allclose(filter_poses(sk, q, lambda x: x), q, atol=1e-12)
    np.testing.assert_allclose(filter_poses(sk, alt, lambda x: x), alt, atol=1e-12)


def test_a_branch_switch_is_not_drawn_as_a_swing():
    """A held pose whose triples switch to the equivalent ones half way: the low-pass
    keeps every joint where it is; filtered per DoF the arm swings through the middle."""
    sk = _skeleton()
    rng = np.random.default_rng(5)
    pose = rng.uniform(-0.8, 0.8, sk.n_dofs)
    q = np.tile(pose, (60, 1))
    q[30:] = _other_branch(q[30:], euler_groups(sk))
    low = partial(filtfilt, *butter(4, 0.1), axis=0)
    held = joint_positions(sk, q[:1])
    smooth = filter_poses(sk, q, low)
    assert np.abs(joint_positions(sk, smooth) - held).max() < 1e-6
    per_dof = low(q)
    assert np.abs(joint_positions(sk, per_dof) - held).max() > 100.0


def test_smoothing_a_slow_motion_changes_it_little():
    sk = _skeleton()
    t = np.linspace(0.0, 2.0, 61)[:, None]
    rng = np.random.default_rng(7)
    q = rng.uniform(-0.6, 0.6, sk.n_dofs) + 0.3 * np.sin(2.0 * np.pi * 0.5 * t)
    low = partial(filtfilt, *butter(4, 0.4), axis=0)
    smooth = filter_poses(sk, q, low)
    # a 0.5 Hz motion through a 6 Hz low-pass (at 30 Hz): the joints move by under 1 mm
    assert np.abs(joint_positions(sk, smooth) - joint_positions(sk, q)).max() < 1.0
