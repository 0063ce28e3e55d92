"""Plausible motion: joint speeds against what the inputs show, bone rolls against a limit."""

from __future__ import annotations

import numpy as np
import pytest

import mocapkit.eval.plausibility as plausibility
from mocapkit.camera.pinhole import Camera, intrinsics_from_fov, look_at
from mocapkit.errors import ConfigError, ShapeError
from mocapkit.eval.continuity import roll_steps_deg
from mocapkit.eval.plausibility import (
    SpeedBound,
    check_motion,
    nearest_input_speeds,
    roll_speeds_deg_s,
    triangulated_speeds_mm_s,
    view_speeds_mm_s,
)
from mocapkit.skeleton import load_preset

DT_S = 0.02
BOUND = SpeedBound(1.5, 1000.0)


def camera_at(eye_mm: list[float], name: str = "c") -> Camera:
    """A 640 x 480 camera with a 60 deg field of view at ``eye_mm`` looking at
    (0, 0, 1000) mm."""
    k = intrinsics_from_fov((640, 480), 60.0)
    return Camera(name, (640, 480), k, np.zeros(5), look_at(eye_mm, [0.0, 0.0, 1000.0]))


def _take(seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """20 frames at 50 Hz: three joints 400 mm apart drifting slowly (< 0.3 m/s), each
    with a marker 30 mm from it moving with it."""
    rng = np.random.default_rng(seed)
    t = np.arange(20) * DT_S
    start = np.array([[0.0, 0.0, 1000.0], [400.0, 0.0, 1000.0], [800.0, 0.0, 1000.0]])
    drift = np.cumsum(rng.uniform(-3.0, 3.0, (20, 1, 3)), axis=0)
    joints = start + drift
    markers = joints + np.array([0.0, 30.0, 0.0])
    return t, joints, markers


def test_a_joint_step_the_inputs_do_not_make_is_flagged_on_exactly_its_frame(
    monkeypatch,
) -> None:
    t, joints, markers = _take()
    joints[10:, 1] += [200.0, 0.0, 0.0]  # 200 mm in one frame: 10 m/s
    inp = nearest_input_speeds(t, joints, markers)
    monkeypatch.setattr(plausibility, "_FRAME_CHUNK", 3)  # in chunks of frames: the same
    np.testing.assert_array_equal(nearest_input_speeds(t, joints, markers), inp)
    check = check_motion(t, ("a", "b", "c"), joints, inp, BOUND, 1200.0)
    assert np.argwhere(check.joint_flags).tolist() == [[10, 1]]
    np.testing.assert_allclose(check.speed_mm_s[10, 1], 10000.0, rtol=0.01)
    cols = check.columns()
    assert cols["implausible_joints"][10] == 1 and cols["worst_joint"][10] == "b"
    assert np.nansum(cols["implausible_joints"]) == 1
    assert np.isnan(cols["implausible_joints"][0]) and cols["worst_joint"][0] == ""
    ratio = check.speed_mm_s[10, 1] / (1.5 * inp[10, 1] + 1000.0)
    np.testing.assert_allclose(cols["worst_speed_ratio"][10], ratio)
    np.testing.assert_allclose(cols["worst_input_speed_mm_per_s"][10], inp[10, 1])


def test_a_joint_step_the_input_makes_too_is_kept() -> None:
    t, joints, markers = _take(1)
    joints[10:, 1] += [200.0, 0.0, 0.0]
    markers[10:, 1] += [200.0, 0.0, 0.0]
    check = check_motion(t, "abc", joints, nearest_input_speeds(t, joints, markers), BOUND, 1200.0)
    assert not check.joint_flags.any()


def test_a_missing_input_is_no_evidence_and_flags_nothing() -> None:
    t, joints, markers = _take(2)
    joints[10:, 1] += [200.0, 0.0, 0.0]
    markers[10, 1] = np.nan  # the joint's marker unseen on the frame of the step
    inp = nearest_input_speeds(t, joints, markers)
    assert np.isnan(inp[10, 1]) and np.isnan(inp[0]).all()
    check = check_motion(t, "abc", joints, inp, BOUND, 1200.0)
    assert not check.joint_flags.any()
    # no evidence anywhere (None): nothing flagged, the columns NaN
    none = check_motion(t, "abc", joints, None, BOUND, 1200.0)
    assert not none.joint_flags.any() and np.isnan(none.columns()["worst_speed_ratio"]).all()


def test_a_set_moves_as_fast_as_its_fastest_marker() -> None:
    t = np.array([0.0, 0.1])
    joints = np.array([[[0.0, 0.0, 0.0]], [[0.0, 0.0, 0.0]]])
    # marker 0 (nearest, still) and marker 1 (200 mm away, 100 mm in the frame) of one
    # set; marker 2 fast but in another set
    markers = np.array(
        [
            [[10.0, 0, 0], [200.0, 0, 0], [50.0, 0, 0]],
            [[10.0, 0, 0], [300.0, 0, 0], [550.0, 0, 0]],
        ]
    )
    np.testing.assert_allclose(nearest_input_speeds(t, joints, markers)[1], [0.0])
    np.testing.assert_allclose(nearest_input_speeds(t, joints, markers, [0, 0, 1])[1], [1000.0])
    with pytest.raises(ShapeError, match="groups: expected 3 group labels"):
        nearest_input_speeds(t, joints, markers, [0, 1])
    # only the fast marker may show the joint's motion (its limb's); none: all may
    np.testing.assert_allclose(
        nearest_input_speeds(t, joints, markers, candidates=[[False, False, True]])[1], [5000.0]
    )
    np.testing.assert_allclose(
        nearest_input_speeds(t, joints, markers, candidates=[[False, False, False]])[1], [0.0]
    )
    with pytest.raises(ShapeError, match=r"candidates: expected shape \(1, 3\)"):
        nearest_input_speeds(t, joints, markers, candidates=[[True, False]])


def test_the_bound_is_factor_times_the_input_plus_the_floor() -> None:
    np.testing.assert_allclose(BOUND.allowed_mm_s([0.0, 2000.0, np.nan]), [1000.0, 4000.0, np.nan])
    with pytest.raises(ConfigError, match="floor_mm_s: expected a speed > 0 mm/s, found 0"):
        SpeedBound(1.5, 0.0)
    with pytest.raises(ConfigError, match="factor: expected a number >= 0, found -1"):
        SpeedBound(-1.0, 1000.0)


def test_a_view_shows_lateral_motion_and_not_depth() -> None:
    cam = camera_at([0.0, -3000.0, 1000.0])
    t = np.array([0.0, 0.1, 0.2])
    # frame 1: 300 mm towards the camera along its axis; frame 2: 100 mm sideways
    joints = np.array([[[0.0, 0.0, 1000.0]], [[0.0, -300.0, 1000.0]], [[100.0, -300.0, 1000.0]]])
    speeds = view_speeds_mm_s(t, joints, cam, cam.project(joints))
    assert np.isnan(speeds[0, 0])
    assert speeds[1, 0] == pytest.approx(0.0, abs=1e-6)
    np.testing.assert_allclose(speeds[2, 0], 1000.0, rtol=1e-9)
    px = cam.project(joints)
    px[2] = np.nan
    assert np.isnan(view_speeds_mm_s(t, joints, cam, px)[2, 0])
    with pytest.raises(ShapeError, match="pixels: expected shape"):
        view_speeds_mm_s(t, joints, cam, px[:, :, :1])


def test_two_views_show_the_depth_one_misses() -> None:
    # a stereo pair 300 mm apart, both looking along +y
    cams = [camera_at([-150.0, -3000.0, 1000.0], "l"), camera_at([150.0, -3000.0, 1000.0], "r")]
    t = np.array([0.0, 0.1, 0.2])
    # 300 mm towards the pair (3 m/s, in depth), then 100 mm sideways (1 m/s)
    joints = np.array([[[0.0, 0.0, 1000.0]], [[0.0, -300.0, 1000.0]], [[100.0, -300.0, 1000.0]]])
    px = np.stack([c.project(joints) for c in cams])
    np.testing.assert_allclose(
        triangulated_speeds_mm_s(t, cams, px)[1:, 0], [3000.0, 1000.0], rtol=1e-6
    )
    assert view_speeds_mm_s(t, joints, cams[0], px[0])[1, 0] < 400.0  # one view: lateral only
    px[1, 2] = np.nan  # one view left on frame 2: no evidence
    speeds = triangulated_speeds_mm_s(t, cams, px)
    assert np.isnan(speeds[[0, 2], 0]).all() and np.isfinite(speeds[1, 0])
    with pytest.raises(ShapeError, match="pixels: expected shape"):
        triangulated_speeds_mm_s(t, cams, px[:1])


def test_a_bone_rolling_faster_than_the_limit_is_flagged(monkeypatch) -> None:
    sk = load_preset("zhang21", ["forearm_rotation"])
    q = np.tile(sk.zero_pose(), (40, 1))
    rot = sk.dof_names.index("l_forearm_rotation")
    q[:, rot] = np.deg2rad(np.linspace(0.0, 39.0, 40))  # 1 deg a frame: 50 deg/s
    q[25:, rot] += np.deg2rad(60.0)  # 60 deg in a frame: 3000 deg/s
    t = np.arange(40) * DT_S
    joints = np.zeros((40, 1, 3))
    check = check_motion(t, ("x",), joints, None, BOUND, 1200.0, sk, q)
    k = check.bone_names.index("l_radius")
    # the forearm and the hand it carries turn together, on that frame only
    flagged = [(int(i), check.bone_names[b]) for i, b in np.argwhere(check.roll_flags)]
    assert flagged == [(25, "l_radius"), (25, "l_hand")]
    np.testing.assert_allclose(check.roll_deg_s[24, k], 50.0, rtol=1e-6)
    cols = check.columns()
    assert cols["implausible_rolls"][25] == 2 and cols["worst_roll_bone"][25] in (
        "l_radius",
        "l_hand",
    )
    # chunked as one pass: the same steps
    monkeypatch.setattr(plausibility, "_FRAME_CHUNK", 7)
    names, speeds = roll_speeds_deg_s(sk, t, q)
    _, steps = roll_steps_deg(sk, q)
    np.testing.assert_allclose(speeds[1:], steps / DT_S, atol=1e-9)
    assert np.isnan(speeds[0]).all() and names == check.bone_names


def test_frames_without_a_pose_have_no_roll_speed() -> None:
    """A subject out of view (NaN ``q`` on some frames): no error, no roll speed on those
    frames nor on the frame after each, the rest as without the gap."""
    sk = load_preset("zhang21", ["forearm_rotation"])
    q = np.tile(sk.zero_pose(), (12, 1))
    rot = sk.dof_names.index("l_forearm_rotation")
    q[:, rot] = np.deg2rad(np.arange(12.0))  # 1 deg a frame: 50 deg/s
    t = np.arange(12) * DT_S
    gap = q.copy()
    gap[4:6] = np.nan
    _, full = roll_speeds_deg_s(sk, t, q)
    _, holed = roll_speeds_deg_s(sk, t, gap)
    unposed = np.zeros(12, dtype=bool)
    unposed[[0, 4, 5, 6]] = True  # frame 0 has no step; 4, 5 no pose; 6 follows one
    assert np.isnan(holed[unposed]).all()
    np.testing.assert_allclose(holed[~unposed], full[~unposed], atol=1e-9)
    check = check_motion(t, ("x",), np.zeros((12, 1, 3)), None, BOUND, 1200.0, sk, gap)
    assert not check.roll_flags.any()
