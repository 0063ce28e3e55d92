"""The canonical-joints CSV: ``time_s`` then ``<joint>_x_mm, _y_mm, _z_mm`` (world, mm).

One row per frame; frames without a pose hold ``nan``.
"""

from __future__ import annotations

import csv
import io
import os

import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import FormatError
from mocapkit.io.atomic import atomic_write
from mocapkit.io.files import read_text
from mocapkit.io.motion import Motion

FloatArray = NDArray[np.float64]


def write_joints_csv(path: str | os.PathLike[str], motion: Motion) -> None:
    """Write a motion's canonical joints to CSV (see the module docstring), atomically.

    Parameters
    ----------
    path : path-like
    motion : Motion
        Its ``joints_mm`` (T, K, 3) are written; frames without a pose hold ``nan``.
    """
    header = ["time_s"] + [f"{n}_{a}_mm" for n in motion.joint_names for a in "xyz"]
    flat = np.asarray(motion.joints_mm).reshape(motion.n_frames, -1)
    with atomic_write(path, "w", newline="") as fh:  # rows go to the file as formatted
        fh.write(",".join(header) + "\n")
        if motion.n_frames:
            fmt = ",".join(["%.9f"] + ["%.6f"] * flat.shape[1])
            np.savetxt(fh, np.column_stack([motion.time_s, flat]), fmt=fmt, delimiter=",")


def read_joints_csv(path: str | os.PathLike[str]) -> tuple[FloatArray, tuple[str, ...], FloatArray]:
    """Read a file written by `write_joints_csv`.

    Returns
    -------
    time_s : ndarray, shape (T,)
    joint_names : tuple of str, length K
    joints_mm : ndarray, shape (T, K, 3)
        NaN where the file holds ``nan``.
    """
    where = str(path)
    rows = list(csv.reader(io.StringIO(read_text(path, "joints CSV"))))
    if not rows or not rows[0] or rows[0][0] != "time_s":
        found = rows[0][:1] if rows else "an empty file"
        raise FormatError(
            f"{where}: line 1: expected a header starting with 'time_s', found {found}"
        )
    header = rows[0]
    cols = header[1:]
    if len(cols) % 3:
        raise FormatError(
            f"{where}: line 1: expected 3 columns per joint, found {len(cols)} columns"
        )
    names: list[str] = []
    for k in range(0, len(cols), 3):
        base = cols[k][: -len("_x_mm")]
        expect = [f"{base}_{a}_mm" for a in "xyz"]
        if cols[k : k + 3] != expect:
            raise FormatError(
                f"{where}: line 1: expected columns {expect}, found {cols[k : k + 3]}"
            )
        names.append(base)
    values = np.empty((len(rows) - 1, len(header)))
    for i, row in enumerate(rows[1:]):
        if len(row) != len(header):
            raise FormatError(
                f"{where}: line {i + 2}: expected {len(header)} values, found {len(row)}"
            )
        try:
            values[i] = [float(v) for v in row]
        except ValueError:
            raise FormatError(f"{where}: line {i + 2}: non-numeric value in {row}") from None
    return values[:, 0].copy(), tuple(names), values[:, 1:].reshape(len(values), len(names), 3)


__all__ = ["read_joints_csv", "write_joints_csv"]
