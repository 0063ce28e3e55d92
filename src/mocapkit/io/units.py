"""Axes and length units of motion files: the Y-up file frame and the unit inferred from stature.

BVH and ASF/AMC readers and the BVH writer share these conventions: the frame
change from the Y-up motion-file frame to the mocapkit world (Z up, subject
facing +Y, right side +X) and the rule that picks a length unit when a file
states none.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import FormatError

FloatArray = NDArray[np.float64]

#: Rotation taking BVH/ASF file coordinates (Y up; a CMU subject faces +Z with its
#: left side towards +X) to the mocapkit world (Z up, facing +Y, right side +X):
#: file X -> world -X, file Y -> world Z, file Z -> world Y (det +1).
WORLD_FROM_FILE: FloatArray = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])
WORLD_FROM_FILE.setflags(write=False)
#: Inverse of `WORLD_FROM_FILE` (it is its own transpose and inverse).
FILE_FROM_WORLD: FloatArray = WORLD_FROM_FILE.T.copy()
FILE_FROM_WORLD.setflags(write=False)
#: Rotation taking the mocapkit world (Z up, facing +Y, right side +X) to OpenSim's
#: ground frame (Y up, X forward, Z to the subject's right): world Y -> X, Z -> Y, X -> Z.
OPENSIM_FROM_WORLD: FloatArray = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
OPENSIM_FROM_WORLD.setflags(write=False)

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


__all__ = [
    "CANDIDATE_UNITS_MM",
    "CMU_UNIT_MM",
    "FILE_FROM_WORLD",
    "REFERENCE_STATURE_MM",
    "WORLD_FROM_FILE",
    "infer_unit_mm",
    "rest_height_units",
]
