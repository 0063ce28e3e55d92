"""OpenSim export: the joints as TRC markers in OpenSim's frame, a model of our skeleton
with a marker at each joint centre, and an inverse-kinematics setup, so that OpenSim's IK
runs on a result in one step.

`write_opensim_folder` writes, into one folder:

- ``markers.trc``: the canonical joints (from the pose, NaN where not observed) as markers
  named by their canonical names, in mm, in OpenSim's frame (`OPENSIM_FROM_WORLD`: X
  forward, Y up, Z to the subject's right);
- ``model.osim``: the skeleton the result was tracked with (so scaled to the subject), one
  body per joint, a ``CustomJoint`` per joint with DoFs whose coordinates are the
  skeleton's DoFs (same names, axes and order; the root gets a free 6-DoF joint to the
  ground), a ``WeldJoint`` elsewhere, and a marker at each canonical joint centre named as
  in the TRC;
- ``ik_setup.xml``: an ``InverseKinematicsTool`` with one marker task per marker
  (weight 1), the whole time range, writing ``ik.mot`` beside it.

Then ``opensim-cmd run-tool ik_setup.xml`` or, in Python,
``opensim.InverseKinematicsTool("ik_setup.xml").run()``. The XML is written with the
standard library (`xml.etree.ElementTree`) in OpenSim 4's document format (version 40000).
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import FormatError
from mocapkit.io.atomic import atomic_write
from mocapkit.io.motion import Motion
from mocapkit.io.trc import write_trc
from mocapkit.io.units import OPENSIM_FROM_WORLD
from mocapkit.skeleton.model import BALL, PRISMATIC, REVOLUTE, Skeleton

FloatArray = NDArray[np.float64]

#: The files `write_opensim_folder` writes.
MODEL_FILE = "model.osim"
MARKER_FILE = "markers.trc"
IK_SETUP_FILE = "ik_setup.xml"
IK_OUTPUT_FILE = "ik.mot"
#: OpenSim's document version for the 4.x format.
_DOC_VERSION = "40000"
#: Smallest body mass written (kg): OpenSim bodies need a mass, end points have none.
_MIN_MASS_KG = 0.01
#: Coordinate names of the root's free joint (rotations about OpenSim Z, X, Y, then
#: translations along X, Y, Z: the order of OpenSim's own gait models).
ROOT_COORDINATES = ("root_tilt", "root_list", "root_rotation", "root_tx", "root_ty", "root_tz")


def _vec(v: FloatArray | Sequence[float]) -> str:
    return " ".join(f"{float(x):.9g}" for x in v)


def _sub(parent: ET.Element, tag: str, text: str | None = None, **attrib: str) -> ET.Element:
    el = ET.SubElement(parent, tag, attrib)
    if text is not None:
        el.text = text
    return el


def _complete_axes(axes: list[FloatArray]) -> list[FloatArray]:
    """Extend up to three independent unit axes to three (the unused ones of a joint)."""
    out = [a / np.linalg.norm(a) for a in axes]
    for e in np.eye(3):
        if len(out) == 3:
            break
        m = np.array([*out, e])
        if np.linalg.matrix_rank(m, tol=1e-6) == len(out) + 1:
            out.append(e)
    return out


def _coordinate(parent: ET.Element, name: str, lo: float, hi: float) -> None:
    c = _sub(parent, "Coordinate", name=name)
    _sub(c, "default_value", "0")
    _sub(c, "default_speed_value", "0")
    _sub(c, "range", f"{lo:.9g} {hi:.9g}")
    _sub(c, "clamped", "false")
    _sub(c, "locked", "false")


def _transform_axis(
    parent: ET.Element, name: str, coordinate: str | None, axis: FloatArray
) -> None:
    ax = _sub(parent, "TransformAxis", name=name)
    _sub(ax, "coordinates", coordinate or "")
    _sub(ax, "axis", _vec(axis))
    if coordinate:
        f = _sub(ax, "LinearFunction", name="function")
        _sub(f, "coefficients", "1 0")
    else:
        f = _sub(ax, "Constant", name="function")
        _sub(f, "value", "0")


def _frames(
    joint: ET.Element, parent_path: str, child_path: str, translation_m: FloatArray
) -> None:
    _sub(joint, "socket_parent_frame", "parent_offset")
    _sub(joint, "socket_child_frame", "child_offset")
    frames = _sub(joint, "frames")
    for name, path, t in (
        ("parent_offset", parent_path, translation_m),
        ("child_offset", child_path, np.zeros(3)),
    ):
        f = _sub(frames, "PhysicalOffsetFrame", name=name)
        _sub(f, "socket_parent", path)
        _sub(f, "translation", _vec(t))
        _sub(f, "orientation", "0 0 0")


def opensim_model_xml(skeleton: Skeleton, marker_names: Sequence[str], name: str) -> ET.Element:
    """The ``OpenSimDocument`` of a model of ``skeleton`` with markers at the canonical
    joints ``marker_names`` (see the module docstring)."""
    r = OPENSIM_FROM_WORLD
    doc = ET.Element("OpenSimDocument", Version=_DOC_VERSION)
    model = _sub(doc, "Model", name=name)
    _sub(model, "credits", "mocapkit: generated from the tracked skeleton")
    _sub(model, "length_units", "meters")
    _sub(model, "force_units", "N")
    _sub(model, "gravity", "0 -9.80665 0")
    bodies = _sub(_sub(model, "BodySet", name="bodyset"), "objects")
    joints = _sub(_sub(model, "JointSet", name="jointset"), "objects")
    names = skeleton.joint_names
    for j, jname in enumerate(names):
        body = _sub(bodies, "Body", name=jname)
        mass = max(float(skeleton.mass_kg[j]), _MIN_MASS_KG)
        end_m = r @ np.asarray(skeleton.bone_end_mm[j], float) / 1000.0
        length = float(np.linalg.norm(end_m))
        _sub(body, "mass", f"{mass:.9g}")
        _sub(body, "mass_center", _vec(end_m * float(skeleton.com_fraction[j])))
        # a slender rod about its centre, never zero
        i_rod = max(mass * length**2 / 12.0, 1e-5)
        _sub(body, "inertia", f"{i_rod:.9g} {i_rod:.9g} {i_rod:.9g} 0 0 0")
        p = int(skeleton.parents[j])
        parent_path = "/ground" if p < 0 else f"/bodyset/{names[p]}"
        offset_m = r @ np.asarray(skeleton.offsets_mm[j], float) / 1000.0
        dofs = np.flatnonzero(skeleton.dof_joint == j)
        if p < 0:
            _root_joint(joints, jname, parent_path, offset_m, skeleton, dofs)
            continue
        if dofs.size == 0:
            weld = _sub(joints, "WeldJoint", name=f"{jname}_joint")
            _frames(weld, parent_path, f"/bodyset/{jname}", offset_m)
            continue
        joint = _sub(joints, "CustomJoint", name=f"{jname}_joint")
        _frames(joint, parent_path, f"/bodyset/{jname}", offset_m)
        coords = _sub(joint, "coordinates")
        rot: list[tuple[str, FloatArray]] = []
        trans: list[tuple[str, FloatArray]] = []
        for d in dofs:
            kind = int(skeleton.dof_kind[d])
            lo, hi = float(skeleton.lower[d]), float(skeleton.upper[d])
            if kind == BALL:
                continue  # its three components are handled with its first DoF below
            if kind == REVOLUTE:
                lo, hi = (lo, hi) if np.isfinite([lo, hi]).all() else (-np.pi, np.pi)
                rot.append((skeleton.dof_names[d], r @ skeleton.dof_axis[d]))
            elif kind == PRISMATIC:
                lo, hi = (lo / 1000, hi / 1000) if np.isfinite([lo, hi]).all() else (-1.0, 1.0)
                trans.append((skeleton.dof_names[d], r @ skeleton.dof_axis[d]))
            _coordinate(coords, skeleton.dof_names[d], lo, hi)
        ball = dofs[skeleton.dof_kind[dofs] == BALL]
        for k, d in enumerate(ball[:3] if ball.size else ()):
            _coordinate(coords, skeleton.dof_names[d], -np.pi, np.pi)
            rot.append((skeleton.dof_names[d], r @ np.eye(3)[k]))
        if len(rot) > 3 or len(trans) > 3:
            raise FormatError(
                f"OpenSim model: joint {jname!r} has {len(rot)} rotational and {len(trans)} "
                "translational DoFs; expected at most 3 of each"
            )
        _spatial_transform(joint, rot, trans)
    markers = _sub(_sub(model, "MarkerSet", name="markerset"), "objects")
    for m in marker_names:
        if m not in skeleton.canonical:
            raise FormatError(
                f"OpenSim model: marker {m!r}: expected a canonical joint of skeleton "
                f"{skeleton.name!r}, found none; valid: {sorted(skeleton.canonical)}"
            )
        jname, point = skeleton.canonical[m]
        mk = _sub(markers, "Marker", name=m)
        _sub(mk, "socket_parent_frame", f"/bodyset/{jname}")
        _sub(mk, "location", _vec(r @ np.asarray(point, float) / 1000.0))
        _sub(mk, "fixed", "false")
    return doc


def _spatial_transform(
    joint: ET.Element,
    rot: list[tuple[str, FloatArray]],
    trans: list[tuple[str, FloatArray]],
) -> None:
    st = _sub(joint, "SpatialTransform")
    for prefix, used in (("rotation", rot), ("translation", trans)):
        axes = _complete_axes([a for _, a in used])
        for k in range(3):
            coord = used[k][0] if k < len(used) else None
            _transform_axis(st, f"{prefix}{k + 1}", coord, axes[k])


def _root_joint(
    joints: ET.Element,
    jname: str,
    parent_path: str,
    offset_m: FloatArray,
    skeleton: Skeleton,
    dofs: NDArray[np.int64],
) -> None:
    """The root's free joint to the ground (whatever DoFs the skeleton's root has: a
    model in OpenSim must be able to stand anywhere)."""
    joint = _sub(joints, "CustomJoint", name=f"{jname}_joint")
    _frames(joint, parent_path, f"/bodyset/{jname}", offset_m)
    coords = _sub(joint, "coordinates")
    for k, c in enumerate(ROOT_COORDINATES):
        if k < 3:
            _coordinate(coords, c, -2 * np.pi, 2 * np.pi)
        else:
            _coordinate(coords, c, -50.0, 50.0)
    e = np.eye(3)
    rot = [(ROOT_COORDINATES[0], e[2]), (ROOT_COORDINATES[1], e[0]), (ROOT_COORDINATES[2], e[1])]
    trans = [(c, e[k]) for k, c in enumerate(ROOT_COORDINATES[3:])]
    _spatial_transform(joint, rot, trans)


def ik_setup_xml(
    marker_names: Sequence[str],
    time_range_s: tuple[float, float],
    model_file: str = MODEL_FILE,
    marker_file: str = MARKER_FILE,
    output_file: str = IK_OUTPUT_FILE,
) -> ET.Element:
    """The ``OpenSimDocument`` of an ``InverseKinematicsTool``: one marker task per marker
    (weight 1) over ``time_range_s``; file names relative to the setup file."""
    doc = ET.Element("OpenSimDocument", Version=_DOC_VERSION)
    tool = _sub(doc, "InverseKinematicsTool", name="mocapkit_ik")
    _sub(tool, "results_directory", ".")
    _sub(tool, "model_file", model_file)
    _sub(tool, "constraint_weight", "Inf")
    _sub(tool, "accuracy", "1e-05")
    tasks = _sub(_sub(tool, "IKTaskSet", name="ik_tasks"), "objects")
    for m in marker_names:
        task = _sub(tasks, "IKMarkerTask", name=m)
        _sub(task, "apply", "true")
        _sub(task, "weight", "1")
    _sub(tool, "marker_file", marker_file)
    _sub(tool, "coordinate_file", "Unassigned")
    _sub(tool, "time_range", f"{time_range_s[0]:.9g} {time_range_s[1]:.9g}")
    _sub(tool, "report_errors", "true")
    _sub(tool, "output_motion_file", output_file)
    _sub(tool, "report_marker_locations", "false")
    return doc


def _write_xml(path: Path, doc: ET.Element) -> None:
    ET.indent(doc, space="\t")
    text = ET.tostring(doc, encoding="unicode")
    with atomic_write(path, "w", newline="\n") as fh:
        fh.write('<?xml version="1.0" encoding="UTF-8" ?>\n' + text + "\n")


def pose_joints_mm(motion: Motion) -> FloatArray:
    """The canonical joints of ``motion``'s pose (forward kinematics of ``q``, in the
    world frame), NaN wherever ``motion.joints_mm`` is NaN (not observed) and for joints
    the skeleton lacks (a mono result's legs beside its upper-body stick)."""
    posed = Motion.from_q(motion.skeleton, motion.time_s, motion.q)
    joints = np.full(np.shape(motion.joints_mm), np.nan)
    have = [k for k, n in enumerate(motion.joint_names) if n in posed.joint_names]
    rows = [posed.joint_names.index(motion.joint_names[k]) for k in have]
    joints[:, have] = posed.joints_mm[:, rows]
    joints[np.isnan(motion.joints_mm).any(axis=-1)] = np.nan
    return joints


def write_opensim_folder(
    folder: str | os.PathLike[str],
    motion: Motion,
    name: str = "mocapkit",
) -> Path:
    """Write ``markers.trc``, ``model.osim`` and ``ik_setup.xml`` (module docstring) into
    ``folder`` (created when missing), each atomically; returns the folder.

    ``motion.joints_mm`` only says which joints were observed: the markers are the
    pose's joints in the world frame (`pose_joints_mm`), so a result whose
    ``joints.csv`` is in a lab's own axes gives the same files.
    """
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    names = [n for n in motion.joint_names if n in motion.skeleton.canonical]
    keep = [motion.joint_names.index(n) for n in names]
    joints = pose_joints_mm(motion)[:, keep]
    seen = np.isfinite(joints).all(axis=-1).any(axis=0)
    names = [names[k] for k in np.flatnonzero(seen)]
    joints = joints[:, seen]
    rate = None if motion.n_frames > 1 else 30.0
    write_trc(
        out / MARKER_FILE,
        motion.time_s,
        names,
        joints,
        rate_hz=rate,
        file_from_world=OPENSIM_FROM_WORLD,
    )
    _write_xml(out / MODEL_FILE, opensim_model_xml(motion.skeleton, names, name))
    t = motion.time_s
    _write_xml(out / IK_SETUP_FILE, ik_setup_xml(names, (float(t[0]), float(t[-1]))))
    return out


__all__ = [
    "IK_OUTPUT_FILE",
    "IK_SETUP_FILE",
    "MARKER_FILE",
    "MODEL_FILE",
    "ROOT_COORDINATES",
    "ik_setup_xml",
    "opensim_model_xml",
    "pose_joints_mm",
    "write_opensim_folder",
]
