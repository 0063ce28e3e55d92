"""The ``mocapkit`` entry point: subcommand discovery, refusals with exit code 2, the demo."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from mocapkit.cli.main import main

SUBCOMMANDS = ("calibrate", "synth", "eval", "track", "bench", "demo")


def test_help_lists_every_subcommand(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    # the subcommand column of argparse's help: "    NAME   help text" (help may wrap)
    listed = set(re.findall(r"^ {4}(\w+)(?:\s|$)", out, flags=re.MULTILINE))
    missing = [name for name in SUBCOMMANDS if name not in listed]
    assert not missing, f"mocapkit --help does not list {missing}:\n{out}"


def test_track_help_lists_hybrid(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["track", "--help"])
    assert re.search(r"^ {4}hybrid\s", capsys.readouterr().out, flags=re.MULTILINE)


def test_unknown_subcommand_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["dance"])
    assert exc.value.code == 2
    assert "invalid choice: 'dance'" in capsys.readouterr().err


def test_track_hybrid_needs_session_or_markers(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["track", "hybrid", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "mocapkit track: error:" in err
    assert "expected a SESSION folder or --markers FILE, found neither" in err
    assert "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_track_hybrid_refuses_both_session_and_markers(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["track", "hybrid", str(tmp_path), "--markers", str(tmp_path / "m.c3d")]
    assert main([*args, "--out", str(tmp_path / "out")]) == 2
    assert "either a SESSION folder or --markers FILE, not both" in capsys.readouterr().err


def test_eval_missing_result_names_the_path(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    missing = tmp_path / "no_such_result"
    assert main(["eval", str(missing), "--truth", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("mocapkit eval: error:")
    assert str(missing) in err and "not found" in err


def test_eval_missing_truth_session_names_the_path(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    result = tmp_path / "result"
    result.mkdir()
    (result / "joints.csv").write_text("time_s,head_x_mm,head_y_mm,head_z_mm\n0.0,1,2,3\n")
    missing = tmp_path / "no_such_session"
    assert main(["eval", str(result), "--truth", str(missing)]) == 2
    err = capsys.readouterr().err
    assert str(missing) in err and "session folder not found" in err


def test_demo_end_to_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--seconds", "1", "--quiet"]) == 0
    captured = capsys.readouterr()
    text = captured.out
    rows = {}
    for tracker in ("hybrid", "stereo", "mono"):
        m = re.search(rf"^{tracker}" + r"\s+(\d+\.\d)" * 4 + r"  \S", text, flags=re.MULTILINE)
        assert m, f"no {tracker!r} row in the demo's table:\n{text}"
        rows[tracker] = tuple(float(g) for g in m.groups())
    # plausible errors (mm): not zero (no tracker reads the truth) and, for the
    # trackers that see the body's place (markers, a stereo pair), far below a body
    # length; mono's pose after Procrustes alignment likewise
    for tracker, (mpjpe, pa_mpjpe, elbow, fps) in rows.items():
        assert all(1.0 < e < 400.0 for e in (pa_mpjpe,)), (tracker, rows)
        if tracker != "mono":
            assert all(1.0 < e < 400.0 for e in (mpjpe, elbow)), (tracker, rows)
        assert fps > 0.0
    page = out / "report" / "index.html"
    assert text.rstrip().endswith(f"report: {page}")
    # --quiet: the table and the report's path only, no narration, no progress
    assert "tracked" not in text and "session written" not in text, text
    assert captured.err == ""
    html = page.read_text()
    for tracker in ("hybrid", "stereo", "mono"):
        assert f'href="{tracker}/index.html"' in html
        assert (out / "report" / tracker / "index.html").is_file()
        for name in ("motion.npz", "joints.csv", "motion.bvh"):
            assert (out / f"result_{tracker}" / name).is_file(), f"result_{tracker}/{name}"
    for sub in ("ik_only", "positions_only_ik", "positions_only_video"):
        assert (out / f"result_hybrid_{sub}" / "motion.npz").is_file(), sub
    for name in ("session.json", "cameras.json", "markers.csv", "truth.npz"):
        assert (out / "session" / name).is_file(), f"session/{name} missing"
    for cam in ("mono", "stereo_left", "stereo_right"):
        assert (out / "session" / "video" / f"{cam}.mp4").is_file()
        assert (out / "session" / "keypoints" / f"{cam}.csv").is_file()


def test_track_hybrid_refuses_options_that_do_not_apply(tmp_path, capsys) -> None:
    code = main(["track", "hybrid", str(tmp_path), "--out", str(tmp_path / "o"), "--free-feet"])
    assert code == 2
    assert "--free-feet apply to --markers" in capsys.readouterr().err
    code = main(["track", "hybrid", "--markers", "m.c3d", "--paper", "--out", str(tmp_path / "o")])
    assert code == 2
    assert "--paper apply to a SESSION" in capsys.readouterr().err
    code = main(["track", "hybrid", "--markers", "m.c3d", "--oriented-sets", "head", "--out", "o"])
    assert code == 2
    assert "--oriented-sets apply to a SESSION" in capsys.readouterr().err
    code = main(
        [
            "track",
            "hybrid",
            str(tmp_path),
            "--out",
            "o",
            "--positions-only",
            "--oriented-sets",
            "head",
        ]
    )
    assert code == 2
    assert "either --positions-only or --oriented-sets" in capsys.readouterr().err
    code = main(
        ["track", "hybrid", "--markers", "m.c3d", "--max-elbow-speed", "5000", "--out", "o"]
    )
    assert code == 2
    assert "--max-elbow-speed apply to a SESSION" in capsys.readouterr().err
    for flag in ("--paper", "--no-video"):
        code = main(
            ["track", "hybrid", str(tmp_path), "--out", "o", flag, "--max-elbow-speed", "5000"]
        )
        assert code == 2
        assert "elbow-jump penalty, which --paper and --no-video do not run" in (
            capsys.readouterr().err
        )


def test_os_errors_are_reported_by_path_not_as_none(tmp_path, capsys):
    """A reader's FileNotFoundError(message) used to print "None: None"."""
    missing = tmp_path / "nope.c3d"
    code = main(["track", "hybrid", "--markers", str(missing), "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert code == 2
    assert "None" not in err and "nope.c3d" in err
    # a folder given as a marker file is called a folder, not "not found" (issue 14)
    folder = tmp_path / "take.c3d"
    folder.mkdir()
    argv = ["track", "hybrid", "--markers", str(folder), "--marker-set", "head=A"]
    code = main([*argv, "--marker-set", "left_hand=B", "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert code == 2 and "take.c3d: expected a marker file, found a folder" in err
    assert "not found" not in err


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        (["--costume", "paper"], {"bare_from": "elbow", "belt": True, "girdle_neck": True}),
        (["--costume", "everyday"], {"bare_from": "mid_upper_arm", "trunk_from_head": True}),
        (
            ["--costume", "paper", "--bare-from", "shoulder"],
            {"bare_from": "shoulder", "belt": True},
        ),
        ([], {"bare_from": None}),
    ],
)
def test_track_mono_costume_sets_the_skin_tracker(
    extra: list[str], expected: dict[str, object], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``--costume`` passes that costume's `SKIN_SETTINGS` to `track_mono`; ``--bare-from``
    overrides where the arms' skin starts; without either, the paper's printed rules."""
    from dataclasses import replace

    import mocapkit.pipelines.mono as mono
    from mocapkit.pipelines.mono import SKIN_SETTINGS, SkinOptions

    seen: dict[str, object] = {}

    class Called(Exception):
        pass

    def record(*args: object, **kwargs: object) -> None:
        seen.update(kwargs)
        raise Called

    monkeypatch.setattr(mono, "track_mono", record)
    with pytest.raises(Called):
        main(["track", "mono", str(tmp_path), "--out", str(tmp_path / "out"), "--skin", *extra])
    assert seen["skin"] is True
    options = seen["skin_options"]
    assert isinstance(options, SkinOptions)
    for key, value in expected.items():
        assert getattr(options, key) == value
    if "--costume" in extra:
        costume = extra[extra.index("--costume") + 1]
        arms = {"bare_from": expected["bare_from"]} if "--bare-from" in extra else {}
        assert options == replace(SKIN_SETTINGS[costume], **arms)
    else:
        assert options == SkinOptions(bare_from=None)


def test_track_mono_costume_needs_skin(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(
        ["track", "mono", str(tmp_path), "--out", str(tmp_path / "o"), "--costume", "paper"]
    )
    assert code == 2
    assert "expected them with --skin" in capsys.readouterr().err


def test_speed_line_says_when_the_run_compiled_the_kernels() -> None:
    from mocapkit.cli.track_stereo import first_run
    from mocapkit.timing import CompileTime

    assert first_run(CompileTime()) == ""
    assert first_run(CompileTime(67, 22.46)) == (
        "; first run: includes compiling 67 kernels, 22.5 s; later runs load them from the cache"
    )
    assert first_run(CompileTime(1, 0.5)).startswith("; first run: includes compiling 1 kernel,")


def test_help_names_every_tracker_setting(capsys: pytest.CaptureFixture[str]) -> None:
    """The top help names the three set-ups, multi-view included; the stereo method's line
    says its default is the full-body fit, the paper's tracker the narrow pair's."""
    with pytest.raises(SystemExit):
        main(["--help"])
    top = " ".join(capsys.readouterr().out.split())
    assert "two or more calibrated cameras (stereo / multi-view)" in top
    assert "one video (mono)" in top and "plus one camera (hybrid)" in top
    with pytest.raises(SystemExit):
        main(["track", "--help"])
    track = " ".join(capsys.readouterr().out.split())
    assert "the full body fitted to every view's 2-D keypoints; on a narrow pair" in track


def test_far_spans_listed_longest_first_then_counted() -> None:
    from mocapkit.cli.track_stereo import far_warnings

    spans = [("left_wrist", 0.5, 0.6, 5), ("right_knee", 1.0, 1.4, 13)]
    spans += [("nose", 2.0 + k, 2.2 + k, 7) for k in range(3)]
    lines = far_warnings(spans, 40.0)
    assert lines == [
        "warning: a joint is more than 40 px from its detections in most views in 5 spans "
        "(39 frames); see fit.csv",
        "  right_knee at 1.00-1.40 s (13 frames)",
        "  nose at 2.00-2.20 s (7 frames)",
        "  nose at 3.00-3.20 s (7 frames)",
        "  ... and 2 more (fit.csv)",
    ]
    assert far_warnings([], 40.0) == []
