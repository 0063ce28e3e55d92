"""Defaults stated once: every option's help and docs/cli.md show the library's own default.

An option whose default the library states (a config field, a keyword of the pipeline
function it calls, a module constant) carries it as ``stated_default``
(`mocapkit.cli.args.shows_default`): its argparse default is None (the library applies
its own) or that same value, and its help shows it through ``%(stated_default)s``. The
few defaults that only the command line has (its own folders, a CLI switch) are listed
here and shown through ``%(default)s``. No help spells a default as a literal.
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Iterator
from pathlib import Path

import pytest

from mocapkit.cli.args import StatedDefault
from mocapkit.cli.main import build_parser
from mocapkit.pipelines import fit_report
from mocapkit.pipelines.harness import JITTER_MM
from mocapkit.tracking.hybrid.arm_refinement import RefineConfig
from mocapkit.tracking.mono.tracker import MonoConfig
from mocapkit.tracking.multiview.config import MultiviewRunConfig
from mocapkit.tracking.stereo.arm_filter import ArmFilterConfig
from mocapkit.tracking.stereo.tracker import StereoConfig

CLI_DOC = Path(__file__).resolve().parents[2] / "docs" / "cli.md"

#: Defaults only the command line states (shown by ``%(default)s``): (command, option).
CLI_OWNED = {
    # the folders the accuracy studies write to
    ("accuracy hybrid", "--work"),
    ("accuracy mono", "--work"),
    ("accuracy stereo", "--work"),
    ("accuracy detect", "--work"),
    # auto: the library's callers say which posture; the command finds it by default
    ("track hybrid", "--posture"),
    # one run on the sessions as rendered (the library's keyword serves its studies)
    ("accuracy hybrid", "--jitter-repeats"),
}


def _parsers(
    parser: argparse.ArgumentParser, path: tuple[str, ...] = ()
) -> Iterator[tuple[str, argparse.ArgumentParser]]:
    """Every (sub)command's parser, by its command path ("track stereo")."""
    if path:
        yield " ".join(path), parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _parsers(sub, (*path, name))


def _options() -> list[tuple[str, argparse.ArgumentParser, argparse.Action]]:
    return [
        (command, parser, action)
        for command, parser in _parsers(build_parser())
        for action in parser._actions
        if action.option_strings and action.dest not in ("help", "version")
    ]


OPTIONS = _options()
STATED = [(c, p, a) for c, p, a in OPTIONS if hasattr(a, "stated_default")]


def _id(option: tuple[str, argparse.ArgumentParser, argparse.Action]) -> str:
    return f"{option[0]} {option[2].option_strings[-1]}"


def _help(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    """The option's help as ``--help`` prints it (one line)."""
    return " ".join(parser._get_formatter()._expand_help(action).split())


def _literal(value: object) -> bool:
    """A default a user could be told (not 'absent', not an off switch, not empty)."""
    return value is not None and value is not False and value != [] and value != ()


def test_every_subcommand_is_walked() -> None:
    commands = {c for c, _, _ in OPTIONS}
    assert {"track hybrid", "track stereo", "track mono", "synth", "accuracy stereo"} <= commands
    assert len(STATED) >= 40


@pytest.mark.parametrize("option", STATED, ids=_id)
def test_stated_default_is_the_librarys_and_shown(
    option: tuple[str, argparse.ArgumentParser, argparse.Action],
) -> None:
    _, parser, action = option
    stated: StatedDefault = action.stated_default  # type: ignore[attr-defined]
    value = stated.value()
    assert _literal(value) or value is None, stated.path
    # the argument leaves the default to the library, or holds the library's own value
    assert action.default is None or action.default == value
    assert f"default {stated}" in _help(parser, action) or f"default: {stated}" in _help(
        parser, action
    )


@pytest.mark.parametrize("option", OPTIONS, ids=_id)
def test_no_default_is_restated_as_a_literal(
    option: tuple[str, argparse.ArgumentParser, argparse.Action],
) -> None:
    command, _, action = option
    raw = action.help or ""
    assert not re.search(r"default:? ?[-+]?\.?\d", raw), f"{raw!r}: a number spelled out"
    if isinstance(action.default, str):
        assert not re.search(rf"default:? `?{re.escape(action.default)}\b", raw), raw
    if _literal(action.default) and not hasattr(action, "stated_default"):
        assert (command, action.option_strings[-1]) in CLI_OWNED, (
            f"{command} {action.option_strings[-1]}: default {action.default!r} stated in the "
            "command line; take it from the library (shows_default) or list it in CLI_OWNED"
        )
        assert "%(default)s" in raw


@pytest.mark.parametrize(
    ("command", "option", "value"),
    [
        ("track hybrid", "--max-elbow-speed", RefineConfig().elbow_speed_mm_per_s),
        ("track hybrid", "--warn-mm", fit_report.WARN_MM),
        ("track hybrid", "--warn-fraction", fit_report.WARN_FRACTION),
        ("track stereo", "--particles", ArmFilterConfig().n_particles),
        ("track stereo", "--cutoff-hz", MultiviewRunConfig().cutoff_hz),
        ("track stereo", "--torso", StereoConfig().torso),
        ("track mono", "--arm-prior-weight", MonoConfig().arm_prior_weight),
        ("track mono", "--cost", MonoConfig().cost),
        ("accuracy mono", "--arm-prior-weight", MonoConfig().arm_prior_weight),
        ("accuracy hybrid", "--jitter-mm", JITTER_MM),
        ("accuracy stereo", "--particles", ArmFilterConfig().n_particles),
    ],
)
def test_help_shows_the_config_default(command: str, option: str, value: object) -> None:
    """Known values, independently of `StatedDefault`'s own lookup."""
    [(parser, action)] = [(p, a) for c, p, a in OPTIONS if c == command and option in
                          a.option_strings]  # fmt: skip
    shown = f"{value:g}" if isinstance(value, float) else str(value)
    assert f"(default {shown}" in _help(parser, action) or f"default {shown})" in _help(
        parser, action
    )


def _doc_sections() -> dict[str, str]:
    """docs/cli.md by ``## command`` heading, each on one line."""
    text = CLI_DOC.read_text(encoding="utf-8")
    parts = re.split(r"^## (.+)$", text, flags=re.MULTILINE)
    return {parts[i].strip(): " ".join(parts[i + 1].split()) for i in range(1, len(parts), 2)}


def _same(shown: str, stated: str) -> bool:
    try:
        return float(shown) == float(stated)
    except ValueError:
        return shown == stated


def test_cli_doc_states_the_library_defaults() -> None:
    """Where docs/cli.md gives an option's default, it is the one the library states."""
    sections = _doc_sections()
    checked, wrong = 0, []
    for command, _, action in STATED:
        text = sections.get(command)
        if text is None:
            continue
        stated = str(action.stated_default)  # type: ignore[attr-defined]
        for option in action.option_strings:
            pattern = (
                rf"`{re.escape(option)}\b[^`]*`[^`]{{0,60}}?\bdefault:? (?:`([^`]+)`|([^\s),;:]+))"
            )
            for found in re.finditer(pattern, text):
                shown = (found.group(1) or found.group(2)).rstrip(".")
                checked += 1
                if not _same(shown, stated):
                    wrong.append(f"{command} {option}: docs say {shown}, the library {stated}")
    assert wrong == []
    assert checked >= 10
