"""Settings of `mocapkit live` and `mocapkit replay`, light to import (the CLI shows them)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from mocapkit.errors import ConfigError

#: Default prefix of the replayed streams' names.
STREAM_PREFIX = "mocapkit_"


@dataclass(frozen=True)
class LiveConfig:
    """Settings of the live loop (defaults stated once; the CLI shows them).

    Attributes
    ----------
    match_wait_s : float
        Longest wait of a frame for a partner sample that is due but not yet received
        (the wait ends as soon as it, or a later one, arrives).
    lost_after_s : float
        An input silent this long (wall clock) is lost: the run stops.
    max_behind_s : float
        A frame already this old (LSL clock) when its turn comes is dropped (counted) so
        that the output keeps up; inf: track every frame.
    connect_timeout_s : float
        How long to wait for each named LSL stream to appear, and then for its first
        sample.
    mono_lag : int
        The mono tracker's online Viterbi lag (frames; latency lag + smoother lag).
    """

    match_wait_s: float = 0.010
    lost_after_s: float = 3.0
    max_behind_s: float = 0.5
    connect_timeout_s: float = 10.0
    mono_lag: int = 10

    def __post_init__(self) -> None:
        for name in ("match_wait_s", "lost_after_s", "max_behind_s", "connect_timeout_s"):
            v = getattr(self, name)
            if not v >= 0 or (math.isinf(v) and name != "max_behind_s"):
                raise ConfigError(f"LiveConfig.{name}: expected a time >= 0 s, found {v}")
        if self.mono_lag < 1:
            raise ConfigError(f"LiveConfig.mono_lag: expected >= 1 frame, found {self.mono_lag}")
