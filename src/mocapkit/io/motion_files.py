"""Read any supported motion file into a `Motion`, choosing the reader by file extension.

Extensions: ``.bvh`` (`mocapkit.io.bvh.read_bvh`), ``.amc`` (`mocapkit.io.asf_amc.read_amc`;
the ASF skeleton is ``asf`` when given, else found by `mocapkit.io.asf_amc.find_asf`:
same stem, then subject prefix before ``_``, then the only ``.asf`` in the folder) and
``.npz`` (`mocapkit.io.motion.load_motion_npz`, written by `Motion.save_npz`).
"""

from __future__ import annotations

import os
from pathlib import Path

from mocapkit.errors import FormatError
from mocapkit.io.asf_amc import read_amc
from mocapkit.io.bvh import read_bvh
from mocapkit.io.motion import Motion, load_motion_npz

#: Extensions `read_motion` accepts.
MOTION_EXTENSIONS: tuple[str, ...] = (".bvh", ".amc", ".npz")


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
    if not p.is_file():
        raise FormatError(f"{p}: motion file not found")
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


__all__ = ["MOTION_EXTENSIONS", "read_motion"]
