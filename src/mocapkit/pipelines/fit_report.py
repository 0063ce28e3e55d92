"""End-of-run fit report: each marker set's distance to the model, like OpenSim IK's marker errors.

`summarize_fit` reads the per-frame ``FrameResult.fit`` figures (``"<set>_mm"``: an
effector's distance to its marker set) of a run and gives, per set, the mean and maximum
over the frames where the set was seen and the share of those frames further than a
threshold; `FitReport.lines` prints it and `FitReport.warnings` names the sets that miss
on too many frames (a wrong marker set, a wrong stature, a mislabelled marker).

`implausible_spans` reads fit.csv's plausibility columns (every tracker's,
`mocapkit.eval.plausibility`) back into spans of frames where a joint moved faster than
its inputs allow or a bone rolled too fast, and `implausible_warnings` says where, the
worst first.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import numpy as np

from mocapkit.errors import ConfigError
from mocapkit.io.markers import true_runs
from mocapkit.pipelines.run import FIT_FILE, ROLL_LIMIT_DEG_S, read_fit_csv
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


#: Spans of each kind that an end-of-run warning lists (`worst_spans_lines`).
SHOWN_SPANS = 3

_Span = TypeVar("_Span")


def span_when(start_s: float, end_s: float, n_frames: int) -> str:
    """When a span of flagged frames happened: ``at 1.00-1.10 s (2 frames)``, or
    ``at 2.00 s`` for one frame."""
    if n_frames == 1:
        return f"at {start_s:.2f} s"
    return f"at {start_s:.2f}-{end_s:.2f} s ({n_frames} frames)"


def worst_spans_lines(
    header: str,
    groups: Sequence[Sequence[_Span]],
    severity: Callable[[_Span], float],
    shown: int = SHOWN_SPANS,
) -> list[str]:
    """An end-of-run warning about spans of flagged frames: ``header``, the ``shown``
    worst spans of each group (largest ``severity``) indented, then how many more
    (fit.csv holds them all); nothing without spans."""
    if not any(groups):
        return []
    worst = [s for g in groups for s in sorted(g, key=lambda s: -severity(s))[:shown]]
    out = [header, *(f"  {s}" for s in worst)]
    n = sum(len(g) for g in groups)
    if n > len(worst):
        out.append(f"  ... and {n - len(worst)} more (fit.csv)")
    return out


@dataclass(frozen=True)
class ImplausibleSpan:
    """Consecutive frames of implausible motion: joints faster than their inputs allow
    (``kind`` ``"joint"``) or bones rolling faster than the limit (``"roll"``).

    ``name``, ``value`` (mm/s, or deg/s for a roll) and ``input_mm_s`` (the speed of the
    inputs near the joint; NaN for a roll) are those of the span's worst frame, the one
    with the largest ``ratio`` of speed to allowed speed.
    """

    kind: str
    name: str
    start_s: float
    end_s: float
    n_frames: int
    value: float
    input_mm_s: float
    ratio: float

    def __str__(self) -> str:
        when = span_when(self.start_s, self.end_s, self.n_frames)
        if self.kind == "roll":
            limit = self.value / self.ratio
            return (
                f"the {self.name} bone rolls {self.value:.0f} deg/s about its axis {when} "
                f"(limit {limit:.0f} deg/s)"
            )
        return (
            f"{self.name} moves {self.value / 1000:.1f} m/s {when} where the inputs near it "
            f"move at most {self.input_mm_s / 1000:.1f} m/s"
        )


def implausible_spans(
    rows: Sequence[Mapping[str, str]], columns: Mapping[str, np.ndarray]
) -> list[ImplausibleSpan]:
    """The spans of fit.csv's frames with implausible joints or rolls, in time order.

    Parameters
    ----------
    rows, columns
        fit.csv as `mocapkit.pipelines.run.read_fit_csv` returns it; without the
        plausibility columns (an older result) there are no spans.
    """
    t = np.asarray(columns["time_s"], dtype=float)
    kinds = (
        ("joint", "implausible_joints", "worst_joint", "worst_joint_speed_mm_per_s"),
        ("roll", "implausible_rolls", "worst_roll_bone", "worst_roll_deg_per_s"),
    )
    out = []
    for kind, count, name, value in kinds:
        if count not in columns:
            continue
        flag = np.nan_to_num(np.asarray(columns[count], dtype=float)) > 0
        v = np.asarray(columns[value], dtype=float)
        if kind == "joint":
            ratio = np.asarray(columns["worst_speed_ratio"], dtype=float)
            inp = np.asarray(columns["worst_input_speed_mm_per_s"], dtype=float)
        else:
            ratio, inp = v / ROLL_LIMIT_DEG_S, np.full(t.shape, np.nan)
        for a, b in true_runs(flag):
            i = a + int(np.nanargmax(ratio[a:b]))
            out.append(
                ImplausibleSpan(
                    kind,
                    rows[i][name],
                    float(t[a]),
                    float(t[b - 1]),
                    int(b - a),
                    float(v[i]),
                    float(inp[i]),
                    float(ratio[i]),
                )
            )
    return sorted(out, key=lambda s: (s.start_s, s.kind))


def implausible_spans_in_folder(result_dir: str | os.PathLike[str]) -> list[ImplausibleSpan]:
    """`implausible_spans` of a result folder's fit.csv."""
    rows, columns = read_fit_csv(Path(result_dir) / FIT_FILE)
    return implausible_spans(rows, columns)


def implausible_warnings(spans: Sequence[ImplausibleSpan], shown: int = SHOWN_SPANS) -> list[str]:
    """The end-of-run warning about implausible motion: a count, the ``shown`` worst
    spans of joints and of rolls (largest ratio to the allowed speed), then how many
    more; nothing without spans."""
    groups = [[s for s in spans if s.kind == kind] for kind in ("joint", "roll")]
    n_joint, n_roll = (sum(s.n_frames for s in g) for g in groups)
    frames = f"{n_joint + n_roll} frame{'s' if n_joint + n_roll != 1 else ''}"
    if n_joint and n_roll:  # a frame may have both: counted apart, not summed
        frames = f"{n_joint} frames of joints, {n_roll} of rolls"
    header = (
        f"WARNING: implausible motion in {len(spans)} span{'s' if len(spans) != 1 else ''} "
        f"({frames}): faster than the inputs show (fit.csv's implausible_joints, "
        "implausible_rolls); check those frames before using them"
    )
    return worst_spans_lines(header, groups, lambda s: s.ratio, shown)


def warn_implausible(result_dir: str | os.PathLike[str]) -> None:
    """Print `implausible_warnings` of a result folder to stderr (the end of a run)."""
    for line in implausible_warnings(implausible_spans_in_folder(result_dir)):
        print(line, file=sys.stderr)


__all__ = [
    "SHOWN_SPANS",
    "WARN_FRACTION",
    "WARN_MM",
    "FitReport",
    "ImplausibleSpan",
    "SetFit",
    "implausible_spans",
    "implausible_spans_in_folder",
    "implausible_warnings",
    "span_when",
    "summarize_fit",
    "warn_implausible",
    "worst_spans_lines",
]
