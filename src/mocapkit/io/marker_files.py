"""Marker files by suffix: `read_markers` (C3D, TRC, CSV) and `write_markers` (TRC, CSV)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from mocapkit.errors import FormatError
from mocapkit.io.c3d import read_c3d
from mocapkit.io.files import require_file
from mocapkit.io.marker_csv import read_markers_csv, write_markers_csv
from mocapkit.io.markers import MarkerData, check_plausible_markers
from mocapkit.io.trc import read_trc, write_trc

#: File extensions `read_markers` understands (lower case, with the dot).
SUPPORTED_MARKER_EXTENSIONS: tuple[str, ...] = (".c3d", ".trc", ".csv")
#: File extensions `write_markers` can write.
WRITABLE_MARKER_EXTENSIONS: tuple[str, ...] = (".trc", ".csv")


def read_markers(path: str | os.PathLike[str]) -> MarkerData:
    """Read labelled marker trajectories from a C3D, TRC or CSV file.

    Parameters
    ----------
    path : path-like
        File whose extension (case-insensitive) is one of `SUPPORTED_MARKER_EXTENSIONS`.

    Returns
    -------
    MarkerData
        Positions in mm, NaN for missing samples.

    Raises
    ------
    FormatError
        Unsupported extension, a file that does not follow its format, or coordinates
        beyond any lab (`mocapkit.io.markers.check_plausible_markers`).
    FileNotFoundError
        The file does not exist.
    """
    p = Path(path)
    ext = p.suffix.lower()
    if ext not in SUPPORTED_MARKER_EXTENSIONS:
        raise FormatError(
            f"{p}: unsupported marker file extension {p.suffix!r}; expected one of "
            f"{', '.join(SUPPORTED_MARKER_EXTENSIONS)}"
        )
    require_file(p, "marker file", missing=FileNotFoundError)
    if ext == ".c3d":
        markers = read_c3d(p)  # ezc3d itself is imported only when a C3D is read
    elif ext == ".trc":
        markers = read_trc(p)
    else:
        markers = read_markers_csv(p)
    check_plausible_markers(markers, speeds=False)
    return markers


def write_markers(path: str | os.PathLike[str], markers: MarkerData, **kwargs: Any) -> None:
    """Write a `MarkerData` as TRC or CSV (chosen by extension), atomically.

    Extra keyword arguments go to `mocapkit.io.trc.write_trc` (e.g. ``units="m"``).
    """
    p = Path(path)
    ext = p.suffix.lower()
    if ext not in WRITABLE_MARKER_EXTENSIONS:
        raise FormatError(
            f"{p}: cannot write markers with extension {p.suffix!r}; expected one of "
            f"{', '.join(WRITABLE_MARKER_EXTENSIONS)}"
        )
    if ext == ".trc":
        write_trc(
            p,
            markers.time_s,
            markers.names,
            markers.positions_mm,
            rate_hz=markers.rate_hz,
            **kwargs,
        )
    else:
        if kwargs:
            raise TypeError(f"write_markers: CSV takes no options, found {sorted(kwargs)}")
        write_markers_csv(p, markers.time_s, markers.names, markers.positions_mm)
