"""The arm swivel: the wrist stays, the elbow circles the shoulder-wrist axis, on both models."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocapkit.errors import ShapeError
from mocapkit.geometry.rotations import matrix_rotvec_nb
from mocapkit.ik.swivel import shoulder_dofs, swivel_angle, swivel_arm
from mocapkit.skeleton import forward_kinematics, load_preset
from mocapkit.skeleton.limbs import arm


def _rodrigues(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation about a unit axis, written out independently of the package."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def _random_pose(sk, rng: np.random.Generator) -> np.ndarray:
    lo = np.where(np.isfinite(sk.lower), sk.lower, -100.0)
    hi = np.where(np.isfinite(sk.upper), sk.upper, 100.0)
    q = sk.zero_pose() + 0.4 * rng.uniform(lo, hi)
    for side in ("left", "right"):  # a bent elbow, so the swivel moves it
        elbow = arm(sk, side).dofs[3]
        q[elbow] = 0.5 * (lo + hi)[elbow]
    return q


@pytest.mark.parametrize("preset", ["zhang21", "azad14"])
def test_swivel_holds_the_wrist_and_rotates_the_elbow_about_the_axis(preset: str) -> None:
    sk = load_preset(preset)
    rng = np.random.default_rng(11)
    for _ in range(5):
        q = _random_pose(sk, rng)
        world = forward_kinematics(sk, q)
        for side in ("left", "right"):
            limb = arm(sk, side)
            s, e, w = (world[j, :3, 3] for j in (limb.root, limb.middle, limb.end))
            n = (w - s) / np.linalg.norm(w - s)
            for deg in (-140.0, -25.0, 10.0, 75.0):
                a = math.radians(deg)
                q2 = swivel_arm(sk, q, side, a)
                world2 = forward_kinematics(sk, q2)
                rot = _rodrigues(n, a)
                np.testing.assert_allclose(world2[limb.end, :3, 3], w, atol=1e-9)
                np.testing.assert_allclose(world2[limb.middle, :3, 3], s + rot @ (e - s), atol=1e-9)
                # the whole hand turns with the swivel
                np.testing.assert_allclose(
                    world2[limb.end, :3, :3], rot @ world[limb.end, :3, :3], atol=1e-9
                )
                assert q2[limb.dofs[3]] == q[limb.dofs[3]]
                other = np.setdiff1d(np.arange(sk.n_dofs), limb.dofs[:3])
                np.testing.assert_array_equal(q2[other], q[other])
                # the angle measured back is the angle applied
                got = swivel_angle(s, world2[limb.middle, :3, 3], w, e)
                assert got == pytest.approx(a, abs=1e-9)


def test_swivel_angle_against_numpy(rng) -> None:
    for _ in range(20):
        s, w = rng.normal(0, 300, 3), rng.normal(0, 300, 3)
        ref = rng.normal(0, 300, 3)
        a = rng.uniform(-math.pi, math.pi)
        n = (w - s) / np.linalg.norm(w - s)
        moved = s + _rodrigues(n, a) @ (ref - s) + 37.0 * n  # sliding along the axis is no swivel
        assert swivel_angle(s, moved, w, ref) == pytest.approx(a, abs=1e-9)


def test_rotation_vector_of_a_matrix_matches_scipy(rng) -> None:
    vecs = [rng.normal(0, 1, 3) for _ in range(50)]
    vecs += [np.array([1e-14, -2e-14, 0.0]), np.zeros(3), np.array([0.0, math.pi - 1e-9, 0.0])]
    vecs += [v / np.linalg.norm(v) * (math.pi - 1e-7) for v in vecs[:5]]
    out = np.empty(3)
    for v in vecs:
        r = Rotation.from_rotvec(v)
        matrix_rotvec_nb(np.ascontiguousarray(r.as_matrix()), out)
        ref = r.as_rotvec()
        # a rotation by pi has two rotation vectors; compare the rotations there
        assert Rotation.from_rotvec(out).approx_equal(r, atol=1e-9)
        if np.linalg.norm(ref) < math.pi - 1e-6:
            np.testing.assert_allclose(out, ref, atol=1e-9)


def test_shoulders_that_cannot_swivel_raise() -> None:
    sk = load_preset("zhang21")
    dofs = arm(sk, "left").dofs
    with pytest.raises(ShapeError, match="3 revolute or one ball shoulder"):
        shoulder_dofs(sk, dofs[:2])
    q = sk.zero_pose()
    with pytest.raises(ShapeError, match="expected one pose"):
        swivel_arm(sk, np.stack([q, q]), "left", 0.1)
    with pytest.raises(ShapeError, match="wrist coincides with the shoulder"):
        swivel_angle(np.zeros(3), np.ones(3), np.zeros(3), np.ones(3))
