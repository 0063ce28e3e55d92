"""Balance heuristic (Zhang §5.3, errata Z12): spine bow keeps the CoG over the feet."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mocapkit.errors import ConfigError, ShapeError
from mocapkit.ik.config import IKConfig
from mocapkit.ik.sdls import SDLSSolver
from mocapkit.skeleton import center_of_mass, load_preset
from mocapkit.tracking.hybrid.balance import (
    AT_GOAL_MM,
    BalanceConfig,
    _lean_range,
    _monotone_bisection,
    apply_lean,
    balance_pose,
    calibrate_balance,
    cog_offset_mm,
    forward_direction,
    restore_ik_config,
    restored_lean_slope,
    spine_dof_indices,
    support_points,
)


@pytest.fixture(scope="module")
def setup():
    sk = load_preset("zhang21")
    solver = SDLSSolver(sk)
    model = calibrate_balance(solver)
    return sk, solver, model


def squat(solver, depths, shift_mm=0.0):
    """IK poses of a squat: head and hands go down by dh (head a little forward), feet
    planted; every target moved by ``shift_mm`` as well."""
    q0 = solver.secondary.omega.copy()
    s0 = solver.effector_positions(q0) + shift_mm
    q = q0.copy()
    for dh in depths:
        t = s0.copy()
        t[:3, 2] += dh
        t[0, 1] -= 0.2 * dh
        q = solver.solve(q, t).q
        yield q, t


def test_tau_zero_at_rest_and_sign(setup):
    sk, solver, model = setup
    np.testing.assert_array_equal(model.taus(0.0), 0.0)
    # a squat (dh < 0) asks for forward flexion, so p < 0 (errata Z12)
    assert np.all(model.p_rad_per_mm < 0)
    q0 = solver.secondary.omega
    res = balance_pose(
        solver,
        q0,
        solver.effector_positions(q0),
        q0[2],
        support_points(sk, q0),
        model,
        BalanceConfig(mode="proportional"),
    )
    np.testing.assert_array_equal(res.taus, 0.0)


@pytest.mark.parametrize("mode", ["proportional", "solve"])
def test_squat_keeps_markers_and_improves_balance(setup, mode):
    sk, solver, model = setup
    q0 = solver.secondary.omega
    support = support_points(sk, q0)
    cfg = BalanceConfig(mode=mode)
    worst_off, worst_on, inside = 0.0, 0.0, 0
    depths = np.linspace(-20.0, -300.0, 12)
    for q, t in squat(solver, depths):
        cog, back, front = cog_offset_mm(sk, q, support)
        worst_off = max(worst_off, cog - front, back - cog)
        res = balance_pose(solver, q, t, q0[2], support, model, cfg)
        # head and hands stay on their markers (Z12): within twice the IK tolerance
        assert np.nanmax(res.residual_mm) <= 2.0 * solver.config.tol_mm
        cog, back, front = cog_offset_mm(sk, res.q, support)
        worst_on = max(worst_on, cog - front, back - cog)
        inside += back <= cog <= front
    assert worst_off > 50.0  # without the heuristic the squat falls forward out of the box
    assert worst_on < worst_off
    if mode == "solve":
        # markers come first (Z12): where head and hands cannot be restored under the
        # needed bow, the bow is halved and the CoG may leave the box (1 of 12 here)
        assert inside >= 0.9 * len(depths)


def test_bad_config():
    with pytest.raises(ConfigError, match="BalanceConfig.mode"):
        BalanceConfig(mode="tilt")


def test_spine_flexion_found_through_canonical_names():
    from mocapkit.tracking.hybrid.balance import spine_dof_indices

    plain = load_preset("zhang21")
    twist = load_preset("zhang21", ("spine_rotation", "neck_rotation"))
    names = ("spine1_flexion", "spine2_flexion", "spine3_flexion")
    assert spine_dof_indices(plain) == tuple(plain.dof_index(n) for n in names)
    # the twist is a spine DoF too, but not a flexion: the bow leaves it alone
    assert spine_dof_indices(twist) == tuple(twist.dof_index(n) for n in names)
    with pytest.raises(ShapeError, match="has no spine flexion DoF"):
        spine_dof_indices(load_preset("azad14"))


def test_support_needs_legs():
    sk = load_preset("upper_stick")
    with pytest.raises(ShapeError, match="has no legs"):
        support_points(sk, sk.zero_pose())
    z = load_preset("zhang21")
    pts = support_points(z, z.zero_pose())
    assert pts.shape == (4, 3) and np.all(np.abs(pts[:, 2] - pts[:, 2].min()) < 200.0)


class _Counting(SDLSSolver):
    solves = 0

    def solve(self, *args, **kwargs):
        type(self).solves += 1
        return super().solve(*args, **kwargs)


def test_no_lean_tried_when_markers_are_off_without_one(setup):
    sk, _solver, _model = setup
    solver = _Counting(sk)
    q0 = solver.secondary.omega
    support = support_points(sk, q0)
    (q, t), *_ = squat(solver, [-300.0])
    t = t.copy()
    t[1] += (0.0, 0.0, 400.0)  # the left hand's marker far out of reach
    _Counting.solves = 0
    res = balance_pose(solver, q, t, q0[2], support, None, BalanceConfig(mode="solve"))
    cog, back, front = cog_offset_mm(sk, q, support)
    assert not back <= cog <= front  # the balance step had work to do
    np.testing.assert_array_equal(res.taus, 0.0)
    assert _Counting.solves == 1  # the restore at zero lean, nothing else


def test_restored_lean_slope_is_the_cog_derivative_along_the_restoring_direction(setup):
    """The slope is that of the CoG along a lean with the free DoFs' correction that keeps
    every active effector in place to first order (checked by central differences)."""
    from mocapkit.tracking.hybrid.balance import _SLOPE_RCOND, _spine_split

    sk, solver, _model = setup
    q0 = solver.secondary.omega
    support = support_points(sk, q0)
    *_, (q, t) = squat(solver, np.linspace(-50.0, -200.0, 4))
    spine = list(spine_dof_indices(sk))
    split = _spine_split(sk, tuple(spine))
    # rebuild the restoring direction: the lean, and the free DoFs' weighted least-norm answer
    _pts, jac, jw = solver.weighted_jacobian(q)
    free = np.ones(sk.n_dofs, dtype=bool)
    free[spine] = False
    y = np.linalg.lstsq(jw[:, free], -(jac[:, spine] @ split), rcond=_SLOPE_RCOND)[0]
    dq = np.zeros(sk.n_dofs)
    dq[spine] = split
    dq[free] = y / solver.mu[free]
    moved = np.abs(jac[:, spine] @ split).max()  # the lean alone moves them this much
    # the effectors stay put but for the cut singular directions (0.02 % of ``moved`` here)
    np.testing.assert_allclose(jac @ dq, 0.0, atol=1e-3 * moved)
    h = 1e-5
    fwd = forward_direction(sk, q)  # the facing direction at q, held fixed
    numeric = fwd @ (center_of_mass(sk, q + h * dq) - center_of_mass(sk, q - h * dq)) / (2 * h)
    slope = restored_lean_slope(solver, q, t)
    assert slope == pytest.approx(numeric, rel=1e-6)
    assert slope < 0  # with the head pinned a forward bow moves the CoG backwards
    # the restore itself moves the CoG the same way (its slope differs: it also relaxes)
    a = apply_lean(solver, q, 0.05 * split, t)[0]
    assert cog_offset_mm(sk, a, support)[0] < cog_offset_mm(sk, q, support)[0]


def test_pose_kept_without_a_restore_where_no_lean_is_applied_when_asked(setup):
    sk, _solver, _model = setup
    solver = _Counting(sk)
    q0 = solver.secondary.omega
    support = support_points(sk, q0)
    (q, t), *_ = squat(solver, [-20.0])
    cog, back, front = cog_offset_mm(sk, q, support)
    margin = 0.15 * (front - back)
    assert back + margin <= cog <= front - margin  # balanced already
    skip = BalanceConfig(mode="solve", restore_without_lean=False)
    _Counting.solves = 0
    res = balance_pose(solver, q, t, q0[2], support, None, skip)
    assert _Counting.solves == 0
    np.testing.assert_array_equal(res.q, q)
    np.testing.assert_array_equal(res.taus, 0.0)
    expected = np.linalg.norm(solver.effector_positions(q) - t, axis=1)
    np.testing.assert_allclose(res.residual_mm, expected, atol=1e-12)
    _Counting.solves = 0
    balance_pose(solver, q, t, q0[2], support, None, BalanceConfig(mode="solve"))
    assert _Counting.solves == 1  # the default restores
    # an effector farther than restore_above_mm from its target: the restore runs
    t_far = t.copy()
    t_far[1, 0] += 2.0 * skip.restore_above_mm
    _Counting.solves = 0
    res = balance_pose(solver, q, t_far, q0[2], support, None, skip)
    assert _Counting.solves == 1
    assert res.residual_mm[1] < 2.0 * skip.restore_above_mm
    # a squat that needs a lean, with a hand a little off its marker (more than twice
    # the IK tolerance, less than restore_above_mm): no lean, no solve
    *_, (q, t) = squat(solver, np.linspace(-100.0, -300.0, 5))
    cog, back, front = cog_offset_mm(sk, q, support)
    assert cog > front  # the balance step had work to do
    t = solver.effector_positions(q)  # every target where its effector is ...
    t[1, 0] += 4.0 * solver.config.tol_mm  # ... but the left hand's, moved off
    _Counting.solves = 0
    res = balance_pose(solver, q, t, q0[2], support, None, skip)
    assert _Counting.solves == 0
    np.testing.assert_array_equal(res.q, q)
    np.testing.assert_array_equal(res.taus, 0.0)
    assert res.residual_mm[1] == pytest.approx(4.0 * solver.config.tol_mm)


#: How far apart (mm) the restored CoGs of nearby leans settle, beyond what the lean
#: itself moves (1-2 mm on the benchmark's leaning frames).
RESTORE_NOISE_MM = 2.0


def _reference_bisection(f, lo, hi, steps):
    """`_bisect_lean`'s plain bisection of ``f`` over ``[lo, hi]`` (as before the guided one)."""
    f0 = f(0.0)
    a, b = (0.0, hi) if f0 > 0 else (lo, 0.0)
    fa, fb = (f0, f(hi)) if f0 > 0 else (f(lo), f0)
    if np.sign(fa) == np.sign(fb):
        return a if abs(fa) < abs(fb) else b
    for _ in range(steps):
        m = 0.5 * (a + b)
        fm = f(m)
        if np.sign(fm) == np.sign(fa):
            a, fa = m, fm
        else:
            b, fb = m, fm
    return 0.5 * (a + b)


def test_guided_bisection_gives_the_plain_bisections_lean_with_fewer_evaluations():
    """The plain bisection's lean bit for bit, or a point of its grid evaluated on the
    way whose value is within `AT_GOAL_MM` of the goal (the search stops there)."""
    rng = np.random.default_rng(7)
    guided, plain = 0, 0
    early = 0
    for trial in range(300):
        lo, hi = -rng.uniform(0.3, 1.0), rng.uniform(0.5, 1.3)
        root = rng.uniform(1.2 * lo, 1.2 * hi)  # some beyond the range: its best end
        k, c = rng.uniform(40.0, 200.0), rng.uniform(0.0, 300.0)

        # decreasing, steeper away from zero (as the restored CoG against the lean)
        def f(x, root=root, k=k, c=c):
            return -k * (x - root) - c * (x * abs(x) - root * abs(root))

        calls = []

        def counted(x, f=f, calls=calls):
            calls.append(x)
            return f(x)

        expected = _reference_bisection(counted, lo, hi, 6)
        plain += len(calls) - 1  # f(0) is known to both
        calls.clear()
        slope = None if trial % 3 == 0 else -k * rng.uniform(0.3, 3.0)
        lean, found = _monotone_bisection(counted, f(0.0), lo, hi, 6, slope)
        guided += len(calls)
        if lean != expected:  # stopped early, at a grid point already at the goal
            assert abs(f(lean)) < AT_GOAL_MM and lean in calls
            early += 1
        else:
            assert lean == expected  # bit for bit
        assert len(set(calls)) == len(calls)  # no point evaluated twice
        assert found is None or found < 0
    assert guided < 0.7 * plain
    assert early > 0


def test_guided_bisection_keeps_the_plain_bisections_answer_where_f_is_not_decreasing():
    # f rises between its crossing and the range's end: the inferred signs may not
    # hold there, but the answer is still a sign change of f on the bisection's grid
    def f(x):
        return -100.0 * (x - 0.2) + (300.0 * (x - 0.6) ** 2 if x > 0.6 else 0.0)

    lean, _ = _monotone_bisection(f, f(0.0), -0.5, 1.0, 6, -100.0)
    assert lean == pytest.approx(0.2, abs=1.0 / 64)


def test_guided_balance_as_close_to_the_goal_with_fewer_restores(setup):
    """The guided search (stopped at a lean already at the goal) ends as close to the
    goal as the plain bisection, up to the spread of restores of nearby leans, with head
    and hands on their markers and fewer restore solves."""
    sk, _solver, _model = setup
    solver = _Counting(sk)
    q0 = solver.secondary.omega
    support = support_points(sk, q0)
    plain = BalanceConfig(mode="solve", bisection_steps=6)
    guided = BalanceConfig(mode="solve", bisection_steps=6, guided_bisection=True)
    n_plain, n_guided, slope, compared = 0, 0, None, 0
    for q, t in squat(solver, np.linspace(-100.0, -300.0, 5)):
        cog, back, front = cog_offset_mm(sk, q, support)
        assert cog > front  # the squat leans forward out of the box: a bow is needed
        goal = front - plain.margin_fraction * (front - back)
        _Counting.solves = 0
        a = balance_pose(solver, q, t, q0[2], support, None, plain)
        n_plain += _Counting.solves
        _Counting.solves = 0
        b = balance_pose(solver, q, t, q0[2], support, None, guided, slope_mm_per_rad=slope)
        n_guided += _Counting.solves
        slope = b.slope_mm_per_rad
        assert np.all(a.taus > 0) and np.all(b.taus > 0)  # a forward bow
        off_a = abs(cog_offset_mm(sk, a.q, support)[0] - goal)
        off_b = abs(cog_offset_mm(sk, b.q, support)[0] - goal)
        if off_a < 5.0:  # where the markers-first rule did not halve the plain one's lean
            # restores of nearby leans settle up to RESTORE_NOISE_MM apart
            assert off_b <= off_a + RESTORE_NOISE_MM
            compared += 1
        assert np.nanmax(b.residual_mm) <= 2.0 * solver.config.tol_mm
    assert slope is not None and slope < 0
    assert compared >= 2 and n_guided < 0.7 * n_plain


def test_restore_ik_config_stops_restores_on_their_best_iterate():
    ik = IKConfig(max_iterations=30, term_clamp_scale=3.0)
    assert restore_ik_config(ik, BalanceConfig(mode="solve")) is ik
    cfg = restore_ik_config(ik, BalanceConfig(mode="solve", restore_stall_iterations=3))
    assert (cfg.stall_iterations, cfg.stall_keep_best) == (3, True)
    assert cfg.max_iterations == 30 and cfg.term_clamp_scale == 3.0
    with pytest.raises(ConfigError, match="restore_stall_iterations: expected >= 0"):
        BalanceConfig(restore_stall_iterations=-1)


#: Frames the stepped search (`BalanceConfig.restores_per_frame`) is given on a held pose.
HELD_FRAMES = 4


def test_stepped_search_reaches_the_full_searchs_lean_on_a_held_pose(setup):
    """Two restores a frame, carried over frames: on each held squat pose the lean is
    within one bisection cell of the full search's after `HELD_FRAMES` frames, as close
    to the goal (up to the restores' spread), never more than two restores a frame, and
    head and hands on their markers. Where the markers-first rule halved the full
    search's lean, the stepped one keeps a lean at least as close to the goal."""
    sk, _solver, _model = setup
    solver = _Counting(sk)
    q0 = solver.secondary.omega
    support = support_points(sk, q0)
    full = BalanceConfig(
        mode="solve", bisection_steps=6, restore_without_lean=False, guided_bisection=True
    )
    stepped = replace(full, restores_per_frame=2)
    compared, halved = 0, 0
    for q, t in squat(solver, np.linspace(-100.0, -300.0, 5)):
        cog, back, front = cog_offset_mm(sk, q, support)
        assert cog > front  # a bow is needed
        goal = front - full.margin_fraction * (front - back)
        a = balance_pose(solver, q, t, q0[2], support, None, full)
        lean, slope = None, None
        for _ in range(HELD_FRAMES):
            _Counting.solves = 0
            b = balance_pose(
                solver, q, t, q0[2], support, None, stepped, slope_mm_per_rad=slope, lean_rad=lean
            )
            assert _Counting.solves <= stepped.restores_per_frame
            lean, slope = b.next_lean_rad, b.slope_mm_per_rad
            assert np.nanmax(b.residual_mm) <= 2.0 * solver.config.tol_mm
        assert lean == pytest.approx(np.sum(b.taus))
        off_a = abs(cog_offset_mm(sk, a.q, support)[0] - goal)
        off_b = abs(cog_offset_mm(sk, b.q, support)[0] - goal)
        if off_a < 5.0:  # the full search reached its goal
            _split, lo, hi = _lean_range(sk, q)
            assert abs(np.sum(b.taus) - np.sum(a.taus)) <= (hi - lo) / 2**full.bisection_steps
            assert off_b <= off_a + RESTORE_NOISE_MM
            compared += 1
        else:  # markers first: the full search halved its lean
            assert off_b <= off_a
            halved += 1
    assert compared >= 3 and halved >= 1


def test_stepped_search_follows_a_squat_with_two_restores_a_frame(setup):
    """A squat going down over 30 frames: the stepped search restores at most twice a
    frame, keeps head and hands on their markers, and keeps the restored CoG nearer the
    goal than without a lean on every frame."""
    sk, _solver, _model = setup
    solver = _Counting(sk)
    q0 = solver.secondary.omega
    support = support_points(sk, q0)
    cfg = BalanceConfig(mode="solve", bisection_steps=6, restores_per_frame=2)
    lean, slope, leant = None, None, 0
    for q, t in squat(solver, np.linspace(-100.0, -250.0, 30)):
        cog, back, front = cog_offset_mm(sk, q, support)
        goal = front - cfg.margin_fraction * (front - back)
        _Counting.solves = 0
        b = balance_pose(
            solver, q, t, q0[2], support, None, cfg, slope_mm_per_rad=slope, lean_rad=lean
        )
        assert _Counting.solves <= 2
        lean, slope = b.next_lean_rad, b.slope_mm_per_rad
        assert np.nanmax(b.residual_mm) <= 2.0 * solver.config.tol_mm
        assert abs(cog_offset_mm(sk, b.q, support)[0] - goal) < abs(cog - goal)
        leant += bool(np.any(b.taus))
    assert leant == 30


def test_stepped_search_needs_two_restores_a_frame():
    with pytest.raises(ConfigError, match="restores_per_frame: expected 0 .* or >= 2"):
        BalanceConfig(mode="solve", restores_per_frame=1)
    with pytest.raises(ConfigError, match="restores_per_frame: expected 0"):
        BalanceConfig(mode="solve", restores_per_frame=-1)
