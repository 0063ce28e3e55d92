"""C3D marker files (the biomechanics binary standard), read through the maintained ``ezc3d``.

Only the POINT section is used (marker trajectories); analog channels are ignored.
What is taken from the file:

- labels: ``POINT:LABELS`` then ``LABELS2``, ``LABELS3``... (C3D parameters hold at most
  255 entries, so larger marker sets continue in the numbered parameters); the first
  ``POINT:USED`` labels name the point columns, stripped of padding blanks.
- rate: ``POINT:RATE`` (the header's frame rate if the parameter is absent).
- units: ``POINT:UNITS`` (``mm``, ``cm`` or ``m``); converted to mm. An empty or absent
  UNITS is read as mm, the C3D default.
- time: ``time_s[i] = (first_frame + i) / rate`` where ``first_frame`` is the 0-based
  index of the first stored frame: ``TRIAL:ACTUAL_START_FIELD - 1`` when a Vicon TRIAL
  group exists (it is a 32-bit value split in two 16-bit words, so it survives trials
  longer than the header's 16-bit field), else the header's first frame.
- occlusion: a sample is missing when its residual is negative (the C3D convention for
  an invalid point; ezc3d then already returns NaN) or when it is exactly (0, 0, 0),
  which some exporters write for gaps. Missing samples become NaN, never zeros.
- truncation: ezc3d reads a truncated file without complaint (and rewrites its frame
  counts to what it read), so the frame range in the file's own header is checked
  against the frames actually read.
"""

from __future__ import annotations

import os
import struct
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.errors import FormatError
from mocapkit.io.files import require_file
from mocapkit.io.markers import MarkerData

#: Length units a C3D ``POINT:UNITS`` may hold, with their size in mm.
C3D_UNITS_MM: dict[str, float] = {"mm": 1.0, "cm": 10.0, "m": 1000.0}


def _param(c3d: Any, group: str, name: str) -> Any | None:
    try:
        return c3d["parameters"][group][name]["value"]
    except KeyError:
        return None


def _labels(c3d: Any, n_points: int, where: str) -> tuple[str, ...]:
    labels: list[str] = []
    key = "LABELS"
    k = 1
    while True:
        value = _param(c3d, "POINT", key)
        if value is None:
            break
        labels.extend(str(v).strip() for v in value)
        k += 1
        key = f"LABELS{k}"
    if len(labels) < n_points:
        raise FormatError(
            f"{where}: POINT:LABELS (with LABELS2...): expected {n_points} labels, one per "
            f"point, found {len(labels)}"
        )
    return tuple(labels[:n_points])


def _units_mm(c3d: Any, where: str) -> float:
    value = _param(c3d, "POINT", "UNITS")
    text = str(value[0]).strip().lower() if value is not None and len(value) else ""
    if not text:
        return 1.0
    if text not in C3D_UNITS_MM:
        raise FormatError(
            f"{where}: POINT:UNITS: expected one of {', '.join(C3D_UNITS_MM)}, found {text!r}"
        )
    return C3D_UNITS_MM[text]


def _first_frame(c3d: Any) -> int:
    start = _param(c3d, "TRIAL", "ACTUAL_START_FIELD")
    if start is not None and len(start) >= 1:
        words = [int(w) & 0xFFFF for w in np.asarray(start).ravel()[:2]]
        value = words[0] + (words[1] << 16 if len(words) > 1 else 0)
        if value >= 1:
            return value - 1
    return int(c3d["header"]["points"]["first_frame"])


def _declared_frames(path: Path) -> tuple[int, int, int] | None:
    """First frame, last frame and frame count as written in the file's 512-byte header.

    ezc3d stops quietly at the end of a truncated file and rewrites its header and
    POINT:FRAMES to what it read, so the declared range is read from the raw bytes:
    header byte 0 points to the parameter block, whose 4th byte is the processor type
    (84 Intel, 85 DEC: little-endian integers; 86 MIPS: big-endian); header words 4
    and 5 (bytes 6-9) are the first and last frame numbers (C3D User Guide, header
    section). Returns None when the bytes do not look like a C3D header.
    """
    with open(path, "rb") as fh:
        head = fh.read(512)
        if len(head) < 10 or head[1] != 0x50 or head[0] < 2:
            return None
        fh.seek((head[0] - 1) * 512)
        param = fh.read(4)
    if len(param) < 4 or param[3] not in (84, 85, 86):
        return None
    order = ">" if param[3] == 86 else "<"
    first, last = struct.unpack(order + "HH", head[6:10])
    if last < first:
        return None
    return int(first), int(last), int(last) - int(first) + 1


def read_c3d(path: str | os.PathLike[str]) -> MarkerData:
    """Read the marker trajectories of a C3D file into a `MarkerData` in mm.

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    FormatError
        ezc3d cannot parse the file, the file holds fewer frames than its header
        declares (truncated), or labels, units or rate are invalid.
    """
    import ezc3d  # heavy compiled dependency: imported only when C3D is read

    p = Path(path)
    where = str(p)
    require_file(p, "C3D file", missing=FileNotFoundError)
    try:
        c3d = ezc3d.c3d(where)
    except (RuntimeError, OSError, ValueError, IndexError, MemoryError) as exc:
        raise FormatError(f"{where}: not a readable C3D file (ezc3d: {exc})") from exc
    points = np.asarray(c3d["data"]["points"], dtype=np.float64)
    if points.ndim != 3 or points.shape[0] < 3:
        raise FormatError(f"{where}: POINT data: expected shape (4, M, T), found {points.shape}")
    n_points, n_frames = points.shape[1], points.shape[2]
    hdr = c3d["header"]["points"]
    declared = _declared_frames(p)
    if n_points and declared is not None and declared[2] > n_frames:
        raise FormatError(
            f"{where}: truncated C3D: header declares {declared[2]} frames "
            f"(first {declared[0]}, last {declared[1]}), the file holds {n_frames}"
        )
    names = _labels(c3d, n_points, where)
    rate_value = _param(c3d, "POINT", "RATE")
    rate = float(rate_value[0]) if rate_value is not None and len(rate_value) else 0.0
    if not rate > 0:
        rate = float(hdr["frame_rate"])
    if not (np.isfinite(rate) and rate > 0):
        raise FormatError(f"{where}: POINT:RATE: expected a positive frame rate, found {rate}")
    xyz = points[:3].transpose(2, 1, 0) * _units_mm(c3d, where)  # (T, M, 3)
    missing = np.all(xyz == 0.0, axis=2)
    try:
        residuals = np.asarray(c3d["data"]["meta_points"]["residuals"], dtype=np.float64)
    except KeyError:
        residuals = None
    if residuals is not None and residuals.shape == (1, n_points, n_frames):
        missing |= residuals[0].T < 0
    xyz[missing] = np.nan
    time_s = (_first_frame(c3d) + np.arange(n_frames)) / rate
    return MarkerData(time_s=time_s, names=names, positions_mm=xyz, rate_hz=rate, source=where)
