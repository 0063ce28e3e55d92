"""Soft pose costs beyond eq. 3 (`mocapkit.tracking.mono.priors`) and their use by the tracker."""

import numpy as np
import pytest

from mocapkit.errors import ShapeError
from mocapkit.tracking.mono.priors import (
    clavicle_forward_cost,
    depth_order_cost,
    girdle_angle_cost,
    planted_feet_cost,
)
from mocapkit.tracking.mono.stick import stick_model
from tests.tracking.mono.conftest import random_pose


def _arm_pose(  # type: ignore[no-untyped-def]
    model,
    left_forearm,
    right_forearm,
    left_clavicle=(1.0, 0.0, 0.0),
    right_clavicle=(-1.0, 0.0, 0.0),
) -> np.ndarray:
    """A subject facing the camera (forward is -z), upper arms hanging straight down."""
    d = {
        "trunk": (0.0, 1.0, 0.0),
        "head": (0.0, -1.0, 0.0),
        "left_clavicle": left_clavicle,
        "right_clavicle": right_clavicle,
        "left_upper_arm": (0.0, 1.0, 0.0),
        "right_upper_arm": (0.0, 1.0, 0.0),
        "left_forearm": left_forearm,
        "right_forearm": right_forearm,
    }
    pos = np.zeros((model.n_joints, 3))
    pos[0] = (0.0, 0.0, 3000.0)
    for i, (_, _, seg) in enumerate(model.links):
        v = np.asarray(d[seg], dtype=float)
        pos[model.child[i]] = pos[model.parent[i]] + 250.0 * v / np.linalg.norm(v)
    return pos


def test_clavicle_forward_cost_known_values() -> None:
    model = stick_model()
    down = (0.0, 1.0, 0.0)
    s30 = (np.cos(np.radians(30.0)), 0.0, -np.sin(np.radians(30.0)))  # 30 deg forward
    back = (-np.cos(np.radians(20.0)), 0.0, np.sin(np.radians(20.0)))  # 20 deg backward
    poses = np.stack(
        [
            _arm_pose(model, down, down),  # straight sideways: 0
            _arm_pose(model, down, down, s30, (-s30[0], 0.0, s30[2])),  # both forward
            _arm_pose(model, down, down, (-back[0], 0.0, back[2]), back),  # both backward
        ]
    )
    np.testing.assert_allclose(
        clavicle_forward_cost(model, poses), [0.0, 2 * (0.5 - 0.05), 0.0], atol=1e-12
    )
    with pytest.raises(ShapeError, match="clavicle_forward_cost: expected positions"):
        clavicle_forward_cost(model, poses[0])


def test_clavicle_forward_cost_equals_the_body_frame_definition_on_random_poses() -> None:
    rng = np.random.default_rng(11)
    model = stick_model()
    poses = np.stack([random_pose(rng, model, 60.0)[0] for _ in range(40)])
    v = model.link_vectors(poses)
    up = -v[:, model.link_index("trunk")]
    up /= np.linalg.norm(up, axis=-1, keepdims=True)
    right = v[:, model.link_index("right_clavicle")] - v[:, model.link_index("left_clavicle")]
    right -= np.sum(right * up, axis=-1, keepdims=True) * up
    right /= np.linalg.norm(right, axis=-1, keepdims=True)
    fwd = np.cross(up, right)
    expect = np.zeros(len(poses))
    for seg in ("left_clavicle", "right_clavicle"):
        u = v[:, model.link_index(seg)]
        expect += np.clip(np.sum(u * fwd, -1) / np.linalg.norm(u, axis=-1) - 0.05, 0.0, None)
    assert (expect > 0).sum() >= 5  # some poses pay
    np.testing.assert_allclose(clavicle_forward_cost(model, poses), expect, atol=1e-12)


def test_girdle_angle_cost_known_values_and_flip_pairs() -> None:
    """Clavicles (+-1/2, -d, z) shoulder widths (the neck d = 0.205 W below the shoulder
    midpoint): in the image plane the cosine is (d^2 - 1/4) / (d^2 + 1/4), cost 0; out of
    it the cosine is (d^2 - 1/4 +- z^2) / (d^2 + 1/4 + z^2), + for the same flip on both
    sides (the shoulders brought together), - for opposite flips (the shoulder line
    turned): the cost tells the pairs apart, not the mirror of both."""
    model = stick_model()
    d, z = 0.205, 0.3
    c0 = (d * d - 0.25) / (d * d + 0.25)
    down = (0.0, 1.0, 0.0)

    def pose(zl: float, zr: float) -> np.ndarray:
        return _arm_pose(model, down, down, (0.5, -d, zl), (-0.5, -d, zr))

    poses = np.stack([pose(0.0, 0.0), pose(z, z), pose(-z, -z), pose(z, -z), pose(-z, z)])
    same = (d * d - 0.25 + z * z) / (d * d + 0.25 + z * z)
    opposite = (d * d - 0.25 - z * z) / (d * d + 0.25 + z * z)
    np.testing.assert_allclose(
        girdle_angle_cost(model, poses, c0),
        [0.0, same - c0, same - c0, c0 - opposite, c0 - opposite],
        atol=1e-12,
    )
    assert same - c0 > 0.2 and c0 - opposite < 0.1  # the turned line is the nearer
    nan = poses[:1].copy()
    nan[0, model.child[model.link_index("left_clavicle")]] = np.nan
    assert girdle_angle_cost(model, nan, c0) == pytest.approx([0.0])
    with pytest.raises(ShapeError, match="girdle_angle_cost: expected positions"):
        girdle_angle_cost(model, poses[0], c0)


def test_depth_order_cost_is_the_out_of_plane_sine_of_each_disagreeing_link() -> None:
    model = stick_model(False)
    fwd = _arm_pose(model, (0.0, 0.0, -1.0), (0.0, 0.0, 1.0))  # left forearm towards us
    lf, rf = model.link_index("left_forearm"), model.link_index("right_forearm")
    sines = np.full(model.n_links, np.nan)
    sines[lf], sines[rf] = -0.8, 0.3  # the detector agrees on both forearms
    mirrored = fwd.copy()  # the left forearm flipped away from the camera
    le, lw = model.joint_names.index("left_elbow"), model.joint_names.index("left_wrist")
    mirrored[lw, 2] = 2 * mirrored[le, 2] - mirrored[lw, 2]
    cost = depth_order_cost(model, np.stack([fwd, mirrored]), sines)
    np.testing.assert_allclose(cost, [0.0, 0.8])
    sines[rf] = -0.3  # now it disagrees on the right forearm in both poses
    np.testing.assert_allclose(depth_order_cost(model, np.stack([fwd, mirrored]), sines),
                               [0.3, 1.1])  # fmt: skip
    assert depth_order_cost(model, np.full((1, model.n_joints, 3), np.nan), sines)[0] == 0.0
    with pytest.raises(ShapeError, match="depth_order_cost"):
        depth_order_cost(model, fwd, sines)


def test_planted_feet_cost_is_the_error_of_the_feets_depth_difference_in_leg_lengths() -> None:
    model = stick_model(True)
    la, ra = model.joint_names.index("left_ankle"), model.joint_names.index("right_ankle")
    poses = np.zeros((3, model.n_joints, 3))
    poses[:, la, 2] = (3000.0, 3300.0, 3200.0)
    poses[:, ra, 2] = (3400.0, 3100.0, 3600.0)
    floor = np.array([2950.0, 3350.0])  # the left foot 400 mm nearer, whatever the depth
    np.testing.assert_allclose(
        planted_feet_cost(model, poses, (la, ra), floor, 800.0), [0.0, 600.0 / 800.0, 0.0]
    )
    # a foot not planted (NaN): no cost; a pose without ankles: no cost
    np.testing.assert_allclose(
        planted_feet_cost(model, poses, (la, ra), np.array([2950.0, np.nan]), 800.0), 0.0
    )
    nan = np.full((1, model.n_joints, 3), np.nan)
    assert planted_feet_cost(model, nan, (la, ra), floor, 800.0)[0] == 0.0
    with pytest.raises(ShapeError, match="planted_feet_cost: expected positions"):
        planted_feet_cost(model, poses[0], (la, ra), floor, 800.0)
