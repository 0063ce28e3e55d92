"""Ground truth of a synthetic session (``truth.npz``): canonical joints and clean markers, mm."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import FormatError, ShapeError
from mocapkit.io.atomic import atomic_save_npz
from mocapkit.io.files import load_npz
from mocapkit.io.session_csv import check_times
from mocapkit.skeleton.model import CANONICAL_JOINTS

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Truth:
    """Ground truth of a synthetic session (world frame, mm).

    Attributes
    ----------
    time_s : (T,) float array
        The video frame times.
    joint_names : tuple of str
        Canonical names (J).
    joints_mm : (T, J, 3) float array
    marker_names : tuple of str
        Clean markers kept with the truth (incl. the elbow reference markers).
    markers_mm : (T, M, 3) float array
    """

    time_s: FloatArray
    joint_names: tuple[str, ...]
    joints_mm: FloatArray
    marker_names: tuple[str, ...] = ()
    markers_mm: FloatArray = field(default_factory=lambda: np.zeros((0, 0, 3)))

    def __post_init__(self) -> None:
        if not self.marker_names and np.size(self.markers_mm) == 0:
            n = int(np.shape(self.time_s)[0])
            object.__setattr__(self, "markers_mm", np.zeros((n, 0, 3)))

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write ``truth.npz`` atomically (no pickles)."""
        atomic_save_npz(
            path,
            time_s=np.asarray(self.time_s, dtype=float),
            joint_names=np.array(self.joint_names, dtype=np.str_),
            joints_mm=np.asarray(self.joints_mm, dtype=float),
            marker_names=np.array(self.marker_names, dtype=np.str_),
            markers_mm=np.asarray(self.markers_mm, dtype=float),
        )


def load_truth(path: str | os.PathLike[str]) -> Truth:
    """Read and validate a ``truth.npz``."""
    p = Path(path)
    data = load_npz(p, "truth (.npz)")
    missing = [k for k in ("time_s", "joint_names", "joints_mm") if k not in data]
    if missing:
        raise FormatError(f"{p}: missing arrays {missing}; found {sorted(data)}")
    t = np.asarray(data["time_s"], dtype=float)
    names = tuple(str(n) for n in np.atleast_1d(data["joint_names"]))
    joints = np.asarray(data["joints_mm"], dtype=float)
    mnames = (
        tuple(str(n) for n in np.atleast_1d(data["marker_names"]))
        if ("marker_names" in data)
        else ()
    )
    markers = (
        np.asarray(data["markers_mm"], dtype=float)
        if "markers_mm" in data
        else (np.zeros((t.shape[0], 0, 3)))
    )
    if t.ndim != 1:
        raise ShapeError(f"{p}: time_s: expected shape (T,), found {t.shape}")
    check_times(t, p, "time_s")
    if joints.shape != (t.shape[0], len(names), 3):
        raise ShapeError(
            f"{p}: joints_mm: expected shape ({t.shape[0]}, {len(names)}, 3), found {joints.shape}"
        )
    bad = [n for n in names if n not in CANONICAL_JOINTS]
    if bad:
        raise FormatError(f"{p}: joint_names: expected canonical names, found {bad}")
    if markers.shape != (t.shape[0], len(mnames), 3):
        raise ShapeError(
            f"{p}: markers_mm: expected shape ({t.shape[0]}, {len(mnames)}, 3), "
            f"found {markers.shape}"
        )
    return Truth(t, names, joints, mnames, markers)
