"""The exception hierarchy: one `MocapError` base, subclasses that are also built-in errors.

Every message names what was looked at (a file, a field, an argument), what was
expected and what was found, so that a user can fix the input without reading code.
"""

from __future__ import annotations

from collections.abc import Iterable


class MocapError(Exception):
    """Base class of every error mocapkit raises on purpose."""


class FormatError(MocapError, ValueError):
    """A file or document does not follow its format (truncated, malformed, wrong field)."""


class ShapeError(MocapError, ValueError):
    """An array has the wrong shape, dtype, or holds NaN where none is allowed."""


class UnknownNameError(MocapError, KeyError):
    """A joint, marker, camera or preset name is not known; the message lists valid names."""

    def __str__(self) -> str:  # KeyError would quote the whole message
        return str(self.args[0]) if self.args else ""


class CalibrationError(MocapError, ValueError):
    """Camera calibration could not be done (too few boards, degenerate views)."""


class SessionError(MocapError, ValueError):
    """A recording session folder lacks what is needed, or is inconsistent."""


def unknown_name(kind: str, name: str, valid: Iterable[str], where: str = "") -> UnknownNameError:
    """Build an `UnknownNameError` listing the valid choices.

    Parameters
    ----------
    kind : str
        What the name designates, e.g. ``"joint"`` or ``"marker"``.
    name : str
        The name that was not found.
    valid : iterable of str
        The names that would have been accepted.
    where : str, optional
        Where the name came from (a file path or an argument name).
    """
    choices = sorted(valid)
    shown = ", ".join(choices[:40]) + (" ..." if len(choices) > 40 else "")
    origin = f" in {where}" if where else ""
    return UnknownNameError(f"unknown {kind} {name!r}{origin}; expected one of: {shown}")


class InputWarning(UserWarning):
    """Input taken with a change the user must know of (dropped samples, a padded size).

    The CLI prints it as ``mocapkit COMMAND: warning: ...``; the message names the file,
    what was found and what was done with it.
    """


class ConfigError(MocapError, ValueError):
    """A setting is out of range, or two settings or options conflict."""
