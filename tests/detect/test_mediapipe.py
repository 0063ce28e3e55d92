"""MediaPipe Pose for real on a short rendered clip (skips where MediaPipe is not installed)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mocapkit.detect.mediapipe_pose import BODY_25_FROM_MEDIAPIPE, body25_from_landmarks
from mocapkit.io.openpose import BODY_25
from mocapkit.io.session import load_session
from mocapkit.synth.session_writer import SynthOptions, synthesize_session


def test_body25_mapping_takes_midpoints_and_named_points() -> None:
    lm = np.arange(33 * 3, dtype=float).reshape(33, 3)
    kp = body25_from_landmarks(lm)
    np.testing.assert_array_equal(kp[BODY_25.index("LWrist")], lm[15])
    np.testing.assert_array_equal(kp[BODY_25.index("RAnkle")], lm[28])
    np.testing.assert_array_equal(kp[BODY_25.index("Neck")], 0.5 * (lm[11] + lm[12]))
    np.testing.assert_array_equal(kp[BODY_25.index("MidHip")], 0.5 * (lm[23] + lm[24]))
    np.testing.assert_array_equal(kp[BODY_25.index("LSmallToe")], 0.0)
    assert len(BODY_25_FROM_MEDIAPIPE) == len(BODY_25)


def test_mediapipe_finds_the_rendered_subject(tmp_path: Path) -> None:
    pytest.importorskip("mediapipe", reason="MediaPipe not installed (mocapkit[detect])")
    from mocapkit.detect import detect_session

    folder = tmp_path / "s"
    synthesize_session("builtin:wave", folder, SynthOptions(seconds=1.0, fps=15.0))
    truth = load_session(folder).keypoints["mono"]
    out = tmp_path / "out"
    res = detect_session(folder, "mediapipe", out_dir=out)
    assert list(res.cameras) == ["mono"]
    got = load_session(folder).keypoints  # the session's own (true) ones stay untouched
    assert set(got) == {"mono"}
    from mocapkit.io.session_csv import read_keypoints_csv

    det = read_keypoints_csv(out / "keypoints" / "mono.csv")
    assert det.pixels.shape[0] == truth.pixels.shape[0]
    names = [
        n for n in det.joint_names if n in truth.joint_names and ("shoulder" in n or "hip" in n)
    ]
    err = np.linalg.norm(
        det.pixels[:, [det.joint_names.index(n) for n in names]]
        - truth.pixels[:, [truth.joint_names.index(n) for n in names]],
        axis=-1,
    )
    # a person in every frame; shoulders and hips within a few percent of the body's height
    assert np.isfinite(err).mean() > 0.9
    assert np.nanmedian(err) < 20.0
    summary = json.loads((out / "keypoints" / "detect.json").read_text())
    assert summary["mono"]["backend"] == "mediapipe"
    assert "largest person on frame 0" in summary["mono"]["followed"]
    world = np.load(out / "keypoints3d" / "mono.npz")
    assert world["world_mm"].shape == (truth.pixels.shape[0], 25, 3)
    # MediaPipe's metric 3-D: shoulders some 250-500 mm apart
    w = world["world_mm"]
    width = np.linalg.norm(
        w[:, BODY_25.index("LShoulder")] - w[:, BODY_25.index("RShoulder")], axis=-1
    )
    assert 200 < np.nanmedian(width) < 500
    # run again: cached
    assert detect_session(folder, "mediapipe", out_dir=out).cached == ["mono"]
