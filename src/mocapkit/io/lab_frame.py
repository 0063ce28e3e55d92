"""A marker file's lab frame: which axis is up and where the floor is, found or given.

Vicon and Qualisys write Z-up files; OpenSim TRC, OptiTrack and many C3D exports Y-up;
the floor is not always at 0. The library tracks in a Z-up world with the floor at
z = 0, so `detect_lab_frame` finds the vertical axis and the floor from the markers,
`to_world` converts a `MarkerData` to that world and `LabFrame.lab_from_world` takes
results back to the file's frame.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ConfigError, FormatError
from mocapkit.io.markers import MarkerData

FloatArray = NDArray[np.float64]

#: Accepted ``--up`` values.
UP_AXES: tuple[str, ...] = ("x", "y", "z", "-x", "-y", "-z")

#: A floor found within this height (mm) above the file's 0 is taken to be the file's
#: calibrated floor at 0: the lowest markers (toe, heel, wheel) sit 10-100 mm above it.
FLOOR_SNAP_MM = 150.0

#: The head must sit this far (mm, median over frames) above the markers' median along
#: the chosen axis, and this many times farther than along any other axis, for a
#: detection to be called sure.
SURE_LIFT_MM = 200.0
SURE_RATIO = 2.0


@dataclass(frozen=True)
class LabFrame:
    """The file's vertical axis and floor, and how they were found.

    Attributes
    ----------
    up : str
        One of `UP_AXES`: the file's axis that points up.
    floor_mm : float
        Floor height along ``up`` (mm; the coordinate along ``up``, so for ``-y`` it is
        minus the file's y of the floor).
    method : str
        ``"given"`` (``--up``), ``"head"`` (head markers highest) or ``"extent"``
        (body extent and lowest markers; no head set).
    sure : bool
        Whether the detection passed its margins (always True when given).
    detail : str
        The figures behind the choice, for the terminal.
    floor_given : bool
        The floor was given (``--floor-mm``), not found from the lowest markers.
    """

    up: str
    floor_mm: float
    method: str
    sure: bool
    detail: str = ""
    floor_given: bool = False

    @property
    def world_from_lab(self) -> FloatArray:
        """(3, 3) rotation taking file vectors to the Z-up world (rows: world x, y, z in
        file coordinates). World x is the file's x unless x is vertical."""
        a, s = _axis(self.up)
        z = np.zeros(3)
        z[a] = s
        x = np.zeros(3)
        x[0 if a != 0 else 1] = 1.0
        return np.stack([x, np.cross(z, x), z])

    def world_from_lab_points(self, points_in_lab_mm: ArrayLike) -> FloatArray:
        """(..., 3) file-frame points (mm) in the world (Z up, floor at z = 0)."""
        p = np.asarray(points_in_lab_mm, dtype=float) @ self.world_from_lab.T
        p[..., 2] -= self.floor_mm
        return p

    def lab_from_world_points(self, points_in_world_mm: ArrayLike) -> FloatArray:
        """Inverse of `world_from_lab_points`."""
        p = np.array(points_in_world_mm, dtype=float)
        p[..., 2] += self.floor_mm
        return p @ self.world_from_lab

    def summary(self) -> str:
        """One line for the terminal."""
        how = {
            "given": "given (--up)",
            "head": "detected (head markers highest)",
            "extent": "detected (body extent, lowest markers)",
        }[self.method]
        certainty = (
            ""
            if self.method == "given"
            else (" sure" if self.sure else " NOT SURE, check it or give --up")
        )
        floor = " (given, --floor-mm)" if self.floor_given else ""
        return (
            f"lab frame: up = {self.up} ({how};{certainty}), floor at {self.floor_mm:.0f} mm"
            f"{floor}" + (f"; {self.detail}" if self.detail else "")
        )


def _axis(up: str) -> tuple[int, float]:
    if up not in UP_AXES:
        raise ConfigError(f"--up: expected one of {', '.join(UP_AXES)}, found {up!r}")
    return "xyz".index(up[-1]), -1.0 if up.startswith("-") else 1.0


def parse_up(text: str) -> str:
    """Check an ``--up`` value (case-insensitive) and return it in `UP_AXES` spelling."""
    up = text.strip().lower().lstrip("+")
    _axis(up)
    return up


def _floor_mm(markers: MarkerData, up: str) -> float:
    """Floor along ``up``: the 1st percentile of each frame's lowest marker, snapped to 0
    when it lies within `FLOOR_SNAP_MM` above 0 (a calibrated floor)."""
    a, s = _axis(up)
    h = s * markers.positions_mm[:, :, a]
    seen = ~np.isnan(h).all(axis=1)
    if not seen.any():
        raise FormatError(f"{markers.source}: lab floor: expected some visible marker, found none")
    low = float(np.percentile(np.nanmin(h[seen], axis=1), 1.0))
    return 0.0 if 0.0 <= low <= FLOOR_SNAP_MM else low


def detect_lab_frame(
    markers: MarkerData,
    head_mm: ArrayLike | None = None,
    up: str | None = None,
    floor_mm: float | None = None,
) -> LabFrame:
    """Find the file's vertical axis and floor from the markers (or take ``up`` as given).

    Rule (a careful engineer's choice; no paper covers it):

    * with a head set: the up axis is the signed axis along which the head sits farthest
      above the median of all markers (median over frames of the head's lift per axis);
      sure when that lift is at least `SURE_LIFT_MM` and `SURE_RATIO` times the largest
      lift along another axis. Holds for standing and seated subjects (the head tops
      the body and the chair), with arms raised on some frames.
    * without: the axis with the largest median per-frame extent of the markers (a
      standing body is taller than it is wide or deep), its sign given by the side where
      the per-frame extreme markers cluster more tightly (the feet on the floor move less
      in height than hands above); sure when the extent is `SURE_RATIO` times the next.
    * the floor: the 1st percentile of each frame's lowest marker along up, taken as 0
      where it lies within `FLOOR_SNAP_MM` above 0.

    Parameters
    ----------
    markers : MarkerData
        In the file's frame (mm).
    head_mm : array_like (T, 3), optional
        Head set centre per frame (NaN when unseen).
    up : str, optional
        One of `UP_AXES`: skip the detection of the axis (the floor is still found).
    floor_mm : float, optional
        The floor's coordinate along the up axis (mm; ``--floor-mm``): skip the floor's
        detection (a file with no marker near the floor, only head and hands).

    Returns
    -------
    LabFrame
    """
    if floor_mm is not None and not math.isfinite(floor_mm):
        raise ConfigError(f"--floor-mm: expected a finite height (mm), found {floor_mm}")
    frame = _detect(markers, head_mm, up)
    if floor_mm is None:
        return frame
    return replace(frame, floor_mm=float(floor_mm), floor_given=True)


def _detect(markers: MarkerData, head_mm: ArrayLike | None, up: str | None) -> LabFrame:
    if up is not None:
        up = parse_up(up)
        return LabFrame(up, _floor_mm(markers, up), "given", True)
    pos = markers.positions_mm
    with warnings.catch_warnings():
        # frames without any marker give all-NaN slices; they are expected
        warnings.simplefilter("ignore", RuntimeWarning)
        centre = np.nanmedian(pos, axis=1)  # (T, 3)
        if head_mm is not None:
            head = np.asarray(head_mm, dtype=float)
            lift = np.nanmedian(head - centre, axis=0)  # (3,)
            if np.isnan(lift).any():
                raise FormatError(
                    f"{markers.source}: lab frame: expected the head set visible on some "
                    "frame, found none (give --up)"
                )
            order = np.argsort(-np.abs(lift))
            a = int(order[0])
            best, second = abs(float(lift[a])), abs(float(lift[order[1]]))
            up = ("-" if lift[a] < 0 else "") + "xyz"[a]
            sure = best >= SURE_LIFT_MM and best >= SURE_RATIO * second
            detail = "head lift x/y/z " + "/".join(f"{v:.0f}" for v in lift) + " mm"
            return LabFrame(up, _floor_mm(markers, up), "head", bool(sure), detail)
        extent = np.nanmedian(np.nanmax(pos, axis=1) - np.nanmin(pos, axis=1), axis=0)
        if np.isnan(extent).any():
            raise FormatError(f"{markers.source}: lab frame: expected visible markers, found none")
        order = np.argsort(-extent)
        a = int(order[0])
        spread_low = float(np.nanstd(np.nanmin(pos[:, :, a], axis=1)))
        spread_high = float(np.nanstd(np.nanmax(pos[:, :, a], axis=1)))
    up = ("-" if spread_high < spread_low else "") + "xyz"[a]
    sure = bool(extent[a] >= SURE_RATIO * extent[order[1]])
    detail = (
        "extent x/y/z " + "/".join(f"{v:.0f}" for v in extent) + " mm, spread of lowest/highest "
        f"{spread_low:.0f}/{spread_high:.0f} mm"
    )
    return LabFrame(up, _floor_mm(markers, up), "extent", sure, detail)


def to_world(markers: MarkerData, frame: LabFrame) -> MarkerData:
    """The markers in the Z-up world of ``frame`` (floor at z = 0)."""
    return MarkerData(
        markers.time_s,
        markers.names,
        frame.world_from_lab_points(markers.positions_mm),
        markers.rate_hz,
        markers.source,
    )


__all__ = ["UP_AXES", "LabFrame", "detect_lab_frame", "parse_up", "to_world"]
