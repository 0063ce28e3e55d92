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
import pkgutil
import sys
from collections.abc import Sequence

import mocapkit.cli as cli_package
from mocapkit import __version__
from mocapkit.errors import MocapError

_NOT_SUBCOMMANDS = {"main", "args"}


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
        description="Human motion capture from markers plus one camera, one video, "
        "or a stereo pair.",
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


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the process exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(_command_in(argv))
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except MocapError as exc:
        print(f"mocapkit {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        # a missing, unreadable or unwritable path: say which, without a traceback; an
        # OSError raised with a message only has no strerror/filename to show
        print(f"mocapkit {args.command}: error: {_os_error_text(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"mocapkit {args.command}: interrupted", file=sys.stderr)
        return 130


def _os_error_text(exc: OSError) -> str:
    if exc.strerror is None:
        return str(exc)
    return f"{exc.strerror}: {exc.filename}" if exc.filename is not None else exc.strerror


if __name__ == "__main__":
    sys.exit(main())
