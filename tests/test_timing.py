"""Stage timer: totals, calls and counts per stage; the null timer records nothing."""

from __future__ import annotations

import time

import pytest

from mocapkit.timing import NULL_TIMER, StageTimer


def test_stage_timer_accumulates_time_calls_and_counts() -> None:
    timer = StageTimer()
    for _ in range(3):
        with timer.stage("ik"):
            time.sleep(0.002)
    with timer.stage("balance"):
        pass
    timer.count("ik_iterations", 7)
    timer.count("ik_iterations", 5)
    assert timer.calls() == {"ik": 3, "balance": 1, "ik_iterations": 0}
    assert timer.totals_s()["ik"] >= 3 * 0.002
    assert timer.totals_s()["balance"] < timer.totals_s()["ik"]
    assert timer.counts()["ik_iterations"] == 12
    timer.reset()
    assert timer.totals_s() == {}


def test_stage_is_timed_when_its_body_raises() -> None:
    timer = StageTimer()
    with pytest.raises(ValueError, match="boom"), timer.stage("io"):
        raise ValueError("boom")
    assert timer.calls() == {"io": 1}


def test_null_timer_records_nothing() -> None:
    with NULL_TIMER.stage("ik"):
        pass
    NULL_TIMER.count("ik_solves", 3)
    assert not NULL_TIMER.enabled
    assert NULL_TIMER.totals_s() == {} and NULL_TIMER.counts() == {}


def test_recorded_stage_keeps_each_call():
    ticks = iter([0.0, 0.5, 1.0, 3.0, 3.0, 3.25])
    timer = StageTimer(clock=lambda: next(ticks), record=("track",))
    for _ in range(2):
        with timer.stage("track"):
            pass
    with timer.stage("other"):
        pass
    assert timer.durations_s("track") == [0.5, 2.0]
    assert timer.durations_s("other") == []  # not recorded
    assert timer.totals_s()["track"] == 2.5


def test_numba_compiling_counts_a_first_compilation_only() -> None:
    import numba

    from mocapkit.timing import numba_compiling

    @numba.njit(cache=False)
    def twice(x: float) -> float:
        return 2.0 * x

    with numba_compiling(time.process_time) as first:
        assert twice(1.5) == 3.0
    assert first.kernels == 1 and first.seconds > 0.0
    with numba_compiling() as again:  # compiled already: nothing to compile
        assert twice(2.5) == 5.0
    assert (again.kernels, again.seconds) == (0, 0.0)
    with numba_compiling() as other:  # a new signature is a new kernel
        assert twice(2) == 4
    assert other.kernels == 1
