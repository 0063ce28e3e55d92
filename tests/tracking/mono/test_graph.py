"""Pose-graph weights (errata M1-M4) and Viterbi against brute force (errata M3)."""

import itertools

import numpy as np
import pytest

from mocapkit.errors import ConfigError, ShapeError
from mocapkit.tracking.mono.motion_cost import (
    acceleration_cost,
    acceleration_min,
    angular_velocity,
    angular_velocity_literal,
    joint_acceleration_cost,
    pair_omegas,
    rotation_cost,
)
from mocapkit.tracking.mono.viterbi import Decoder, pair_viterbi, viterbi


def test_corrected_omega_is_angle_over_dt_times_the_axis() -> None:
    rng = np.random.default_rng(20)
    dt = 1 / 30
    for _ in range(50):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        r0 = np.cross(axis, rng.normal(size=3))
        r0 *= rng.uniform(50, 500) / np.linalg.norm(r0)  # perpendicular to the axis
        delta = rng.uniform(0.0, 3.0)
        c, s = np.cos(delta), np.sin(delta)
        r1 = r0 * c + np.cross(axis, r0) * s
        np.testing.assert_allclose(angular_velocity(r0, r1, dt), delta / dt * axis, atol=1e-9)


def test_literal_omega_scales_with_the_squared_length() -> None:
    rng = np.random.default_rng(21)
    r0, r1 = rng.normal(size=(2, 3))
    r1 = r1 / np.linalg.norm(r1) * np.linalg.norm(r0)
    for scale in (2.0, 10.0):
        np.testing.assert_allclose(
            angular_velocity_literal(scale * r0, scale * r1, 0.1),
            scale**2 * angular_velocity_literal(r0, r1, 0.1),
        )
        np.testing.assert_allclose(
            angular_velocity(scale * r0, scale * r1, 0.1), angular_velocity(r0, r1, 0.1)
        )
    # for unit vectors the printed formula is sin(delta)/dt along the axis
    lit = np.linalg.norm(
        angular_velocity_literal(r0 / np.linalg.norm(r0), r1 / np.linalg.norm(r1), 0.1)
    )
    delta = np.arccos(np.clip(r0 @ r1 / (r0 @ r0), -1, 1))
    assert lit == pytest.approx(np.sin(delta) / 0.1)


def test_omega_of_parallel_and_opposite_vectors() -> None:
    r = np.array([0.0, 0.0, 300.0])
    np.testing.assert_array_equal(angular_velocity(r, 2 * r, 0.5), np.zeros(3))
    w = angular_velocity(r, -r, 0.5)
    assert np.linalg.norm(w) == pytest.approx(np.pi / 0.5)
    assert abs(w @ r) < 1e-9


def test_acceleration_cost_matches_its_definition() -> None:
    rng = np.random.default_rng(22)
    va, vb, vc = (rng.normal(size=(n, 4, 3)) for n in (2, 3, 2))
    dt = 0.04
    wa, wb = pair_omegas(va, vb, dt), pair_omegas(vb, vc, dt)
    acc = acceleration_cost(wa, wb, dt)
    for i, j, m in itertools.product(range(2), range(3), range(2)):
        ref = sum(
            np.linalg.norm(
                (
                    angular_velocity(vb[j, k], vc[m, k], dt)
                    - angular_velocity(va[i, k], vb[j, k], dt)
                )
                / dt
            )
            for k in range(4)
        )
        assert acc[i, j, m] == pytest.approx(ref)
    rot = rotation_cost(wa)
    assert rot[1, 2] == pytest.approx(
        sum(np.linalg.norm(angular_velocity(va[1, k], vb[2, k], dt)) for k in range(4))
    )
    pa, pb, pc = (rng.normal(size=(n, 5, 3)) for n in (2, 3, 2))
    jac = joint_acceleration_cost(pa, pb, pc, dt)
    assert jac[1, 0, 1] == pytest.approx(
        np.linalg.norm(pc[1] - 2 * pb[0] + pa[1], axis=-1).sum() / dt**2
    )


def _random_graph(rng: np.random.Generator, t: int) -> tuple[list, list, list]:
    sizes = rng.integers(1, 4, size=t)
    unary = [rng.uniform(0, 1, size=n) for n in sizes]
    pair = [rng.uniform(0, 1, size=(sizes[k], sizes[k + 1])) for k in range(t - 1)]
    triple = [rng.uniform(0, 1, size=(sizes[k], sizes[k + 1], sizes[k + 2])) for k in range(t - 2)]
    return unary, pair, triple


def _brute(unary: list, pair: list, triple: list | None) -> float:
    best = np.inf
    for path in itertools.product(*(range(len(u)) for u in unary)):
        c = sum(u[s] for u, s in zip(unary, path))
        c += sum(pair[k][path[k], path[k + 1]] for k in range(len(pair)))
        if triple is not None:
            c += sum(triple[k][path[k], path[k + 1], path[k + 2]] for k in range(len(triple)))
        best = min(best, c)
    return float(best)


def _cost(path: np.ndarray, unary: list, pair: list, triple: list | None) -> float:
    c = sum(u[s] for u, s in zip(unary, path))
    c += sum(pair[k][path[k], path[k + 1]] for k in range(len(pair)))
    if triple is not None:
        c += sum(triple[k][path[k], path[k + 1], path[k + 2]] for k in range(len(triple)))
    return float(c)


@pytest.mark.parametrize("t", [1, 2, 3, 4, 5])
def test_viterbi_and_pair_viterbi_equal_brute_force(t: int) -> None:
    rng = np.random.default_rng(30 + t)
    for _ in range(40):
        unary, pair, triple = _random_graph(rng, t)
        path, cost = viterbi(unary, pair)
        assert cost == pytest.approx(_brute(unary, pair, None))
        assert _cost(path, unary, pair, None) == pytest.approx(cost)
        path2, cost2 = pair_viterbi(unary, pair, triple)
        assert cost2 == pytest.approx(_brute(unary, pair, triple))
        assert _cost(path2, unary, pair, triple) == pytest.approx(cost2)


def test_acceleration_min_equals_the_full_array_and_its_argmin() -> None:
    """The fused, pruned pair-state step against ``min``/``argmin`` of eq. 3's array:
    equal to the bit, ties (rounded omegas and costs) to the first i, unreachable (inf)
    pair states included."""
    rng = np.random.default_rng(50)
    for trial in range(150):
        ni, nj, nm = (int(v) for v in rng.integers(1, 10, 3))
        nl = int(rng.integers(1, 9))
        wa = rng.normal(size=(ni, nj, nl, 3))
        wb = rng.normal(size=(nj, nm, nl, 3))
        cost = 5.0 * rng.normal(size=(ni, nj))
        if trial % 3 == 0:
            wa, wb, cost = np.round(wa), np.round(wb), np.round(cost)
        if trial % 5 == 0:
            cost[rng.random(cost.shape) < 0.3] = np.inf
        tot = cost[:, :, None] + acceleration_cost(wa, wb, 1 / 30)
        best, back = acceleration_min(cost, wa, wb, 1 / 30)
        np.testing.assert_array_equal(best, tot.min(axis=0))
        np.testing.assert_array_equal(back, tot.argmin(axis=0))
    with pytest.raises(ShapeError, match="acceleration_min: expected"):
        acceleration_min(np.zeros((2, 3)), np.zeros((2, 2, 1, 3)), np.zeros((2, 2, 1, 3)), 0.1)


def test_push_reduced_equals_push_with_the_triple() -> None:
    rng = np.random.default_rng(41)
    unary, pair, triple = _random_graph(rng, 7)
    full, reduced = Decoder(2, lag=2), Decoder(2, lag=2)
    for k, u in enumerate(unary):
        if k < 2:
            a = full.push(u, pair[k - 1] if k else None)
            b = reduced.push(u, pair[k - 1] if k else None)
        else:
            tot = reduced.pair_costs()[:, :, None] + triple[k - 2]
            a = full.push(u, pair[k - 1], triple[k - 2])
            b = reduced.push_reduced(u, pair[k - 1], tot.min(axis=0), tot.argmin(axis=0))
        assert a == b
    assert full.flush() == reduced.flush()
    assert full.best_cost() == reduced.best_cost()
    with pytest.raises(ShapeError, match="push_reduced: needs order 2"):
        Decoder(1).push_reduced(np.zeros(1), np.zeros((1, 1)), np.zeros((1, 1)), np.zeros((1, 1)))


def _path(decisions: list[tuple[int, int]], n: int) -> np.ndarray:
    """The states of frames 0 .. n - 1 from a decoder's decisions (each frame once, in
    order)."""
    assert [f for f, _ in decisions] == list(range(n))
    return np.array([s for _, s in decisions], dtype=np.int64)


def test_online_decoder_with_a_long_lag_equals_offline() -> None:
    rng = np.random.default_rng(40)
    unary, pair, triple = _random_graph(rng, 12)
    for order in (1, 2):
        off = Decoder(order)
        on = Decoder(order, lag=20)
        short = Decoder(order, lag=2)
        decided, off_d, on_d = [], [], []
        for k, u in enumerate(unary):
            tri = triple[k - 2] if (k >= 2 and order == 2) else None
            args = (u, pair[k - 1] if k else None, tri)
            off_d += off.push(*args)
            assert on.push(*args) == []
            decided += short.push(*args)
        assert [f for f, _ in decided] == list(range(10))  # frame k - 2 fixed at frame k
        np.testing.assert_array_equal(_path(off_d + off.flush(), 12), _path(on_d + on.flush(), 12))
        _path(decided + short.flush(), 12)


def _offline(order: int, unary: list, pair: list, triple: list, window: int) -> tuple:
    dec = Decoder(order, window=window)
    decided, open_most = [], 0
    for k, u in enumerate(unary):
        tri = triple[k - 2] if (k >= 2 and order == 2) else None
        decided += dec.push(u, pair[k - 1] if k else None, tri)
        open_most = max(open_most, k + 1 - len(decided))
    return _path(decided + dec.flush(), len(unary)), open_most, dec


def test_offline_decoder_fixes_merged_frames_early_and_stays_exact() -> None:
    """Offline, frames are fixed as soon as every current state's best path agrees on
    them, and the path is the exact one; a window caps the open frames."""
    rng = np.random.default_rng(43)
    for order in (1, 2):
        for _ in range(10):
            unary, pair, triple = _random_graph(rng, 6)
            path, _, dec = _offline(order, unary, pair, triple, 1 << 30)
            best = _brute(unary, pair, triple if order == 2 else None)
            assert _cost(path, unary, pair, triple if order == 2 else None) == pytest.approx(best)
            assert dec.n_forced == 0
        # a long sequence whose paths merge: few frames stay open
        n = 200
        unary = [rng.normal(size=3) * 5 for _ in range(n)]
        pair = [rng.normal(size=(3, 3)) for _ in range(n - 1)]
        triple = [rng.normal(size=(3, 3, 3)) for _ in range(n - 2)]
        exact, open_exact, _ = _offline(order, unary, pair, triple, 1 << 30)
        assert open_exact < 40
        # a window of 2 frames: open frames capped, the path a valid one
        capped, open_capped, dec = _offline(order, unary, pair, triple, 2)
        assert open_capped <= 3
        assert dec.n_forced > 0
        assert capped.shape == exact.shape


def test_decoder_refuses_bad_input() -> None:
    with pytest.raises(ConfigError, match="order"):
        Decoder(3)
    dec = Decoder(1)
    dec.push(np.zeros(2))
    with pytest.raises(ShapeError, match="pairwise"):
        dec.push(np.zeros(3), np.zeros((3, 3)))


@pytest.mark.parametrize("lag", [0, 1, 3])
def test_online_decisions_are_those_of_the_full_backtrack(lag: int) -> None:
    """Each online decision (a walk over the newest lag + 1 frames only) is the state
    that the best path over all frames so far gives the decided frame."""
    rng = np.random.default_rng(60 + lag)
    unary, pair, triple = _random_graph(rng, 9)
    for order in (1, 2):
        on = Decoder(order, lag=lag)
        for k, u in enumerate(unary):
            tri = triple[k - 2] if (k >= 2 and order == 2) else None
            decided = on.push(u, pair[k - 1] if k else None, tri)
            full = Decoder(order)
            full_d = []
            for i in range(k + 1):
                t2 = triple[i - 2] if (i >= 2 and order == 2) else None
                full_d += full.push(unary[i], pair[i - 1] if i else None, t2)
            best = _path(full_d + full.flush(), k + 1)
            if k >= lag:
                assert decided == [(k - lag, int(best[k - lag]))]
            else:
                assert decided == []
