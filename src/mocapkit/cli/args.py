"""Argument types shared by the subcommands: bad values become argparse usage errors.

A ``type=`` built here rejects a value while the command line is parsed, so argparse
prints the usage line and ``argument --opt: <reason>`` and exits with status 2, before
any work starts. The library keeps its own checks (`mocapkit.errors.ConfigError`) for
callers that do not go through the command line.
"""

from __future__ import annotations

import argparse
import importlib
import math
import os
from collections.abc import Callable, Iterator, Sequence
from dataclasses import MISSING
from pathlib import Path
from typing import Any, TypeVar, overload

from mocapkit.errors import MocapError, SessionError

T = TypeVar("T")


def _reason(exc: MocapError) -> str:
    """The library's message without a leading ``--option:`` (argparse names the option)."""
    text = str(exc)
    if text.startswith("--") and ": " in text:
        return text.split(": ", 1)[1]
    return text


def parsed_by(parse: Callable[[str], T], name: str) -> Callable[[str], T]:
    """A ``type=`` that converts with a library parser; its `MocapError` is a usage error.

    Parameters
    ----------
    parse : callable
        Takes the argument text; raises a `MocapError` subclass for a bad value.
    name : str
        What the value is (argparse shows it in its own messages).
    """

    def convert(text: str) -> T:
        try:
            return parse(text)
        except MocapError as exc:
            raise argparse.ArgumentTypeError(_reason(exc)) from None

    convert.__name__ = name
    return convert


def checked_by(
    check: Callable[[str], object], name: str, *, default: str | None = None
) -> Callable[[str], str]:
    """A ``type=`` that keeps the text as given once a library parser accepts it.

    ``default``, the argument's default, passes unchecked: argparse runs ``type=`` on a
    text default at every parse, a usage error included, and the check may import the
    library behind it.
    """

    def convert(text: str) -> str:
        if default is None or text != default:
            parsed_by(check, name)(text)
        return text

    convert.__name__ = name
    return convert


def number(
    kind: type[float] | type[int] = float,
    *,
    at_least: float | None = None,
    above: float | None = None,
    at_most: float | None = None,
) -> Callable[[str], float]:
    """A ``type=`` for a finite number with optional bounds.

    Parameters
    ----------
    kind : float or int
    at_least, above, at_most : float, optional
        ``value >= at_least``, ``value > above``, ``value <= at_most``.

    Examples
    --------
    >>> number(at_least=0.0, at_most=1.0)("0.5")
    0.5
    """
    what = "an integer" if kind is int else "a number"
    bounds = [
        f"{op} {b:g}"
        for op, b in ((">=", at_least), (">", above), ("<=", at_most))
        if b is not None
    ]
    expected = what + (" " + " and ".join(bounds) if bounds else "")

    def convert(text: str) -> float:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {expected}, found {text!r}") from None
        if not (
            math.isfinite(value)
            and (at_least is None or value >= at_least)
            and (above is None or value > above)
            and (at_most is None or value <= at_most)
        ):
            raise argparse.ArgumentTypeError(f"expected {expected}, found {text}")
        return value

    convert.__name__ = "int" if kind is int else "float"
    return convert


def imported(path: str) -> Callable[..., Any]:
    """A library function imported at its first call (``"mocapkit.eval.metrics:joint_subset"``).

    A subcommand's ``register`` builds its ``type=`` from it so that a usage error or
    ``--help`` does not import the library (and numpy, OpenCV, Numba) behind it.
    """
    module, _, attr = path.partition(":")

    def call(*args: Any, **kwargs: Any) -> Any:
        return getattr(importlib.import_module(module), attr)(*args, **kwargs)

    return call


class LazyChoices(Sequence[str]):
    """``choices=`` read from the library when first asked for (``"module:function"``).

    Give the argument a ``metavar`` so that the usage line does not list the choices (the
    help can, with ``%(choices)s``, shown only by ``--help``).
    """

    def __init__(self, path: str) -> None:
        self._names_of = imported(path)
        self._names: tuple[str, ...] | None = None

    def _all(self) -> tuple[str, ...]:
        if self._names is None:
            self._names = tuple(self._names_of())
        return self._names

    @overload
    def __getitem__(self, index: int) -> str: ...
    @overload
    def __getitem__(self, index: slice) -> Sequence[str]: ...
    def __getitem__(self, index: int | slice) -> str | Sequence[str]:
        return self._all()[index]

    def __len__(self) -> int:
        return len(self._all())

    def __iter__(self) -> Iterator[str]:
        return iter(self._all())

    def __contains__(self, value: object) -> bool:
        return value in self._all()


class StatedDefault:
    """A default stated once in the library, read when ``--help`` shows it.

    ``path`` is ``"module:Name"``, ``"module:ConfigClass.field"`` (a dataclass field's
    default) or ``"module:function.parameter"`` (a keyword's default). Set on an
    argument with `shows_default`; its help names it as ``%(stated_default)s``, which
    argparse fills only when it prints the help, so a usage error does not import the
    library.
    """

    def __init__(self, path: str) -> None:
        self.path = path

    def value(self) -> Any:
        """The default itself."""
        import inspect

        module, _, attrs = self.path.partition(":")
        obj: Any = importlib.import_module(module)
        for attr in attrs.split("."):
            fields = getattr(obj, "__dataclass_fields__", None)
            if isinstance(obj, type) and fields is not None and attr in fields:
                field = fields[attr]
                obj = field.default_factory() if field.default is MISSING else field.default
            elif inspect.isfunction(obj):
                obj = inspect.signature(obj).parameters[attr].default
            else:
                obj = getattr(obj, attr)
        return obj

    def __str__(self) -> str:
        v = self.value()
        if isinstance(v, float):
            return f"{v:g}"
        if isinstance(v, tuple) and all(isinstance(x, int) for x in v):
            return "x".join(str(x) for x in v)  # an image size: 640x480
        if isinstance(v, (tuple, list)):
            return ",".join(str(x) for x in v)  # as the option takes it
        return str(v)


def shows_default(action: argparse.Action, path: str) -> argparse.Action:
    """Give ``action``'s help the library's default at ``path`` as ``%(stated_default)s``.

    The argument's own default is then None (the library applies its default: pass the
    value on only when given, `given`) or, where the library states it in a module light
    to import, that same value.
    """
    action.stated_default = StatedDefault(path)  # type: ignore[attr-defined]
    return action


def given(**values: Any) -> dict[str, Any]:
    """The keywords whose value was given (not None): the library's defaults fill the rest."""
    return {k: v for k, v in values.items() if v is not None}


def add_clip_options(parser: argparse.ArgumentParser) -> None:
    """``--clips`` and ``--clip-set`` of an accuracy harness (`pipelines.harness.CLIP_SETS`)."""
    from mocapkit.pipelines.harness import CLIP_SETS

    clips = parser.add_mutually_exclusive_group()
    clips.add_argument("--clips", nargs="*", help="clip file names (default: the tuning set)")
    clips.add_argument(
        "--clip-set",
        choices=tuple(CLIP_SETS),
        help="the project's tuning clips (the default) or its report clips, which nothing "
        "was tuned on",
    )


def chosen_clips(args: argparse.Namespace) -> list[str] | None:
    """The clips of ``--clips`` or ``--clip-set`` (None: the harness's default)."""
    from mocapkit.pipelines.harness import CLIP_SETS

    return list(CLIP_SETS[args.clip_set]) if args.clip_set else args.clips


__all__ = [
    "MOCAP_HELP",
    "LazyChoices",
    "StatedDefault",
    "add_clip_options",
    "checked_by",
    "chosen_clips",
    "given",
    "imported",
    "number",
    "parsed_by",
    "shows_default",
]


def output_folder(text: str) -> str:
    """A ``type=`` for ``--out`` folders: checked before any work starts.

    Refuses an existing path that is not a folder (a file would only be found after the
    whole run, when the first output is written) and a place that cannot be written to:
    the nearest existing ancestor of a new folder, or an existing folder and the folder
    that holds it (results are built beside ``--out`` and swapped in,
    `mocapkit.io.atomic.atomic_folder`). Writable means both that `os.access` allows it
    and that a folder can really be made there and removed again: root passes
    `os.access` everywhere, even where nothing can be written (``/proc``, a read-only
    mount). Whether an existing folder may be reused stays the subcommand's rule.
    """
    import os
    from pathlib import Path

    p = Path(text).expanduser()
    if not text.strip():
        raise argparse.ArgumentTypeError("expected a folder, found an empty path")
    if p.exists() and not p.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: expected a folder, found an existing file")
    ancestor = p.parent if p.exists() else p
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise argparse.ArgumentTypeError(
            f"{text}: cannot create a folder under {ancestor}, which is a file"
        )
    for place in [ancestor] + ([p] if p.exists() else []):
        if not os.access(place, os.W_OK | os.X_OK) or not _can_make_folder_in(place):
            raise argparse.ArgumentTypeError(f"{text}: cannot write to {place} (read-only)")
    return text


def output_file(text: str) -> str:
    """A ``type=`` for ``--out`` files (``calibrate``'s cameras.json): checked before the
    work. Refuses an existing folder (it used to fail only at the end, naming an internal
    temporary file) and a place where nothing can be written (as `output_folder`)."""
    from pathlib import Path

    p = Path(text).expanduser()
    if not text.strip():
        raise argparse.ArgumentTypeError("expected a file, found an empty path")
    if p.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: expected a file to write, found a folder")
    output_folder(str(p.parent))  # the folder it goes in: creatable and writable
    return text


def _can_make_folder_in(folder: object) -> bool:
    """Whether a folder can be made in ``folder`` (made and removed at once)."""
    import os
    import tempfile

    try:
        probe = tempfile.mkdtemp(prefix=".mocapkit-probe-", dir=str(folder))
    except OSError:
        return False
    os.rmdir(probe)
    return True


#: The ``--mocap`` option's help (`mocap_folder`).
MOCAP_HELP = (
    "folder of motion clips (default: mocap in $MOCAPKIT_SHARED_DATA, else in shared/data or "
    "../shared/data above the working directory or the installed package)"
)


def mocap_folder(given: str | None) -> Path:
    """The ``--mocap`` folder of the accuracy studies: as given, else ``mocap`` in the
    shared data (`mocapkit.pipelines.demo.find_shared_data`: ``$MOCAPKIT_SHARED_DATA``,
    else ``shared/data`` or ``../shared/data`` above the working directory, then above
    the installed package: a checkout's own).

    Raises
    ------
    SessionError
        Neither given nor found; the message names the places tried and the variable.
    """
    import mocapkit
    from mocapkit.pipelines.demo import find_shared_data

    if given is not None:
        return Path(given)
    package = Path(mocapkit.__file__).resolve().parent
    data = find_shared_data() or find_shared_data(package)
    if data is None or not (data / "mocap").is_dir():
        env = os.environ.get("MOCAPKIT_SHARED_DATA")
        tried = (
            f"MOCAPKIT_SHARED_DATA={env}"
            if env
            else f"shared/data and ../shared/data above {Path.cwd()} and above {package}"
        )
        found = f"{data / 'mocap'} is not a folder" if data is not None else "none found"
        raise SessionError(
            f"no --mocap folder given and no shared mocap folder: tried {tried} ({found}); "
            "pass --mocap FOLDER or set MOCAPKIT_SHARED_DATA to the shared data folder"
        )
    return data / "mocap"
