"""3-D head and hand tracking: blobs, cross-view candidates, identity through a crossing."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from mocapkit.camera.pinhole import Camera, intrinsics_from_fov, look_at
from mocapkit.errors import ConfigError
from mocapkit.tracking.stereo.hands import (
    BlobConfig,
    HeadHandTracker,
    candidates_3d,
    keypoint_targets,
    skin_blobs,
)

SIZE = (320, 240)


def _stereo():
    k = intrinsics_from_fov(SIZE, 62.0)
    return [
        Camera(n, SIZE, k, np.zeros(5), look_at((x, 2700.0, 1500.0), (x, 0.0, 1300.0)))
        for n, x in (("l", -45.0), ("r", 45.0))
    ]


def test_blobs_are_the_largest_components_with_their_centroids():
    m = np.zeros((100, 120), np.uint8)
    cv2.circle(m, (30, 40), 8, 255, -1)
    cv2.circle(m, (90, 60), 5, 255, -1)
    m[5, 5] = 255  # a speck below the area threshold
    cents, areas = skin_blobs(m, BlobConfig(min_area_px=10))
    assert cents.shape == (2, 2) and areas[0] > areas[1]
    np.testing.assert_allclose(cents[0], (30, 40), atol=0.1)
    np.testing.assert_allclose(cents[1], (90, 60), atol=0.1)


def test_candidates_recover_3d_points_from_projected_blobs():
    cams = _stereo()
    pts = np.array([[0.0, 0.0, 1600.0], [-300.0, 200.0, 1100.0], [320.0, 150.0, 1000.0]])
    blobs = [c.project(pts) for c in cams]
    cands = candidates_3d(cams, blobs, BlobConfig())
    for p in pts:
        assert np.min(np.linalg.norm(cands - p, axis=1)) < 1e-6
    # a view with nothing gives nothing
    assert candidates_3d(cams, [blobs[0], np.zeros((0, 2))], BlobConfig()).shape == (0, 3)


def test_keypoints_triangulate_head_and_wrists():
    cams = _stereo()
    pts = np.array([[0.0, 0.0, 1600.0], [-300.0, 200.0, 1100.0], [320.0, 150.0, 1000.0]])
    names = ("head", "neck", "left_wrist", "right_wrist")
    kps = []
    for c in cams:
        px = np.full((4, 2), np.nan)
        px[[0, 2, 3]] = c.project(pts)
        kps.append(px)
    np.testing.assert_allclose(keypoint_targets(cams, kps, names), pts, atol=1e-6)


def test_hands_keep_their_identity_through_a_crossing_and_a_short_occlusion():
    cams = _stereo()
    tracker = HeadHandTracker(cams, BlobConfig(), np.array([1.0, 0.0, 0.0]))
    head = np.array([0.0, 0.0, 1600.0])
    dt = 1.0 / 30.0
    for k in range(40):
        t = k * dt
        # the hands swap sides: left moves to +x, right to -x, crossing at k = 20
        s = math.cos(math.pi * k / 40.0)
        left = np.array([-300.0 * s, 250.0, 1100.0 + 5.0 * k])
        right = np.array([300.0 * s, 250.0, 1050.0 - 3.0 * k])
        cands = [head, left, right]
        if 18 <= k <= 21:
            cands = [head, 0.5 * (left + right)]  # merged blob while crossing
        if 30 <= k <= 32:
            cands = [head, right]  # left hand hidden for three frames
        out = tracker.update_candidates(t, np.array(cands))
        if k < 18 or 22 <= k < 30 or k > 33:
            np.testing.assert_allclose(out[1], left, atol=1e-6)
            np.testing.assert_allclose(out[2], right, atol=1e-6)
        if 30 <= k <= 32:
            assert np.all(np.isnan(out[1]))  # coasting is not a measurement
        np.testing.assert_allclose(out[0], head, atol=1e-6)


def test_a_target_lost_for_long_is_reinitialised_on_its_side():
    cams = _stereo()
    cfg = BlobConfig(coast_frames=2)
    tracker = HeadHandTracker(cams, cfg, np.array([1.0, 0.0, 0.0]))
    head = np.array([0.0, 0.0, 1600.0])
    left = np.array([-300.0, 200.0, 1100.0])
    right = np.array([300.0, 200.0, 1100.0])
    tracker.update_candidates(0.0, np.array([head, left, right]))
    for k in range(1, 6):
        out = tracker.update_candidates(k / 30.0, np.array([head, right]))
    assert np.all(np.isnan(tracker.predicted()[1]))
    new_left = left + np.array([0.0, 0.0, 400.0])  # reappears far from where it was lost
    out = tracker.update_candidates(0.2, np.array([head, new_left, right]))
    np.testing.assert_allclose(out[1], new_left)


def test_an_unseen_head_is_held_slowing_down_then_released():
    cams = _stereo()
    cfg = BlobConfig(head_coast_frames=15)
    tracker = HeadHandTracker(cams, cfg, np.array([1.0, 0.0, 0.0]))
    left = np.array([-300.0, 200.0, 1100.0])
    right = np.array([300.0, 200.0, 1100.0])
    dt = 1.0 / 30.0
    for k in range(5):  # the head walks at 300 mm/s (10 mm a frame)
        head = np.array([10.0 * k, 0.0, 1600.0])
        tracker.update_candidates(k * dt, np.array([head, left, right]))
    last = head.copy()
    for k in range(5, 5 + 15):  # face turned away: only the hands
        out = tracker.update_candidates(k * dt, np.array([left, right]))
        assert np.all(np.isnan(out[0]))  # held, not measured
        held = tracker.predicted()[0]
        # velocity halves every frame: at most 10 * (1/2 + 1/4 + ...) = 10 mm beyond
        assert np.linalg.norm(held - last) <= 10.0 + 1e-9
    assert np.all(np.isfinite(tracker.predicted()[0]))
    tracker.update_candidates(20 * dt, np.array([left, right]))  # the 16th unseen frame
    assert np.all(np.isnan(tracker.predicted()[0]))
    with pytest.raises(ConfigError, match="head_coast_frames: expected >= 0, found -1"):
        BlobConfig(head_coast_frames=-1)
