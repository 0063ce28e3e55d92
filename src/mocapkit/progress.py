"""Progress reporting for long work: frames done, rate and ETA on a terminal, silence elsewhere."""

from __future__ import annotations

import sys
import time
from typing import TextIO


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
    """

    def __init__(
        self,
        total: int,
        label: str = "",
        stream: TextIO | None = None,
        min_interval_s: float = 0.2,
    ) -> None:
        self.total = max(int(total), 0)
        self.label = label
        self.stream = sys.stderr if stream is None else stream
        isatty = getattr(self.stream, "isatty", None)
        self.enabled = bool(isatty and isatty())
        self.min_interval_s = min_interval_s
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
        """The status text: ``label done/total frames, X fps, ETA Ys``."""
        now = time.perf_counter() if now is None else now
        elapsed = max(now - self._start, 1e-9)
        rate = self.done / elapsed
        remaining = (self.total - self.done) / rate if rate > 0 else float("inf")
        eta = f"{remaining:5.1f}s" if remaining != float("inf") else "  ?"
        return f"{self.label} {self.done}/{self.total} frames, {rate:6.1f} fps, ETA {eta}"

    def close(self) -> None:
        """Finish the line on a terminal."""
        if self.enabled:
            self.stream.write("\r" + self.line() + "\033[K\n")
            self.stream.flush()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
