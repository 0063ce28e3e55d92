"""Atomic output: write a file or a whole folder beside the target, then rename it into place.

A crash, a kill or Ctrl-C mid-write leaves the previous file or folder intact, never a
truncated file or a folder that mixes old and new files.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import IO, Any

from mocapkit.errors import ConfigError


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
    if target.is_dir():  # refused before writing, by its own name (not the temporary's)
        raise IsADirectoryError(
            errno.EISDIR, "expected a file to write, found a folder", str(target)
        )
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    if mode == "w":
        open_kwargs.setdefault("encoding", "utf-8")
    try:
        with os.fdopen(fd, mode, **open_kwargs) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        # mkstemp creates the file private (0600); give it the mode a plain open() would
        os.chmod(tmp_name, 0o666 & ~_umask())
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


def _umask() -> int:
    """The process's umask (reading it means setting it; set it straight back)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_folder(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Build a folder under a temporary name beside ``path``; on success swap it in.

    Yields the temporary folder to write into. When the block ends without an
    exception, an existing ``path`` is renamed aside (an empty one removed), the new
    folder renamed to ``path`` and the old one deleted; on any exception (Ctrl-C
    included) the temporary folder is deleted and ``path`` is left as it was. The swap
    is two renames on one file system: a kill between them leaves the old folder whole
    under its aside name (``.NAME.old-*``) and no half-written ``path``;
    `remove_stale_temporaries` renames it back. Callers decide beforehand whether
    ``path`` may be replaced, and call `remove_stale_temporaries` first to clear what a
    killed earlier build left.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.new-", dir=target.parent))
    try:
        os.chmod(tmp, 0o777 & ~_umask())
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    old: Path | None = None
    if target.is_dir() and not target.is_symlink() and not any(target.iterdir()):
        os.rmdir(target)  # an empty folder (a fresh --out, a caller's own temporary): no copy
    elif target.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{target.name}.old-", dir=target.parent))
        os.replace(target, old / target.name)
    os.replace(tmp, target)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def check_own_folder(
    path: str | os.PathLike[str], own_files: Sequence[str], what: str, writer: str
) -> Path:
    """Refuse a folder that a command would replace whole but did not write; call it
    before the work.

    The one rule of every command that swaps a folder in whole (`atomic_folder`): an
    existing ``path`` must be empty or hold one of ``own_files`` (the files that mark it
    as this command's own output); any other folder with files in it (a session, a
    user's notes, a thesis) is refused rather than deleted. Hidden entries (the
    temporaries of an interrupted swap) do not count.

    Parameters
    ----------
    path : path-like
    own_files : sequence of str
        Names of which at least one marks the folder as the command's own.
    what : str
        What the folder is, for the message (``"result folder"``, ``"report folder"``).
    writer : str
        Who replaces it, for the message (``"a run"``, ``"mocapkit view"``).

    Raises
    ------
    ConfigError
        ``path`` is a file, or a folder with files but none of ``own_files``.
    """
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"{out}: expected a {what}, found an existing file")
    if out.is_dir() and not any((out / f).is_file() for f in own_files):
        found = sorted(p.name for p in out.iterdir() if not p.name.startswith("."))
        if found:
            shown = ", ".join(found[:5]) + (", ..." if len(found) > 5 else "")
            marks = " or ".join(own_files)
            raise ConfigError(
                f"{out}: {writer} replaces its {what} whole, but this folder is not a "
                f"{what} (no {marks}; it holds {shown}); give a new or empty folder, or a "
                f"previous {what}"
            )
    return out


def remove_stale_temporaries(folder: str | os.PathLike[str], name: str) -> None:
    """Clear what interrupted `atomic_write` / `atomic_folder` calls left beside ``name``.

    Deleted: ``.NAME.*.tmp`` files, ``.NAME.new-*`` folders (a build that never finished)
    and the temporaries of a folder built inside such a build (``..NAME.new-*``, as when a
    result folder is written into a batch take's temporary folder). An ``.NAME.old-*``
    folder is the previous ``NAME`` renamed aside by a swap: when ``NAME`` itself is
    missing, the kill came between the swap's two renames, and the previous folder,
    which is whole, is renamed back to ``NAME``; otherwise it is deleted.
    """
    base = Path(folder)
    target = base / name
    for p in sorted(base.glob(f".{name}.old-*")):
        kept = p / name
        if not target.exists() and not target.is_symlink() and kept.is_dir():
            os.replace(kept, target)
        shutil.rmtree(p, ignore_errors=True)
    for pattern in (f".{name}.*.tmp", f".{name}.new-*", f"..{name}.new-*"):
        for p in base.glob(pattern):
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p, ignore_errors=True)
            else:
                p.unlink(missing_ok=True)
