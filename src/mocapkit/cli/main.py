"""``mocapkit`` entry point.

Each subcommand lives in its own module of this package and exposes
``register(subparsers)``, which adds its parser and sets ``func`` to a function
taking the parsed arguments and returning an exit code. Subcommands parse
arguments, call one library function and write its output; they hold no logic.
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


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser with every subcommand module registered."""
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
        if register is not None:
            register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the process exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    _show_input_warnings(args.command)
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


if __name__ == "__main__":
    sys.exit(main())
