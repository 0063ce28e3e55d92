"""Procedural motions: within limits, smooth, feet planted, and doing what they say."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ConfigError, UnknownNameError
from mocapkit.skeleton import load_preset
from mocapkit.synth.builtin_motions import BUILTIN_NAMES, builtin_motion


@pytest.mark.parametrize("name", BUILTIN_NAMES)
def test_common_properties(name):
    m = builtin_motion(name, duration_s=6.0)
    skel = load_preset("zhang21")
    assert m.skeleton.dof_names == skel.dof_names
    np.testing.assert_allclose(np.diff(m.time_s), 1 / 120, atol=1e-12)
    assert m.time_s[-1] == pytest.approx(6.0)
    rot = skel.dof_kind != 1
    assert np.all(m.q[:, rot] >= skel.lower[rot] - 1e-12)
    assert np.all(m.q[:, rot] <= skel.upper[rot] + 1e-12)
    # feet stay planted: the mean ankle exactly, each ankle within 10 mm (stance width
    # changes a little with hip flexion because the hips are slightly abducted)
    mean_ankle = 0.5 * (m.joint("left_ankle") + m.joint("right_ankle"))
    assert np.ptp(mean_ankle, axis=0).max() < 1e-6
    for ankle in ("left_ankle", "right_ankle"):
        assert np.ptp(m.joint(ankle), axis=0).max() < 10.0
    # smooth: joint speeds stay human (< 15 rad/s) and positions have no jumps
    qd = np.diff(m.q[:, rot], axis=0) * 120
    assert np.abs(qd).max() < 15.0
    step = np.linalg.norm(np.diff(m.joints_mm, axis=0), axis=-1)
    assert step.max() < 60.0  # mm per 1/120 s, i.e. < 7.2 m/s


def test_squat_lowers_the_pelvis():
    m = builtin_motion("squat", duration_s=4.0)
    z = m.joint("pelvis")[:, 2]
    assert z[0] - z.min() > 300.0
    assert abs(z[-1] - z[0]) < 5.0


def test_wave_moves_one_arm():
    m = builtin_motion("wave", duration_s=5.0)
    right = m.joint("right_wrist")
    left = m.joint("left_wrist")
    assert np.ptp(right, axis=0).max() > 500.0
    assert np.ptp(left, axis=0).max() < 1.0
    # the waving hand is above the head
    late = m.time_s > 2.0
    assert np.all(right[late, 2] > m.joint("head")[late, 2] - 50.0)


def test_table_tennis_swings_across_the_body_with_the_trunk():
    m = builtin_motion("table-tennis", duration_s=4.0)
    wrist_x = m.joint("right_wrist")[:, 0] - m.joint("pelvis")[:, 0]
    assert wrist_x.max() > 300.0  # forehand backswing out to the right (+x)
    assert wrist_x.min() < -100.0  # follow-through across to the left
    spine = m.q[:, m.skeleton.dof_index("spine2_flexion")]
    assert np.degrees(np.ptp(spine)) > 3.0
    neck_z = m.joint("neck")[:, 2]
    assert np.ptp(neck_z) > 15.0


def test_errors():
    with pytest.raises(UnknownNameError, match="expected one of: squat, table-tennis, wave"):
        builtin_motion("jump")
    with pytest.raises(ConfigError, match="duration_s"):
        builtin_motion("wave", duration_s=0.0)
