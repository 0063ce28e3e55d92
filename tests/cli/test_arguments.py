"""Bad values and conflicting options are refused by argparse, before any work starts."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from mocapkit.cli.args import checked_by, number, parsed_by
from mocapkit.cli.main import build_parser, main
from mocapkit.errors import ConfigError
from mocapkit.synth.options import REALISM_RANGES


def _usage_error(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """Run the command line; it must stop with a usage error (status 2); its stderr."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: mocapkit")
    assert "Traceback" not in err
    return err


def test_number_bounds_and_messages() -> None:
    assert number(at_least=0.0, at_most=1.0)("0") == 0.0
    assert number(at_least=0.0, at_most=1.0)("1") == 1.0
    assert number(int, at_least=3)("3") == 3
    with pytest.raises(argparse.ArgumentTypeError, match=r"expected a number > 0, found 0"):
        number(above=0.0)("0")
    with pytest.raises(argparse.ArgumentTypeError, match=r"a number >= 0 and <= 1, found 1.5"):
        number(at_least=0.0, at_most=1.0)("1.5")
    with pytest.raises(argparse.ArgumentTypeError, match=r"expected a number, found nan"):
        number()("nan")
    with pytest.raises(argparse.ArgumentTypeError, match=r"expected an integer >= 3, found '2.5'"):
        number(int, at_least=3)("2.5")


def test_library_parsers_become_usage_errors() -> None:
    def parse(text: str) -> int:
        if text != "ok":
            raise ConfigError(f"--thing: expected 'ok', found {text!r}")
        return 1

    assert parsed_by(parse, "thing")("ok") == 1
    assert checked_by(parse, "thing")("ok") == "ok"
    # argparse names the option itself, so the library's "--thing:" prefix is dropped
    with pytest.raises(argparse.ArgumentTypeError) as exc:
        parsed_by(parse, "thing")("no")
    assert str(exc.value) == "expected 'ok', found 'no'"


def test_accuracy_positions_only_and_oriented_sets_exclude_each_other(
    capsys: pytest.CaptureFixture[str],
) -> None:
    err = _usage_error(
        ["accuracy", "hybrid", "--positions-only", "--oriented-sets", "head"], capsys
    )
    assert "argument --oriented-sets: not allowed with argument --positions-only" in err


def test_accuracy_oriented_sets_are_parsed_when_read(capsys: pytest.CaptureFixture[str]) -> None:
    args = build_parser().parse_args(["accuracy", "hybrid", "--oriented-sets", "head,right_hand"])
    assert args.oriented_sets == ("head", "right_hand")
    err = _usage_error(["accuracy", "hybrid", "--oriented-sets", "tail"], capsys)
    assert "argument --oriented-sets: unknown marker set 'tail'" in err
    err = _usage_error(["accuracy", "hybrid", "--oriented-sets", ","], capsys)
    assert "argument --oriented-sets: expected 'none' or comma-separated marker sets" in err


def test_accuracy_jitter_repeats_are_counts_and_the_jitter_positive(
    capsys: pytest.CaptureFixture[str],
) -> None:
    args = build_parser().parse_args(["accuracy", "hybrid", "--jitter-repeats", "4"])
    assert args.jitter_repeats == 4 and args.jitter_mm == 1e-6
    args = build_parser().parse_args(["accuracy", "hybrid", "--jitter-mm", "1e-5"])
    assert args.jitter_repeats == 0 and args.jitter_mm == 1e-5
    err = _usage_error(["accuracy", "hybrid", "--jitter-repeats", "-1"], capsys)
    assert "argument --jitter-repeats: expected an integer >= 0, found -1" in err
    err = _usage_error(["accuracy", "hybrid", "--jitter-mm", "0"], capsys)
    assert "argument --jitter-mm: expected a number > 0, found 0" in err


@pytest.mark.parametrize(
    ("option", "value", "reason"),
    [
        ("--size", "640x", "expected WIDTHxHEIGHT such as 640x480, found '640x'"),
        (
            "--size",
            "16x16",
            "expected WIDTHxHEIGHT with sides between 32 and 8192 px, found '16x16'",
        ),
        ("--fps", "0", "expected a number >= 1 and <= 1000, found 0"),
        ("--marker-rate", "5000", "expected a number >= 1 and <= 2000, found 5000"),
        ("--seconds", "-1", "expected a number > 0, found -1"),
        ("--start-s", "-0.5", "expected a number >= 0, found -0.5"),
        ("--blur", "2", "expected a number >= 0 and <= 1, found 2"),
        ("--dropout", "x", "expected a number >= 0 and <= 1, found 'x'"),
        ("--shirt-colour", "mauve-ish", "colour 'mauve-ish': expected one of black, blue"),
    ],
)
def test_synth_values_are_checked_while_parsing(
    option: str, value: str, reason: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "session"
    err = _usage_error(["synth", "builtin:wave", "--out", str(out), option, value], capsys)
    assert f"argument {option}: {reason}" in err
    assert not out.exists()


def test_synth_ranges_are_the_library_ranges() -> None:
    args = build_parser().parse_args(
        ["synth", "builtin:wave", "--out", "o", "--size", "96x72", "--blur", "1", "--noise", "0"]
    )
    assert args.size == (96, 72) and args.blur == 1.0 and args.noise == 0.0
    lo, hi = REALISM_RANGES["marker_noise_mm"]
    for accepted in (lo, hi):
        argv = ["synth", "m.bvh", "--out", "o", "--marker-noise-mm", str(accepted)]
        assert build_parser().parse_args(argv).marker_noise_mm == accepted
    for refused in (lo - 1.0, hi + 1.0):
        with pytest.raises(SystemExit):
            build_parser().parse_args(
                ["synth", "m.bvh", "--out", "o", "--marker-noise-mm", str(refused)]
            )


def test_calibrate_board_square_and_min_boards(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    base = ["calibrate", str(tmp_path), "--out", str(tmp_path / "cameras.json")]
    err = _usage_error([*base, "--board", "9by6", "--square-mm", "25"], capsys)
    assert "argument --board: expected inner corners as COLUMNSxROWS such as '9x6'" in err
    err = _usage_error([*base, "--board", "9x6", "--square-mm", "0"], capsys)
    assert "argument --square-mm: expected a number > 0, found 0" in err
    err = _usage_error([*base, "--board", "9x6", "--square-mm", "25", "--min-boards", "2"], capsys)
    assert "argument --min-boards: expected an integer >= 3, found 2" in err
    assert not (tmp_path / "cameras.json").exists()


def test_eval_joints_and_demo_seconds(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = build_parser().parse_args(["eval", "r", "--truth", "s", "--joints", "head, neck"])
    assert args.joints == ("head", "neck")
    assert build_parser().parse_args(["eval", "r", "--truth", "s"]).joints is None
    err = _usage_error(["eval", "r", "--truth", "s", "--joints", "head,nose"], capsys)
    assert "argument --joints: unknown canonical joint 'nose' in --joints" in err
    err = _usage_error(["demo", "--out", str(tmp_path / "d"), "--seconds", "0"], capsys)
    assert "argument --seconds: expected a number > 0, found 0" in err
    assert not (tmp_path / "d").exists()


@pytest.mark.parametrize(
    "argv",
    [
        ["track", "hybrid", "session"],
        ["track", "mono", "session"],
        ["track", "stereo", "session"],
        ["synth", "builtin:wave"],
        ["batch", "sessions"],
        ["demo"],
        ["view", "result"],
    ],
)
def test_out_naming_a_file_is_refused_before_the_work(
    argv: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Every subcommand that writes a folder checks --out while parsing (issue 14)."""
    existing = tmp_path / "taken.txt"
    existing.write_text("x")
    err = _usage_error([*argv, "--out", str(existing)], capsys)
    assert "argument --out: " in err and "expected a folder, found an existing file" in err
    err = _usage_error([*argv, "--out", str(existing / "sub")], capsys)
    assert "cannot create a folder under" in err and "which is a file" in err


def test_output_folder_accepts_new_and_existing_folders(tmp_path: Path) -> None:
    from mocapkit.cli.args import output_folder

    assert output_folder(str(tmp_path)) == str(tmp_path)
    assert output_folder(str(tmp_path / "a" / "b")) == str(tmp_path / "a" / "b")
    with pytest.raises(argparse.ArgumentTypeError, match="empty path"):
        output_folder(" ")


@pytest.mark.parametrize(
    "argv",
    [
        ["track", "hybrid", "SESSION"],
        ["track", "stereo", "SESSION"],
        ["track", "mono", "SESSION"],
        ["synth", "builtin:wave"],
    ],
)
def test_out_on_a_read_only_place_is_refused_before_the_work(
    argv: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch
) -> None:
    """A read-only --out is refused while parsing (issue 14). Root passes `os.access`
    everywhere, so both ways are tested: `os.access` saying no (monkeypatched), and a
    place where root passes `os.access` but nothing can be made (/proc)."""
    import os

    err = _usage_error([*argv, "--out", "/proc/mocapkit-result"], capsys)
    assert "argument --out: /proc/mocapkit-result: cannot write to /proc (read-only)" in err
    readonly = tmp_path / "ro"
    readonly.mkdir()
    real_access = os.access

    def access(path: object, mode: int) -> bool:
        return False if Path(str(path)) == readonly else real_access(path, mode)

    monkeypatch.setattr(os, "access", access)
    err = _usage_error([*argv, "--out", str(readonly / "new" / "result")], capsys)
    assert f"cannot write to {readonly} (read-only)" in err
    # an existing --out is swapped in from beside it: the folder holding it must be writable
    (readonly / "old").mkdir()
    err = _usage_error([*argv, "--out", str(readonly / "old")], capsys)
    assert f"cannot write to {readonly} (read-only)" in err
    assert sorted(p.name for p in readonly.iterdir()) == ["old"]  # no probe left behind


def test_mocap_folder_default_from_the_shared_data(tmp_path, monkeypatch):
    """``--mocap`` defaults to ``mocap`` in the shared data: ``$MOCAPKIT_SHARED_DATA``, else
    found from the working directory, else from the installed package (a checkout's own);
    when missing, the message names what was tried and the variable."""
    import mocapkit
    from mocapkit.cli.args import mocap_folder
    from mocapkit.errors import SessionError
    from mocapkit.pipelines import demo

    assert mocap_folder("clips") == Path("clips")
    monkeypatch.setenv("MOCAPKIT_SHARED_DATA", str(tmp_path))
    with pytest.raises(
        SessionError,
        match=rf"tried MOCAPKIT_SHARED_DATA={tmp_path} \(.*mocap is not a folder\); pass --mocap",
    ):
        mocap_folder(None)
    (tmp_path / "mocap").mkdir()
    assert mocap_folder(None) == tmp_path / "mocap"
    monkeypatch.delenv("MOCAPKIT_SHARED_DATA")
    starts = []

    def found_beside_the_package(start=None):
        starts.append(start)
        return tmp_path if start is not None else None

    monkeypatch.setattr(demo, "find_shared_data", found_beside_the_package)
    assert mocap_folder(None) == tmp_path / "mocap"
    assert starts == [None, Path(mocapkit.__file__).resolve().parent]
    monkeypatch.setattr(demo, "find_shared_data", lambda start=None: None)
    with pytest.raises(SessionError, match=r"tried shared/data and .* \(none found\)"):
        mocap_folder(None)
