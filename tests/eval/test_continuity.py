"""Continuity figures: joint speeds, their peak, bone roll per frame."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ShapeError
from mocapkit.eval.continuity import peak, roll_steps_deg, speeds_mm_s
from mocapkit.skeleton import load_preset


def test_speeds_and_their_peak_are_known_values() -> None:
    t = np.array([0.0, 0.5, 1.0])
    p = np.zeros((3, 2, 3))
    p[1, 1] = [300.0, 400.0, 0.0]  # 500 mm in 0.5 s, then back
    p[2, 0] = [0.0, 0.0, 100.0]
    s = speeds_mm_s(t, p)
    np.testing.assert_allclose(s, [[0.0, 1000.0], [200.0, 1000.0]])
    top = peak(s, ("a", "b"))
    assert (top.value, top.frame, top.name) == (1000.0, 1, "b")
    with pytest.raises(ShapeError, match=r"expected shape \(3, K, 3\)"):
        speeds_mm_s(t, p[:2])


def test_roll_steps_deg_sees_a_turn_of_the_forearm_about_its_axis() -> None:
    sk = load_preset("zhang21", ["forearm_rotation"])
    q = np.tile(sk.zero_pose(), (3, 1))
    q[2, sk.dof_names.index("l_forearm_rotation")] = np.deg2rad(30.0)
    names, steps = roll_steps_deg(sk, q)
    k = names.index("l_radius")
    np.testing.assert_allclose(steps[:, k], [0.0, 30.0], atol=1e-9)
