"""Lossless conversion of a `Skeleton` to and from a plain dict / JSON text.

Floats are written by Python's shortest round-trip representation, so
``skeleton_from_json(skeleton_to_json(s))`` reproduces every array bit for bit.
Infinite limits (no limit) are stored as ``null`` because strict JSON has no infinity.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from mocapkit.errors import FormatError
from mocapkit.skeleton.model import Skeleton

SKELETON_FORMAT = "mocapkit.skeleton"
SKELETON_FORMAT_VERSION = 1

_ARRAY_FIELDS = (
    "parents",
    "offsets_mm",
    "dof_joint",
    "dof_kind",
    "dof_axis",
    "bone_end_mm",
    "mass_kg",
    "com_fraction",
    "radii_mm",
)


def _limits_to_list(values: np.ndarray) -> list[float | None]:
    return [None if math.isinf(v) else float(v) for v in values.tolist()]


def skeleton_to_dict(skeleton: Skeleton) -> dict[str, Any]:
    """A plain dict (lists, str, float, None) holding every field of the skeleton.

    Parameters
    ----------
    skeleton : Skeleton

    Returns
    -------
    dict
        JSON-serialisable; ``lower``/``upper`` hold ``None`` for an infinite limit.
    """
    out: dict[str, Any] = {
        "format": SKELETON_FORMAT,
        "version": SKELETON_FORMAT_VERSION,
        "name": skeleton.name,
        "joint_names": list(skeleton.joint_names),
        "dof_names": list(skeleton.dof_names),
    }
    for f in _ARRAY_FIELDS:
        out[f] = np.asarray(getattr(skeleton, f)).tolist()
    out["lower"] = _limits_to_list(skeleton.lower)
    out["upper"] = _limits_to_list(skeleton.upper)
    out["canonical"] = {
        cname: {"joint": jname, "point_mm": [float(v) for v in point]}
        for cname, (jname, point) in skeleton.canonical.items()
    }
    return out


def _field(data: Mapping[str, Any], key: str, where: str) -> Any:
    if key not in data:
        raise FormatError(f"{where}: missing field {key!r} (expected a {SKELETON_FORMAT} document)")
    return data[key]


def skeleton_from_dict(data: Mapping[str, Any], where: str = "skeleton dict") -> Skeleton:
    """Rebuild a `Skeleton` from `skeleton_to_dict` output.

    Parameters
    ----------
    data : mapping
        As produced by `skeleton_to_dict` (possibly after a JSON round trip).
    where : str
        Origin named in error messages (e.g. a file path).
    """
    if not isinstance(data, Mapping):
        raise FormatError(f"{where}: expected a JSON object, found {type(data).__name__}")
    fmt = data.get("format")
    if fmt != SKELETON_FORMAT:
        raise FormatError(f"{where}: field 'format' should be {SKELETON_FORMAT!r}, found {fmt!r}")
    version = data.get("version")
    if version != SKELETON_FORMAT_VERSION:
        raise FormatError(
            f"{where}: unsupported skeleton format version {version!r} "
            f"(this mocapkit reads version {SKELETON_FORMAT_VERSION})"
        )
    kwargs: dict[str, Any] = {
        "name": str(_field(data, "name", where)),
        "joint_names": tuple(_field(data, "joint_names", where)),
        "dof_names": tuple(_field(data, "dof_names", where)),
    }
    n_dofs = len(kwargs["dof_names"])
    for f in _ARRAY_FIELDS:
        value = _field(data, f, where)
        if f in ("dof_axis",) and n_dofs == 0:
            value = np.zeros((0, 3))
        kwargs[f] = value
    for key, inf in (("lower", -math.inf), ("upper", math.inf)):
        values = _field(data, key, where)
        try:
            kwargs[key] = np.array([inf if v is None else float(v) for v in values], dtype=float)
        except (TypeError, ValueError):
            raise FormatError(f"{where}: field {key!r} must hold numbers or null") from None
    canonical = {}
    for cname, entry in dict(_field(data, "canonical", where)).items():
        try:
            point = tuple(float(v) for v in entry["point_mm"])
            canonical[str(cname)] = (str(entry["joint"]), point)
        except (KeyError, TypeError, ValueError):
            raise FormatError(
                f"{where}: canonical[{cname!r}] should be {{'joint': str, 'point_mm': [x, y, z]}}, "
                f"found {entry!r}"
            ) from None
        if len(point) != 3:
            raise FormatError(
                f"{where}: canonical[{cname!r}].point_mm needs 3 numbers, found {point}"
            )
    kwargs["canonical"] = canonical
    try:
        return Skeleton(**kwargs)
    except (TypeError, ValueError) as exc:
        raise FormatError(f"{where}: invalid skeleton: {exc}") from exc


def skeleton_to_json(skeleton: Skeleton, indent: int | None = None) -> str:
    """JSON text of `skeleton_to_dict` (strict JSON: no NaN or Infinity literals)."""
    return json.dumps(skeleton_to_dict(skeleton), indent=indent, allow_nan=False)


def skeleton_from_json(text: str, where: str = "skeleton JSON") -> Skeleton:
    """Rebuild a `Skeleton` from `skeleton_to_json` text."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise FormatError(f"{where}: not valid JSON ({exc})") from None
    return skeleton_from_dict(data, where)


__all__ = [
    "SKELETON_FORMAT",
    "SKELETON_FORMAT_VERSION",
    "skeleton_from_dict",
    "skeleton_from_json",
    "skeleton_to_dict",
    "skeleton_to_json",
]
