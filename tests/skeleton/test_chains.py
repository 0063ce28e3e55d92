"""A limb chain below a fixed parent poses its joints as the whole-body FK does."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ShapeError
from mocapkit.skeleton import forward_kinematics, load_preset
from mocapkit.skeleton.chains import chain_frames_nb, limb_chain
from mocapkit.skeleton.limbs import arm, leg


def _random_pose(sk, rng: np.random.Generator) -> np.ndarray:
    lo = np.where(np.isfinite(sk.lower), sk.lower, -300.0)
    hi = np.where(np.isfinite(sk.upper), sk.upper, 300.0)
    return rng.uniform(lo, hi)


@pytest.mark.parametrize(
    ("preset", "options", "limb_of"),
    [
        ("zhang21", (), arm),
        ("zhang21", (), leg),
        ("azad14", (), arm),
        ("azad14", ("adaptive_shoulder",), arm),  # prismatic shoulder offsets held fixed
    ],
)
def test_chain_frames_equal_forward_kinematics(preset, options, limb_of, rng) -> None:
    sk = load_preset(preset, options)
    for side in ("left", "right"):
        limb = limb_of(sk, side)
        for _ in range(5):
            q = _random_pose(sk, rng)
            chain = limb_chain(sk, q, limb.chain, limb.dofs)
            # search over the limb's DoFs: every other DoF keeps q's value
            q2 = q.copy()
            q2[limb.dofs] = _random_pose(sk, rng)[limb.dofs]
            n = limb.chain.size
            rots, orig = np.empty((n, 3, 3)), np.empty((n, 3))
            chain_frames_nb(np.ascontiguousarray(q2[limb.dofs]), chain, rots, orig)
            world = forward_kinematics(sk, q2)[limb.chain]
            np.testing.assert_allclose(rots, world[:, :3, :3], atol=1e-12)
            np.testing.assert_allclose(orig, world[:, :3, 3], atol=1e-9)


def test_bad_chains_raise() -> None:
    sk = load_preset("zhang21")
    limb = arm(sk, "left")
    q = sk.zero_pose()
    with pytest.raises(ShapeError, match="are not a chain"):
        limb_chain(sk, q, limb.chain[::-1], limb.dofs)
    with pytest.raises(ShapeError, match="are not all on joints"):
        limb_chain(sk, q, limb.chain[:1], limb.dofs)
