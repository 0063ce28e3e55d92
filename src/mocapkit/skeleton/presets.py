"""Body-model presets, each a TOML data table under ``skeleton/presets/``.

A table lists joints in topological order with their parent, rest offset, DoFs
(kind, axis, limits in degrees or mm, optional ``option`` group), segment end,
mass (g), centre-of-mass fraction and cone radii, plus the map onto the canonical
joint vocabulary. Degrees appear only in these tables, where people read and
edit them; the loaded `Skeleton` holds radians.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Iterable, Mapping
from importlib import resources
from typing import Any

import numpy as np

from mocapkit.errors import FormatError, unknown_name
from mocapkit.skeleton.model import DOF_KINDS, Skeleton


def preset_names() -> tuple[str, ...]:
    """Names of the built-in presets."""
    folder = resources.files("mocapkit.skeleton") / "presets"
    return tuple(sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml")))


def preset_options(name: str) -> tuple[str, ...]:
    """Option groups a preset's table declares (e.g. ``adaptive_shoulder``)."""
    table = _read_table(name)
    opts = {d["option"] for j in table.get("joint", []) for d in j.get("dofs", []) if "option" in d}
    return tuple(sorted(opts))


def _read_table(name: str) -> dict[str, Any]:
    names = preset_names()
    if name not in names:
        raise unknown_name("skeleton preset", name, names)
    path = resources.files("mocapkit.skeleton") / "presets" / f"{name}.toml"
    with path.open("rb") as fh:
        return tomllib.load(fh)


def load_preset(name: str, options: Iterable[str] = ()) -> Skeleton:
    """Load a built-in body model.

    Parameters
    ----------
    name : str
        One of `preset_names` (``zhang21``, ``azad14``, ``upper_stick``).
    options : iterable of str
        Optional DoF groups to include (see `preset_options`).
    """
    table = _read_table(name)
    options = set(options)
    unknown = options - set(preset_options(name))
    if unknown:
        raise unknown_name("preset option", sorted(unknown)[0], preset_options(name), name)
    return skeleton_from_table(table, options, source=f"preset {name!r}")


def _vec3(value: Any, where: str) -> tuple[float, float, float]:
    try:
        x, y, z = (float(v) for v in value)
    except (TypeError, ValueError):
        raise FormatError(f"{where}: expected three numbers, found {value!r}") from None
    return (x, y, z)


def skeleton_from_table(
    table: Mapping[str, Any], options: Iterable[str] = (), source: str = "table"
) -> Skeleton:
    """Build a `Skeleton` from a parsed preset table (see module docstring)."""
    options = set(options)
    joints = table.get("joint")
    if not isinstance(joints, list) or not joints:
        raise FormatError(f"{source}: expected a non-empty [[joint]] list, found {joints!r}")
    names: list[str] = []
    parents: list[int] = []
    offsets, ends, masses, fracs, radii = [], [], [], [], []
    dof_joint: list[int] = []
    dof_kind: list[int] = []
    dof_axis: list[tuple[float, float, float]] = []
    dof_names: list[str] = []
    lower: list[float] = []
    upper: list[float] = []
    for j, jt in enumerate(joints):
        where = f"{source} joint #{j}"
        name = jt.get("name")
        if not isinstance(name, str):
            raise FormatError(f"{where}: expected a string 'name', found {name!r}")
        where = f"{source} joint {name!r}"
        parent = jt.get("parent")
        if parent is None:
            parents.append(-1)
        elif parent in names:
            parents.append(names.index(parent))
        else:
            raise FormatError(
                f"{where}: parent {parent!r} must be a joint listed before it; "
                f"listed so far: {names}"
            )
        names.append(name)
        offsets.append(_vec3(jt.get("offset_mm", (0, 0, 0)), f"{where} offset_mm"))
        ends.append(_vec3(jt.get("bone_end_mm", (0, 0, 0)), f"{where} bone_end_mm"))
        masses.append(float(jt.get("mass_g", 0.0)) / 1000.0)
        fracs.append(float(jt.get("com_fraction", 0.5)))
        r = jt.get("radii_mm", (0.0, 0.0))
        if len(r) != 2:
            raise FormatError(f"{where}: radii_mm expects [proximal, distal], found {r!r}")
        radii.append((float(r[0]), float(r[1])))
        for dt in jt.get("dofs", []):
            if "option" in dt and dt["option"] not in options:
                continue
            kind = dt.get("kind")
            if kind not in DOF_KINDS:
                raise FormatError(
                    f"{where} DoF {dt.get('name')!r}: kind must be one of {sorted(DOF_KINDS)}, "
                    f"found {kind!r}"
                )
            axis = np.array(_vec3(dt.get("axis"), f"{where} DoF axis"))
            axis = axis / np.linalg.norm(axis)
            if kind == "prismatic":
                lo, hi = dt.get("limits_mm", (-math.inf, math.inf))
            else:
                lo_d, hi_d = dt.get("limits_deg", (-180.0, 180.0))
                lo, hi = math.radians(lo_d), math.radians(hi_d)
            dof_joint.append(j)
            dof_kind.append(DOF_KINDS[kind])
            dof_axis.append((float(axis[0]), float(axis[1]), float(axis[2])))
            dof_names.append(str(dt.get("name", f"{name}_{len(dof_names)}")))
            lower.append(float(lo))
            upper.append(float(hi))
    canonical: dict[str, tuple[str, tuple[float, float, float]]] = {}
    for cname, ct in table.get("canonical", {}).items():
        canonical[cname] = (
            str(ct["joint"]),
            _vec3(ct.get("point_mm", (0, 0, 0)), f"{source} canonical {cname}"),
        )
    return Skeleton(
        name=str(table.get("name", source)),
        joint_names=tuple(names),
        parents=np.array(parents),
        offsets_mm=np.array(offsets),
        dof_joint=np.array(dof_joint, dtype=np.int64),
        dof_kind=np.array(dof_kind, dtype=np.int64),
        dof_axis=np.array(dof_axis).reshape(-1, 3),
        dof_names=tuple(dof_names),
        lower=np.array(lower),
        upper=np.array(upper),
        bone_end_mm=np.array(ends),
        mass_kg=np.array(masses),
        com_fraction=np.array(fracs),
        radii_mm=np.array(radii),
        canonical=canonical,
    )
