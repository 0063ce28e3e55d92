"""The command starts without the heavy libraries: checked on `sys.modules` in a fresh process."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import pytest

from mocapkit.cli.main import build_parser

HEAVY = ("dask", "numba", "cv2", "scipy", "filterpy", "matplotlib", "plotly")


def _loaded_after(code: str) -> list[str]:
    """The heavy top-level packages a fresh interpreter holds after running ``code``."""
    probe = (
        f"{code}\nimport json, sys\n"
        f"print(json.dumps(sorted({{m.split('.')[0] for m in sys.modules}} & set({HEAVY!r}))))"
    )
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True
    ).stdout
    return list(json.loads(out.strip().splitlines()[-1]))


def test_importing_the_command_loads_no_heavy_library() -> None:
    assert _loaded_after("import mocapkit.cli.main") == []
    assert _loaded_after("import mocapkit") == []


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    sub = next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)
    return {} if sub is None else dict(sub.choices)


def _usage_errors() -> list[list[str]]:
    """An unknown option given to every command and to every method of a command."""
    argvs = []
    for name, command in _subcommands(build_parser()).items():
        argvs.append([name, "--bogus"])
        argvs += [[name, method, "--bogus"] for method in _subcommands(command)]
    return argvs


def _main_loads(argv: list[str]) -> list[str]:
    code = (
        "import contextlib, io\nfrom mocapkit.cli.main import main\n"
        "out, err = io.StringIO(), io.StringIO()\n"
        "with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):\n"
        f"    try: main({argv!r})\n"
        "    except SystemExit: pass"
    )
    return _loaded_after(code)


@pytest.mark.parametrize("argv", [["--help"], ["trak"], ["view", "--help"]])
def test_help_loads_no_heavy_library(argv: list[str]) -> None:
    assert _main_loads(argv) == []


def test_every_usage_error_loads_no_heavy_library() -> None:
    """Each command's and each method's usage error: checked in one fresh process each."""
    argvs = _usage_errors()
    assert ["track", "hybrid", "--bogus"] in argvs and ["synth", "--bogus"] in argvs
    loaded = {" ".join(argv): _main_loads(argv) for argv in argvs}
    assert {k: v for k, v in loaded.items() if v} == {}


def test_help_only_entries_name_every_command() -> None:
    """The top-level help (help-only entries) lists the same commands as the full parser."""

    def commands(parser: object) -> dict[str, str]:
        sub = next(a for a in parser._actions if a.dest == "command")  # type: ignore[attr-defined]
        return {c.dest: c.help for c in sub._choices_actions}

    assert commands(build_parser("")) == commands(build_parser())
