"""What the inputs of a run show near each joint: markers by set, keypoints per view."""

from __future__ import annotations

import numpy as np

from mocapkit.io.motion import Motion
from mocapkit.pipelines.hybrid import hybrid_skeleton
from mocapkit.pipelines.input_speeds import (
    limb_candidates,
    marker_input_speeds,
    pixel_input_speeds,
)
from mocapkit.skeleton import load_preset
from tests.eval.test_plausibility import camera_at


def _motion(t: np.ndarray, joints: np.ndarray, names: tuple[str, ...]) -> Motion:
    sk = load_preset("upper_stick")
    return Motion(sk, t, np.tile(sk.zero_pose(), (t.shape[0], 1)), names, joints)


def test_markers_are_sampled_as_the_session_does_and_read_by_set() -> None:
    # markers at 100 Hz, frames at 50 Hz: each frame sees the newest sample at or before it
    mt = np.arange(9) * 0.01
    markers = np.zeros((9, 2, 3))
    markers[:, 0, 0] = 10.0 * np.arange(9)  # the joint's own marker: 1 m/s
    markers[:, 1, 0] = 500.0 + 30.0 * np.arange(9)  # its set-mate, 500 mm off: 3 m/s
    t = np.arange(5) * 0.02
    joints = np.zeros((5, 1, 3))
    joints[:, 0, 0] = 20.0 * np.arange(5)
    motion = _motion(t, joints, ("head",))
    alone = marker_input_speeds(mt, markers, ["a", "b"])(motion)
    np.testing.assert_allclose(alone[1:, 0], 1000.0)
    together = marker_input_speeds(mt, markers, ["a", "a"])(motion)
    np.testing.assert_allclose(together[1:, 0], 3000.0)
    assert np.isnan(alone[0]).all()
    # frames before the first marker sample have no evidence
    late = marker_input_speeds(mt + 0.03, markers, ["a", "b"])(motion)
    assert np.isnan(late[:3, 0]).all() and np.isfinite(late[3:, 0]).all()


def test_keypoints_are_matched_to_the_joints_by_name() -> None:
    cam = camera_at([0.0, -3000.0, 1000.0])
    t = np.array([0.0, 0.1])
    joints = np.array([[[0.0, 0.0, 1000.0], [0.0, 0.0, 1500.0]]])
    joints = np.concatenate([joints, joints + np.array([100.0, 0.0, 0.0])])  # 1 m/s sideways
    motion = _motion(t, joints, ("head", "neck"))
    px = cam.project(joints)[:, ::-1]  # the keypoints list neck, then head
    speeds = pixel_input_speeds([cam], [px], ("neck", "head"), motion)
    np.testing.assert_allclose(speeds[1], [1000.0, 1000.0], rtol=1e-6)
    only_neck = pixel_input_speeds([cam], [px[:, :1]], ("neck",), motion)
    assert np.isnan(only_neck[1, 0]) and np.isfinite(only_neck[1, 1])


def test_a_joint_is_shown_by_the_sets_on_its_limb() -> None:
    sk = hybrid_skeleton(1750.0)
    sets = ["head", "left_hand", "right_hand", "pelvis", "left_foot", "nowhere"]
    joints = ("right_elbow", "left_shoulder", "pelvis", "head", "right_knee")
    cand = limb_candidates(sk, joints, sets)
    assert cand.tolist() == [
        [False, False, True, True, False, True],  # its hand below, the pelvis above
        [False, True, False, True, False, True],
        [True, True, True, True, True, True],  # the root: every set hangs below it
        [True, False, False, True, False, True],
        [False, False, False, True, False, True],  # no right foot set: the pelvis
    ]
