"""Progress reporting for long work: frames done, rate and ETA on a terminal, silence elsewhere."""

from __future__ import annotations

import contextlib
import contextvars
import sys
import time
from collections.abc import Iterator
from typing import TextIO

# Set inside work that runs beside other work (a batch's takes on Dask worker threads),
# whose own meters would garble the one line of the run that drives them. A context
# variable, so one worker thread's silence does not reach its neighbours.
_SILENCED: contextvars.ContextVar[bool] = contextvars.ContextVar("mocapkit_progress_silenced")


@contextlib.contextmanager
def silenced() -> Iterator[None]:
    """Within the block (this thread or task only), every new `Progress` stays quiet."""
    token = _SILENCED.set(True)
    try:
        yield
    finally:
        _SILENCED.reset(token)


class Progress:
    """A single-line progress meter written to a stream only when it is a terminal.

    Parameters
    ----------
    total : int
        Number of items (frames) expected.
    label : str
        Short description shown before the counts.
    stream : file-like, optional
        Where to write; defaults to ``sys.stderr``. Nothing is written unless
        ``stream.isatty()`` is true, so pipes, logs and tests stay quiet.
    min_interval_s : float
        Minimum time between two redraws.
    unit : str
        What the items are (``frames``, ``takes``).
    rate_unit : str
        Unit of the rate shown; ``rate_scale`` converts items per second into it
        (``fps`` and 1 for frames; ``takes/min`` and 60 for a batch's takes).
    rate_scale : float

    Attributes
    ----------
    status : str
        Extra text shown after the counts (e.g. ``"1 failed, 3 remaining"``); set it
        before `update`.
    """

    def __init__(
        self,
        total: int,
        label: str = "",
        stream: TextIO | None = None,
        min_interval_s: float = 0.2,
        unit: str = "frames",
        rate_unit: str = "fps",
        rate_scale: float = 1.0,
    ) -> None:
        self.total = max(int(total), 0)
        self.label = label
        self.stream = sys.stderr if stream is None else stream
        isatty = getattr(self.stream, "isatty", None)
        self.enabled = bool(isatty and isatty()) and not _SILENCED.get(False)
        self.min_interval_s = min_interval_s
        self.unit = unit
        self.rate_unit = rate_unit
        self.rate_scale = rate_scale
        self.status = ""
        self.done = 0
        self._start = time.perf_counter()
        self._last_draw = 0.0

    def update(self, n: int = 1) -> None:
        """Record ``n`` more items done and redraw if enough time has passed."""
        self.done += n
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self._last_draw >= self.min_interval_s or self.done >= self.total:
            self._last_draw = now
            self.stream.write("\r" + self.line(now) + "\033[K")
            self.stream.flush()

    def line(self, now: float | None = None) -> str:
        """The status text: ``label done/total frames, X fps, ETA Ys`` (with `status`
        after the counts when set)."""
        now = time.perf_counter() if now is None else now
        elapsed = max(now - self._start, 1e-9)
        rate = self.done / elapsed
        remaining = (self.total - self.done) / rate if rate > 0 else float("inf")
        eta = f"{remaining:5.1f}s" if remaining != float("inf") else "  ?"
        status = f", {self.status}" if self.status else ""
        return (
            f"{self.label} {self.done}/{self.total} {self.unit}{status}, "
            f"{rate * self.rate_scale:6.1f} {self.rate_unit}, ETA {eta}"
        )

    def close(self) -> None:
        """Finish the line on a terminal."""
        if self.enabled:
            self.stream.write("\r" + self.line() + "\033[K\n")
            self.stream.flush()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
