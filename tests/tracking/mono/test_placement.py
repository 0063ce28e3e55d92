"""The neck's depth from the feet on the floor (`mocapkit.tracking.mono.placement`)."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.camera.pinhole import Camera, intrinsics_from_fov, look_at
from mocapkit.tracking.base import UNSEEN_SPEED_MM_S
from mocapkit.tracking.mono.placement import (
    ANKLE_SHARE,
    DepthRate,
    FloorConfig,
    FloorDepth,
    detector_ankle_lift_mm,
    floor_neck_depth,
    floor_points,
)

STATURE = 1700.0


def _camera() -> Camera:
    k = intrinsics_from_fov((640, 480), 60.0)
    # 1.6 m up, tilted down towards a point 3 m away at 1 m
    return Camera("c", (640, 480), k, np.zeros(5), look_at((0, -3000, 1600), (0, 0, 1000)))


def test_a_standing_subject_gets_its_necks_depth_and_a_raised_foot_is_ignored() -> None:
    cam = _camera()
    rng = np.random.default_rng(3)
    for _ in range(20):
        x, y = rng.uniform(-600, 600), rng.uniform(-800, 1500)
        foot = np.array([x, y, ANKLE_SHARE * STATURE])
        neck = foot + np.array([0.0, 0.0, 0.78 * STATURE])
        # the other foot lifted 300 mm and 200 mm forward: its ray meets the floor beyond
        other = foot + np.array([150.0, -200.0, 300.0])
        px = cam.project(np.stack([neck, foot, other]))
        z = floor_neck_depth(cam, STATURE, px[0], px[1:])
        assert abs(z - cam.to_camera(neck[None])[0, 2]) < 1e-6
    # no ankle seen; a neck far too high above the foot (the foot on a box): no depth
    assert np.isnan(floor_neck_depth(cam, STATURE, px[0], np.full((2, 2), np.nan)))
    foot = np.array([0.0, 500.0, ANKLE_SHARE * STATURE])
    high = cam.project(np.stack([foot + np.array([0.0, 0.0, 1.3 * STATURE]), foot]))
    assert np.isnan(floor_neck_depth(cam, STATURE, high[0], high[1:]))


def test_floor_depth_is_a_percentile_of_the_window_around_a_frame() -> None:
    cam = _camera()
    floor = FloorDepth(cam, STATURE, FloorConfig(half_window=2, percentile=25.0))
    depths = []
    for y in (0.0, 100.0, 200.0, 300.0, 400.0, 500.0):
        foot = np.array([0.0, y, ANKLE_SHARE * STATURE])
        neck = foot + np.array([0.0, 0.0, 0.78 * STATURE])
        px = cam.project(np.stack([neck, foot]))
        floor.push(px[0], px[1:])
        depths.append(cam.to_camera(neck[None])[0, 2])
    floor.push(np.full(2, np.nan), np.full((2, 2), np.nan))  # an unseen frame adds nothing
    assert floor.window_depth(0) == pytest.approx(np.percentile(depths[:3], 25.0))
    assert floor.window_depth(3) == pytest.approx(np.percentile(depths[1:6], 25.0))
    assert floor.window_depth(6) == pytest.approx(np.percentile(depths[4:6], 25.0))


def test_the_floor_is_not_trusted_where_the_tracker_puts_the_foot_well_above_it() -> None:
    """A subject on a box: the foot's ray meets the floor beyond it. At the tracker's
    (true) depth the foot stands ``gap`` above the floor: the floor's depth is refused
    above ``gap_mm`` and taken below it; a tracker's depth beyond the floor's is never
    a reason to refuse (the foot would be under the floor). The subject bends (its neck
    0.6 of the stature above the foot), so that the neck's height band passes it."""
    cam = _camera()
    box_mm = 300.0
    foot = np.array([0.0, 500.0, ANKLE_SHARE * STATURE + box_mm])
    neck = foot + np.array([0.0, 0.0, 0.6 * STATURE])
    px = cam.project(np.stack([neck, foot]))
    true_z = float(cam.to_camera(neck[None])[0, 2])
    for gap_mm, trusted in ((200.0, False), (400.0, True)):
        floor = FloorDepth(cam, STATURE, FloorConfig(half_window=0, gap_mm=gap_mm))
        floor.push(px[0], px[1:])
        z_floor = floor.window_depth(0)
        assert z_floor > true_z + 300.0  # placed too far
        # the height at the tracker's depth, by similar triangles along the foot's ray
        lift = 1600.0 - ANKLE_SHARE * STATURE
        assert lift * (1 - true_z / z_floor) == pytest.approx(box_mm, rel=0.1)
        got = floor.depth(0, true_z)
        assert (got == pytest.approx(z_floor)) if trusted else np.isnan(got)
        assert floor.depth(0, z_floor + 1000.0) == pytest.approx(z_floor)
        assert np.isnan(floor.depth(1, true_z))  # no floor depth: the tracker's stays


def test_a_detectors_raised_ankle_point_is_cut_with_a_raised_plane() -> None:
    """The ankle point a detector marks ``lift`` above the joint: read at the joint's
    height its ray meets the floor beyond the foot (the neck placed too far); with the
    detector's lift, at the neck's depth again. The lift is the z of the ankles'
    offsets in the shank's frame (z up at rest), their mean."""
    offsets = {"left_ankle": (11.7, 8.0, 61.0), "right_ankle": (-11.7, 8.0, 63.0),
               "left_wrist": (0.0, 5.0, 40.0)}  # fmt: skip
    lift = detector_ankle_lift_mm(offsets)
    assert lift == pytest.approx(62.0)
    assert detector_ankle_lift_mm({"left_wrist": (0.0, 5.0, 40.0)}) == 0.0
    cam = _camera()
    foot = np.array([100.0, 400.0, ANKLE_SHARE * STATURE])
    neck = foot + np.array([0.0, 0.0, 0.78 * STATURE])
    px = cam.project(np.stack([neck, foot + np.array([0.0, 0.0, lift])]))
    true_z = float(cam.to_camera(neck[None])[0, 2])
    assert floor_neck_depth(cam, STATURE, px[0], px[1:]) > true_z + 100.0
    assert floor_neck_depth(cam, STATURE, px[0], px[1:], lift) == pytest.approx(true_z)
    floor = FloorDepth(cam, STATURE, FloorConfig(half_window=0), ankle_lift_mm=lift)
    floor.push(px[0], px[1:])
    assert floor.depth(0, true_z) == pytest.approx(true_z)


def test_depth_rate_passes_the_trackers_motion_and_bounds_a_change_of_estimate() -> None:
    dt = 1 / 30
    rate = DepthRate()
    assert rate.speed_mm_s == UNSEEN_SPEED_MM_S
    assert rate.place(0.0, 3000.0, 2900.0) == 3000.0  # the first frame: the target
    # the tracker's own depth moves 300 mm in a frame (the subject walks): passed whole
    assert rate.place(dt, 3300.0, 3200.0) == pytest.approx(3300.0)
    # the estimate switches (floor refused: the tracker's depth, 100 mm nearer) with the
    # tracker's depth still: the placed depth goes there at the bound, not in one frame
    placed = [rate.place((2 + k) * dt, 3200.0, 3200.0) for k in range(5)]
    step = UNSEEN_SPEED_MM_S * dt
    np.testing.assert_allclose(placed[:3], 3300.0 - step * np.arange(1, 4))
    np.testing.assert_allclose(placed[3:], 3200.0)
    # both at once: the own motion whole plus the bounded share of the rest
    assert rate.place(7 * dt, 3500.0, 3250.0) == pytest.approx(3200.0 + 50.0 + step)


def test_floor_points_are_where_the_rays_meet_the_plane_and_nan_above_the_horizon() -> None:
    cam = _camera()
    world = np.array([[300.0, 500.0, 80.0], [-400.0, 1500.0, 80.0]])
    n = cam.undistort_pixels(cam.project(world))
    depth, met = floor_points(cam, n, 80.0)
    np.testing.assert_allclose(met, world, atol=1e-6)
    np.testing.assert_allclose(depth, cam.to_camera(world)[:, 2], rtol=1e-12)
    # a point above the camera's height (its ray rises) and an unseen one: NaN
    up = cam.undistort_pixels(cam.project(np.array([[0.0, 2000.0, 3000.0]])))
    depth, met = floor_points(cam, np.vstack([up, [[np.nan, np.nan]]]), 80.0)
    assert np.isnan(depth).all() and np.isnan(met).all()
