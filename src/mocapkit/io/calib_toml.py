"""``Calib.toml``: the multi-camera calibration of Pose2Sim, anipose and FreeMoCap.

One table per camera (the ``[metadata]`` table, and any table without a ``matrix``, is
skipped)::

    [cam01]
    name = "cam01"
    size = [1088.0, 1920.0]                  # [width, height] px
    matrix = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]
    distortions = [k1, k2, p1, p2]           # OpenCV order; 4, 5 or 8 of them
    rotation = [rx, ry, rz]                  # Rodrigues vector of the world-to-camera rotation
    translation = [tx, ty, tz]               # world-to-camera translation
    fisheye = false

The camera is named by ``name``, else by its table's name. ``rotation`` and
``translation`` give ``camera_from_world`` (x_cam = R x_world + t), as OpenCV's
``solvePnP`` and ``stereoCalibrate`` do.

**Units of the translation.** Pose2Sim writes metres; anipose and FreeMoCap write the
unit of the board's square length, which labs give in mm or in m. A file does not say
which, so the unit is read from the distances (`translation_unit`): cameras stand
between 0.3 m and 50 m from a lab's origin, so a largest ``|t|`` below
``METRE_LIMIT`` (50) is metres and one of ``MILLIMETRE_FLOOR`` (300) or more is mm;
a file in between is refused and ``unit="m"`` or ``unit="mm"`` decides. A fisheye
camera (``fisheye = true``) is refused: its distortion model is not OpenCV's pinhole one
that `mocapkit.camera` uses.
"""

from __future__ import annotations

import os
import tomllib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.errors import FormatError
from mocapkit.geometry.transforms import make_transform
from mocapkit.io.atomic import atomic_write
from mocapkit.io.camera_checks import camera_from_entry, check_unique_names, number_array
from mocapkit.io.files import read_text
from mocapkit.io.session_options import UNITS_MM

FloatArray = NDArray[np.float64]
PathLike = str | os.PathLike[str]

#: A largest camera translation below this is in metres (no lab camera stands 50 m away).
METRE_LIMIT = 50.0
#: A largest camera translation at or above this is in mm (no lab camera stands 300 m away,
#: nor 300 mm from the origin with others further).
MILLIMETRE_FLOOR = 300.0


def translation_unit(largest: float, source: str) -> str:
    """``"m"`` or ``"mm"`` for a file whose largest camera translation is ``largest``.

    See the module docstring; a file whose cameras all sit at the origin (one camera, its
    own frame the world) has no scale to read and is taken as metres, which changes
    nothing there.
    """
    if largest < METRE_LIMIT:
        return "m"
    if largest >= MILLIMETRE_FLOOR:
        return "mm"
    raise FormatError(
        f"{source}: translation: the largest camera translation is {largest:g}, between "
        f"{METRE_LIMIT:g} (metres below it) and {MILLIMETRE_FLOOR:g} (mm from it on); "
        "expected a lab's distances: say the unit (unit='m' or 'mm', or "
        "--calibration-unit m|mm)"
    )


def read_calib_toml(path: PathLike, unit: str | None = None) -> list[Camera]:
    """Read a ``Calib.toml`` (Pose2Sim, anipose, FreeMoCap) into cameras (mm).

    Parameters
    ----------
    path : path-like
    unit : {"m", "mm"}, optional
        Unit of the translations; default: read from their size (module docstring).

    Raises
    ------
    FormatError
        Naming the file, the table and the field.
    """
    p = Path(path)
    if unit is not None and unit not in UNITS_MM:
        raise FormatError(f"{p}: unit: expected one of {sorted(UNITS_MM)}, found {unit!r}")
    try:
        doc = tomllib.loads(read_text(p, "Calib.toml calibration"))
    except tomllib.TOMLDecodeError as exc:
        raise FormatError(f"{p}: not valid TOML ({exc})") from None
    entries = [(k, v) for k, v in doc.items() if isinstance(v, dict) and "matrix" in v]
    if not entries:
        raise FormatError(
            f"{p}: expected one table per camera with name, size, matrix, distortions, "
            f"rotation and translation; found tables {sorted(doc)}"
        )
    raw: list[tuple[str, str, tuple[int, int], FloatArray, FloatArray, FloatArray, FloatArray]] = []
    for key, entry in entries:
        where = f"{p}: [{key}]"
        missing = [f for f in ("size", "distortions", "rotation", "translation") if f not in entry]
        if missing:
            raise FormatError(
                f"{where}: missing {', '.join(missing)}; expected name, size, matrix, "
                "distortions, rotation, translation"
            )
        name = entry.get("name", key)
        if not isinstance(name, str) or not name:
            raise FormatError(f"{where}.name: expected a non-empty string, found {name!r}")
        if entry.get("fisheye", False) is not False:
            raise FormatError(
                f"{where}.fisheye: expected false (OpenCV's pinhole model), found "
                f"{entry['fisheye']!r}; fisheye calibrations are not supported"
            )
        size = number_array(entry["size"], (2,), f"{where}.size")
        if not np.all(size == np.round(size)) or np.any(size <= 0):
            raise FormatError(
                f"{where}.size: expected [width, height] positive whole pixels, found "
                f"{entry['size']!r}"
            )
        k = number_array(entry["matrix"], (3, 3), f"{where}.matrix")
        dist_raw = entry["distortions"]
        n_dist = len(dist_raw) if isinstance(dist_raw, list) else -1
        dist = number_array(dist_raw, (max(n_dist, 0),), f"{where}.distortions")
        rvec = number_array(entry["rotation"], (3,), f"{where}.rotation")
        tvec = number_array(entry["translation"], (3,), f"{where}.translation")
        raw.append((key, name, (int(size[0]), int(size[1])), k, dist, rvec, tvec))
    if unit is None:
        unit = translation_unit(max(float(np.linalg.norm(r[6])) for r in raw), str(p))
    scale = UNITS_MM[unit]
    cameras = []
    for key, name, size_px, k, dist, rvec, tvec in raw:
        rot = np.asarray(cv2.Rodrigues(rvec.reshape(3, 1))[0], dtype=float)
        entry = {
            "name": name,
            "image_size": list(size_px),
            "K": k.tolist(),
            "dist": dist.tolist(),
            "camera_from_world": make_transform(rot, tvec * scale).tolist(),
        }
        # the one set of camera checks (K's form, distortion lengths and sizes, rotation)
        cameras.append(camera_from_entry(entry, f"{p}: [{key}] (matrix as K)"))
    check_unique_names([c.name for c in cameras], str(p))
    return cameras


def _toml_row(values: Any) -> str:
    return "[" + ", ".join(repr(float(v)) for v in np.ravel(values)) + "]"


def _toml_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def write_calib_toml(path: PathLike, cameras: Sequence[Camera]) -> None:
    """Write cameras as a Pose2Sim ``Calib.toml`` (translations in metres), atomically.

    Values are written at full double precision; `read_calib_toml` gives the same
    cameras back (the rotation through its Rodrigues vector, within 1e-12).
    """
    cams = list(cameras)
    if not cams:
        raise FormatError(f"{path}: expected at least one camera to write, found none")
    blocks = []
    for c in cams:
        rot = c.camera_from_world[:3, :3]
        rvec = np.asarray(cv2.Rodrigues(np.ascontiguousarray(rot))[0], dtype=float).ravel()
        t_m = c.camera_from_world[:3, 3] / UNITS_MM["m"]
        matrix = "[" + ", ".join(_toml_row(r) for r in c.K) + "]"
        key = c.name if c.name.replace("_", "").replace("-", "").isalnum() else _toml_string(c.name)
        blocks.append(
            f"[{key}]\n"
            f"name = {_toml_string(c.name)}\n"
            f"size = [{float(c.image_size[0])!r}, {float(c.image_size[1])!r}]\n"
            f"matrix = {matrix}\n"
            f"distortions = {_toml_row(c.dist)}\n"
            f"rotation = {_toml_row(rvec)}\n"
            f"translation = {_toml_row(t_m)}\n"
            "fisheye = false\n"
        )
    text = "\n".join(blocks) + "\n[metadata]\nadjusted = false\nerror = 0.0\n"
    tomllib.loads(text)  # the hand layout must stay valid TOML
    with atomic_write(path, "w") as fh:
        fh.write(text)


__all__ = [
    "METRE_LIMIT",
    "MILLIMETRE_FLOOR",
    "UNITS_MM",
    "read_calib_toml",
    "translation_unit",
    "write_calib_toml",
]
