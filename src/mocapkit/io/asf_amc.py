"""Acclaim ASF (skeleton) and AMC (motion) files, as used by the CMU motion-capture database.

Skeleton
--------
Each ASF bone becomes a joint at the bone's start (the end of its parent bone)
that owns the bone (``bone_end_mm = direction x length``). Its local rotation
is ``C @ M @ C^-1`` with ``C`` the ``axis`` orientation and ``M`` the product of
the rotations of its ``dof`` list, the first listed applied first
(``dof rx ry rz`` -> ``M = Rz @ Ry @ Rx``, column vectors; Acclaim's row-vector
``Mx My Mz``). Because ``C R_e(a) C^-1`` is the rotation by ``a`` about ``C e``,
this is a chain of revolute DoFs about the columns of ``C``, listed last dof
first (our product order). ``C`` itself is built the same way from the
``axis`` angles and their order letters (``XYZ`` -> ``Rz @ Ry @ Rx``). The
root: prismatic DoFs for ``TX TY TZ`` and revolute DoFs for its rotations
(``order``), conjugated by its ``orientation``; its rest offset is ``position``
and the AMC root translation is taken as absolute (``q = value - position``; the
CMU files have ``position 0 0 0``).
This convention was checked against the cgspeed BVH conversion of the same trial
(a CMU trial; see tests/io/test_asf_amc.py).

The file frame (Y up) is turned into the mocapkit world (Z up, facing +Y) by
`WORLD_FROM_FILE`. Units: ``:units length L`` means one file unit is ``1/L``
inch (CMU FAQ: with ``length 0.45`` one unit is (1/0.45) inch = 56.444 mm); an
explicit ``unit_mm`` overrides. Angles follow ``:units angle deg|rad``; an AMC
``:DEGREES``/``:RADIANS`` line overrides for the motion values.

Motion
------
AMC files carry no frame rate: CMU's standard rate, 120 Hz, is the default
(``fps`` overrides). AMC frame ``n`` (numbered from 1) is at ``(n - 1) / fps``
seconds. Every bone with DoFs must appear in every frame.

ASF lookup (when ``asf_path`` is not given): ``<stem>.asf`` beside the AMC, then the
subject prefix before ``_`` (``02_05.amc`` -> ``02.asf``), then the stem without its
trailing take number (``dance1.amc`` -> ``dance.asf``), then the only ``.asf`` in
the folder; otherwise `FormatError` listing what was tried.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import FormatError, unknown_name
from mocapkit.io.motion import Motion
from mocapkit.io.naming import canonical_map, detect_convention
from mocapkit.io.units import WORLD_FROM_FILE
from mocapkit.skeleton.model import PRISMATIC, REVOLUTE, Skeleton

FloatArray = NDArray[np.float64]

#: CMU's standard capture rate; AMC files store none.
CMU_AMC_FPS = 120.0
_AXES = {"x": 0, "y": 1, "z": 2}


@dataclass
class AsfBone:
    """One ASF bone (file units and frame; angles in radians)."""

    name: str
    direction: FloatArray
    length: float
    axis_rad: FloatArray
    axis_order: str
    dofs: list[str] = field(default_factory=list)  # "rx", "ry", "rz", "tx", ..., "l"
    limits: list[tuple[float, float]] = field(default_factory=list)
    bone_id: int | None = None


@dataclass
class AsfData:
    """Parsed ASF content."""

    name: str
    length_unit: float
    angle_in_degrees: bool
    root_order: list[str]
    root_axis_order: str
    root_position: FloatArray
    root_orientation_rad: FloatArray
    bones: dict[str, AsfBone]
    children: dict[str, list[str]]


def _axis_rotation(axis: int, angle: float) -> FloatArray:
    c, s = np.cos(angle), np.sin(angle)
    i, j = (axis + 1) % 3, (axis + 2) % 3
    r = np.eye(3)
    r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
    return r


def euler_matrix(angles_rad: FloatArray, order: str) -> FloatArray:
    """Rotation from three angles about fixed x/y/z axes, the first letter applied first.

    ``order="XYZ"`` gives ``Rz @ Ry @ Rx`` (column vectors).
    """
    out = np.eye(3)
    for letter, angle in zip(order.lower(), angles_rad, strict=True):
        out = _axis_rotation(_AXES[letter], float(angle)) @ out
    return out


def _content_lines(path: Path, what: str) -> list[tuple[int, str]]:
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise FormatError(f"{path}: cannot read {what} file ({exc})") from None
    out = []
    for n, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if s and not s.startswith("#"):
            out.append((n, s))
    return out


def _floats(parts: list[str], count: int, where: str, line: int, what: str) -> FloatArray:
    if len(parts) < count:
        raise FormatError(f"{where}: line {line}: {what}: expected {count} numbers, found {parts}")
    try:
        return np.array([float(v) for v in parts[:count]])
    except ValueError:
        raise FormatError(
            f"{where}: line {line}: {what}: expected {count} numbers, found {parts[:count]}"
        ) from None


def parse_asf(path: str | os.PathLike[str]) -> AsfData:
    """Parse an ASF skeleton file (comments ``#`` skipped). Raises `FormatError`."""
    p = Path(path)
    where = str(p)
    lines = _content_lines(p, "ASF")
    section = ""
    length_unit = 1.0
    angle_unit = "deg"
    root: dict[str, list[str]] = {}
    bones: dict[str, AsfBone] = {}
    children: dict[str, list[str]] = {}
    name = p.stem  # the skeleton is named after its file (CMU files all say ':name VICON')
    raw_bones: list[tuple[int, dict[str, list[str]], list[tuple[int, str]]]] = []
    current: dict[str, list[str]] | None = None
    current_limits: list[tuple[int, str]] = []
    in_limits = False
    begin_line = 0
    for n, s in lines:
        if s.startswith(":"):
            parts = s.split(None, 1)
            section = parts[0][1:].lower()
            continue
        parts = s.split()
        key = parts[0].lower()
        if section == "units":
            if key == "length":
                length_unit = float(_floats(parts[1:], 1, where, n, "units length")[0])
            elif key == "angle":
                if len(parts) < 2 or parts[1].lower() not in ("deg", "rad"):
                    raise FormatError(
                        f"{where}: line {n}: units angle: expected 'deg' or 'rad', "
                        f"found {parts[1:]}"
                    )
                angle_unit = parts[1].lower()
        elif section == "root":
            root[key] = parts[1:]
        elif section == "bonedata":
            if key == "begin":
                current, current_limits, in_limits, begin_line = {}, [], False, n
            elif key == "end":
                if current is None:
                    raise FormatError(f"{where}: line {n}: 'end' without 'begin' in :bonedata")
                raw_bones.append((begin_line, current, current_limits))
                current = None
            elif current is None:
                raise FormatError(f"{where}: line {n}: expected 'begin' in :bonedata, found {s!r}")
            elif key == "limits":
                in_limits = True
                current_limits.append((n, s[len("limits") :]))
            elif in_limits and s.startswith("("):
                current_limits.append((n, s))
            else:
                in_limits = False
                current[key] = parts[1:]
        elif section == "hierarchy":
            if key in ("begin", "end"):
                continue
            children.setdefault(parts[0], []).extend(parts[1:])
    if current is not None:
        raise FormatError(
            f"{where}: line {begin_line}: bone block 'begin' is never closed by 'end'"
        )
    angle_deg = angle_unit == "deg"
    to_rad = np.pi / 180.0 if angle_deg else 1.0
    for begin_line, fields, limit_lines in raw_bones:
        for req in ("name", "direction", "length"):
            if req not in fields:
                raise FormatError(
                    f"{where}: bone starting line {begin_line}: missing field {req!r}"
                )
        bname = fields["name"][0]
        direction = _floats(fields["direction"], 3, where, begin_line, f"bone {bname!r} direction")
        norm = np.linalg.norm(direction)
        if norm > 0:
            direction = direction / norm
        length = float(_floats(fields["length"], 1, where, begin_line, f"bone {bname!r} length")[0])
        axis = fields.get("axis", ["0", "0", "0", "XYZ"])
        axis_rad = _floats(axis, 3, where, begin_line, f"bone {bname!r} axis") * to_rad
        order = axis[3] if len(axis) > 3 else "XYZ"
        if sorted(order.lower()) != ["x", "y", "z"]:
            raise FormatError(
                f"{where}: bone {bname!r}: axis order should be a permutation of XYZ, "
                f"found {order!r}"
            )
        dofs = [d.lower() for d in fields.get("dof", [])]
        for d in dofs:
            if d not in ("rx", "ry", "rz", "tx", "ty", "tz", "l"):
                raise FormatError(
                    f"{where}: bone {bname!r}: unknown dof {d!r}; expected rx ry rz tx ty tz l"
                )
        if "l" in dofs:
            raise FormatError(f"{where}: bone {bname!r}: length DoF 'l' is not supported")
        limits: list[tuple[float, float]] = []
        text = " ".join(t for _, t in limit_lines).replace("(", " ").replace(")", " ").split()
        for k in range(0, len(text) - 1, 2):
            try:
                limits.append((float(text[k]), float(text[k + 1])))
            except ValueError:
                raise FormatError(
                    f"{where}: line {limit_lines[0][0]}: bone {bname!r}: limits: expected numbers, "
                    f"found {text[k : k + 2]}"
                ) from None
        if limit_lines and len(limits) != len(dofs):
            raise FormatError(
                f"{where}: line {limit_lines[0][0]}: bone {bname!r}: "
                f"expected {len(dofs)} limit pairs "
                f"(one per dof), found {len(limits)}"
            )
        bone_id = int(fields["id"][0]) if "id" in fields else None
        bones[bname] = AsfBone(bname, direction, length, axis_rad, order, dofs, limits, bone_id)
    if "order" not in root:
        raise FormatError(f"{where}: :root section lacks 'order' (e.g. 'order TX TY TZ RX RY RZ')")
    root_order = [o.lower() for o in root["order"]]
    for o in root_order:
        if o not in ("tx", "ty", "tz", "rx", "ry", "rz"):
            raise FormatError(
                f"{where}: :root order: unknown channel {o!r}; expected TX TY TZ RX RY RZ"
            )
    root_axis = root.get("axis", ["XYZ"])[0]
    position = _floats(root.get("position", ["0", "0", "0"]), 3, where, 0, ":root position")
    orientation = (
        _floats(root.get("orientation", ["0", "0", "0"]), 3, where, 0, ":root orientation") * to_rad
    )
    for parent, kids in children.items():
        for b in (parent, *kids):
            if b != "root" and b not in bones:
                raise unknown_name("bone", b, bones, f"{where} :hierarchy")
    return AsfData(
        name,
        length_unit,
        angle_deg,
        root_order,
        root_axis,
        position,
        orientation,
        bones,
        children,
    )


def skeleton_from_asf(
    asf: AsfData, unit_mm: float, where: str = ""
) -> tuple[Skeleton, dict[str, list[int]]]:
    """Build the `Skeleton` of a parsed ASF.

    Returns
    -------
    skeleton : Skeleton
    amc_columns : dict
        Per AMC line name (``root`` and each bone with DoFs): the DoF index in
        ``q`` fed by each value of that line, in file order.
    """
    w = WORLD_FROM_FILE
    order: list[str] = ["root"]
    stack = list(reversed(asf.children.get("root", [])))
    parent_of = {"root": -1}
    while stack:  # depth-first, children in file order
        b = stack.pop()
        if b in parent_of:
            raise FormatError(f"{where}: :hierarchy lists bone {b!r} twice (not a tree)")
        for pname, kids in asf.children.items():
            if b in kids:
                parent_of[b] = order.index(pname) if pname in order else -2
        if parent_of[b] < 0:
            raise FormatError(f"{where}: :hierarchy: bone {b!r} is listed before its parent")
        order.append(b)
        stack.extend(reversed(asf.children.get(b, [])))
    missing = sorted(set(asf.bones) - set(order))
    if missing:
        raise FormatError(f"{where}: bones {missing} are not reachable from 'root' in :hierarchy")
    n = len(order)
    offsets = np.zeros((n, 3))
    ends = np.zeros((n, 3))
    offsets[0] = w @ asf.root_position * unit_mm
    for j, b in enumerate(order[1:], start=1):
        bone = asf.bones[b]
        ends[j] = w @ (bone.direction * bone.length) * unit_mm
        offsets[j] = ends[parent_of[b]] if parent_of[b] > 0 else 0.0
    # the root's segment ends at its first child (zero for the CMU skeletons)
    dof_joint: list[int] = []
    dof_kind: list[int] = []
    dof_axis: list[FloatArray] = []
    dof_names: list[str] = []
    lower: list[float] = []
    upper: list[float] = []
    amc_columns: dict[str, list[int]] = {}

    def add_joint(
        j: int,
        jname: str,
        dofs: list[str],
        c: FloatArray,
        c_trans: FloatArray,
        limits: list[tuple[float, float]],
    ) -> None:
        cols = [-1] * len(dofs)
        to_rad = np.pi / 180.0 if asf.angle_in_degrees else 1.0
        trans = [k for k, d in enumerate(dofs) if d.startswith("t")]
        rots = [k for k, d in enumerate(dofs) if d.startswith("r")]
        # prismatic first (translation precedes rotation), then rotations, last listed first
        for k in trans + rots[::-1]:
            d = dofs[k]
            axis = w @ (c_trans if d.startswith("t") else c)[:, _AXES[d[1]]]
            cols[k] = len(dof_names)
            dof_joint.append(j)
            dof_kind.append(PRISMATIC if d.startswith("t") else REVOLUTE)
            dof_axis.append(axis)
            dof_names.append(f"{jname}_{d}")
            lo, hi = limits[k] if k < len(limits) else (-np.inf, np.inf)
            scale = unit_mm if d.startswith("t") else to_rad
            lower.append(lo * scale)
            upper.append(hi * scale)
        if dofs:
            amc_columns[jname] = cols

    root_c = euler_matrix(asf.root_orientation_rad, asf.root_axis_order)
    # root translations are along the file axes; its rotations are conjugated by orientation
    add_joint(0, "root", asf.root_order, root_c, np.eye(3), [])
    for j, b in enumerate(order[1:], start=1):
        bone = asf.bones[b]
        c = euler_matrix(bone.axis_rad, bone.axis_order)
        add_joint(j, b, bone.dofs, c, c, bone.limits)
    for j in range(n):  # root (and any bone) without own length: segment ends at the first child
        if not np.any(ends[j]):
            first_child = [k for k in range(1, n) if parent_of[order[k]] == j]
            if first_child:
                ends[j] = offsets[first_child[0]]
    d = len(dof_names)
    convention, _exact = detect_convention(order)
    skeleton = Skeleton(
        name=asf.name,
        joint_names=tuple(order),
        parents=np.array([parent_of[b] for b in order], dtype=np.int64),
        offsets_mm=offsets,
        dof_joint=np.array(dof_joint, dtype=np.int64),
        dof_kind=np.array(dof_kind, dtype=np.int64),
        dof_axis=np.array(dof_axis).reshape(d, 3),
        dof_names=tuple(dof_names),
        lower=np.array(lower),
        upper=np.array(upper),
        bone_end_mm=ends,
        mass_kg=np.zeros(n),
        com_fraction=np.full(n, 0.5),
        radii_mm=np.zeros((n, 2)),
        canonical=canonical_map(order, ends, convention),
    )
    return skeleton, amc_columns


def read_asf(path: str | os.PathLike[str], unit_mm: float | None = None) -> Skeleton:
    """Read an ASF file into a `Skeleton` (world frame, mm; default unit ``25.4 / length`` mm)."""
    asf = parse_asf(path)
    return skeleton_from_asf(asf, _unit(asf, unit_mm, str(path)), str(path))[0]


def _unit(asf: AsfData, unit_mm: float | None, where: str) -> float:
    if unit_mm is None:
        if not asf.length_unit > 0:
            raise FormatError(f"{where}: :units length must be > 0, found {asf.length_unit}")
        return 25.4 / asf.length_unit
    if not (unit_mm > 0 and np.isfinite(unit_mm)):
        raise FormatError(
            f"read_amc({where}): unit_mm must be a positive number, found {unit_mm!r}"
        )
    return float(unit_mm)


def find_asf(amc_path: str | os.PathLike[str]) -> Path:
    """Locate the ASF skeleton of an AMC file (rule in the module docstring)."""
    amc = Path(amc_path)
    folder = amc.parent
    tried: list[str] = []
    candidates = [folder / f"{amc.stem}.asf"]
    if "_" in amc.stem:
        candidates.append(folder / f"{amc.stem.split('_', 1)[0]}.asf")
    # a numbered take of a named subject: dance1.amc -> dance.asf
    stripped = amc.stem.rstrip("0123456789")
    if stripped and stripped != amc.stem:
        candidates.append(folder / f"{stripped}.asf")
    for c in candidates:
        tried.append(str(c))
        if c.is_file():
            return c
    all_asf = sorted(folder.glob("*.asf")) + sorted(folder.glob("*.ASF"))
    all_asf = sorted(set(all_asf))
    if len(all_asf) == 1:
        return all_asf[0]
    tried.append(
        f"the only .asf in {folder} (found {len(all_asf)}: {[a.name for a in all_asf][:10]})"
    )
    raise FormatError(
        f"{amc}: no ASF skeleton found; tried: " + "; ".join(tried) + ". Pass asf_path explicitly."
    )


def read_amc(
    amc_path: str | os.PathLike[str],
    asf_path: str | os.PathLike[str] | None = None,
    unit_mm: float | None = None,
    fps: float = CMU_AMC_FPS,
) -> Motion:
    """Read an AMC motion with its ASF skeleton into a `Motion` (world frame, mm, radians).

    Parameters
    ----------
    amc_path : path-like
    asf_path : path-like, optional
        Default: found by `find_asf`.
    unit_mm : float, optional
        Millimetres per file unit; default ``25.4 / L`` from the ASF ``:units length L``.
    fps : float
        Frame rate (AMC stores none); default 120 Hz (CMU).
    """
    amc = Path(amc_path)
    where = str(amc)
    if not fps > 0:
        raise FormatError(f"read_amc({where}): fps must be > 0, found {fps!r}")
    asf_file = Path(asf_path) if asf_path is not None else find_asf(amc)
    if not asf_file.is_file():
        raise FormatError(f"{where}: ASF skeleton file {asf_file} does not exist")
    asf = parse_asf(asf_file)
    unit = _unit(asf, unit_mm, str(asf_file))
    skeleton, columns = skeleton_from_asf(asf, unit, str(asf_file))
    lines = _content_lines(amc, "AMC")
    angle_deg = asf.angle_in_degrees
    frame_numbers: list[int] = []
    frame_lines: list[int] = []
    bone_ids = {b: k for k, b in enumerate(columns)}
    n_cols = np.array([len(c) for c in columns.values()], dtype=np.int64)
    line_bone: list[int] = []
    line_frame: list[int] = []
    line_no: list[int] = []
    flat_values: list[str] = []
    for n, s in lines:
        if s[0] == ":":
            key = s.split()[0].upper()
            if key == ":DEGREES":
                angle_deg = True
            elif key == ":RADIANS":
                angle_deg = False
            continue
        parts = s.split()
        bid = bone_ids.get(parts[0])
        if bid is None:
            if len(parts) == 1 and parts[0].isdigit():
                frame_numbers.append(int(parts[0]))
                frame_lines.append(n)
                continue
            bname = parts[0]
            if bname in asf.bones or bname == "root":
                raise FormatError(
                    f"{where}: line {n}: bone {bname!r} has no DoFs in {asf_file.name} "
                    "but the AMC gives it values"
                )
            raise unknown_name(
                "bone", bname, columns, f"{where} line {n} (skeleton {asf_file.name})"
            )
        if not frame_numbers:
            raise FormatError(
                f"{where}: line {n}: expected a frame number before bone values, found {s!r}"
            )
        if len(parts) - 1 != n_cols[bid]:
            raise FormatError(
                f"{where}: line {n}: bone {parts[0]!r} expects {n_cols[bid]} values "
                f"({n_cols[bid]} DoFs in {asf_file.name}), found {len(parts) - 1}"
            )
        line_bone.append(bid)
        line_frame.append(len(frame_numbers) - 1)
        line_no.append(n)
        flat_values.extend(parts[1:])
    if not frame_numbers:
        raise FormatError(f"{where}: no frames found (expected a frame number line such as '1')")
    n_frames, n_bones = len(frame_numbers), len(columns)
    lb = np.array(line_bone, dtype=np.int64)
    lf = np.array(line_frame, dtype=np.int64)
    counts = np.bincount(lf * n_bones + lb, minlength=n_frames * n_bones).reshape(n_frames, n_bones)
    if np.any(counts != 1):
        k, b = np.argwhere(counts != 1)[0]
        names = list(columns)
        if counts[k, b] == 0:
            lost = [names[i] for i in np.flatnonzero(counts[k] == 0)]
            raise FormatError(
                f"{where}: frame {frame_numbers[k]} (line {frame_lines[k]}): "
                f"missing values for bone "
                f"{lost[0]!r}"
                + (f" and {len(lost) - 1} more ({lost[1:6]})" if len(lost) > 1 else "")
            )
        raise FormatError(
            f"{where}: frame {frame_numbers[k]} (line {frame_lines[k]}): bone {names[b]!r} appears "
            f"{counts[k, b]} times (expected once)"
        )
    try:
        vals = np.array(flat_values, dtype=float)
    except ValueError:
        line_of_value = np.repeat(np.array(line_no), n_cols[lb])
        for tok, ln in zip(flat_values, line_of_value, strict=True):
            try:
                float(tok)
            except ValueError:
                raise FormatError(f"{where}: line {ln}: expected a number, found {tok!r}") from None
        raise
    width = int(n_cols.max()) if n_bones else 0
    table = np.full((n_bones, width), -1, dtype=np.int64)
    for k, cols in enumerate(columns.values()):
        table[k, : len(cols)] = cols
    per_line = table[lb]
    dof_idx = per_line[per_line >= 0]
    base = np.repeat(lf * skeleton.n_dofs, n_cols[lb])
    q_flat = np.empty(n_frames * skeleton.n_dofs)
    q_flat[base + dof_idx] = vals
    q = q_flat.reshape(n_frames, skeleton.n_dofs)
    rot = skeleton.dof_kind == REVOLUTE
    if angle_deg:
        q[:, rot] *= np.pi / 180.0
    q[:, ~rot] *= unit
    # translations: the AMC gives the root's position; the rest offset (:root position)
    # is already in the skeleton, and AMC root values are absolute in CMU files, so remove it
    q[:, ~rot] -= (skeleton.offsets_mm[0] @ skeleton.dof_axis[~rot].T)[None, :] * (
        skeleton.dof_joint[~rot] == 0
    )
    time_s = (np.array(frame_numbers, dtype=float) - 1.0) / fps
    source = f"{where} (AMC with {asf_file.name}; unit {unit:.6g} mm; {fps:g} fps)"
    return Motion.from_q(skeleton, time_s, q, source)


__all__ = [
    "CMU_AMC_FPS",
    "AsfBone",
    "AsfData",
    "euler_matrix",
    "find_asf",
    "parse_asf",
    "read_amc",
    "read_asf",
    "skeleton_from_asf",
]
