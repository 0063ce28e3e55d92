"""The checks of one calibrated camera, shared by every calibration reader.

`camera_from_entry` builds a `Camera` from a ``cameras.json`` entry (``name``,
``image_size``, ``K``, ``dist``, ``camera_from_world``) with every check: K's form, the
distortion's length and size, a proper rotation; `mocapkit.io.cameras` and
`mocapkit.io.calib_toml` build their cameras through it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.errors import FormatError

_KEYS = ("name", "image_size", "K", "dist", "camera_from_world")
DIST_LENGTHS = (0, 4, 5, 8, 12, 14)
_ROTATION_TOL = 1e-6
#: Largest |k1|, |k2| accepted: real lenses, fisheye-like wide angles included, stay
#: within a few units under OpenCV's model (larger values fold the image on itself).
MAX_RADIAL_DISTORTION = 10.0


def _numbers_only(value: Any) -> bool:
    """Whether a nested list holds JSON numbers only (no strings, booleans or nulls)."""
    if isinstance(value, np.ndarray):  # from cv2.FileStorage
        return value.dtype.kind in "iuf"
    if isinstance(value, list | tuple):
        return all(_numbers_only(v) for v in value)
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)


def number_array(value: Any, shape: tuple[int, ...], where: str) -> NDArray[np.float64]:
    """``value`` as a finite float array of ``shape``; `FormatError` naming ``where``."""
    if not _numbers_only(value):
        # numpy would turn "532" into 532.0: a string is a mistake to name, not a number
        raise FormatError(f"{where}: expected a {shape} array of numbers, found {value!r}")
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise FormatError(f"{where}: expected a {shape} array of numbers, found {value!r}") from exc
    if arr.shape != shape:
        raise FormatError(f"{where}: expected shape {shape}, found {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise FormatError(f"{where}: expected finite numbers, found NaN or infinity")
    return arr


def check_rotation(rot: NDArray[np.float64], where: str, tol: float = _ROTATION_TOL) -> None:
    """Raise `FormatError` naming ``where`` unless ``rot`` is a proper rotation."""
    err = float(np.max(np.abs(rot @ rot.T - np.eye(3))))
    det = float(np.linalg.det(rot))
    if err > tol or det < 0:
        raise FormatError(
            f"{where}: expected a proper rotation (R R^T = I within {tol:g}, det +1), "
            f"found max |R R^T - I| = {err:.3g}, det = {det:.6g}"
        )


def camera_from_entry(entry: Any, where: str) -> Camera:
    """One camera from a ``cameras.json`` entry, every check applied (``where`` names it)."""
    if not isinstance(entry, dict):
        raise FormatError(f"{where}: expected an object, found {type(entry).__name__}")
    missing = [k for k in _KEYS if k not in entry]
    if missing:
        raise FormatError(f"{where}: missing key(s) {', '.join(missing)}; expected {list(_KEYS)}")
    extra = sorted(set(entry) - set(_KEYS))
    if extra:
        raise FormatError(f"{where}: unknown key(s) {', '.join(extra)}; expected {list(_KEYS)}")
    name = entry["name"]
    if not isinstance(name, str) or not name:
        raise FormatError(f"{where}.name: expected a non-empty string, found {name!r}")
    where = f"{where} ({name!r})"
    size = entry["image_size"]
    if (
        not isinstance(size, list)
        or len(size) != 2
        or not all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in size)
    ):
        raise FormatError(
            f"{where}.image_size: expected [width, height] positive integers, found {size!r}"
        )
    k = number_array(entry["K"], (3, 3), f"{where}.K")
    if not np.allclose(k[2], [0.0, 0.0, 1.0]) or k[0, 0] <= 0 or k[1, 1] <= 0 or k[1, 0] != 0:
        raise FormatError(
            f"{where}.K: expected [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0, "
            f"found {k.tolist()}"
        )
    dist_raw = entry["dist"]
    if not isinstance(dist_raw, list):
        raise FormatError(f"{where}.dist: expected a list of numbers, found {dist_raw!r}")
    dist = number_array(dist_raw, (len(dist_raw),), f"{where}.dist")
    if dist.shape[0] not in DIST_LENGTHS:
        raise FormatError(
            f"{where}.dist: expected {', '.join(map(str, DIST_LENGTHS))} OpenCV coefficients, "
            f"found {dist.shape[0]}"
        )
    for i in (0, 1):  # k1, k2
        if dist.shape[0] > i and abs(dist[i]) > MAX_RADIAL_DISTORTION:
            raise FormatError(
                f"{where}.dist[{i}] (k{i + 1}): expected a radial coefficient within "
                f"+-{MAX_RADIAL_DISTORTION:g}, found {dist[i]:g}"
            )
    m = number_array(entry["camera_from_world"], (4, 4), f"{where}.camera_from_world")
    if not np.allclose(m[3], [0.0, 0.0, 0.0, 1.0]):
        raise FormatError(
            f"{where}.camera_from_world: expected last row [0, 0, 0, 1], found {m[3].tolist()}"
        )
    check_rotation(m[:3, :3], f"{where}.camera_from_world rotation part")
    return Camera(name, (size[0], size[1]), k, dist, m)


def check_unique_names(names: Sequence[str], source: str) -> None:
    """Raise `FormatError` naming ``source`` when two cameras share a name."""
    seen: set[str] = set()
    dups = sorted({n for n in names if n in seen or seen.add(n)})  # type: ignore[func-returns-value]
    if dups:
        raise FormatError(
            f"{source}: duplicate camera name(s) {', '.join(map(repr, dups))}; names must be unique"
        )
