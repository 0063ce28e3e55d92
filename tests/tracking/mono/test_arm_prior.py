"""The arm prior (`mocapkit.tracking.mono.arm_prior`): features, mixture density, EM fit."""

import numpy as np
import pytest

from mocapkit.errors import ConfigError, ShapeError
from mocapkit.tracking.mono.arm_prior import (
    ArmPrior,
    arm_features,
    default_arm_prior,
    fit_arm_prior,
)
from mocapkit.tracking.mono.stick import stick_model
from tests.tracking.mono.conftest import random_pose


def _pose(model, upper_r, fore_r, upper_l, fore_l):  # type: ignore[no-untyped-def]
    """A pose in a frame with x = subject's right, y = forward, z = up (mm)."""
    p = {
        "neck": np.zeros(3),
        "pelvis": np.array([0.0, 0.0, -500.0]),
        "head": np.array([0.0, 0.0, 200.0]),
        "right_shoulder": np.array([150.0, 0.0, 0.0]),
        "left_shoulder": np.array([-150.0, 0.0, 0.0]),
    }
    p["right_elbow"] = p["right_shoulder"] + 300.0 * np.asarray(upper_r, dtype=float)
    p["right_wrist"] = p["right_elbow"] + 250.0 * np.asarray(fore_r, dtype=float)
    p["left_elbow"] = p["left_shoulder"] + 300.0 * np.asarray(upper_l, dtype=float)
    p["left_wrist"] = p["left_elbow"] + 250.0 * np.asarray(fore_l, dtype=float)
    return np.array([p[n] for n in model.joint_names])


def test_arm_features_known_pose_mirrors_the_left_arm_and_ignore_rigid_motion() -> None:
    model = stick_model()
    # right arm: upper arm forwards, forearm up; left arm: upper arm out to the left,
    # forearm down
    pos = _pose(model, (0, 1, 0), (0, 0, 1), (-1, 0, 0), (0, 0, -1))
    f = arm_features(model, pos[None])[0]
    # per arm (u_right, u_up, u_fwd, f_right, f_up, f_fwd); the left arm mirrored
    assert f[1] == pytest.approx([0, 0, 1, 0, 1, 0], abs=1e-12)
    assert f[0] == pytest.approx([1, 0, 0, 0, -1, 0], abs=1e-12)
    # a rigid motion (rotation + translation) of the pose changes nothing
    rng = np.random.default_rng(1)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))  # a proper rotation
    moved = pos @ q.T + rng.normal(size=3) * 1000.0
    assert arm_features(model, moved[None])[0] == pytest.approx(f, abs=1e-9)
    # the mirror image of the pose swaps the arms' features
    mirrored = pos * np.array([-1.0, 1.0, 1.0])
    names = list(model.joint_names)
    swap = [
        names.index(n.replace("left", "R").replace("right", "left").replace("R", "right"))
        for n in names
    ]
    g = arm_features(model, mirrored[swap][None])[0]
    assert g[0] == pytest.approx(f[1], abs=1e-12)
    assert g[1] == pytest.approx(f[0], abs=1e-12)
    with pytest.raises(ShapeError, match=r"arm_features: expected positions \(N, 9, 3\)"):
        arm_features(model, pos)


def test_mixture_density_equals_the_gaussian_formula() -> None:
    rng = np.random.default_rng(2)
    a = rng.normal(size=(6, 6))
    cov1 = a @ a.T + 0.5 * np.eye(6)
    cov2 = 0.3 * np.eye(6)
    mu = rng.normal(size=(2, 6))
    w = np.array([0.3, 0.7])
    prior = ArmPrior(w, mu, np.stack([cov1, cov2]), cap=5.0)
    x = rng.normal(size=(4, 6))

    def gauss(x, m, c):  # type: ignore[no-untyped-def]
        d = x - m
        return np.exp(-0.5 * d @ np.linalg.solve(c, d)) / np.sqrt(
            (2 * np.pi) ** 6 * np.linalg.det(c)
        )

    want = [np.log(0.3 * gauss(xi, mu[0], cov1) + 0.7 * gauss(xi, mu[1], cov2)) for xi in x]
    assert prior.log_density(x) == pytest.approx(want, rel=1e-10)
    # the cost: nats below the densest mean, clipped to [0, cap]; NaN costs nothing
    peak = max(prior.log_density(mu))
    cost = prior.arm_cost(x)
    assert cost == pytest.approx(np.clip(peak - np.array(want), 0.0, 5.0))
    assert prior.arm_cost(np.full(6, np.nan)) == 0.0
    far = prior.arm_cost(mu[1] + 100.0)
    assert far == pytest.approx(5.0)


def test_bad_mixtures_are_refused() -> None:
    eye = np.eye(6)[None]
    with pytest.raises(ConfigError, match="ArmPrior: expected M >= 1 weights >= 0 summing to 1"):
        ArmPrior(np.array([0.5]), np.zeros((1, 6)), eye)
    with pytest.raises(ShapeError, match=r"ArmPrior: expected weights \(M,\), means \(M, 6\)"):
        ArmPrior(np.array([1.0]), np.zeros((1, 5)), eye)
    with pytest.raises(ConfigError, match="ArmPrior.cap: expected > 0 nats"):
        ArmPrior(np.array([1.0]), np.zeros((1, 6)), eye, cap=0.0)
    with pytest.raises(ConfigError, match="fit_arm_prior: expected >= 1 component and >= 10"):
        fit_arm_prior(np.zeros((15, 6)), 2, np.random.default_rng(0))


def test_em_recovers_a_known_two_component_mixture() -> None:
    rng = np.random.default_rng(3)
    mu = np.array([[1.0, 0, 0, 0, 1, 0], [0, -1.0, 0, 0, 0, -1]])
    sd = np.array([0.05, 0.1])
    n = np.array([3000, 1000])
    x = np.concatenate([mu[i] + sd[i] * rng.normal(size=(n[i], 6)) for i in range(2)])
    x = np.concatenate([x, np.full((5, 6), np.nan)])  # dropped
    prior = fit_arm_prior(x, 2, np.random.default_rng(0), regularisation=1e-6)
    order = np.argsort(-prior.weights)
    assert prior.weights[order] == pytest.approx([0.75, 0.25], abs=0.01)
    assert prior.means[order] == pytest.approx(mu, abs=0.02)
    var = np.diagonal(prior.covariances[order], axis1=1, axis2=2)
    assert np.sqrt(var) == pytest.approx(np.repeat(sd[:, None], 6, axis=1), rel=0.1)


def test_shipped_prior_prefers_common_arm_postures() -> None:
    prior = default_arm_prior()
    model = stick_model()
    assert prior.weights.sum() == pytest.approx(1.0)
    down = (0, 0, -1)
    s = np.sqrt(0.5)
    poses = np.stack(
        [
            _pose(model, down, down, down, down),  # arms hanging
            _pose(model, down, (0, s, -s), down, (0, s, -s)),  # forearms forwards, down
            # upper arms 50 deg behind the back, forearms folded forwards and up
            _pose(model, (0, -0.64, -0.77), (0, 0.77, 0.64), (0, -0.64, -0.77), (0, 0.77, 0.64)),
        ]
    )
    cost = prior.cost(model, poses)
    assert cost[0] < cost[2] and cost[1] < cost[2]
    assert cost[2] > 4.0  # nats above the hanging arms' cost, both arms together
    # random poses: the cost is the sum of both arms' clipped costs
    rng = np.random.default_rng(4)
    pos = np.stack([random_pose(rng, model, 40.0)[0] for _ in range(20)])
    arms = prior.arm_cost(arm_features(model, pos))
    assert prior.cost(model, pos) == pytest.approx(arms.sum(axis=1))
    assert np.all((arms >= 0) & (arms <= prior.cap))
