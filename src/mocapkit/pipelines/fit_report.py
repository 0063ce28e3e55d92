"""End-of-run fit report: each marker set's distance to the model, like OpenSim IK's marker errors.

`summarize_fit` reads the per-frame ``FrameResult.fit`` figures (``"<set>_mm"``: an
effector's distance to its marker set) of a run and gives, per set, the mean and maximum
over the frames where the set was seen and the share of those frames further than a
threshold; `FitReport.lines` prints it and `FitReport.warnings` names the sets that miss
on too many frames (a wrong marker set, a wrong stature, a mislabelled marker).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mocapkit.errors import ConfigError
from mocapkit.tracking.base import FrameResult

#: Default distance (mm) above which a set counts as off the model on a frame.
WARN_MM = 30.0
#: Default share of seen frames above which a set off the model is warned about.
WARN_FRACTION = 0.05

#: Fit figures that are summaries over the sets, not sets.
_SUMMARY_FIGURES = ("rms_mm", "max_mm")


@dataclass(frozen=True)
class SetFit:
    """Fit of one effector over a run (mm; NaN when never seen).

    ``n_seen`` counts the frames with a target: its marker set seen or bridged, or a
    foot plant.
    """

    name: str
    n_seen: int
    mean_mm: float
    max_mm: float
    n_over: int

    @property
    def fraction_over(self) -> float:
        """Share of seen frames further than the threshold, in [0, 1]."""
        return self.n_over / self.n_seen if self.n_seen else 0.0


@dataclass(frozen=True)
class FitReport:
    """Per-set fit of a run with its warning thresholds."""

    sets: tuple[SetFit, ...]
    n_frames: int
    warn_mm: float
    warn_fraction: float

    @property
    def flagged(self) -> tuple[SetFit, ...]:
        """Sets further than ``warn_mm`` on more than ``warn_fraction`` of their frames."""
        return tuple(s for s in self.sets if s.n_seen and s.fraction_over > self.warn_fraction)

    def lines(self) -> list[str]:
        """The table for the terminal (the name column as wide as the longest name)."""
        width = max([len("effector"), 12, *(len(s.name) for s in self.sets)])
        out = [
            f"fit over {self.n_frames} frames (each effector's distance to its marker set "
            "or foot plant):",
            f"  {'effector':{width}s} {'frames':>6s} {'mean mm':>8s} {'max mm':>8s}"
            f"  > {self.warn_mm:g} mm",
        ]
        for s in self.sets:
            out.append(
                f"  {s.name:{width}s} {s.n_seen:6d} {s.mean_mm:8.1f} {s.max_mm:8.1f}  "
                f"{s.n_over} frames ({100 * s.fraction_over:.1f} %)"
            )
        return out

    def warnings(self) -> list[str]:
        """One loud line per flagged set."""
        return [
            f"WARNING: {s.name!r} is more than {self.warn_mm:g} mm from the model on "
            f"{100 * s.fraction_over:.1f} % of its {s.n_seen} frames (limit "
            f"{100 * self.warn_fraction:g} %; mean {s.mean_mm:.1f} mm, max {s.max_mm:.1f} mm): "
            "check the marker set, the subject's height and the lab axes"
            for s in self.flagged
        ]


def summarize_fit(
    results: Sequence[FrameResult], warn_mm: float = WARN_MM, warn_fraction: float = WARN_FRACTION
) -> FitReport:
    """Summarize the ``"<set>_mm"`` fit figures of a run.

    Parameters
    ----------
    results : sequence of FrameResult
    warn_mm : float
        Distance (mm) above which a set is off the model on a frame (> 0).
    warn_fraction : float
        Share of a set's seen frames in [0, 1] beyond which it is flagged.
    """
    if not (math.isfinite(warn_mm) and warn_mm > 0):
        raise ConfigError(f"--warn-mm: expected a distance > 0 mm, found {warn_mm}")
    if not (math.isfinite(warn_fraction) and 0.0 <= warn_fraction <= 1.0):
        raise ConfigError(f"--warn-fraction: expected a share in [0, 1], found {warn_fraction}")
    names: dict[str, None] = {}
    for r in results:
        names.update(
            dict.fromkeys(k for k in r.fit if k.endswith("_mm") and k not in _SUMMARY_FIGURES)
        )
    sets = []
    for key in names:
        d = np.array([r.fit.get(key, math.nan) for r in results], dtype=float)
        seen = d[np.isfinite(d)]
        sets.append(
            SetFit(
                key.removesuffix("_mm"),
                int(seen.size),
                float(seen.mean()) if seen.size else math.nan,
                float(seen.max()) if seen.size else math.nan,
                int(np.count_nonzero(seen > warn_mm)),
            )
        )
    return FitReport(tuple(sets), len(results), float(warn_mm), float(warn_fraction))


__all__ = ["WARN_FRACTION", "WARN_MM", "FitReport", "SetFit", "summarize_fit"]
