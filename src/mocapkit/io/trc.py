"""TRC marker files (the OpenSim / Motion Analysis Cortex tab-separated text format).

Layout (tab separated)::

    PathFileType  4  (X/Y/Z)  <file name>
    DataRate CameraRate NumFrames NumMarkers Units OrigDataRate OrigDataStartFrame OrigNumFrames
    50.00    50.00      1092      39         mm    50.00        1                  1092
    Frame#    Time   C7              CLAV ...
                     X1   Y1   Z1    X2   Y2   Z2 ...
    <optional blank line>
    1         0.000  ...

A missing sample is an empty field (``NaN`` is also accepted). Units ``mm``, ``cm`` or
``m`` are converted to mm on reading.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from mocapkit.errors import ConfigError, FormatError
from mocapkit.io.atomic import atomic_write
from mocapkit.io.files import read_text
from mocapkit.io.markers import MarkerData, check_marker_arrays, infer_rate_hz

#: Length units a TRC file may declare, with their size in mm.
TRC_UNITS_MM: dict[str, float] = {"mm": 1.0, "cm": 10.0, "m": 1000.0}
#: Decimals written per unit so that every unit keeps 1e-6 mm resolution.
_DECIMALS = {"mm": 6, "cm": 7, "m": 9}
_TIME_DECIMALS = 8
_REQUIRED_KEYS = ("DataRate", "NumFrames", "NumMarkers", "Units")


def _fields(line: str) -> list[str]:
    return line.rstrip("\r\n").split("\t")


def read_trc(path: str | os.PathLike[str]) -> MarkerData:
    """Read a TRC file into a `MarkerData` in mm.

    Time stamps come from the ``Time`` column; the rate from the ``DataRate`` header.

    Raises
    ------
    FormatError
        A missing or malformed header, unknown units, a marker count different from
        ``NumMarkers``, a frame count different from ``NumFrames``, a data row with the
        wrong number of columns or a non-numeric field (file, line and column named),
        or non-increasing time stamps.
    """
    p = Path(path)
    where = str(p)
    lines = read_text(p, "TRC marker file").splitlines(keepends=True)
    if len(lines) < 5:
        raise FormatError(
            f"{where}: expected at least 5 header lines (PathFileType, keys, values, marker "
            f"names, X/Y/Z), found {len(lines)} lines"
        )
    if not lines[0].startswith("PathFileType"):
        raise FormatError(
            f"{where} line 1: expected a TRC header starting with 'PathFileType', "
            f"found {lines[0].strip()[:40]!r}"
        )
    keys = [k.strip() for k in _fields(lines[1])]
    vals = [v.strip() for v in _fields(lines[2])]
    header = dict(zip(keys, vals))
    for req in _REQUIRED_KEYS:
        if req not in header or not header[req]:
            raise FormatError(
                f"{where} lines 2-3: expected header field {req!r} with a value, found keys "
                f"{[k for k in keys if k]}"
            )
    try:
        rate = float(header["DataRate"])
    except ValueError:
        raise FormatError(
            f"{where} line 3 (DataRate): expected a number, found {header['DataRate']!r}"
        ) from None
    if rate <= 0:  # NaN (not written) falls back on the time stamps below
        raise FormatError(
            f"{where} line 3 (DataRate): expected a positive rate in Hz, found {rate:g}"
        )
    n_frames_decl, n_markers_decl = 0, 0
    for key in ("NumFrames", "NumMarkers"):
        try:
            value = int(float(header[key]))
        except ValueError:
            raise FormatError(
                f"{where} line 3 ({key}): expected an integer, found {header[key]!r}"
            ) from None
        if key == "NumFrames":
            n_frames_decl = value
        else:
            n_markers_decl = value
    units = header["Units"].lower()
    if units not in TRC_UNITS_MM:
        raise FormatError(
            f"{where} line 3 (Units): expected one of {', '.join(TRC_UNITS_MM)}, "
            f"found {header['Units']!r}"
        )
    name_fields = _fields(lines[3])
    if [f.strip() for f in name_fields[:2]] != ["Frame#", "Time"]:
        raise FormatError(
            f"{where} line 4: expected the columns 'Frame#' and 'Time' then marker names, "
            f"found {name_fields[:2]}"
        )
    names = tuple(f.strip() for f in name_fields[2:] if f.strip())
    if len(names) != n_markers_decl:
        raise FormatError(
            f"{where} line 4: expected NumMarkers = {n_markers_decl} marker names, "
            f"found {len(names)}"
        )
    n_cols = 2 + 3 * len(names)
    col_names = ["Frame#", "Time"] + [f"{n} {a}" for n in names for a in "XYZ"]
    data_rows: list[tuple[int, list[str]]] = []
    for i, line in enumerate(lines[5:], start=6):
        if not line.strip():
            continue
        f = _fields(line)
        if len(f) == n_cols + 1 and not f[-1].strip():
            f = f[:-1]  # a trailing tab, written by some exporters
        if len(f) != n_cols:
            raise FormatError(
                f"{where} line {i}: expected {n_cols} tab-separated columns (Frame#, Time, "
                f"X/Y/Z for {len(names)} markers), found {len(f)}"
            )
        data_rows.append((i, f))
    if len(data_rows) != n_frames_decl:
        raise FormatError(
            f"{where}: header NumFrames = {n_frames_decl}, found {len(data_rows)} data rows"
        )
    t = np.empty(len(data_rows))
    values = np.empty((len(data_rows), n_cols - 2))
    for r, (line_no, f) in enumerate(data_rows):
        for c in range(1, n_cols):
            s = f[c].strip()
            if not s:
                if c == 1:
                    raise FormatError(
                        f"{where} line {line_no} column 2 (Time): expected a "
                        f"time stamp, found an empty field"
                    )
                v = math.nan
            else:
                try:
                    v = float(s)
                except ValueError:
                    raise FormatError(
                        f"{where} line {line_no} column {c + 1} ({col_names[c]}): expected a "
                        f"number or an empty field, found {f[c]!r}"
                    ) from None
            if c == 1:
                t[r] = v
            else:
                values[r, c - 2] = v
    if len(data_rows) > 1 and np.any(np.diff(t) <= 0):
        k = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise FormatError(
            f"{where} line {data_rows[k + 1][0]} column 2 (Time): expected strictly increasing "
            f"time stamps, found {t[k + 1]!r} after {t[k]!r}"
        )
    if not (math.isfinite(rate) and rate > 0):
        rate = infer_rate_hz(t, where)
    pos = values.reshape(len(data_rows), len(names), 3) * TRC_UNITS_MM[units]
    return MarkerData(time_s=t, names=names, positions_mm=pos, rate_hz=rate, source=where)


def write_trc(
    path: str | os.PathLike[str],
    time_s: ArrayLike,
    marker_names: Sequence[str],
    positions_mm: ArrayLike,
    units: str = "mm",
    *,
    rate_hz: float | None = None,
    rename: Mapping[str, str] | None = None,
    file_from_world: ArrayLike | None = None,
) -> None:
    """Write marker trajectories as a TRC file, atomically.

    For OpenSim or Pose2Sim, one call writes markers under their names in OpenSim's Y-up
    frame: ``write_trc(path, t, names, joints_mm, rename=DIRECT,
    file_from_world=OPENSIM_FROM_WORLD)`` (`mocapkit.io.openpose.DIRECT` maps canonical
    joints to BODY_25 names, `mocapkit.io.units.OPENSIM_FROM_WORLD`).

    Coordinates are printed with 1e-6 mm resolution whatever the units (6 decimals in
    mm, 9 in m), time with 8 decimals; NaN samples become empty fields.

    Parameters
    ----------
    path : path-like
    time_s : (T,) float array
        Strictly increasing time stamps in seconds.
    marker_names : sequence of str
        M unique names (no tabs or line breaks).
    positions_mm : (T, M, 3) float array
        Positions in mm; NaN for missing samples.
    units : {"mm", "cm", "m"}
        Units written in the file (values are converted from mm).
    rate_hz : float, optional
        DataRate/CameraRate written in the header; by default the inverse of the median
        time step (required when T < 2).
    rename : mapping, optional
        Name written for each marker; markers it does not name are left out.
    file_from_world : (3, 3) array, optional
        Rotation applied to every position before writing (the file's axes from ours).
    """
    where = str(path)
    if rename is not None or file_from_world is not None:
        names_in = list(marker_names)
        pos_in = np.asarray(positions_mm, dtype=float)
        if rename is not None:
            keep = [k for k, n in enumerate(names_in) if n in rename]
            if not keep:
                raise ConfigError(
                    f"{where}: rename: expected a map naming some of the markers "
                    f"{names_in[:5]}, found none of them in {sorted(rename)[:5]}"
                )
            names_in = [rename[names_in[k]] for k in keep]
            pos_in = pos_in[..., keep, :]
        if file_from_world is not None:
            rot = np.asarray(file_from_world, dtype=float)
            if rot.shape != (3, 3) or not np.allclose(rot @ rot.T, np.eye(3), atol=1e-9):
                raise ConfigError(
                    f"{where}: file_from_world: expected a 3x3 rotation, found {rot.tolist()}"
                )
            pos_in = pos_in @ rot.T
        marker_names, positions_mm = names_in, pos_in
    if units not in TRC_UNITS_MM:
        raise FormatError(
            f"{where}: units: expected one of {', '.join(TRC_UNITS_MM)}, found {units!r}"
        )
    t, names, pos = check_marker_arrays(time_s, marker_names, positions_mm, where)
    if rate_hz is None:
        if t.shape[0] < 2:
            raise ConfigError(f"{where}: rate_hz: required when fewer than 2 frames are written")
        rate = infer_rate_hz(t, where)
    else:
        rate = float(rate_hz)
        if not (math.isfinite(rate) and rate > 0):
            raise ConfigError(f"{where}: rate_hz: expected a positive rate, found {rate_hz}")
    scaled = (pos / TRC_UNITS_MM[units]).reshape(t.shape[0], -1)
    fmt = f"{{:.{_DECIMALS[units]}f}}"
    n_t, n_m = t.shape[0], len(names)
    head = [
        f"PathFileType\t4\t(X/Y/Z)\t{Path(path).name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\t"
        "OrigDataStartFrame\tOrigNumFrames",
        f"{rate:.6f}\t{rate:.6f}\t{n_t}\t{n_m}\t{units}\t{rate:.6f}\t1\t{n_t}",
        "\t".join(["Frame#", "Time"] + [f"{n}\t\t" for n in names]).rstrip("\t"),
        "\t".join(["", ""] + [f"{a}{k + 1}" for k in range(n_m) for a in "XYZ"]),
        "",
    ]
    with atomic_write(path, "w", newline="\n") as fh:
        fh.write("\n".join(head) + "\n")
        for i, (ti, row_arr) in enumerate(zip(t.tolist(), scaled)):
            cells = ["" if v != v else fmt.format(v) for v in row_arr.tolist()]  # row by row
            fh.write(f"{i + 1}\t{ti:.{_TIME_DECIMALS}f}\t" + "\t".join(cells) + "\n")
