"""The small CSV files of a session: 2-D keypoints per camera and per-frame video time stamps.

``keypoints/<camera>.csv``: ``time_s`` then ``<joint>_x_px, <joint>_y_px`` per canonical
joint (``nan`` where unseen). ``video/<camera>.timestamps.csv``: ``frame,time_s``.
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import FormatError, ShapeError
from mocapkit.io.atomic import atomic_write
from mocapkit.io.files import read_text
from mocapkit.skeleton.model import CANONICAL_JOINTS

FloatArray = NDArray[np.float64]


def write_keypoints_csv(
    path: str | os.PathLike[str], time_s: ArrayLike, joint_names: Sequence[str], pixels: ArrayLike
) -> None:
    """Write 2-D keypoints: ``time_s`` then ``<joint>_x_px, <joint>_y_px``; NaN where unseen.

    Parameters
    ----------
    path : path-like
    time_s : (T,) float array
    joint_names : sequence of str
        Canonical joint names (K).
    pixels : (T, K, 2) float array
        Image positions (px, distorted image); NaN where the joint is not seen.
    """
    t = np.asarray(time_s, dtype=float)
    px = np.asarray(pixels, dtype=float)
    names = tuple(joint_names)
    if t.ndim != 1 or px.shape != (t.shape[0], len(names), 2):
        raise ShapeError(
            f"{path}: keypoints: expected time_s (T,) and pixels (T, {len(names)}, 2), found "
            f"{t.shape} and {px.shape}"
        )
    bad = [n for n in names if n not in CANONICAL_JOINTS]
    if bad:
        raise ShapeError(f"{path}: keypoints: not canonical joint names: {bad}")
    header = ["time_s"] + [f"{n}_{a}_px" for n in names for a in "xy"]
    with atomic_write(path, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(header)
        for ti, row in zip(t.tolist(), px.reshape(t.shape[0], -1).tolist()):
            w.writerow([repr(ti)] + ["nan" if v != v else f"{v:.3f}" for v in row])


@dataclass(frozen=True, eq=False)
class Keypoints:
    """2-D joint detections of one camera.

    Attributes
    ----------
    time_s : (T,) float array
    joint_names : tuple of str
        Canonical names (K).
    pixels : (T, K, 2) float array
        Image positions (px); NaN where unseen.
    source : str
    rebuilt_joints : tuple of str
        Joints not observed but placed from others by the reader (a detector's neck and
        pelvis, `mocapkit.io.openpose`); empty for keypoints that give every joint.
    """

    time_s: FloatArray
    joint_names: tuple[str, ...]
    pixels: FloatArray
    source: str = ""
    rebuilt_joints: tuple[str, ...] = ()


def _read_numeric_csv(path: Path, what: str) -> tuple[list[str], FloatArray]:
    rows = [r for r in csv.reader(io.StringIO(read_text(path, what))) if r]
    if not rows:
        raise FormatError(f"{path}: {what}: expected a header line, found an empty file")
    header = [h.strip() for h in rows[0]]
    values = np.empty((len(rows) - 1, len(header)))
    for i, row in enumerate(rows[1:]):
        if len(row) != len(header):
            raise FormatError(
                f"{path}: line {i + 2}: expected {len(header)} columns, found {len(row)}"
            )
        for j, cell in enumerate(row):
            c = cell.strip()
            try:
                values[i, j] = float(c) if c else math.nan
            except ValueError:
                raise FormatError(
                    f"{path}: line {i + 2}, column {header[j]!r}: expected a number, found {c!r}"
                ) from None
    return header, values


def check_times(t: FloatArray, path: Path | str, what: str) -> None:
    """Raise `FormatError` naming ``path`` unless ``t`` is finite and strictly increasing."""
    if not np.all(np.isfinite(t)):
        raise FormatError(f"{path}: {what}: expected finite time stamps, found NaN or inf")
    if t.shape[0] > 1 and np.any(np.diff(t) <= 0):
        k = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise FormatError(
            f"{path}: {what}: expected strictly increasing time stamps, found {t[k + 1]!r} s at "
            f"row {k + 1} after {t[k]!r} s"
        )


def read_keypoints_csv(path: str | os.PathLike[str]) -> Keypoints:
    """Read a file written by `write_keypoints_csv`."""
    p = Path(path)
    header, values = _read_numeric_csv(p, "keypoints")
    if header[0] != "time_s" or (len(header) - 1) % 2:
        raise FormatError(
            f"{p}: line 1: expected 'time_s' then pairs '<joint>_x_px,<joint>_y_px', found "
            f"{header[:5]}"
        )
    names: list[str] = []
    for k in range(1, len(header), 2):
        base = header[k][: -len("_x_px")]
        expect = [f"{base}_x_px", f"{base}_y_px"]
        if header[k : k + 2] != expect:
            raise FormatError(f"{p}: line 1: expected columns {expect}, found {header[k : k + 2]}")
        if base not in CANONICAL_JOINTS:
            raise FormatError(
                f"{p}: line 1: column {header[k]!r}: expected a canonical joint "
                f"({', '.join(CANONICAL_JOINTS)}), found {base!r}"
            )
        names.append(base)
    t = values[:, 0]
    check_times(t, p, "time_s")
    return Keypoints(t, tuple(names), values[:, 1:].reshape(len(t), len(names), 2), str(p))


def write_timestamps_csv(path: str | os.PathLike[str], time_s: ArrayLike) -> None:
    """Write per-frame video time stamps: ``frame,time_s``."""
    t = np.asarray(time_s, dtype=float)
    with atomic_write(path, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["frame", "time_s"])
        for i, ti in enumerate(t.tolist()):
            w.writerow([i, repr(ti)])


def read_timestamps_csv(path: str | os.PathLike[str]) -> FloatArray:
    """Read per-frame video time stamps (a ``time_s`` column; ``frame`` optional)."""
    p = Path(path)
    header, values = _read_numeric_csv(p, "video time stamps")
    if "time_s" not in header:
        raise FormatError(f"{p}: line 1: expected a 'time_s' column, found {header}")
    t = values[:, header.index("time_s")]
    check_times(t, p, "time_s")
    return t
