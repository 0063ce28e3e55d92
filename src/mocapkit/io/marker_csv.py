"""The marker CSV format: one row per frame, ``time_s`` then ``NAME_x, NAME_y, NAME_z`` (mm).

Layout (comma separated, UTF-8)::

    time_s,LFHD_x,LFHD_y,LFHD_z,RFHD_x,RFHD_y,RFHD_z,...
    0.0,12.5,803.1,1601.2,,,,...

Coordinates are in mm; an empty cell (or ``nan``) is a missing sample.
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from mocapkit.errors import FormatError
from mocapkit.io.atomic import atomic_write
from mocapkit.io.files import read_text
from mocapkit.io.markers import MarkerData, check_marker_arrays, infer_rate_hz

_AXES = ("x", "y", "z")


def _format_float(v: float) -> str:
    # repr gives the shortest string that reads back to the same double: exact round trip.
    return "" if v != v else repr(v)


def write_markers_csv(
    path: str | os.PathLike[str],
    time_s: ArrayLike,
    marker_names: Sequence[str],
    positions_mm: ArrayLike,
) -> None:
    """Write marker trajectories as CSV (``time_s, NAME_x, NAME_y, NAME_z, ...``), atomically.

    Values are written with full double precision (exact round trip); NaN becomes an
    empty cell.

    Parameters
    ----------
    path : path-like
    time_s : (T,) float array
        Strictly increasing time stamps in seconds.
    marker_names : sequence of str
        M unique names (no commas, tabs or line breaks).
    positions_mm : (T, M, 3) float array
        Positions in mm; NaN for missing samples.
    """
    t, names, pos = check_marker_arrays(time_s, marker_names, positions_mm, str(path))
    header = ["time_s"] + [f"{n}_{a}" for n in names for a in _AXES]
    flat = pos.reshape(t.shape[0], -1).tolist()
    with atomic_write(path, "w", newline="") as fh:
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(header)
        for ti, row in zip(t.tolist(), flat):
            writer.writerow([repr(ti)] + [_format_float(v) for v in row])


def _parse_cell(text: str, where: str, line: int, col: int, column_name: str) -> float:
    s = text.strip()
    if not s:
        return math.nan
    try:
        return float(s)
    except ValueError:
        raise FormatError(
            f"{where} line {line} column {col} ({column_name}): expected a number or an empty "
            f"cell, found {text!r}"
        ) from None


def _lines(text: str) -> Iterator[str]:
    """The lines of ``text`` with their ends, one at a time (as ``io.StringIO(text)``
    gives them, without its copy of the whole text)."""
    start, n = 0, len(text)
    while start < n:
        end = text.find("\n", start)
        end = n if end < 0 else end + 1
        yield text[start:end]
        start = end


def read_markers_csv(path: str | os.PathLike[str]) -> MarkerData:
    """Read marker trajectories from a CSV file (see the module docstring for the layout).

    The sampling rate is the inverse of the median time step.

    Raises
    ------
    FormatError
        Missing ``time_s`` first column, a column not ending in ``_x``/``_y``/``_z``,
        an incomplete x/y/z triple, a row with the wrong number of cells, a non-numeric
        cell (file, line and column named), or non-increasing time stamps.
    """
    p = Path(path)
    where = str(p)
    text = read_text(p, "marker CSV")
    # rows are read one at a time into arrays sized by the line count: a list of every
    # row's cells held ~9x the file's size (78 MB for a 9 MB file of 2 minutes)
    records = enumerate(csv.reader(_lines(text)), start=1)
    # blank lines (e.g. a trailing newline) are dropped; line numbers kept for messages
    first = next(((i, r) for i, r in records if any(c.strip() for c in r)), None)
    if first is None:
        raise FormatError(
            f"{where}: expected a header row starting with 'time_s', found an empty file"
        )
    header_line, header = first
    header = [h.strip() for h in header]
    if header[0] != "time_s":
        raise FormatError(
            f"{where} line {header_line} column 1: expected the time column 'time_s', "
            f"found {header[0]!r}"
        )
    names: list[str] = []
    slots: dict[str, list[int]] = {}
    for col, h in enumerate(header[1:], start=1):
        stem, sep, axis = h.rpartition("_")
        if not sep or not stem or axis not in _AXES:
            raise FormatError(
                f"{where} line {header_line} column {col + 1}: expected a column named "
                f"NAME_x, NAME_y or NAME_z, found {h!r}"
            )
        if stem not in slots:
            slots[stem] = [-1, -1, -1]
            names.append(stem)
        k = _AXES.index(axis)
        if slots[stem][k] != -1:
            raise FormatError(
                f"{where} line {header_line} column {col + 1}: duplicate column {h!r}"
            )
        slots[stem][k] = col
    for n in names:
        lacking = [f"{n}_{a}" for a, c in zip(_AXES, slots[n]) if c == -1]
        if lacking:
            raise FormatError(
                f"{where} line {header_line}: marker {n!r} lacks column(s) {', '.join(lacking)}"
            )
    n_cols = len(header)
    capacity = text.count("\n") + 1  # at least the rows left
    t = np.empty(capacity)
    values = np.empty((capacity, n_cols - 1))
    lines = np.empty(capacity, dtype=np.int64)
    r = 0
    for line, row in records:
        if not any(c.strip() for c in row):
            continue
        if len(row) != n_cols:
            raise FormatError(
                f"{where} line {line}: expected {n_cols} cells as in the header, found {len(row)}"
            )
        lines[r] = line
        ts = row[0].strip()
        try:
            t[r] = float(ts)
        except ValueError:
            raise FormatError(
                f"{where} line {line} column 1 (time_s): expected a number, found {row[0]!r}"
            ) from None
        if not math.isfinite(t[r]):
            raise FormatError(
                f"{where} line {line} column 1 (time_s): expected a finite time, found {row[0]!r}"
            )
        try:
            # float() ignores surrounding blanks as _parse_cell's strip does; a cell it
            # cannot read goes through _parse_cell, which names it
            values[r] = [float(c) if c.strip() else math.nan for c in row[1:]]
        except ValueError:
            for c in range(1, n_cols):
                values[r, c - 1] = _parse_cell(row[c], where, line, c + 1, header[c])
        r += 1
    del text
    t, values = t[:r].copy(), values[:r]
    if r > 1 and np.any(np.diff(t) <= 0):
        k = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise FormatError(
            f"{where} line {lines[k + 1]} column 1 (time_s): expected time stamps strictly "
            f"increasing, found {t[k + 1]!r} after {t[k]!r}"
        )
    cols = np.array([slots[n] for n in names], dtype=np.int64).reshape(len(names), 3) - 1
    pos = values[:, cols] if names else np.empty((r, 0, 3))
    return MarkerData(
        time_s=t,
        names=tuple(names),
        positions_mm=pos,
        rate_hz=infer_rate_hz(t, where),
        source=where,
    )
