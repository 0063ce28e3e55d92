"""Labelled 3-D marker trajectories (`MarkerData`) and their occlusion statistics.

Positions are in mm with NaN for occluded samples (never zero-filled). Files are read
and written by the format modules (`mocapkit.io.c3d`, `mocapkit.io.trc`,
`mocapkit.io.marker_csv`), chosen by suffix in `mocapkit.io.marker_files`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import FormatError, ShapeError, UnknownNameError, unknown_name


def bare_marker_name(name: str) -> str:
    """The marker name without a Vicon ``Subject:`` prefix (``"Derrick:LFHD"`` -> ``"LFHD"``)."""
    return name.rsplit(":", 1)[-1]


def _readonly(a: NDArray[np.float64]) -> NDArray[np.float64]:
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class MarkerOcclusion:
    """Missing samples of one marker.

    Attributes
    ----------
    name : str
        Marker name as in the file.
    n_frames : int
        Number of frames in the recording.
    n_missing : int
        Frames where the marker is missing (any coordinate NaN).
    longest_gap_frames : int
        Longest run of consecutive missing frames.
    longest_gap_s : float
        Duration of that run: ``longest_gap_frames / rate_hz`` (samples times period).
    """

    name: str
    n_frames: int
    n_missing: int
    longest_gap_frames: int
    longest_gap_s: float

    @property
    def fraction_missing(self) -> float:
        """Share of frames where the marker is missing, in [0, 1]."""
        return self.n_missing / self.n_frames if self.n_frames else 0.0


@dataclass(frozen=True)
class OcclusionReport:
    """Per-marker occlusion statistics of a `MarkerData` (see `MarkerData.occlusions`)."""

    source: str
    rate_hz: float
    n_frames: int
    markers: tuple[MarkerOcclusion, ...]

    @property
    def total_missing(self) -> int:
        """Missing marker samples summed over all markers."""
        return sum(m.n_missing for m in self.markers)

    def get(self, name: str) -> MarkerOcclusion:
        """The entry of the marker called exactly ``name``."""
        for m in self.markers:
            if m.name == name:
                return m
        raise unknown_name("marker", name, (m.name for m in self.markers), self.source)

    def summary(self) -> str:
        """A readable table: one line per marker with missing samples, worst first."""
        n_m = len(self.markers)
        complete = sum(1 for m in self.markers if m.n_missing == 0)
        lines = [
            f"{self.source}: {n_m} markers x {self.n_frames} frames at {self.rate_hz:g} Hz; "
            f"{self.total_missing} missing samples; {complete}/{n_m} markers complete"
        ]
        gappy = sorted(
            (m for m in self.markers if m.n_missing),
            key=lambda m: (-m.n_missing, m.name),
        )
        if gappy:
            width = max(len(m.name) for m in gappy)
            lines.append(f"  {'marker':<{width}}  missing  (%)     longest gap")
            for m in gappy:
                lines.append(
                    f"  {m.name:<{width}}  {m.n_missing:7d}  {100 * m.fraction_missing:5.1f}  "
                    f"{m.longest_gap_frames:6d} frames = {m.longest_gap_s:.3f} s"
                )
        return "\n".join(lines)


def true_runs(mask: ArrayLike) -> list[tuple[int, int]]:
    """The runs of True in a 1-D mask, in order, as half-open ``(start, stop)`` indices."""
    m = np.asarray(mask, dtype=bool).astype(np.int8)
    if m.ndim != 1:
        raise ShapeError(f"true_runs: expected a 1-D mask, found shape {m.shape}")
    edges = np.flatnonzero(np.diff(np.concatenate(([0], m, [0]))))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def longest_true_run(mask: NDArray[np.bool_]) -> NDArray[np.int64]:
    """Length of the longest run of True along axis 0.

    Parameters
    ----------
    mask : (T, ...) bool array

    Returns
    -------
    (...) int array
    """
    m = np.asarray(mask, dtype=bool)
    t = m.shape[0]
    flat = m.reshape(t, -1)
    out = np.zeros(flat.shape[1], dtype=np.int64)
    for j in range(flat.shape[1]):
        runs = true_runs(flat[:, j])
        if runs:
            out[j] = max(b - a for a, b in runs)
    return out.reshape(m.shape[1:])


@dataclass(frozen=True, eq=False)
class MarkerData:
    """Labelled marker trajectories of one recording.

    Arrays are stored read-only copies; the object is immutable.

    Attributes
    ----------
    time_s : (T,) float array
        Time stamps in seconds, strictly increasing.
    names : tuple of str
        The M marker names as in the file (a Vicon ``Subject:`` prefix is kept).
    positions_mm : (T, M, 3) float array
        Marker positions in the file's lab frame, in mm; NaN where a marker is missing.
    rate_hz : float
        Sampling rate in Hz.
    source : str
        Where the data came from (file path), used in error messages.
    """

    time_s: NDArray[np.float64]
    names: tuple[str, ...]
    positions_mm: NDArray[np.float64]
    rate_hz: float
    source: str = "<memory>"
    _lookup: dict[str, int] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        src = self.source
        time_s = np.array(self.time_s, dtype=np.float64)
        pos = np.array(self.positions_mm, dtype=np.float64)
        names = tuple(self.names)
        if time_s.ndim != 1:
            raise ShapeError(f"{src}: time_s: expected shape (T,), found {time_s.shape}")
        t = time_s.shape[0]
        if pos.ndim != 3 or pos.shape[0] != t or pos.shape[2] != 3:
            raise ShapeError(
                f"{src}: positions_mm: expected shape (T={t}, M, 3), found {pos.shape}"
            )
        if len(names) != pos.shape[1]:
            raise ShapeError(
                f"{src}: names: expected {pos.shape[1]} names (one per marker column), "
                f"found {len(names)}"
            )
        for n in names:
            if not isinstance(n, str) or not n.strip():
                raise FormatError(f"{src}: marker names: expected non-empty strings, found {n!r}")
        seen: dict[str, int] = {}
        for i, n in enumerate(names):
            if n in seen:
                raise FormatError(
                    f"{src}: marker names: expected unique names, found {n!r} at columns "
                    f"{seen[n]} and {i}"
                )
            seen[n] = i
        if not np.all(np.isfinite(time_s)):
            bad = int(np.flatnonzero(~np.isfinite(time_s))[0])
            raise FormatError(
                f"{src}: time stamps: expected finite values, found {time_s[bad]} at frame {bad}"
            )
        if t > 1:
            steps = np.diff(time_s)
            if np.any(steps <= 0):
                k = int(np.flatnonzero(steps <= 0)[0])
                raise FormatError(
                    f"{src}: time stamps: expected strictly increasing values, found "
                    f"{time_s[k + 1]!r} s at frame {k + 1} after {time_s[k]!r} s at frame {k}"
                )
        if np.isinf(pos).any():
            raise FormatError(f"{src}: positions_mm: expected finite values or NaN, found inf")
        rate = float(self.rate_hz)
        if not math.isfinite(rate) or rate <= 0:
            raise FormatError(f"{src}: rate_hz: expected a positive sampling rate, found {rate}")
        object.__setattr__(self, "time_s", _readonly(time_s))
        object.__setattr__(self, "positions_mm", _readonly(pos))
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "rate_hz", rate)
        object.__setattr__(self, "source", str(src))
        object.__setattr__(self, "_lookup", seen)

    # ------------------------------------------------------------------ sizes
    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.positions_mm.shape[0])

    @property
    def n_markers(self) -> int:
        """Number of markers M."""
        return int(self.positions_mm.shape[1])

    @property
    def missing(self) -> NDArray[np.bool_]:
        """(T, M) bool: True where a marker sample is missing (any coordinate NaN)."""
        return np.asarray(np.isnan(self.positions_mm).any(axis=2), dtype=bool)

    # ------------------------------------------------------------------ names
    def index(self, name: str) -> int:
        """Column of a marker, matched with or without a Vicon ``Subject:`` prefix.

        An exact match wins. Otherwise a bare name (``"LFHD"``) matches a prefixed one
        (``"Derrick:LFHD"``) when exactly one subject has it.

        Raises
        ------
        UnknownNameError
            Unknown name (the message lists the valid names), or a bare name that
            several subjects share (the message lists the candidates).
        """
        if name in self._lookup:
            return self._lookup[name]
        bare = bare_marker_name(name)
        hits = [i for i, n in enumerate(self.names) if bare_marker_name(n) == bare]
        if ":" in name:
            # A prefixed query matches only itself, or a bare file name when the file has
            # no prefixes at all (e.g. a TRC exported without subject names).
            hits = [i for i in hits if ":" not in self.names[i]]
        if len(hits) == 1:
            return hits[0]
        if len(hits) > 1:
            listed = ", ".join(self.names[i] for i in hits)
            raise UnknownNameError(
                f"ambiguous marker {name!r} in {self.source}: matches {listed}; "
                f"give the full 'Subject:Marker' name"
            )
        raise unknown_name("marker", name, self.names, self.source)

    def indices(self, names: Iterable[str]) -> list[int]:
        """Columns of several markers (see `index`)."""
        if isinstance(names, str):
            names = [names]
        return [self.index(n) for n in names]

    def trajectory(self, name: str) -> NDArray[np.float64]:
        """(T, 3) read-only positions of one marker in mm (NaN where missing)."""
        return self.positions_mm[:, self.index(name), :]

    def select(self, names: Iterable[str]) -> MarkerData:
        """A new `MarkerData` with the given markers, in the given order.

        Names are matched as in `index`; the result keeps the names as in the file.
        """
        idx = self.indices(names)
        return MarkerData(
            time_s=self.time_s,
            names=tuple(self.names[i] for i in idx),
            positions_mm=self.positions_mm[:, idx, :],
            rate_hz=self.rate_hz,
            source=self.source,
        )

    # ------------------------------------------------------------------ reports
    def occlusions(self) -> OcclusionReport:
        """Per-marker count of missing samples and longest gap (frames and seconds)."""
        miss = self.missing
        counts = miss.sum(axis=0)
        longest = longest_true_run(miss)
        return OcclusionReport(
            source=self.source,
            rate_hz=self.rate_hz,
            n_frames=self.n_frames,
            markers=tuple(
                MarkerOcclusion(
                    name=n,
                    n_frames=self.n_frames,
                    n_missing=int(counts[i]),
                    longest_gap_frames=int(longest[i]),
                    longest_gap_s=float(longest[i]) / self.rate_hz,
                )
                for i, n in enumerate(self.names)
            ),
        )

    def summary(self) -> str:
        """Readable description: size, rate, duration, and the occlusion table."""
        dur = float(self.time_s[-1] - self.time_s[0]) if self.n_frames else 0.0
        head = (
            f"time {self.time_s[0]:.4f}..{self.time_s[-1]:.4f} s ({dur:.3f} s)"
            if self.n_frames
            else "no frames"
        )
        return f"{head}\n{self.occlusions().summary()}"


# ---------------------------------------------------------------------- helpers
def infer_rate_hz(time_s: NDArray[np.float64], where: str) -> float:
    """Sampling rate from time stamps: the inverse of the median step.

    Raises `FormatError` naming ``where`` when fewer than two frames are given.
    """
    if time_s.shape[0] < 2:
        raise FormatError(
            f"{where}: time_s: expected at least 2 frames to infer the sampling rate, "
            f"found {time_s.shape[0]}"
        )
    step = float(np.median(np.diff(time_s)))
    if not step > 0:
        raise FormatError(
            f"{where}: time_s: expected increasing time stamps, found median step {step}"
        )
    return 1.0 / step


def check_marker_arrays(
    time_s: ArrayLike, marker_names: Sequence[str], positions_mm: ArrayLike, where: str
) -> tuple[NDArray[np.float64], tuple[str, ...], NDArray[np.float64]]:
    """Validate writer inputs; returns float arrays and the names as a tuple.

    Raises `ShapeError` for wrong shapes and `FormatError` for names that cannot be
    written (empty, duplicated, or holding separators or line breaks).
    """
    t = np.asarray(time_s, dtype=np.float64)
    pos = np.asarray(positions_mm, dtype=np.float64)
    if isinstance(marker_names, str):
        raise ShapeError(f"{where}: marker_names: expected a sequence of names, found a string")
    names = tuple(marker_names)
    if t.ndim != 1:
        raise ShapeError(f"{where}: time_s: expected shape (T,), found {t.shape}")
    if pos.shape != (t.shape[0], len(names), 3):
        raise ShapeError(
            f"{where}: positions_mm: expected shape (T={t.shape[0]}, M={len(names)}, 3), "
            f"found {pos.shape}"
        )
    # Reuse MarkerData's checks (unique non-empty names, increasing finite time, no inf).
    MarkerData(time_s=t, names=names, positions_mm=pos, rate_hz=1.0, source=where)
    for n in names:
        if any(c in n for c in "\t\r\n,") or n != n.strip():
            raise FormatError(
                f"{where}: marker name {n!r}: expected no tab, comma, line break or "
                f"surrounding spaces"
            )
    return t, names, pos


#: Largest marker coordinate (mm) a recording may hold: 100 m from the lab origin, far
#: beyond any capture volume; larger finite values are glitches or unit mistakes.
MAX_MARKER_COORDINATE_MM = 100_000.0
#: Largest marker speed (mm/s) between two consecutive samples: 100 m/s, several times
#: what a hand or a racket reaches (the real serve and sprint takes peak near 14 m/s).
MAX_MARKER_SPEED_MM_PER_S = 100_000.0


def check_plausible_markers(markers: MarkerData, speeds: bool = True) -> None:
    """Refuse finite marker values no body can produce (at the boundary where they enter).

    Every marker reader checks the coordinates (`mocapkit.io.marker_files.read_markers`);
    the speeds are checked where the markers are taken as a body's motion (a session, the
    hybrid tracker's raw marker files), since a marker file may hold other point clouds.

    Parameters
    ----------
    markers : MarkerData
    speeds : bool
        Also check the speed between consecutive samples.

    Raises
    ------
    FormatError
        Naming the file, the marker and the time of the first coordinate beyond
        `MAX_MARKER_COORDINATE_MM` or step faster than `MAX_MARKER_SPEED_MM_PER_S`.
    """
    pos = markers.positions_mm
    with np.errstate(invalid="ignore"):
        far = np.abs(pos) > MAX_MARKER_COORDINATE_MM
    if np.any(far):
        f, m, _ = (int(i) for i in np.argwhere(far)[0])
        raise FormatError(
            f"{markers.source}: marker {markers.names[m]!r} at {markers.time_s[f]:.4f} s: "
            f"expected coordinates within +-{MAX_MARKER_COORDINATE_MM:.0f} mm, found "
            f"{pos[f, m].tolist()}"
        )
    if not speeds or markers.n_frames < 2:
        return
    step = np.linalg.norm(np.diff(pos, axis=0), axis=2)
    speed = step / np.diff(markers.time_s)[:, None]
    with np.errstate(invalid="ignore"):
        fast = speed > MAX_MARKER_SPEED_MM_PER_S
    if np.any(fast):
        f, m = (int(i) for i in np.argwhere(fast)[0])
        raise FormatError(
            f"{markers.source}: marker {markers.names[m]!r} at {markers.time_s[f + 1]:.4f} s: "
            f"expected a speed below {MAX_MARKER_SPEED_MM_PER_S:.0f} mm/s, found "
            f"{speed[f, m]:.0f} mm/s (a jump of {step[f, m]:.0f} mm)"
        )
