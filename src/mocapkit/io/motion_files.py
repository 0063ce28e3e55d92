"""Motion files by suffix: read or write a `Motion` in any supported format; the result folder.

Extensions: ``.bvh`` (`mocapkit.io.bvh.read_bvh`), ``.amc`` (`mocapkit.io.asf_amc.read_amc`;
the ASF skeleton is ``asf`` when given, else found by `mocapkit.io.asf_amc.find_asf`:
same stem, then subject prefix before ``_``, then the only ``.asf`` in the folder) and
``.npz`` (`mocapkit.io.motion_npz.load_motion_npz`, written by `save_motion_npz`).
`write_motion` writes ``.npz``, ``.bvh``, a canonical-joints ``.csv``
(`mocapkit.io.joints_csv`) or the canonical joints as ``.trc`` markers;
`write_result_folder` writes ``motion.npz``, ``joints.csv`` and ``motion.bvh``.
"""

from __future__ import annotations

import os
from pathlib import Path

from mocapkit.errors import FormatError
from mocapkit.io.asf_amc import read_amc
from mocapkit.io.bvh import MAX_ROLL_SPEED_RAD_S, read_bvh, write_bvh
from mocapkit.io.files import require_file
from mocapkit.io.joints_csv import write_joints_csv
from mocapkit.io.motion import Motion
from mocapkit.io.motion_npz import load_motion_npz, save_motion_npz
from mocapkit.io.trc import write_trc

#: Extensions `read_motion` accepts.
MOTION_EXTENSIONS: tuple[str, ...] = (".bvh", ".amc", ".npz")
#: Extensions `write_motion` writes.
WRITABLE_MOTION_EXTENSIONS: tuple[str, ...] = (".npz", ".bvh", ".csv", ".trc")


def read_motion(
    path: str | os.PathLike[str],
    asf: str | os.PathLike[str] | None = None,
    unit_mm: float | None = None,
) -> Motion:
    """Read a motion file (``.bvh``, ``.amc`` or mocapkit ``.npz``).

    Parameters
    ----------
    path : path-like
    asf : path-like, optional
        ASF skeleton for an ``.amc`` file (default: looked up beside it).
    unit_mm : float, optional
        Millimetres per file unit (BVH/AMC); default per reader (CMU unit for
        recognised CMU files, stature-based inference for other BVH files,
        ``25.4 / length`` for ASF). Not allowed for ``.npz`` (already in mm).
    """
    p = Path(path)
    ext = p.suffix.lower()
    require_file(p, "motion file")
    if asf is not None and ext != ".amc":
        raise FormatError(
            f"{p}: an ASF skeleton is only used with .amc files, found a {ext or 'no'} extension"
        )
    if ext == ".bvh":
        return read_bvh(p, unit_mm=unit_mm)
    if ext == ".amc":
        return read_amc(p, asf_path=asf, unit_mm=unit_mm)
    if ext == ".npz":
        if unit_mm is not None:
            raise FormatError(
                f"{p}: unit_mm does not apply to a mocapkit .npz motion (it is stored in mm)"
            )
        return load_motion_npz(p)
    raise FormatError(
        f"{p}: unsupported motion file extension {ext!r}; "
        f"expected one of {', '.join(MOTION_EXTENSIONS)}"
        + (" (an .asf holds only a skeleton: read the .amc that uses it)" if ext == ".asf" else "")
    )


def write_motion(path: str | os.PathLike[str], motion: Motion) -> None:
    """Write a motion in the format its extension names, atomically.

    ``.npz``: the whole motion (`save_motion_npz`); ``.bvh``: skeleton and joint
    parameters (`write_bvh`); ``.csv``: the canonical joints (`write_joints_csv`);
    ``.trc``: the canonical joints as markers in mm (`mocapkit.io.trc.write_trc`).

    Parameters
    ----------
    path : path-like
    motion : Motion
    """
    p = Path(path)
    ext = p.suffix.lower()
    if ext == ".npz":
        save_motion_npz(p, motion)
    elif ext == ".bvh":
        write_bvh(p, motion)
    elif ext == ".csv":
        write_joints_csv(p, motion)
    elif ext == ".trc":
        write_trc(p, motion.time_s, list(motion.joint_names), motion.joints_mm, units="mm")
    else:
        raise FormatError(
            f"{p}: cannot write a motion with extension {ext or 'none'!r}; "
            f"expected one of {', '.join(WRITABLE_MOTION_EXTENSIONS)}"
        )


def write_result_folder(folder: str | os.PathLike[str], motion: Motion) -> Path:
    """Write ``motion.npz``, ``joints.csv`` and ``motion.bvh`` into a folder (each atomic).

    Returns the folder path (created when missing). See `mocapkit.io.bvh.write_bvh` for
    how frames without a pose are written to BVH.
    """
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    save_motion_npz(out / "motion.npz", motion)
    write_joints_csv(out / "joints.csv", motion)
    write_bvh(
        out / "motion.bvh",
        motion,
        max_roll_speed_rad_s=MAX_ROLL_SPEED_RAD_S,
    )
    return out


__all__ = [
    "MOTION_EXTENSIONS",
    "WRITABLE_MOTION_EXTENSIONS",
    "read_motion",
    "write_motion",
    "write_result_folder",
]
