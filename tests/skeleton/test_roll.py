"""Bone roll: which bones may turn about their own axis, the roll per frame, and its limit."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ShapeError
from mocapkit.skeleton import forward_kinematics, load_preset
from mocapkit.skeleton.roll import limit_roll, roll_free_bones, roll_steps


def _arm_motion(n: int = 90) -> tuple[object, np.ndarray]:
    """A straight arm raised slowly forward while it turns slowly about its own line, with
    one frame where the upper arm's turn jumps by 170 deg (which moves no joint)."""
    sk = load_preset("zhang21", ["forearm_rotation"])
    q = np.tile(sk.zero_pose(), (n, 1))
    flex = sk.dof_names.index("r_shoulder_flexion")
    rot = sk.dof_names.index("r_shoulder_rotation")
    q[:, flex] = np.linspace(0.0, 1.5, n)
    q[:, rot] = np.linspace(0.0, 0.6, n)
    q[n // 2 :, rot] += np.deg2rad(170.0)
    return sk, q


def test_roll_free_bones_are_those_whose_children_lie_on_their_axis() -> None:
    sk = load_preset("zhang21")
    names = {sk.joint_names[j] for j in roll_free_bones(sk)}
    assert {"r_humerus", "r_radius", "r_hand", "l_femur", "l_tibia"} <= names
    assert "root" not in names  # the hips and spine leave the root off its bone's axis


def test_roll_steps_find_the_jump_and_limit_roll_removes_it_without_moving_a_joint() -> None:
    sk, q = _arm_motion()
    world = forward_kinematics(sk, q)
    bones, steps = roll_steps(sk, world[..., :3, :3])
    humerus = list(bones).index(sk.joint_index("r_humerus"))
    slow = np.deg2rad(0.6 * 180 / np.pi / 89)  # the ramp's own turn per frame
    assert abs(np.rad2deg(steps[44, humerus])) == pytest.approx(170.0 + np.rad2deg(slow), abs=1)
    limit = np.deg2rad(10.0)
    out = limit_roll(sk, world[..., :3, :3], limit)
    _, after = roll_steps(sk, out)
    assert np.abs(after).max() <= limit + 1e-9
    # the slow ramp is followed where no jump is being caught up
    np.testing.assert_allclose(after[:40, humerus], steps[:40, humerus], atol=1e-9)
    # children keep their world rotations; rotations stay proper
    np.testing.assert_allclose(np.linalg.det(out), 1.0, atol=1e-12)
    axis_before = world[:, :, :3, :3] @ np.array([0.0, 0.0, -1.0])
    axis_after = out @ np.array([0.0, 0.0, -1.0])
    j = sk.joint_index("r_humerus")
    np.testing.assert_allclose(axis_after[:, j], axis_before[:, j], atol=1e-12)
    # once caught up (170 deg at 10 deg a frame), the output is the input again
    np.testing.assert_allclose(out[70:], world[70:, :, :3, :3], atol=1e-9)


def test_limit_roll_rejects_bad_input() -> None:
    sk = load_preset("zhang21")
    with pytest.raises(ShapeError, match="expected shape"):
        limit_roll(sk, np.zeros((3, 2, 3, 3)), 0.1)
    with pytest.raises(ShapeError, match="positive angle"):
        limit_roll(sk, np.tile(np.eye(3), (2, sk.n_joints, 1, 1)), 0.0)


@pytest.mark.parametrize("chunk", [1, 7, 45])
def test_roll_limiter_over_chunks_equals_limit_roll_over_the_whole(chunk: int) -> None:
    """Chunk edges before, on and after the 170 deg jump: the offsets being caught up and
    the step into each chunk's first frame are carried over exactly."""
    from mocapkit.skeleton.roll import RollLimiter

    sk, q = _arm_motion()
    rot = forward_kinematics(sk, q)[..., :3, :3]
    rot[60] = np.nan  # a frame without a pose restarts the follow, in chunks too
    limit = np.deg2rad(10.0)
    whole = limit_roll(sk, rot, limit)
    limiter = RollLimiter(sk, limit)
    parts = np.concatenate([limiter(rot[a : a + chunk]) for a in range(0, len(rot), chunk)])
    np.testing.assert_array_equal(parts, whole)
    assert not np.array_equal(whole[46:50], rot[46:50])  # the jump is being caught up
