"""Azad Algorithm 2 as corrected (errata A1-A9): IK -> FK round trips and the alpha bounds."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocapkit.errors import ConfigError, ShapeError
from mocapkit.geometry.rotations import (
    matrix_from_rotvec,
    matrix_rotvec_nb,
    rotate_nb,
    rotvec_from_matrix,
    signed_angle_nb,
)
from mocapkit.ik.arm_analytic import (
    ALPHA_RANGE_RAD,
    PAPER_TO_TORSO,
    REACH_CLAMP,
    arm_fk,
    arm_ik,
    elbow_circle,
    make_problem,
)
from mocapkit.skeleton.kinematics import canonical_positions
from mocapkit.skeleton.limbs import arm
from mocapkit.skeleton.presets import load_preset


def _signed_angle(u, v, k):
    k = k / np.linalg.norm(k)
    up = u - (u @ k) * k
    vp = v - (v @ k) * k
    return math.atan2(k @ np.cross(up, vp), up @ vp)


def _random_case(rng, a, b, c_len, direction=None):
    rb = Rotation.random(random_state=rng.integers(1 << 31)).as_matrix()
    s = rng.uniform(-500, 500, 3)
    d = rng.normal(size=3) if direction is None else np.asarray(direction, float)
    d /= np.linalg.norm(d)
    # direction given in the torso frame
    return rb, s, s + rb @ (c_len * d)


def _check_round_trip(rb, s, h, a, b, alphas):
    prob = make_problem(rb, s, h, a, b)
    q, elbow = arm_ik(prob, alphas)
    e_fk, h_fk = arm_fk(rb, s, q, a, b)
    tol = 1e-6 * (a + b)
    assert np.max(np.linalg.norm(h_fk - h, axis=-1)) < tol
    assert np.max(np.abs(np.linalg.norm(e_fk - s, axis=-1) - a)) < tol
    np.testing.assert_allclose(elbow, e_fk, atol=tol)
    assert np.all((q[:, 3] >= -math.pi - 1e-12) & (q[:, 3] <= 1e-12))
    _hand, centre, n0 = elbow_circle(prob)
    axis = h - s
    for al, e in zip(alphas, elbow):
        got = _signed_angle(n0, e - centre, axis)
        assert abs(math.remainder(got - al, 2 * math.pi)) < 1e-7


def test_round_trip_random_cases():
    rng = np.random.default_rng(0)
    for _ in range(300):
        a, b = rng.uniform(200, 350), rng.uniform(180, 320)
        c_len = rng.uniform(1.01 * abs(a - b), REACH_CLAMP * (a + b))
        # a tiny |a-b| makes the lower end degenerate; keep c away from 0
        c_len = max(c_len, 0.02 * (a + b))
        rb, s, h = _random_case(rng, a, b, c_len)
        _check_round_trip(rb, s, h, a, b, rng.uniform(-math.pi, math.pi, 7))


@pytest.mark.parametrize(
    "direction",
    [
        (1.0, 0.3, 0.0),  # c_z = 0 in the paper's frame (torso y = 0)
        (-0.4, 0.0, -1.0),
        (0.0, 0.0, -1.0),  # hand straight down: c along the paper's +y
        (0.0, 0.0, 1.0),  # straight up
        (0.0, 1.0, 0.0),
    ],
)
def test_round_trip_special_directions(direction):
    rng = np.random.default_rng(1)
    a, b = 300.0, 270.0
    alphas = np.linspace(-math.pi, math.pi, 25)
    for c_len in (0.3 * (a + b), 0.6 * (a + b), REACH_CLAMP * (a + b)):
        rb, s, h = _random_case(rng, a, b, c_len, direction)
        _check_round_trip(rb, s, h, a, b, alphas)


def test_upper_arm_parallel_to_y_is_handled():
    """Errata A7: a_vec parallel to the paper's +-y (preset -+z) is singular in steps 15-17."""
    a, b = 300.0, 270.0
    rb = np.eye(3)
    s = np.zeros(3)
    # elbow straight below the shoulder, forearm forward: a_vec = paper +y
    h_down = np.array([0.0, b, -a])
    # elbow straight above the shoulder, forearm forward: a_vec = paper -y
    h_up = np.array([0.0, b, a])
    for h in (h_down, h_up):
        prob = make_problem(rb, s, h, a, b)
        alphas = np.linspace(-math.pi, math.pi, 721)
        q, elbow = arm_ik(prob, alphas)
        _e, h_fk = arm_fk(rb, s, q, a, b)
        assert np.max(np.linalg.norm(h_fk - h, axis=-1)) < 1e-6 * (a + b)
        # one of these alphas puts the elbow on the vertical through the shoulder
        assert np.min(np.linalg.norm(elbow[:, :2], axis=-1)) < 2.0
        i = int(np.argmin(np.linalg.norm(elbow[:, :2], axis=-1)))
        _check_round_trip(rb, s, h, a, b, alphas[i : i + 1])


def test_fk_agrees_with_the_azad14_preset():
    """The IK's frames are the preset's: its own kinematics put the hand on the target."""
    sk = load_preset("azad14")
    rng = np.random.default_rng(2)
    for side in ("left", "right"):
        limb = arm(sk, side)
        q0 = sk.zero_pose()
        q0[:3] = (10.0, -20.0, 5.0)
        q0[3:6] = (0.2, -0.1, 0.4)  # base rotation vector
        names = (f"{side}_shoulder", f"{side}_elbow", f"{side}_wrist")
        base = canonical_positions(sk, q0, names)
        s = base[0]
        rb = matrix_from_rotvec(q0[3:6])
        a = float(np.linalg.norm(base[1] - base[0]))
        b = float(np.linalg.norm(base[2] - base[1]))
        for _ in range(20):
            h = s + rb @ (rng.normal(size=3) * 150 + (0, 150, -150))
            prob = make_problem(rb, s, h, a, b)
            q, elbow = arm_ik(prob, rng.uniform(-math.pi, math.pi, 3))
            for qi, ei in zip(q, elbow):
                qq = q0.copy()
                qq[limb.dofs] = qi
                pts = canonical_positions(sk, qq, names)
                clamped, _c, _n0 = elbow_circle(prob)
                np.testing.assert_allclose(pts[1], ei, atol=1e-6)
                np.testing.assert_allclose(pts[2], clamped, atol=1e-6)


def test_out_of_range_hands_land_on_the_clamp_sphere():
    rng = np.random.default_rng(3)
    a, b = 300.0, 250.0
    for c_len in (2.0 * (a + b), 0.99 * (a + b), 0.5 * abs(a - b), 0.0):
        rb, s, h = _random_case(rng, a, b, c_len)
        prob = make_problem(rb, s, h, a, b)
        q, _elbow = arm_ik(prob, np.linspace(-3, 3, 7))
        _e, h_fk = arm_fk(rb, s, q, a, b)
        r = np.linalg.norm(h_fk - s, axis=-1)
        want = REACH_CLAMP * (a + b) if c_len > REACH_CLAMP * (a + b) else abs(a - b)
        np.testing.assert_allclose(r, want, atol=1e-6 * (a + b))
        if c_len > 0:  # same direction as the target
            d = (h_fk - s) / r[:, None]
            np.testing.assert_allclose(d, np.broadcast_to((h - s) / c_len, d.shape), atol=1e-9)
    # errata A8: with a = b the lower clamp keeps c away from 0
    prob = make_problem(np.eye(3), np.zeros(3), np.zeros(3), 300.0, 300.0)
    q, _e = arm_ik(prob, [0.5])
    assert np.all(np.isfinite(q))
    _e, h_fk = arm_fk(np.eye(3), np.zeros(3), q, 300.0, 300.0)
    assert abs(np.linalg.norm(h_fk) - 1e-3 * 600.0) < 1e-6


def test_ik_samples_never_straighten_beyond_the_clamp():
    """Errata A8: under the 0.95(a+b) clamp theta4 stays below about -36.4 degrees (a = b)."""
    prob = make_problem(np.eye(3), np.zeros(3), np.array([0.0, 0.0, -5000.0]), 300.0, 300.0)
    q, _e = arm_ik(prob, np.linspace(-3, 3, 5))
    # a = b, c = 1.9 a: cos(gamma) = (2 a^2 - c^2) / (2 a^2) = 1 - 1.805
    want = math.degrees(math.acos(1.0 - 2.0 * REACH_CLAMP**2)) - 180.0
    assert want == pytest.approx(-36.39, abs=0.01)
    np.testing.assert_allclose(np.degrees(q[:, 3]), want, atol=1e-9)


def test_no_alpha_in_range_sends_the_elbow_through_the_torso():
    """Errata A9: for hands below or in front of the shoulder, every alpha in the side's
    range keeps the elbow lateral of the shoulder's sagittal plane (x to the right)."""
    a, b = 300.0, 270.0
    for side, sx in (("left", -1.0), ("right", 1.0)):
        lo, hi = ALPHA_RANGE_RAD[side]
        alphas = np.linspace(lo, hi, 181)
        slack = a * math.sin(0.2) + 1e-6  # the 0.2 rad the bounds reach past the plane
        for hand in ((0, 0, -450), (0, 0, -300), (0, 250, -300), (0, 350, 0), (0, 200, -150)):
            s = np.array([sx * 190.0, 0.0, 1410.0])
            prob = make_problem(np.eye(3), s, s + np.asarray(hand, float), a, b)
            _q, elbow = arm_ik(prob, alphas)
            medial = -sx * (elbow[:, 0] - s[0])
            assert medial.max() <= slack, (side, hand)
    # the paper's own (unmirrored) left range would: alpha = pi/2, hand hanging down
    s = np.array([-190.0, 0.0, 1410.0])
    prob = make_problem(np.eye(3), s, s + np.array([0.0, 0.0, -300.0]), a, b)
    _q, elbow = arm_ik(prob, [math.pi / 2])
    assert elbow[0, 0] - s[0] > 0.5 * a


def test_rotate_and_signed_angle_agree():
    rng = np.random.default_rng(4)
    out = np.empty(3)
    for _ in range(200):
        u, v, k = rng.normal(size=(3, 3))
        ang = signed_angle_nb(u, v, k)
        assert abs(ang - _signed_angle(u, v, k)) < 1e-12
        rotate_nb(u, k, ang, out)
        kh = k / np.linalg.norm(k)
        proj_v = v - (v @ kh) * kh
        proj_o = out - (out @ kh) * kh
        scale = np.linalg.norm(proj_v) * np.linalg.norm(u)
        assert np.linalg.norm(np.cross(proj_o, proj_v)) < 1e-9 * scale
        assert proj_o @ proj_v > 0
        np.testing.assert_allclose(out @ kh, u @ kh, atol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(out), np.linalg.norm(u), rtol=1e-12)


@pytest.mark.parametrize("angle", [0.0, 1e-9, 1e-4, 1.0, math.pi - 1e-4, math.pi - 1e-9, math.pi])
def test_log_exp_round_trip_near_zero_and_pi(angle):
    rng = np.random.default_rng(5)
    out = np.empty(3)
    for _ in range(50):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        r = matrix_from_rotvec(axis * angle)
        matrix_rotvec_nb(r, out)
        np.testing.assert_allclose(matrix_from_rotvec(out), r, atol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(out), angle, atol=1e-9)
        if angle < math.pi - 1e-6:
            np.testing.assert_allclose(out, rotvec_from_matrix(r), atol=1e-9)


def test_paper_frame_matrix_maps_the_elbow_axis():
    p = PAPER_TO_TORSO
    np.testing.assert_allclose(p @ p.T, np.eye(3))
    assert np.linalg.det(p) == pytest.approx(1.0)
    np.testing.assert_allclose(p @ (0, 1, 0), (0, 0, -1))  # the arm hangs along -z
    np.testing.assert_allclose(p @ (1, 0, 0), (-1, 0, 0))  # elbow axis x -> -x


def test_refusals():
    with pytest.raises(ShapeError, match="base_rotation"):
        make_problem(np.eye(2), np.zeros(3), np.zeros(3), 1.0, 1.0)
    with pytest.raises(ConfigError, match="positive segment lengths"):
        make_problem(np.eye(3), np.zeros(3), np.zeros(3), 0.0, 1.0)
    with pytest.raises(ShapeError, match="finite"):
        make_problem(np.eye(3), np.full(3, np.nan), np.zeros(3), 1.0, 1.0)
