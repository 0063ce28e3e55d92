"""Reading a file's bytes for the format readers: text and ``.npz``, errors as `FormatError`.

Every reader gets its text or its arrays here, so a file that is not text (binary
garbage as a marker CSV, TRC, session.json or joints.csv) or a truncated ``.npz`` is
refused with the file named, never as a raw ``UnicodeDecodeError`` or ``BadZipFile``.
"""

from __future__ import annotations

import os
import zipfile
import zlib
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import FormatError


def require_file(
    path: str | os.PathLike[str], what: str = "file", missing: type[Exception] = FormatError
) -> Path:
    """``path`` as a `Path` when it is a regular file; otherwise refused, saying what it is.

    A missing path raises ``missing`` (`FormatError`, or `FileNotFoundError` where a
    caller's contract says so) with ``"PATH: WHAT not found"``; a folder or any other
    non-file raises `FormatError` (``"PATH: expected a WHAT, found a folder"``), never
    "not found" for a path that exists.
    """
    p = Path(path)
    if p.is_file():
        return p
    if p.is_dir():
        raise FormatError(f"{p}: expected a {what}, found a folder")
    if p.exists():
        raise FormatError(f"{p}: expected a {what}, found something that is not a regular file")
    raise missing(f"{p}: {what} not found")


#: The first bytes of a zip archive (an ``.npz``: local file header, or an empty archive).
_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")


def read_text(path: str | os.PathLike[str], what: str = "file", encoding: str = "utf-8") -> str:
    """The whole text of ``path`` (universal newlines; a UTF-8 byte-order mark is dropped).

    Parameters
    ----------
    path : path-like
    what : str
        What the file should be, for the message (``"marker CSV"``).
    encoding : str

    Raises
    ------
    FormatError
        The file is missing or unreadable, or is not text in ``encoding``.
    """
    p = require_file(path, what)
    try:
        with open(p, encoding=encoding, newline=None) as fh:
            text = fh.read()
    except FileNotFoundError:
        raise FormatError(f"{p}: {what} not found") from None
    except UnicodeDecodeError as exc:
        raise FormatError(
            f"{p}: expected a {what} as {encoding} text, found a byte it cannot hold at "
            f"offset {exc.start} (a binary file?)"
        ) from None
    except OSError as exc:
        raise FormatError(f"{p}: cannot read the {what} ({exc.strerror or exc})") from None
    return text.removeprefix("\ufeff")


def load_npz(path: str | os.PathLike[str], what: str = ".npz archive") -> dict[str, NDArray]:
    """All arrays of a ``.npz`` file, read at once (no pickles).

    Raises
    ------
    FormatError
        The file is missing, unreadable, not a zip archive, truncated, or holds an
        array that does not load.
    """
    p = require_file(path, what)
    try:
        with p.open("rb") as fh:
            head = fh.read(6)
    except OSError as exc:
        raise FormatError(f"{p}: cannot read the {what} ({exc.strerror or exc})") from None
    if not head.startswith(_ZIP_MAGIC) and not head.startswith(b"\x93NUMPY"):
        # np.load would take it for a pickle and advise allow_pickle, which is wrong here
        raise FormatError(
            f"{p}: cannot read as .npz (expected a {what}, a zip archive; found a file that "
            f"starts with {head!r})"
        )
    try:
        with np.load(p, allow_pickle=False) as data:
            return {k: np.asarray(data[k]) for k in data.files}
    except FileNotFoundError:
        raise FormatError(f"{p}: {what} not found") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
        raise FormatError(
            f"{p}: cannot read as .npz (expected a {what}; {exc or type(exc).__name__})"
        ) from None
    except (AttributeError, TypeError):
        # np.load returns a bare array for a .npy file, which is no archive
        raise FormatError(f"{p}: expected a {what} (.npz), found a single .npy array") from None
