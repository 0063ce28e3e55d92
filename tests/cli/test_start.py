"""The command starts without the heavy libraries: checked on `sys.modules` in a fresh process."""

from __future__ import annotations

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


@pytest.mark.parametrize(
    "argv", [["--help"], ["track", "hybrid", "--bogus"], ["trak"], ["view", "--help"]]
)
def test_help_and_usage_errors_load_no_heavy_library(argv: list[str]) -> None:
    code = (
        "import contextlib, io\nfrom mocapkit.cli.main import main\n"
        "out, err = io.StringIO(), io.StringIO()\n"
        "with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):\n"
        f"    try: main({argv!r})\n"
        "    except SystemExit: pass"
    )
    assert _loaded_after(code) == []


def test_help_only_entries_name_every_command() -> None:
    """The top-level help (help-only entries) lists the same commands as the full parser."""

    def commands(parser: object) -> dict[str, str]:
        sub = next(a for a in parser._actions if a.dest == "command")  # type: ignore[attr-defined]
        return {c.dest: c.help for c in sub._choices_actions}

    assert commands(build_parser("")) == commands(build_parser())
