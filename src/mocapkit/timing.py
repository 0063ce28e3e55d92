"""Stage timer: wall time and call counts per named stage of a per-frame pipeline.

Trackers and runners wrap their stages (``with timer.stage("ik"): ...``); the benchmark
reads the totals. The default `NULL_TIMER` does nothing, so untimed runs pay only an
attribute look-up and an empty ``with`` per stage (well under a microsecond); a real
`StageTimer` adds two ``perf_counter`` calls (about 0.1 us each), nothing measurable
against a frame of several milliseconds.

`numba_compiling` measures the time Numba spends compiling kernels inside a block (a
first run after installing, before the kernels are in their on-disk cache), so a run's
speed line can say its time includes it.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from types import TracebackType
from typing import Any


class _Stage:
    """Context manager of one stage; re-used, so entering it allocates nothing."""

    __slots__ = ("_clock", "_start", "calls", "count", "durations_s", "name", "total_s")

    def __init__(
        self, name: str, clock: Callable[[], float] = time.perf_counter, record: bool = False
    ) -> None:
        self.name = name
        self._clock = clock
        self.total_s = 0.0
        self.calls = 0
        #: Items the stage counted (e.g. IK iterations), see `StageTimer.count`.
        self.count = 0
        self._start = 0.0
        #: Seconds of each call, when the timer records this stage (`StageTimer` ``record``).
        self.durations_s: list[float] | None = [] if record else None

    def __enter__(self) -> _Stage:
        self._start = self._clock()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        elapsed = self._clock() - self._start
        self.total_s += elapsed
        self.calls += 1
        if self.durations_s is not None:
            self.durations_s.append(elapsed)


class _NullStage:
    __slots__ = ()

    def __enter__(self) -> _NullStage:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        return None


_NULL_STAGE = _NullStage()


class StageTimer:
    """Accumulates time (s), calls and counts per stage name.

    A stage must not be nested in itself (one start time per name); different stages
    may nest (``"io"`` around a decode inside ``"track"``).

    Parameters
    ----------
    clock : callable
        ``time.perf_counter`` (wall time, default) or ``time.process_time`` (CPU time
        of the process: on a shared machine, the time the work itself took).
    record : tuple of str
        Stages whose every call's time is kept (`durations_s`: per-frame times).
    """

    enabled = True

    def __init__(
        self, clock: Callable[[], float] = time.perf_counter, record: tuple[str, ...] = ()
    ) -> None:
        self.clock = clock
        self.record = tuple(record)
        self._stages: dict[str, _Stage] = {}

    def stage(self, name: str) -> _Stage | _NullStage:
        """The context manager timing stage ``name``."""
        s = self._stages.get(name)
        if s is None:
            s = self._stages[name] = _Stage(name, self.clock, name in self.record)
        return s

    def durations_s(self, name: str) -> list[float]:
        """Seconds of each call of a recorded stage (empty if not recorded or not run)."""
        s = self._stages.get(name)
        return list(s.durations_s) if s is not None and s.durations_s is not None else []

    def count(self, name: str, n: int) -> None:
        """Add ``n`` items (iterations, solves) to stage ``name``'s count."""
        s = self._stages.get(name)
        if s is None:
            s = self._stages[name] = _Stage(name, self.clock)
        s.count += int(n)

    def totals_s(self) -> dict[str, float]:
        """Total seconds per stage."""
        return {n: s.total_s for n, s in self._stages.items()}

    def calls(self) -> dict[str, int]:
        """Number of timed calls per stage."""
        return {n: s.calls for n, s in self._stages.items()}

    def counts(self) -> dict[str, int]:
        """Counted items per stage (see `count`)."""
        return {n: s.count for n, s in self._stages.items()}

    def reset(self) -> None:
        """Forget every stage."""
        self._stages.clear()


class NullTimer(StageTimer):
    """A timer that records nothing (the default of trackers and runners)."""

    enabled = False

    def stage(self, name: str) -> _Stage | _NullStage:
        """A shared no-op context manager."""
        return _NULL_STAGE

    def count(self, name: str, n: int) -> None:
        """Ignored."""


#: The shared no-op timer.
NULL_TIMER = NullTimer()


@dataclass
class CompileTime:
    """Numba compilation inside a `numba_compiling` block: the kernels compiled (not
    loaded from their cache nor compiled before) and the seconds it took (nested
    compilations counted once)."""

    kernels: int = 0
    seconds: float = 0.0


@contextmanager
def numba_compiling(clock: Callable[[], float] = time.perf_counter) -> Iterator[CompileTime]:
    """The `CompileTime` of the block, on ``clock`` (that of the times it is set beside:
    ``time.process_time`` for CPU time)."""
    from numba.core import event

    found = CompileTime()

    class _Listener(event.Listener):
        depth = 0
        start = 0.0

        def on_start(self, ev: Any) -> None:
            if self.depth == 0:
                self.start = clock()
            self.depth += 1
            found.kernels += 1

        def on_end(self, ev: Any) -> None:
            self.depth -= 1
            if self.depth == 0:
                found.seconds += clock() - self.start

    with event.install_listener("numba:compile", _Listener()):
        yield found


__all__ = ["NULL_TIMER", "CompileTime", "NullTimer", "StageTimer", "numba_compiling"]
