"""The mocapkit motion ``.npz`` format: a `Motion` saved without pickles, read back exactly.

Arrays: ``format`` (``"mocapkit.motion"``), ``version``, ``time_s`` (T,), ``q`` (T, D),
``joints_mm`` (T, K, 3), ``joint_names`` (K,), ``skeleton_json`` (the skeleton as JSON
text, `mocapkit.skeleton.serialize`) and ``source``.
"""

from __future__ import annotations

import os

import numpy as np

from mocapkit.errors import FormatError
from mocapkit.io.atomic import atomic_save_npz
from mocapkit.io.files import load_npz
from mocapkit.io.motion import Motion
from mocapkit.skeleton.serialize import skeleton_from_json, skeleton_to_json


def save_motion_npz(path: str | os.PathLike[str], motion: Motion) -> None:
    """Save a motion to ``.npz`` (no pickles; the skeleton is stored as JSON text), atomically.

    Parameters
    ----------
    path : path-like
    motion : Motion
    """
    atomic_save_npz(
        path,
        format=np.array("mocapkit.motion"),
        version=np.array(1),
        time_s=np.asarray(motion.time_s),
        q=np.asarray(motion.q),
        joints_mm=np.asarray(motion.joints_mm),
        joint_names=np.array(motion.joint_names, dtype=np.str_).reshape(len(motion.joint_names)),
        skeleton_json=np.array(skeleton_to_json(motion.skeleton)),
        source=np.array(motion.source),
    )


def load_motion_npz(path: str | os.PathLike[str]) -> Motion:
    """Load a motion saved by `save_motion_npz`."""
    where = str(path)
    data = load_npz(path, "mocapkit motion (.npz)")
    need = ("format", "time_s", "q", "joints_mm", "joint_names", "skeleton_json", "source")
    missing = [k for k in need if k not in data]
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


__all__ = ["load_motion_npz", "save_motion_npz"]
