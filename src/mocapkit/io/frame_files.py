"""Per-frame files (an image folder, an OpenPose JSON folder) put in frame order.

The frame number of a file is the last run of digits in its name without the extension
(``000012.png``, ``frame_12.png``, ``video_000000000012_keypoints.json``,
``cam01_000012_keypoints.json`` -> 12). Files are ordered by that number, never by
their text (``frame_10`` before ``frame_2`` in text order), so numbers may be padded
with zeros or not. The numbers must run without gaps or repeats from the first one on
(0 or 1 or any other): a missing frame would shift every later frame in time, and two
files of one number are two recordings in one folder, so both are refused, naming the
files.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from itertools import pairwise
from pathlib import Path

from mocapkit.errors import SessionError

_LAST_NUMBER = re.compile(r"(\d+)(?!.*\d)")


def frame_number(path: Path) -> int | None:
    """The last run of digits in ``path``'s name without its extension; None if none."""
    found = _LAST_NUMBER.search(path.name[: len(path.name) - len(path.suffix)])
    return int(found.group(1)) if found else None


def in_frame_order(files: Iterable[Path], folder: Path, what: str) -> list[Path]:
    """``files`` sorted by frame number (module docstring); `SessionError` naming
    ``folder`` and ``what`` (e.g. "OpenPose JSON files") for a file without a number, a
    repeated number or a gap."""
    numbered: list[tuple[int, Path]] = []
    for f in files:
        n = frame_number(f)
        if n is None:
            raise SessionError(
                f"{folder}: {what}: expected a frame number in every file name, found {f.name!r}"
            )
        numbered.append((n, f))
    numbered.sort(key=lambda nf: (nf[0], nf[1].name))
    for (a, fa), (b, fb) in pairwise(numbered):
        if b == a:
            raise SessionError(
                f"{folder}: {what}: {fa.name!r} and {fb.name!r} both have frame number {a}; "
                "expected one file per frame"
            )
        if b != a + 1:
            missing = f"frame {a + 1}" if b == a + 2 else f"frames {a + 1}-{b - 1}"
            raise SessionError(
                f"{folder}: {what}: frame numbers jump from {a} ({fa.name!r}) to {b} "
                f"({fb.name!r}); {missing} missing. Expected consecutive numbers"
            )
    return [f for _, f in numbered]


__all__ = ["frame_number", "in_frame_order"]
