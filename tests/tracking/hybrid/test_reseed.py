"""The arm re-seed's seeds and choice (`mocapkit.tracking.hybrid.reseed`)."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ShapeError
from mocapkit.ik.swivel import swivel_arm
from mocapkit.skeleton import forward_kinematics, load_preset
from mocapkit.skeleton.limbs import arm
from mocapkit.tracking.hybrid.reseed import SWIVEL_SEEDS, arm_seeds, nearest_fit


def test_nearest_fit_takes_the_smallest_move_among_the_fits_near_the_best():
    fit = [3.0, 7.5, 9.0, 40.0]
    move = [300.0, 120.0, 80.0, 10.0]
    assert nearest_fit(fit, move, 5.0) == 1  # 9.0 is beyond 3 + 5, 40 far beyond
    assert nearest_fit(fit, move, 6.0) == 2
    assert nearest_fit(fit, move, 0.0) == 0
    with pytest.raises(ShapeError, match="two equal non-empty 1-D arrays"):
        nearest_fit([1.0, 2.0], [1.0], 5.0)


def test_arm_seeds_are_the_relaxed_arm_and_the_arm_turned_about_its_wrist():
    sk = load_preset("zhang21")
    rng = np.random.default_rng(7)
    relaxed = rng.uniform(np.maximum(sk.lower, -3.0), np.minimum(sk.upper, 3.0))
    q = np.clip(sk.zero_pose(), sk.lower, sk.upper)
    limb = arm(sk, "left")
    for name, deg in (("l_shoulder_flexion", 60.0), ("l_shoulder_abduction", 40.0)):
        q[sk.dof_index(name)] = np.radians(deg)
    q[sk.dof_index("l_elbow_flexion")] = np.radians(80.0)
    seeds = arm_seeds(sk, q, "left", relaxed)
    assert len(seeds) == SWIVEL_SEEDS
    others = np.setdiff1d(np.arange(sk.n_dofs), limb.dofs)
    np.testing.assert_array_equal(seeds[0][limb.dofs], relaxed[limb.dofs])
    wrist = forward_kinematics(sk, q)[limb.end, :3, 3]
    elbow = forward_kinematics(sk, q)[limb.middle, :3, 3]
    kept = 0
    for k, seed in enumerate(seeds):
        np.testing.assert_array_equal(seed[others], q[others])
        assert np.all(seed >= sk.lower) and np.all(seed <= sk.upper)
        if k == 0:
            continue
        turned = swivel_arm(sk, q, "left", 2.0 * np.pi * k / SWIVEL_SEEDS)
        if np.array_equal(turned, seed):  # within the limits: the wrist stays put
            world = forward_kinematics(sk, seed)
            np.testing.assert_allclose(world[limb.end, :3, 3], wrist, atol=1e-6)
            assert np.linalg.norm(world[limb.middle, :3, 3] - elbow) > 1.0
            kept += 1
    assert kept >= 2
