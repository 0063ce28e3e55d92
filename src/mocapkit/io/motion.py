"""The `Motion` result type (skeleton, joint parameters, canonical joints over time) and exports.

Also holds the shared conventions of the motion readers: the frame change from
the Y-up motion-file frame to the mocapkit world (Z up, subject facing +Y, right
side +X), the unit inference from stature, and the naming tables that map each
known file convention onto the canonical joint vocabulary.
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import FormatError, ShapeError
from mocapkit.io.atomic import atomic_save_npz, atomic_write
from mocapkit.skeleton.kinematics import canonical_positions
from mocapkit.skeleton.model import CANONICAL_JOINTS, Skeleton
from mocapkit.skeleton.serialize import skeleton_from_json, skeleton_to_json

FloatArray = NDArray[np.float64]

# ---------------------------------------------------------------- frame and units

#: Rotation taking BVH/ASF file coordinates (Y up; a CMU subject faces +Z with its
#: left side towards +X) to the mocapkit world (Z up, facing +Y, right side +X):
#: file X -> world -X, file Y -> world Z, file Z -> world Y (det +1).
WORLD_FROM_FILE: FloatArray = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])
WORLD_FROM_FILE.setflags(write=False)
#: Inverse of `WORLD_FROM_FILE` (it is its own transpose and inverse).
FILE_FROM_WORLD: FloatArray = WORLD_FROM_FILE.T.copy()
FILE_FROM_WORLD.setflags(write=False)

#: One CMU length unit in mm: the ASF header says ``length 0.45`` and the CMU FAQ
#: states that one unit is (1/0.45) inch. The cgspeed BVH conversions keep the same
#: numbers (their OFFSETs equal ASF direction x length, root positions equal AMC).
CMU_UNIT_MM = 25.4 / 0.45

#: Units considered when a file has none: mm, cm, inch, CMU unit, m.
CANDIDATE_UNITS_MM: Mapping[str, float] = {
    "mm": 1.0,
    "cm": 10.0,
    "inch": 25.4,
    "CMU unit (1/0.45 inch)": CMU_UNIT_MM,
    "m": 1000.0,
}
#: Assumed rest-pose height of the captured person when inferring a unit.
REFERENCE_STATURE_MM = 1700.0


def infer_unit_mm(rest_height_units: float, where: str) -> float:
    """Length unit (mm per file unit) that makes a rest pose about 1.7 m tall.

    The rule: among `CANDIDATE_UNITS_MM` take the one whose scaled height is
    closest to `REFERENCE_STATURE_MM` in ratio (log scale). Raises `FormatError`
    when even the best candidate is off by more than a factor 1.6 (not a
    standing adult, or an unusual unit): then pass ``unit_mm`` explicitly.

    Parameters
    ----------
    rest_height_units : float
        Vertical extent of the skeleton at rest, in file units.
    where : str
        The file, for messages.
    """
    if not (rest_height_units > 0 and math.isfinite(rest_height_units)):
        raise FormatError(
            f"{where}: cannot infer the length unit: the rest pose has height "
            f"{rest_height_units!r} units; pass unit_mm explicitly"
        )
    best_name, best_unit = min(
        CANDIDATE_UNITS_MM.items(),
        key=lambda kv: abs(math.log(rest_height_units * kv[1] / REFERENCE_STATURE_MM)),
    )
    ratio = rest_height_units * best_unit / REFERENCE_STATURE_MM
    if not 1 / 1.6 <= ratio <= 1.6:
        raise FormatError(
            f"{where}: cannot infer the length unit: rest height {rest_height_units:.4g} units is "
            f"{rest_height_units * best_unit:.0f} mm in the closest unit ({best_name}), not near a "
            f"{REFERENCE_STATURE_MM:.0f} mm person; pass unit_mm explicitly"
        )
    return best_unit


def rest_height_units(offsets: FloatArray, parents: Sequence[int], ends: FloatArray) -> float:
    """Vertical (file Y) extent of joint origins and segment ends at rest, in file units.

    Parameters
    ----------
    offsets : ndarray, shape (J, 3)
        Joint offsets in the parent frame (file frame, Y up).
    parents : sequence of int, length J
    ends : ndarray, shape (J, 3)
        Segment ends in each joint frame.
    """
    pos = np.zeros_like(offsets)
    for j, p in enumerate(parents):
        pos[j] = offsets[j] + (pos[p] if p >= 0 else 0.0)
    pts = np.concatenate([pos, pos + ends])
    return float(pts[:, 1].max() - pts[:, 1].min())


# ---------------------------------------------------------------- naming conventions


@dataclass(frozen=True)
class NamingConvention:
    """How one family of files names its joints, and which joint gives each canonical joint.

    ``joints`` maps canonical name -> file joint name; the canonical point is that
    joint's origin, except for ``head``, which is the midpoint of the named joint's
    segment (half its ``bone_end_mm``). ``signature`` lists names that identify the
    convention (all must be present).
    """

    name: str
    signature: frozenset[str]
    joints: Mapping[str, str]


def _sided(
    central: Mapping[str, str], left: Mapping[str, str], right: Mapping[str, str]
) -> dict[str, str]:
    out = dict(central)
    out.update({f"left_{k}": v for k, v in left.items()})
    out.update({f"right_{k}": v for k, v in right.items()})
    return out


#: Limb joints named Left*/Right* + Shoulder (upper arm), Elbow, Wrist, Hip, Knee, Ankle,
#: shared by the CMU 3dsMax-friendly and the Hips/Ab/Chest conventions.
_LEFT_RIGHT_LIMBS: tuple[dict[str, str], dict[str, str]] = tuple(  # type: ignore[assignment]
    {
        "shoulder": f"{side}Shoulder",
        "elbow": f"{side}Elbow",
        "wrist": f"{side}Wrist",
        "hip": f"{side}Hip",
        "knee": f"{side}Knee",
        "ankle": f"{side}Ankle",
    }
    for side in ("Left", "Right")
)

#: Naming tables (data). Neck choice per convention: the joint at the base of the
#: neck, where the clavicles start (top of the thorax). In the CMU files that is the
#: start of the ASF bone ``lowerneck`` (MotionBuilder-friendly BVH: ``Neck``;
#: 3dsMax-friendly BVH: ``lowerneck``); in Boxing_Toes-style files ``Neck`` (which
#: sits where the collars start).
NAMING_CONVENTIONS: tuple[NamingConvention, ...] = (
    NamingConvention(
        "CMU MotionBuilder-friendly BVH (cgspeed)",
        frozenset({"Hips", "LHipJoint", "LeftUpLeg", "Spine1", "Neck1", "LeftForeArm"}),
        _sided(
            {"pelvis": "Hips", "neck": "Neck", "head": "Head"},
            {
                "shoulder": "LeftArm",
                "elbow": "LeftForeArm",
                "wrist": "LeftHand",
                "hip": "LeftUpLeg",
                "knee": "LeftLeg",
                "ankle": "LeftFoot",
            },
            {
                "shoulder": "RightArm",
                "elbow": "RightForeArm",
                "wrist": "RightHand",
                "hip": "RightUpLeg",
                "knee": "RightLeg",
                "ankle": "RightFoot",
            },
        ),
    ),
    NamingConvention(
        "CMU 3dsMax-friendly BVH (cgspeed)",
        frozenset({"Hips", "LHipJoint", "LeftHip", "lowerneck", "LeftCollar", "Chest2"}),
        _sided(
            {"pelvis": "Hips", "neck": "lowerneck", "head": "Head"},
            *_LEFT_RIGHT_LIMBS,
        ),
    ),
    NamingConvention(
        "Hips/Ab/Chest BVH (Boxing_Toes style)",
        frozenset({"Hips", "Ab", "Chest", "LeftCollar", "LeftHip"}),
        _sided(
            {"pelvis": "Hips", "neck": "Neck", "head": "Head"},
            *_LEFT_RIGHT_LIMBS,
        ),
    ),
    NamingConvention(
        "CMU ASF/AMC (Acclaim)",
        frozenset({"root", "lfemur", "ltibia", "lhumerus", "lradius", "lowerneck"}),
        _sided(
            {"pelvis": "root", "neck": "lowerneck", "head": "head"},
            {
                "shoulder": "lhumerus",
                "elbow": "lradius",
                "wrist": "lwrist",
                "hip": "lfemur",
                "knee": "ltibia",
                "ankle": "lfoot",
            },
            {
                "shoulder": "rhumerus",
                "elbow": "rradius",
                "wrist": "rwrist",
                "hip": "rfemur",
                "knee": "rtibia",
                "ankle": "rfoot",
            },
        ),
    ),
    NamingConvention(
        "mocapkit zhang21 preset",
        frozenset({"root", "spine1", "l_humerus", "l_radius", "l_femur", "l_tibia"}),
        _sided(
            {"pelvis": "root", "neck": "neck", "head": "head"},
            {
                "shoulder": "l_humerus",
                "elbow": "l_radius",
                "wrist": "l_hand",
                "hip": "l_femur",
                "knee": "l_tibia",
                "ankle": "l_foot",
            },
            {
                "shoulder": "r_humerus",
                "elbow": "r_radius",
                "wrist": "r_hand",
                "hip": "r_femur",
                "knee": "r_tibia",
                "ankle": "r_foot",
            },
        ),
    ),
    NamingConvention(
        "mocapkit upper_stick preset",
        frozenset({"waist", "neck", "l_shoulder", "l_elbow", "l_wrist"}),
        _sided(
            {"pelvis": "waist", "neck": "neck", "head": "head"},
            {"shoulder": "l_shoulder", "elbow": "l_elbow", "wrist": "l_wrist"},
            {"shoulder": "r_shoulder", "elbow": "r_elbow", "wrist": "r_wrist"},
        ),
    ),
)


def detect_convention(joint_names: Sequence[str]) -> tuple[NamingConvention | None, bool]:
    """The naming convention of a set of joint names.

    Returns ``(convention, exact)``: ``exact`` is true when the convention's whole
    signature is present. Otherwise the convention sharing the most canonical joint
    names is returned with ``exact=False`` (``None`` when none shares any), so that
    a reader can fill the canonical joints it recognises and leave out the rest.
    """
    names = set(joint_names)
    for conv in NAMING_CONVENTIONS:
        if conv.signature <= names:
            return conv, True
    scored = [
        (sum(v in names for v in c.joints.values()), i) for i, c in enumerate(NAMING_CONVENTIONS)
    ]
    best, idx = max(scored)
    return (NAMING_CONVENTIONS[idx], False) if best > 0 else (None, False)


def canonical_map(
    joint_names: Sequence[str], bone_end_mm: FloatArray, convention: NamingConvention | None
) -> dict[str, tuple[str, tuple[float, float, float]]]:
    """Canonical map (canonical name -> (joint, point in joint frame mm)) for a skeleton.

    Only joints present by exact name are used; canonical joints whose file joint
    is missing are left out (never guessed).

    Parameters
    ----------
    joint_names : sequence of str, length J
    bone_end_mm : ndarray, shape (J, 3)
        Segment ends (mm, joint frame); the head point is half the head joint's.
    convention : NamingConvention or None
    """
    if convention is None:
        return {}
    index = {n: j for j, n in enumerate(joint_names)}
    out: dict[str, tuple[str, tuple[float, float, float]]] = {}
    for cname in CANONICAL_JOINTS:
        jname = convention.joints.get(cname)
        if jname is None or jname not in index:
            continue
        if cname == "head":
            half = 0.5 * np.asarray(bone_end_mm[index[jname]], dtype=float)
            out[cname] = (jname, (float(half[0]), float(half[1]), float(half[2])))
        else:
            out[cname] = (jname, (0.0, 0.0, 0.0))
    return out


# ---------------------------------------------------------------- Motion


def _readonly(a: ArrayLike, dtype: Any = float) -> NDArray[Any]:
    arr = np.array(a, dtype=dtype, copy=True)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Motion:
    """A motion clip: a skeleton, its joint parameters over time and the canonical joints.

    Parameters
    ----------
    skeleton : Skeleton
    time_s : ndarray, shape (T,)
        Sample times (s), non-decreasing.
    q : ndarray, shape (T, D)
        Joint parameters (rad, mm); a row of NaN marks a frame without a pose.
    joint_names : tuple of str, length K
        Canonical joints provided, in canonical order.
    joints_mm : ndarray, shape (T, K, 3)
        Canonical joint positions in the world frame (mm); NaN where no pose.
    source : str
        Where the motion came from (file path and reader notes).
    """

    skeleton: Skeleton
    time_s: FloatArray
    q: FloatArray
    joint_names: tuple[str, ...]
    joints_mm: FloatArray
    source: str = ""

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "time_s", _readonly(self.time_s))
        set_(self, "q", _readonly(self.q))
        set_(self, "joints_mm", _readonly(self.joints_mm))
        set_(self, "joint_names", tuple(self.joint_names))
        t, d, k = self.time_s.shape, self.skeleton.n_dofs, len(self.joint_names)
        if self.time_s.ndim != 1:
            raise ShapeError(f"Motion.time_s: expected shape (T,), found {self.time_s.shape}")
        n = t[0]
        if self.q.shape != (n, d):
            raise ShapeError(f"Motion.q: expected shape ({n}, {d}), found {self.q.shape}")
        if self.joints_mm.shape != (n, k, 3):
            raise ShapeError(
                f"Motion.joints_mm: expected shape ({n}, {k}, 3), found {self.joints_mm.shape}"
            )
        unknown = [c for c in self.joint_names if c not in CANONICAL_JOINTS]
        if unknown:
            raise ShapeError(f"Motion.joint_names: not canonical joint names: {unknown}")

    @classmethod
    def from_q(
        cls, skeleton: Skeleton, time_s: ArrayLike, q: ArrayLike, source: str = ""
    ) -> Motion:
        """Build a motion from joint parameters; canonical joints come from forward kinematics.

        Parameters
        ----------
        skeleton : Skeleton
        time_s : array_like, shape (T,)
        q : array_like, shape (T, D)
            Rows that contain NaN are frames without a pose (their joints are NaN).
        source : str
        """
        qa = np.asarray(q, dtype=float)
        ta = np.asarray(time_s, dtype=float)
        if qa.ndim != 2 or qa.shape[1] != skeleton.n_dofs or ta.shape != (qa.shape[0],):
            raise ShapeError(
                f"Motion.from_q: expected time_s (T,) and q (T, {skeleton.n_dofs}), "
                f"found {ta.shape} and {qa.shape}"
            )
        names = skeleton.canonical_names
        joints = np.full((qa.shape[0], len(names), 3), np.nan)
        valid = ~np.any(np.isnan(qa), axis=1)
        if names and np.any(valid):
            joints[valid] = canonical_positions(skeleton, qa[valid], names)
        return cls(skeleton, ta, qa, names, joints, source)

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.time_s.shape[0])

    def joint(self, name: str) -> FloatArray:
        """Trajectory (T, 3) of one canonical joint (mm, world)."""
        if name not in self.joint_names:
            from mocapkit.errors import unknown_name

            raise unknown_name("canonical joint", name, self.joint_names, f"motion {self.source!r}")
        return self.joints_mm[:, self.joint_names.index(name)]

    # ------------------------------------------------------------ exports

    def save_npz(self, path: str | os.PathLike[str]) -> None:
        """Save to ``.npz`` (no pickles; the skeleton is stored as JSON text), atomically."""
        atomic_save_npz(
            path,
            format=np.array("mocapkit.motion"),
            version=np.array(1),
            time_s=np.asarray(self.time_s),
            q=np.asarray(self.q),
            joints_mm=np.asarray(self.joints_mm),
            joint_names=np.array(self.joint_names, dtype=np.str_).reshape(len(self.joint_names)),
            skeleton_json=np.array(skeleton_to_json(self.skeleton)),
            source=np.array(self.source),
        )

    def write_joints_csv(self, path: str | os.PathLike[str]) -> None:
        """Write canonical joints to CSV: ``time_s`` then ``<joint>_x_mm, _y_mm, _z_mm`` (world).

        Frames without a pose hold ``nan``. Written atomically.
        """
        header = ["time_s"] + [f"{n}_{a}_mm" for n in self.joint_names for a in "xyz"]
        flat = np.asarray(self.joints_mm).reshape(self.n_frames, -1)
        buf = io.StringIO()
        buf.write(",".join(header) + "\n")
        if self.n_frames:
            fmt = ",".join(["%.9f"] + ["%.6f"] * flat.shape[1])
            np.savetxt(buf, np.column_stack([self.time_s, flat]), fmt=fmt, delimiter=",")
        with atomic_write(path, "w", newline="") as fh:
            fh.write(buf.getvalue())

    def write_trc(self, path: str | os.PathLike[str]) -> None:
        """Write the canonical joints as TRC markers (mm) via `mocapkit.io.trc.write_trc`."""
        from mocapkit.io.trc import write_trc  # written by another module; imported on use

        write_trc(path, self.time_s, list(self.joint_names), self.joints_mm, units="mm")

    def write_result_folder(self, folder: str | os.PathLike[str]) -> Path:
        """Write ``motion.npz``, ``joints.csv`` and ``motion.bvh`` into a folder (each atomic).

        Returns the folder path. See `mocapkit.io.bvh.write_bvh` for how frames
        without a pose are written to BVH.
        """
        from mocapkit.io.bvh import write_bvh  # bvh imports this module

        out = Path(folder)
        out.mkdir(parents=True, exist_ok=True)
        self.save_npz(out / "motion.npz")
        self.write_joints_csv(out / "joints.csv")
        write_bvh(out / "motion.bvh", self)
        return out


def load_motion_npz(path: str | os.PathLike[str]) -> Motion:
    """Load a motion saved by `Motion.save_npz`."""
    where = str(path)
    try:
        data = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise FormatError(f"{where}: cannot read as .npz ({exc})") from None
    with data:
        need = ("format", "time_s", "q", "joints_mm", "joint_names", "skeleton_json", "source")
        missing = [k for k in need if k not in data.files]
        if missing:
            raise FormatError(f"{where}: not a mocapkit motion file; missing arrays {missing}")
        if str(data["format"]) != "mocapkit.motion":
            raise FormatError(
                f"{where}: field 'format' should be 'mocapkit.motion', found {data['format']}"
            )
        skeleton = skeleton_from_json(str(data["skeleton_json"]), where)
        return Motion(
            skeleton,
            data["time_s"],
            data["q"],
            tuple(str(n) for n in data["joint_names"]),
            data["joints_mm"],
            str(data["source"]),
        )


def read_joints_csv(path: str | os.PathLike[str]) -> tuple[FloatArray, tuple[str, ...], FloatArray]:
    """Read a file written by `Motion.write_joints_csv`.

    Returns
    -------
    time_s : ndarray, shape (T,)
    joint_names : tuple of str, length K
    joints_mm : ndarray, shape (T, K, 3)
        NaN where the file holds ``nan``.
    """
    where = str(path)
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = list(csv.reader(fh))
    except OSError as exc:
        raise FormatError(f"{where}: cannot read ({exc})") from None
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


__all__ = [
    "CMU_UNIT_MM",
    "FILE_FROM_WORLD",
    "NAMING_CONVENTIONS",
    "WORLD_FROM_FILE",
    "Motion",
    "NamingConvention",
    "canonical_map",
    "detect_convention",
    "infer_unit_mm",
    "load_motion_npz",
    "read_joints_csv",
    "rest_height_units",
]
