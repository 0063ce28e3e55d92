"""Blending each link's depth offset with a detector's, along the joints' rays."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.camera.pinhole import Camera, intrinsics_from_fov, look_at
from mocapkit.errors import ConfigError, ShapeError
from mocapkit.tracking.mono.depth_fusion import fuse_link_depths
from mocapkit.tracking.mono.stick import stick_model
from mocapkit.tracking.mono.stream import MonoSample, MonoStream, output_skeleton
from mocapkit.tracking.mono.tracker import MonoConfig, MonoTracker

from .conftest import random_pose


def _pose_and_sines(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A random stick pose (camera frame), its lengths and another pose's link sines."""
    rng = np.random.default_rng(seed)
    model = stick_model(legs=True)
    pose, lengths = random_pose(rng, model, 40.0)
    other, _ = random_pose(rng, model, 40.0)
    v = model.link_vectors(other)
    return pose, lengths, v[:, 2] / np.linalg.norm(v, axis=-1)


def _pixels(q: np.ndarray) -> np.ndarray:
    return q[:, :2] / q[:, 2:]


def test_every_joint_keeps_its_pixel_and_the_weights_ends_are_ours_and_the_detectors() -> None:
    model = stick_model(legs=True)
    pose, lengths, sines = _pose_and_sines(1)
    for w in (0.0, 0.4, 1.0):
        fused = fuse_link_depths(pose, model.parent, model.child, lengths, sines, w)
        np.testing.assert_allclose(_pixels(fused), _pixels(pose), rtol=0, atol=1e-12)
        np.testing.assert_array_equal(fused[0], pose[0])  # the root stays
    ours = fuse_link_depths(pose, model.parent, model.child, lengths, sines, 0.0)
    np.testing.assert_array_equal(ours, pose)
    theirs = fuse_link_depths(pose, model.parent, model.child, lengths, sines, 1.0)
    dz = theirs[model.child, 2] - theirs[model.parent, 2]
    np.testing.assert_allclose(dz, sines * lengths, rtol=0, atol=1e-9)
    half = fuse_link_depths(pose, model.parent, model.child, lengths, sines, 0.5)
    own = pose[model.child, 2] - pose[model.parent, 2]
    np.testing.assert_allclose(
        half[model.child, 2] - half[model.parent, 2], 0.5 * (own + sines * lengths), atol=1e-9
    )


def test_links_without_a_sine_keep_their_offset_from_the_fused_parent() -> None:
    model = stick_model(legs=True)
    pose, lengths, sines = _pose_and_sines(2)
    sines[model.link_index("left_upper_arm")] = np.nan
    fused = fuse_link_depths(pose, model.parent, model.child, lengths, sines[:8], 1.0)
    own = pose[model.child, 2] - pose[model.parent, 2]
    dz = fused[model.child, 2] - fused[model.parent, 2]
    kept = np.zeros(model.n_links, dtype=bool)
    kept[model.link_index("left_upper_arm")] = True
    kept[8:] = True  # the legs: beyond the sines given
    np.testing.assert_allclose(dz[kept], own[kept], atol=1e-9)
    np.testing.assert_allclose(dz[~kept], (sines * lengths)[~kept], atol=1e-9)
    np.testing.assert_allclose(_pixels(fused), _pixels(pose), atol=1e-12)


def test_a_fused_depth_behind_the_camera_keeps_the_links_own_offset() -> None:
    model = stick_model()
    pose, lengths, _ = _pose_and_sines(3)
    pose = pose[: model.n_joints]
    sines = np.zeros(model.n_links)
    sines[0] = -1.0
    far = np.array(lengths[: model.n_links])
    far[0] = 1e5  # the pelvis 100 m towards the camera: behind it
    fused = fuse_link_depths(pose, model.parent, model.child, far, sines, 1.0)
    np.testing.assert_array_equal(fused[1], pose[1])
    assert np.isfinite(fused).all()


def test_bad_shapes_and_weights_are_refused() -> None:
    model = stick_model()
    pose = np.ones((model.n_joints, 3))
    with pytest.raises(ShapeError, match="expected joints \\(K, 3\\)"):
        fuse_link_depths(pose[:, :2], model.parent, model.child, np.ones(8), np.zeros(8), 0.4)
    with pytest.raises(ShapeError, match="at most 8 link sines, found \\(9,\\)"):
        fuse_link_depths(pose, model.parent, model.child, np.ones(8), np.zeros(9), 0.4)
    with pytest.raises(ConfigError, match="depth_fusion_weight: expected \\[0, 1\\]"):
        MonoConfig(depth_fusion_weight=1.5)


def test_the_stream_fuses_the_detectors_depth_where_a_frame_brings_it() -> None:
    """Weight 1 and the true sines in every frame: each link's depth offset is the
    detector's; the image is kept; weight 0 ignores the sines."""
    model = stick_model()
    k = intrinsics_from_fov((640, 480), 62.0)
    cam = Camera("mono", (640, 480), k, np.zeros(5), look_at((0, -3000, 1250), (0, 0, 1250)))
    rng = np.random.default_rng(4)
    truth, lengths = random_pose(rng, model, 25.0)
    v = model.link_vectors(truth)
    sines = v[:, 2] / np.linalg.norm(v, axis=-1)
    mirrored = -sines  # what the tracker would not choose by itself
    px = cam.project_camera_points(truth)

    def run(weight: float) -> np.ndarray:
        cfg = MonoConfig(depth_fusion_weight=weight, depth_order_weight=0.0, trunk_lean_sines=())
        tracker = MonoTracker(lengths, cam, 1 / 30.0, cfg, model)
        stream = MonoStream(tracker, output_skeleton(model, lengths), cam, float("nan"))
        out = []
        for i in range(12):
            out += stream.push(MonoSample(i / 30.0, px, None, mirrored))
        out += stream.finish()
        return np.stack([r.frame.joints_in_camera for r in out])  # type: ignore[attr-defined]

    off, on = run(0.0), run(1.0)
    posed = np.isfinite(on).all(axis=(1, 2))
    assert posed.sum() >= 6
    dz = on[posed][:, model.child, 2] - on[posed][:, model.parent, 2]
    np.testing.assert_allclose(dz, np.broadcast_to(mirrored * lengths, dz.shape), atol=1e-6)
    np.testing.assert_allclose(
        cam.project_camera_points(on[posed].reshape(-1, 3)).reshape(-1, model.n_joints, 2),
        cam.project_camera_points(off[posed].reshape(-1, 3)).reshape(-1, model.n_joints, 2),
        atol=1e-6,
    )
    assert not np.allclose(on[posed], off[posed])
