"""Atomic file output: write to a temporary file beside the target, then rename over it.

A crash mid-write leaves the previous file intact, never a truncated one.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any


@contextlib.contextmanager
def atomic_write(
    path: str | os.PathLike[str], mode: str = "w", **open_kwargs: Any
) -> Iterator[IO[Any]]:
    """Open a temporary file for writing; on success rename it to ``path``.

    Parameters
    ----------
    path : path-like
        Final destination; its folder is created if missing.
    mode : str
        ``"w"`` (text) or ``"wb"`` (binary).
    **open_kwargs
        Passed to `open` (e.g. ``newline=""`` for CSV).
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_write: mode must be 'w' or 'wb', found {mode!r}")
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    if mode == "w":
        open_kwargs.setdefault("encoding", "utf-8")
    try:
        with os.fdopen(fd, mode, **open_kwargs) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp_name, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp_name)
        raise


def atomic_save_npz(path: str | os.PathLike[str], **arrays: Any) -> None:
    """Save arrays to an ``.npz`` file atomically (uncompressed, no pickles)."""
    import numpy as np

    with atomic_write(path, "wb") as fh:
        np.savez(fh, **arrays)
