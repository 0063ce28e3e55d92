"""``mocapkit`` entry point.

Each subcommand lives in its own module of this package and exposes
``register(subparsers)``, which adds its parser and sets ``func`` to a function
taking the parsed arguments and returning an exit code. Subcommands parse
arguments, call one library function and write its output; they hold no logic.

The command starts fast: a subcommand module imports its pipeline inside its handler
(and ``register``), and states its one-line ``HELP`` at module level. Only the command
named on the command line is registered in full; the others appear in the top-level
help by their ``HELP`` alone, so ``mocapkit --help`` or a usage error loads none of
numpy, OpenCV, Numba or Dask.
"""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import signal
import sys
from collections.abc import Sequence
from types import FrameType
from typing import Any

import mocapkit.cli as cli_package
from mocapkit import __version__
from mocapkit.errors import MocapError

_NOT_SUBCOMMANDS = {"main", "args"}

#: Exit code after Ctrl-C (128 + SIGINT, as shells report it).
INTERRUPTED_EXIT = 130


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The argument parser with its subcommand modules registered.

    Parameters
    ----------
    command : str, optional
        Register only this subcommand in full (the one on the command line); the others
        get a help-only entry from their module's ``HELP``. Default: all in full.
    """
    parser = argparse.ArgumentParser(
        prog="mocapkit",
        description="Human motion capture from head and hand markers plus one camera "
        "(hybrid), two or more calibrated cameras (stereo / multi-view), or one video (mono).",
    )
    parser.add_argument("--version", action="version", version=f"mocapkit {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for info in sorted(pkgutil.iter_modules(cli_package.__path__), key=lambda m: m.name):
        if info.name in _NOT_SUBCOMMANDS or info.name.startswith("_"):
            continue
        module = importlib.import_module(f"mocapkit.cli.{info.name}")
        register = getattr(module, "register", None)
        if register is None:
            continue
        help_line = getattr(module, "HELP", None)
        if command is None or info.name == command or help_line is None:
            register(sub)
        else:
            sub.add_parser(info.name, help=help_line, add_help=False)
    return parser


def _command_in(argv: Sequence[str]) -> str:
    """The subcommand named in ``argv`` ('' when none: the top-level options only)."""
    return next((a for a in argv if not a.startswith("-")), "")


class _Interrupts:
    """Records that Ctrl-C (SIGINT) came, then raises `KeyboardInterrupt` as Python does.

    A `KeyboardInterrupt` raised inside compiled code (a Numba kernel, a C extension, a
    generator being closed) may reach `main` as another exception (``SystemError: ...
    returned a result with an exception set``); with the record, whatever ends the
    command after a Ctrl-C is reported as the interruption it is.
    """

    def __init__(self, after: Any = None) -> None:
        self.seen = False
        self._previous: Any = None
        self._after = after

    def __enter__(self) -> _Interrupts:
        try:
            self._previous = signal.signal(signal.SIGINT, self._handle)
        except ValueError:  # not the main thread (an embedding application): leave it
            self._previous = None
        return self

    def __exit__(self, *exc: object) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous if self._after is None else self._after)

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        self.seen = True
        raise KeyboardInterrupt


def main(argv: Sequence[str] | None = None, *, process: bool = False) -> int:
    """Run the command line; returns the process exit code.

    ``process``: this call is the whole process (`entry`): once the command has ended,
    Ctrl-C is ignored rather than handed back to Python, whose shutdown resets it to the
    system default, so a Ctrl-C in the last instants would kill the process (exit -2)
    after its results were written.

    Errors of the input (`MocapError`, `OSError`) print one line and return 2; Ctrl-C,
    wherever it lands (loading the subcommands included), prints one line and returns
    130, results written before it intact (they are written atomically).
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    command = "mocapkit"
    with _Interrupts(signal.SIG_IGN if process else None) as interrupts:
        try:
            parser = build_parser(_command_in(argv))
            args = parser.parse_args(argv)
            command = f"mocapkit {args.command}"
            _show_input_warnings(args.command)
            return int(args.func(args) or 0)
        except MocapError as exc:
            if interrupts.seen:
                return _interrupted(command)
            print(f"{command}: error: {exc}", file=sys.stderr)
            return 2
        except OSError as exc:
            if interrupts.seen:
                return _interrupted(command)
            # a missing, unreadable or unwritable path: say which, without a traceback; an
            # OSError raised with a message only has no strerror/filename to show
            print(f"{command}: error: {_os_error_text(exc)}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            return _interrupted(command)
        except BaseException:
            if interrupts.seen and not isinstance(sys.exc_info()[1], SystemExit):
                return _interrupted(command)
            raise


def _interrupted(command: str) -> int:
    print(f"{command}: interrupted", file=sys.stderr)
    return INTERRUPTED_EXIT


def _show_input_warnings(command: str) -> None:
    """Print `InputWarning`s as ``mocapkit COMMAND: warning: ...`` (no source line)."""
    import warnings

    from mocapkit.errors import InputWarning

    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, InputWarning):
            print(f"mocapkit {command}: warning: {message}", file=sys.stderr)
        else:
            shown(message, category, filename, lineno, file, line)

    warnings.showwarning = show


def _os_error_text(exc: OSError) -> str:
    if exc.strerror is None:
        return str(exc)
    return f"{exc.strerror}: {exc.filename}" if exc.filename is not None else exc.strerror


def entry() -> None:
    """The ``mocapkit`` command: `main` as the whole process.

    After a Ctrl-C the process ends here, at once, with 130: a `KeyboardInterrupt` that
    landed in Python code run by an extension module while it was being imported is
    taken by the interpreter as unhandled even though `main` caught it, and its shutdown
    would then end the process by SIGINT (exit -2). The results are written atomically
    before this point; only the interpreter's own clean-up is skipped.
    """
    code = main(process=True)
    if code == INTERRUPTED_EXIT:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)


if __name__ == "__main__":
    entry()
