"""Defaults stated once: the help and docs/cli.md show the library's own defaults."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from mocapkit.cli.main import build_parser
from mocapkit.pipelines import fit_report
from mocapkit.pipelines.harness import JITTER_MM
from mocapkit.tracking.hybrid.arm_refinement import RefineConfig
from mocapkit.tracking.mono.tracker import MonoConfig
from mocapkit.tracking.multiview.config import MultiviewRunConfig
from mocapkit.tracking.stereo.arm_filter import ArmFilterConfig

CLI_DOC = Path(__file__).resolve().parents[2] / "docs" / "cli.md"

#: (command, option, the library's default)
DEFAULTS = [
    (["track", "hybrid"], "--max-elbow-speed", RefineConfig().elbow_speed_mm_per_s),
    (["track", "hybrid"], "--warn-mm", fit_report.WARN_MM),
    (["track", "hybrid"], "--warn-fraction", fit_report.WARN_FRACTION),
    (["track", "stereo"], "--particles", ArmFilterConfig().n_particles),
    (["track", "stereo"], "--cutoff-hz", MultiviewRunConfig().cutoff_hz),
    (["track", "mono"], "--arm-prior-weight", MonoConfig().arm_prior_weight),
    (["accuracy", "mono"], "--arm-prior-weight", MonoConfig().arm_prior_weight),
    (["accuracy", "hybrid"], "--jitter-mm", JITTER_MM),
]


def _help_of(argv: list[str], option: str) -> str:
    """The help of ``option`` in ``mocapkit ARGV --help``, as argparse prints it."""
    parser = build_parser()
    for name in argv:
        sub = next(a for a in parser._actions if a.dest in ("command", "method"))
        parser = sub.choices[name]  # type: ignore[index]
    action = next(a for a in parser._actions if option in a.option_strings)
    return " ".join(parser._get_formatter()._expand_help(action).split())


@pytest.mark.parametrize(("argv", "option", "value"), DEFAULTS)
def test_help_shows_the_library_default(argv: list[str], option: str, value: float) -> None:
    assert f"(default {value:g}" in _help_of(argv, option)


@pytest.mark.parametrize(
    ("option", "value"),
    [(o, v) for a, o, v in DEFAULTS if a[0] == "track" and o != "--cutoff-hz"],
)
def test_cli_doc_states_the_library_default(option: str, value: float) -> None:
    doc = " ".join(CLI_DOC.read_text(encoding="utf-8").split())
    assert re.search(rf"{re.escape(option)}[^(]{{0,40}}\(default {value:g}\b", doc) or re.search(
        rf"{re.escape(option)}[^.]{{0,60}}default {value:g}\b", doc
    ), f"docs/cli.md: {option} with default {value:g}"
