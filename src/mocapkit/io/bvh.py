"""BVH (Biovision hierarchy) motion files: read into a `Motion`, write any `Motion` back.

Reading
-------
Every joint becomes a `Skeleton` joint whose frame is parallel to the world at
rest, as in BVH. Its DoFs are its position channels (prismatic, listed first)
then its rotation channels in file order, so ``CHANNELS 3 Zrotation Yrotation
Xrotation`` gives ``R = Rz @ Ry @ Rx``. Position channels hold the joint's
whole local translation (Blender's reading; the CMU roots have a zero OFFSET
anyway): the skeleton keeps the OFFSET as rest offset and the prismatic DoF
holds ``channel - OFFSET``. An ``End Site`` is not a joint; it becomes the
``bone_end_mm`` of its joint; otherwise a joint's segment ends at its first
child. The file frame (Y up) is turned into the mocapkit world (Z up, facing
+Y) by `WORLD_FROM_FILE`, applied to offsets, DoF axes and translations, so
that world FK equals the file's FK rotated by that matrix.

Units (``unit_mm=None``): the cgspeed CMU conversions (both naming conventions)
use the CMU unit, (1/0.45) inch = 56.444 mm (their OFFSETs are the ASF
``direction x length`` and their root positions equal the AMC's), so files with
CMU joint names are read in CMU units when that gives a rest height between
0.9 and 2.3 m. Other files (and CMU-named files outside that range, e.g.
re-exported in cm): the unit among mm, cm, inch, CMU unit and m that makes the
rest pose about 1.7 m tall (`mocapkit.io.units.infer_unit_mm`).

Rest frame of the cgspeed MotionBuilder-friendly files: their frame 0 is a
reference pose added by the converter. ``drop_rest_frame="auto"`` drops frame 0
when the joint names follow that convention and frame 0 looks added: its root
rotation is zero and every rotation value is a whole number of degrees (never
the case for captured data). ``True`` always drops frame 0, ``False`` never does.
Times start at 0 s at the first returned frame.

Known property of the cgspeed MotionBuilder-friendly skeleton (checked on a CMU
trial against the original ASF/AMC): it omits the ASF ``thorax`` segment (Neck,
LeftShoulder and RightShoulder sit at Spine1's origin with OFFSET 0) and the
``lwrist``/``rwrist`` lengths, so its neck, head, shoulders, elbows and wrists
lie one thorax length (116.55 mm for subject 01) lower than the AMC's, while
pelvis, hips, knees and ankles agree to 0.005 mm. The 3dsMax-friendly files have
the same layout (``lowerneck`` at ``Chest2``'s origin).

Writing
-------
`write_bvh` writes any skeleton: OFFSETs from the rest offsets, ``End Site``
for leaf joints (their ``bone_end_mm``), the root with ``Xposition Yposition
Zposition Zrotation Yrotation Xrotation``, other joints with ``Zrotation
Yrotation Xrotation`` (plus the three position channels first for a non-root
joint that has its own prismatic DoFs: BVH allows them and Blender reads them).
Values come from forward kinematics, so any DoF layout (arbitrary axes, ball
joints) is written exactly: each joint's local rotation is converted into the
file frame (`FILE_FROM_WORLD`) and into ZYX Euler degrees.
"""

from __future__ import annotations

import io
import os
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numba
import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from mocapkit.errors import FormatError
from mocapkit.io.atomic import atomic_write
from mocapkit.io.motion import Motion
from mocapkit.io.naming import canonical_map, detect_convention
from mocapkit.io.units import (
    CMU_UNIT_MM,
    FILE_FROM_WORLD,
    WORLD_FROM_FILE,
    infer_unit_mm,
    rest_height_units,
)
from mocapkit.skeleton.kinematics import forward_kinematics
from mocapkit.skeleton.model import PRISMATIC, REVOLUTE, Skeleton
from mocapkit.skeleton.roll import RollLimiter

FloatArray = NDArray[np.float64]

_CHANNELS = {
    "xposition": ("P", 0),
    "yposition": ("P", 1),
    "zposition": ("P", 2),
    "xrotation": ("R", 0),
    "yrotation": ("R", 1),
    "zrotation": ("R", 2),
}
_MB_CONVENTION = "CMU MotionBuilder-friendly BVH (cgspeed)"
#: Rest heights (mm) for which CMU-named files are taken to be in CMU units; outside
#: this range (e.g. a CMU skeleton re-exported in cm) the stature rule decides.
CMU_PLAUSIBLE_HEIGHT_MM = (900.0, 2300.0)


@dataclass
class BvhJoint:
    """One joint of a parsed BVH hierarchy (file units, file frame)."""

    name: str
    parent: int
    offset: FloatArray
    channels: list[str]
    end_site: FloatArray | None = None
    children: list[int] = field(default_factory=list)


@dataclass
class BvhData:
    """The raw content of a BVH file: hierarchy, frame time and the channel values."""

    joints: list[BvhJoint]
    frame_time_s: float
    values: FloatArray  # (T, C) in file units and degrees, channels in file order
    ignored_extra_frames: int = 0  # complete frames found after the declared 'Frames:' count


class _Tokens:
    """Whitespace tokens of the hierarchy with their line numbers."""

    def __init__(self, lines: list[str], where: str) -> None:
        self.items: list[tuple[str, int]] = []
        for n, line in enumerate(lines, start=1):
            for tok in line.replace("{", " { ").replace("}", " } ").split():
                self.items.append((tok, n))
        self.pos = 0
        self.where = where
        self.last_line = len(lines)

    def peek(self) -> tuple[str, int]:
        if self.pos >= len(self.items):
            return ("", self.last_line)
        return self.items[self.pos]

    def next(self, expected: str) -> tuple[str, int]:
        tok, line = self.peek()
        if not tok:
            raise FormatError(
                f"{self.where}: line {line}: hierarchy ends early (unbalanced braces?): "
                f"expected {expected}, found the end of the HIERARCHY section"
            )
        self.pos += 1
        return tok, line

    def expect(self, word: str) -> int:
        tok, line = self.next(repr(word))
        if tok.lower() != word.lower():
            raise FormatError(f"{self.where}: line {line}: expected {word!r}, found {tok!r}")
        return line

    def rest_of_line(self, line: int, what: str) -> str:
        parts = []
        while (
            self.pos < len(self.items)
            and self.items[self.pos][1] == line
            and self.items[self.pos][0] not in "{}"
        ):
            parts.append(self.items[self.pos][0])
            self.pos += 1
        if not parts:
            raise FormatError(f"{self.where}: line {line}: expected {what}, found nothing")
        return " ".join(parts)

    def numbers(self, count: int, what: str) -> FloatArray:
        out = np.empty(count)
        for i in range(count):
            tok, line = self.next(f"{count} numbers for {what}")
            try:
                out[i] = float(tok)
            except ValueError:
                raise FormatError(
                    f"{self.where}: line {line}: expected a number for {what}, found {tok!r}"
                ) from None
        return out


def _parse_joint(tokens: _Tokens, name: str, parent: int, joints: list[BvhJoint]) -> None:
    where = tokens.where
    tokens.expect("{")
    tokens.expect("OFFSET")
    offset = tokens.numbers(3, f"OFFSET of joint {name!r}")
    channels: list[str] = []
    if tokens.peek()[0].upper() == "CHANNELS":
        tokens.next("CHANNELS")
        n_tok, line = tokens.next("channel count")
        try:
            n_ch = int(n_tok)
        except ValueError:
            raise FormatError(
                f"{where}: line {line}: expected a channel count, found {n_tok!r}"
            ) from None
        for _ in range(n_ch):
            ch, line = tokens.next(f"{n_ch} channel names for joint {name!r}")
            if ch.lower() not in _CHANNELS:
                raise FormatError(
                    f"{where}: line {line}: joint {name!r}: unknown channel {ch!r}; "
                    "expected one of "
                    f"Xposition Yposition Zposition Xrotation Yrotation Zrotation"
                )
            channels.append(ch.lower())
        if len(set(channels)) != len(channels):
            raise FormatError(f"{where}: line {line}: joint {name!r} repeats a channel: {channels}")
    index = len(joints)
    joints.append(BvhJoint(name, parent, offset, channels))
    if parent >= 0:
        joints[parent].children.append(index)
    while True:
        tok, line = tokens.next(f"JOINT, End Site or '}}' closing joint {name!r}")
        key = tok.upper()
        if key == "}":
            return
        if key == "JOINT":
            child = tokens.rest_of_line(line, "a joint name")
            _parse_joint(tokens, child, index, joints)
        elif key == "END":
            tokens.expect("Site")
            tokens.expect("{")
            tokens.expect("OFFSET")
            end = tokens.numbers(3, f"End Site of joint {name!r}")
            tokens.expect("}")
            if joints[index].end_site is None:
                joints[index].end_site = end
        else:
            raise FormatError(
                f"{where}: line {line}: inside joint {name!r}: expected JOINT, End Site or '}}', "
                f"found {tok!r}"
            )


def parse_bvh(path: str | os.PathLike[str]) -> BvhData:
    """Parse a BVH file into its hierarchy and raw channel values (no unit or frame change).

    Raises `FormatError` naming the file, line, what was expected and what was found.
    """
    where = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise FormatError(f"{where}: cannot read BVH file ({exc})") from None
    lines = text.splitlines()
    motion_at = next((i for i, ln in enumerate(lines) if ln.strip().upper() == "MOTION"), None)
    if motion_at is None:
        raise FormatError(f"{where}: missing 'MOTION' section (expected after the HIERARCHY)")
    tokens = _Tokens(lines[:motion_at], where)
    tokens.expect("HIERARCHY")
    line = tokens.expect("ROOT")
    joints: list[BvhJoint] = []
    _parse_joint(tokens, tokens.rest_of_line(line, "the root joint name"), -1, joints)
    extra, line = tokens.peek()
    if extra:
        raise FormatError(
            f"{where}: line {line}: expected 'MOTION' after the root joint's closing brace "
            f"(one ROOT per file, braces balanced), found {extra!r}"
        )

    # --- MOTION header
    def header(i: int, key: str) -> str:
        if i >= len(lines):
            raise FormatError(f"{where}: line {i + 1}: expected {key!r}, found the end of the file")
        s = lines[i].strip()
        if not s.lower().replace(" ", "").startswith(key.lower().replace(" ", "") + ":"):
            raise FormatError(f"{where}: line {i + 1}: expected '{key}: <value>', found {s!r}")
        return s.split(":", 1)[1].strip()

    i = motion_at + 1
    frames_txt = header(i, "Frames")
    ftime_txt = header(i + 1, "Frame Time")
    try:
        n_frames = int(frames_txt)
    except ValueError:
        raise FormatError(
            f"{where}: line {i + 1}: 'Frames:' expects an integer, found {frames_txt!r}"
        ) from None
    try:
        frame_time = float(ftime_txt)
    except ValueError:
        raise FormatError(
            f"{where}: line {i + 2}: 'Frame Time:' expects a number, found {ftime_txt!r}"
        ) from None
    if n_frames < 0 or not frame_time > 0:
        raise FormatError(
            f"{where}: line {i + 1}: expected Frames >= 0 and Frame Time > 0, "
            f"found {n_frames} and {frame_time}"
        )
    n_ch = sum(len(j.channels) for j in joints)
    data_lines = lines[i + 2 :]
    tokens_flat = " ".join(data_lines).split()
    extra_frames = 0
    if len(tokens_flat) != n_frames * n_ch:
        counts = [len(ln.split()) for ln in data_lines]
        nonempty = [(k, c) for k, c in enumerate(counts) if c]
        bad = next(((k, c) for k, c in nonempty if c != n_ch), None)
        if bad is None and n_ch and len(nonempty) > n_frames:
            # whole extra frames after the declared count (some exporters miscount by one):
            # the header is authoritative; the extras are ignored and reported in Motion.source
            extra_frames = len(nonempty) - n_frames
            tokens_flat = tokens_flat[: n_frames * n_ch]
        else:
            detail = f"; line {i + 3 + bad[0]} has {bad[1]} values" if bad is not None else ""
            raise FormatError(
                f"{where}: MOTION block: expected {n_frames} frames x {n_ch} channels = "
                f"{n_frames * n_ch} values, found {len(tokens_flat)} values "
                f"in {len(nonempty)} lines "
                f"(truncated file or wrong 'Frames:'?){detail}"
            )
    try:
        values = np.array(tokens_flat, dtype=float).reshape(n_frames, n_ch)
    except ValueError:
        for k, ln in enumerate(data_lines):
            for tok in ln.split():
                try:
                    float(tok)
                except ValueError:
                    raise FormatError(
                        f"{where}: line {i + 3 + k}: expected a number, found {tok!r}"
                    ) from None
        raise  # unreachable: every token parsed above
    if not np.all(np.isfinite(values)):
        raise FormatError(f"{where}: MOTION block holds non-finite values (nan/inf)")
    return BvhData(joints, frame_time, values, extra_frames)


def _looks_like_added_rest_frame(data: BvhData) -> bool:
    """True when frame 0 is the converter's reference pose (see module docstring)."""
    if data.values.shape[0] < 2:
        return False
    col = 0
    rot_cols: list[int] = []
    root_rot: list[int] = []
    for j, joint in enumerate(data.joints):
        for ch in joint.channels:
            if _CHANNELS[ch][0] == "R":
                rot_cols.append(col)
                if j == 0:
                    root_rot.append(col)
            col += 1
    first = data.values[0]
    return bool(
        np.all(first[root_rot] == 0) and np.all(first[rot_cols] == np.round(first[rot_cols]))
    )


def skeleton_from_bvh(
    data: BvhData,
    unit_mm: float,
    name: str,
    canonical: dict[str, tuple[str, tuple[float, float, float]]] | None = None,
) -> tuple[Skeleton, NDArray[np.int64], FloatArray, FloatArray]:
    """Build the `Skeleton` of a parsed BVH and the map from channel values to ``q``.

    Returns
    -------
    skeleton : Skeleton
    columns : ndarray of int, shape (D,)
        File channel column feeding each DoF.
    scale : ndarray, shape (D,)
        Multiplier from channel value to ``q`` (mm per unit, or rad per degree).
    shift : ndarray, shape (D,)
        Subtracted from the channel value before scaling (the OFFSET for positions).
    """
    w = WORLD_FROM_FILE
    n = len(data.joints)
    offsets = np.array([w @ j.offset for j in data.joints]) * unit_mm
    ends = np.zeros((n, 3))
    for k, j in enumerate(data.joints):
        if j.children:
            ends[k] = offsets[j.children[0]]
        elif j.end_site is not None:
            ends[k] = (w @ j.end_site) * unit_mm
    dof_joint, dof_kind, dof_axis, dof_names, cols, scale, shift = [], [], [], [], [], [], []
    col = 0
    for k, j in enumerate(data.joints):
        start = col
        entries = [(_CHANNELS[ch], start + c, ch) for c, ch in enumerate(j.channels)]
        col += len(j.channels)
        # prismatic DoFs first (translation is applied before the rotations in BVH, T @ R)
        for (kind, axis), c, ch in sorted(entries, key=lambda e: e[0][0] != "P"):
            dof_joint.append(k)
            dof_axis.append(w[:, axis])
            dof_names.append(f"{j.name}_{ch}")
            cols.append(c)
            if kind == "P":
                dof_kind.append(PRISMATIC)
                scale.append(unit_mm)
                shift.append(j.offset[axis])
            else:
                dof_kind.append(REVOLUTE)
                scale.append(np.pi / 180.0)
                shift.append(0.0)
    d = len(dof_names)
    skeleton = Skeleton(
        name=name,
        joint_names=tuple(j.name for j in data.joints),
        parents=np.array([j.parent for j in data.joints], dtype=np.int64),
        offsets_mm=offsets,
        dof_joint=np.array(dof_joint, dtype=np.int64),
        dof_kind=np.array(dof_kind, dtype=np.int64),
        dof_axis=np.array(dof_axis).reshape(d, 3),
        dof_names=tuple(dof_names),
        lower=np.full(d, -np.inf),
        upper=np.full(d, np.inf),
        bone_end_mm=ends,
        mass_kg=np.zeros(n),
        com_fraction=np.full(n, 0.5),
        radii_mm=np.zeros((n, 2)),
        canonical=canonical or {},
    )
    return skeleton, np.array(cols, dtype=np.int64), np.array(scale), np.array(shift)


def read_bvh(
    path: str | os.PathLike[str],
    unit_mm: float | None = None,
    drop_rest_frame: bool | str = "auto",
) -> Motion:
    """Read a BVH file into a `Motion` (world frame Z up, mm, radians).

    Parameters
    ----------
    path : path-like
    unit_mm : float, optional
        Millimetres per file unit. Default: the CMU unit (56.444 mm) for the
        cgspeed CMU naming conventions, otherwise inferred from a 1.7 m rest
        stature (see module docstring).
    drop_rest_frame : {"auto", True, False}
        Whether to drop frame 0 as an added reference pose (see module docstring).

    Returns
    -------
    Motion
        ``time_s`` starts at 0 at the first returned frame; canonical joints are
        filled from the naming tables in `mocapkit.io.naming` (joints whose name
        is not found are left out).
    """
    where = str(path)
    if drop_rest_frame not in ("auto", True, False):
        raise FormatError(
            f"read_bvh: drop_rest_frame must be 'auto', True or False, found {drop_rest_frame!r}"
        )
    data = parse_bvh(path)
    names = [j.name for j in data.joints]
    convention, exact = detect_convention(names)
    if unit_mm is None:
        ends = np.array(
            [
                data.joints[j.children[0]].offset
                if j.children
                else (j.end_site if j.end_site is not None else np.zeros(3))
                for j in data.joints
            ]
        )
        height = rest_height_units(
            np.array([j.offset for j in data.joints]), [j.parent for j in data.joints], ends
        )
        cmu_named = exact and convention is not None and convention.name.startswith("CMU")
        if (
            cmu_named
            and CMU_PLAUSIBLE_HEIGHT_MM[0] <= height * CMU_UNIT_MM <= CMU_PLAUSIBLE_HEIGHT_MM[1]
        ):
            unit_mm = CMU_UNIT_MM
        else:
            unit_mm = infer_unit_mm(height, where)
    elif not (unit_mm > 0 and np.isfinite(unit_mm)):
        raise FormatError(
            f"read_bvh({where}): unit_mm must be a positive number, found {unit_mm!r}"
        )
    if drop_rest_frame == "auto":
        drop = bool(
            exact
            and convention is not None
            and convention.name == _MB_CONVENTION
            and _looks_like_added_rest_frame(data)
        )
    else:
        drop = bool(drop_rest_frame) and data.values.shape[0] > 0
    values = data.values[1:] if drop else data.values
    skeleton, cols, scale, shift = skeleton_from_bvh(data, float(unit_mm), Path(path).stem)
    skeleton = skeleton.replace(
        canonical=canonical_map(skeleton.joint_names, skeleton.bone_end_mm, convention)
    )
    q = (values[:, cols] - shift) * scale
    time_s = np.arange(values.shape[0]) * data.frame_time_s
    conv_txt = (
        convention.name
        if (convention and exact)
        else (
            f"unknown naming (partial match to {convention.name})"
            if convention
            else "unknown naming"
        )
    )
    extra = data.ignored_extra_frames
    extra_note = f"; {extra} frames beyond 'Frames:' ignored" if extra else ""
    source = (
        f"{where} (BVH; {conv_txt}; unit {float(unit_mm):.6g} mm"
        f"{'; added rest frame 0 dropped' if drop else ''}"
        f"{extra_note})"
    )
    return Motion.from_q(skeleton, time_s, q, source)


# ---------------------------------------------------------------- writing

_NAME_SAFE = re.compile(r"\s+")


def _fill_missing(q: FloatArray) -> FloatArray:
    """Hold the previous valid pose over rows with NaN (the first valid one before it)."""
    valid = ~np.any(np.isnan(q), axis=1)
    if not np.any(valid):
        raise FormatError("write_bvh: the motion has no frame with a pose; BVH cannot hold it")
    idx = np.where(valid, np.arange(len(q)), -1)
    idx = np.maximum.accumulate(idx)
    idx[idx < 0] = np.flatnonzero(valid)[0]
    return q[idx]


def continuous_euler(angles_rad: FloatArray) -> FloatArray:
    """ZYX Euler angles (T, ..., 3) made continuous over time: each frame takes, of its two
    equivalent triples ``(z, y, x)`` and ``(z + pi, pi - y, x + pi)`` and every whole turn
    added to each, the one nearest the previous frame's. The rotations are unchanged; the
    channels no longer jump by 360 deg or flip between the two solutions, so a program
    that interpolates or filters the channels (Blender's F-curves) sees no spin.
    """
    a = np.array(angles_rad, dtype=float, copy=True)
    if a.shape[0] < 2:
        return a
    flat = np.ascontiguousarray(a.reshape(a.shape[0], -1, 3))
    _continuous_euler_nb(flat)
    return flat.reshape(a.shape)


@numba.njit(cache=True)
def _continuous_euler_nb(a: FloatArray) -> None:
    """`continuous_euler` in place on (T, N, 3)."""
    two_pi = 2.0 * np.pi
    best = np.empty(3)
    cand = np.empty(3)
    for t in range(1, a.shape[0]):
        for n in range(a.shape[1]):
            p0, p1, p2 = a[t - 1, n, 0], a[t - 1, n, 1], a[t - 1, n, 2]
            if not (np.isfinite(p0) and np.isfinite(p1) and np.isfinite(p2)):
                continue
            if not np.isfinite(a[t, n, 0] + a[t, n, 1] + a[t, n, 2]):
                continue
            best_d = np.inf
            for branch in range(2):
                if branch == 0:
                    cand[0], cand[1], cand[2] = a[t, n, 0], a[t, n, 1], a[t, n, 2]
                else:
                    cand[0] = a[t, n, 0] + np.pi
                    cand[1] = np.pi - a[t, n, 1]
                    cand[2] = a[t, n, 2] + np.pi
                d = 0.0
                for k in range(3):
                    prev = (p0, p1, p2)[k]
                    cand[k] -= two_pi * np.round((cand[k] - prev) / two_pi)
                    d += (cand[k] - prev) ** 2
                if d < best_d:
                    best_d = d
                    best[:] = cand
            a[t, n, :] = best


#: Fastest turn of a bone about its own axis written to a result's BVH (rad/s): about
#: 1200 deg/s, near the fastest forearm pronation reported in throwing; a roll that the
#: tracker changes faster (a flip of an arm about its own line, which no joint shows) is
#: caught up at this speed (`mocapkit.skeleton.roll.limit_roll`).
MAX_ROLL_SPEED_RAD_S = float(np.deg2rad(1200.0))


def write_bvh(
    path: str | os.PathLike[str],
    motion: Motion,
    unit_mm: float = 1000.0,
    frame_time_s: float | None = None,
    max_roll_speed_rad_s: float | None = None,
) -> None:
    """Write a motion of any skeleton as BVH (Y up, atomically).

    Parameters
    ----------
    path : path-like
    motion : Motion
    unit_mm : float
        Millimetres per file unit; default 1000 (metres), so Blender, which reads one BVH
        unit as one metre, imports the subject at true size.
    frame_time_s : float, optional
        ``Frame Time``; default the median step of ``motion.time_s`` (BVH assumes a
        constant rate), or 1/30 s for a single frame.
    max_roll_speed_rad_s : float, optional
        Where given, each bone that turns about its own axis without moving a joint
        (`mocapkit.skeleton.roll.roll_free_bones`) turns by at most this speed times the
        frame time per frame (`mocapkit.skeleton.roll.limit_roll`; result folders use
        `MAX_ROLL_SPEED_RAD_S`); joint positions are unchanged. Default: the rotations
        as they are.

    Notes
    -----
    Frames without a pose (NaN rows of ``q``) cannot be expressed in BVH; they are
    written as the previous valid pose (the first valid pose for leading ones).
    Values are written with 10 decimals, enough for a sub-micrometre round trip.
    Euler angles are continuous from frame to frame (`continuous_euler`).
    """
    if not (unit_mm > 0 and np.isfinite(unit_mm)):
        raise FormatError(
            f"write_bvh({path}): unit_mm must be a positive number, found {unit_mm!r}"
        )
    skel = motion.skeleton
    if motion.n_frames == 0:
        raise FormatError(f"write_bvh({path}): the motion has no frames")
    q = _fill_missing(np.asarray(motion.q, dtype=float))
    if frame_time_s is None:
        steps = np.diff(motion.time_s)
        frame_time_s = float(np.median(steps)) if steps.size else 1.0 / 30.0
    if not frame_time_s > 0:
        raise FormatError(f"write_bvh({path}): frame time must be > 0 s, found {frame_time_s!r}")
    n_t, n_j = q.shape[0], skel.n_joints
    parents = skel.parents
    has_prismatic = np.zeros(n_j, dtype=bool)
    has_prismatic[skel.dof_joint[skel.dof_kind == PRISMATIC]] = True
    limiter = (
        None
        if max_roll_speed_rad_s is None
        else RollLimiter(skel, max_roll_speed_rad_s * frame_time_s)
    )

    names = [_NAME_SAFE.sub("_", n) for n in skel.joint_names]
    children: list[list[int]] = [[] for _ in range(n_j)]
    for j in range(1, n_j):
        children[parents[j]].append(j)
    out = io.StringIO()
    out.write("HIERARCHY\n")

    def vec(v: FloatArray) -> str:
        return " ".join(f"{x:.10f}" for x in (FILE_FROM_WORLD @ v) / unit_mm)

    def emit(j: int, depth: int) -> None:
        ind = "\t" * depth
        out.write(f"{ind}{'ROOT' if depth == 0 else 'JOINT'} {names[j]}\n{ind}{{\n")
        out.write(f"{ind}\tOFFSET {vec(skel.offsets_mm[j])}\n")
        if j == 0 or has_prismatic[j]:
            out.write(
                f"{ind}\tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\n"
            )
        else:
            out.write(f"{ind}\tCHANNELS 3 Zrotation Yrotation Xrotation\n")
        for c in children[j]:
            emit(c, depth + 1)
        if not children[j]:
            out.write(
                f"{ind}\tEnd Site\n{ind}\t{{\n"
                f"{ind}\t\tOFFSET {vec(skel.bone_end_mm[j])}\n{ind}\t}}\n"
            )
        out.write(f"{ind}}}\n")

    emit(0, 0)
    out.write(f"MOTION\nFrames: {n_t}\nFrame Time: {frame_time_s:.10g}\n")
    with atomic_write(path, "w") as fh:
        fh.write(out.getvalue())  # the hierarchy; the frames go to the file as written
        # in chunks of frames, the roll limit and the Euler continuity carried across
        # their edges (the same values as the whole motion at once, in bounded memory)
        last: FloatArray | None = None
        for a in range(0, n_t, _WRITE_CHUNK):
            values, last = _bvh_values(
                skel, q[a : a + _WRITE_CHUNK], has_prismatic, unit_mm, limiter, last
            )
            np.savetxt(fh, values, fmt="%.10f", delimiter=" ")


#: Frames whose channel values `write_bvh` computes at a time.
_WRITE_CHUNK = 512


def _bvh_values(
    skel: Skeleton,
    q: FloatArray,
    has_prismatic: NDArray[np.bool_],
    unit_mm: float,
    limiter: RollLimiter | None,
    previous: FloatArray | None,
) -> tuple[FloatArray, FloatArray | None]:
    """Channel values (T, C) of consecutive frames ``q`` of `write_bvh`, and their last
    frame's Euler angles (J, 3) (rad) that the next chunk continues from (``previous``:
    those of the chunk before; None at the first)."""
    world = forward_kinematics(skel, q)  # (T, J, 4, 4)
    rot = world[..., :3, :3]
    pos = world[..., :3, 3]
    if limiter is not None:
        rot = limiter(rot)
    f = FILE_FROM_WORLD
    n_t, n_j = q.shape[0], skel.n_joints
    parents = skel.parents
    columns: list[FloatArray] = []
    eulers: list[FloatArray] = []
    slots: list[int] = []
    for j in range(n_j):
        p = parents[j]
        if p < 0:
            local_r = rot[:, j]
            local_t = pos[:, j]
        else:
            local_r = np.einsum("tki,tkl->til", rot[:, p], rot[:, j])
            local_t = np.einsum("tki,tk->ti", rot[:, p], pos[:, j] - pos[:, p])
        if p < 0 or has_prismatic[j]:
            columns.append((local_t @ f.T) / unit_mm)
        r_file = np.einsum("ik,tkl,jl->tij", f, local_r, f)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # gimbal lock: the matrix is still exact
            eulers.append(Rotation.from_matrix(r_file).as_euler("ZYX"))
        slots.append(len(columns))
        columns.append(np.zeros((n_t, 0)))  # joint j's angles, made continuous below
    last = previous
    if eulers:
        angles = np.stack(eulers, axis=1)
        if previous is not None:
            angles = continuous_euler(np.concatenate([previous[None], angles]))[1:]
        else:
            angles = continuous_euler(angles)
        last = angles[-1].copy()
        smooth = np.rad2deg(angles)
        for j, slot in enumerate(slots):
            columns[slot] = smooth[:, j]
    values = np.concatenate(columns, axis=1) if columns else np.zeros((n_t, 0))
    return values, last


__all__ = [
    "MAX_ROLL_SPEED_RAD_S",
    "BvhData",
    "BvhJoint",
    "continuous_euler",
    "parse_bvh",
    "read_bvh",
    "skeleton_from_bvh",
    "write_bvh",
]
