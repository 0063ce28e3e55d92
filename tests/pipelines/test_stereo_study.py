"""The stereo accuracy and ablation studies' argument checks."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.pipelines.stereo import stereo_ablations


def test_ablations_refuse_a_reset_outside_the_excerpt(tmp_path):
    # checked before any session is rendered: nothing is written
    with pytest.raises(ConfigError, match=r"expected the reset time within the excerpt .* 0.5 s"):
        stereo_ablations(tmp_path / "mocap", tmp_path / "work", seconds=0.5, reset_s=1.0)
    with pytest.raises(ConfigError, match=r"found reset_s = 0 s"):
        stereo_ablations(tmp_path / "mocap", tmp_path / "work", reset_s=0.0)
    assert not (tmp_path / "work").exists()


class _Rendered(Exception):
    """Stops a study at its first session."""


def _studied(monkeypatch, run) -> list[tuple[str, float]]:
    """The (clip, start) excerpts a study renders, recorded instead of rendering."""
    from mocapkit.pipelines import stereo

    seen: list[tuple[str, float]] = []

    def record(work, mocap_dir, clip, start, seconds):
        seen.append((clip, start))
        raise _Rendered

    monkeypatch.setattr(stereo, "_study_session", record)
    with pytest.raises(_Rendered):
        run()
    return seen


def test_studies_default_to_the_tuning_clips(tmp_path, monkeypatch):
    from mocapkit.pipelines.harness import TUNING_CLIPS
    from mocapkit.pipelines.stereo import STEREO_CLIPS, stereo_accuracy

    assert _studied(monkeypatch, lambda: stereo_accuracy(tmp_path, tmp_path)) == [
        (TUNING_CLIPS[0], STEREO_CLIPS[TUNING_CLIPS[0]])
    ]
    assert _studied(monkeypatch, lambda: stereo_ablations(tmp_path, tmp_path)) == [
        (TUNING_CLIPS[0], STEREO_CLIPS[TUNING_CLIPS[0]])
    ]


def test_an_unlisted_clip_starts_where_its_pelvis_travels_least():
    from mocapkit.pipelines.stereo import stillest_start_s

    t = 5.0 + np.arange(0, 241) / 30.0  # 8 s from 5 s
    pelvis = np.zeros((t.size, 3))
    pelvis[:, 0] = 400.0 * (t - 5.0)  # walks 0.4 m/s ...
    pelvis[(t >= 7.0) & (t <= 7.0 + 4.0), 0] = 800.0  # ... but stands 2-6 s in
    pelvis[t > 11.0, 0] = 800.0 + 400.0 * (t[t > 11.0] - 11.0)
    assert stillest_start_s(t, pelvis, 4.0) == 2.0
    assert stillest_start_s(t, pelvis, 4.0, step_s=1.5) == 1.5  # the grid's nearest
    assert stillest_start_s(t[:90], pelvis[:90], 4.0) == 0.0  # shorter than the excerpt


def test_unlisted_clip_start_from_the_real_clip(shared_data, monkeypatch):
    from mocapkit.io.motion_files import read_motion
    from mocapkit.pipelines.stereo import STEREO_CLIPS, excerpt_start_s, stillest_start_s

    mocap = shared_data / "mocap"
    assert "zombie.amc" not in STEREO_CLIPS
    m = read_motion(mocap / "zombie.amc")
    start = stillest_start_s(m.time_s, m.joint("pelvis"), 4.0)
    assert excerpt_start_s(mocap, "zombie.amc", 4.0) == start
    assert excerpt_start_s(mocap, "13_26.bvh", 4.0) == STEREO_CLIPS["13_26.bvh"]


def _row(clip: str, mode: str, err: float, yaw: float) -> dict:
    from mocapkit.pipelines.stereo import ARM_JOINTS

    per = {j: err + k for k, j in enumerate(ARM_JOINTS)}
    return {
        "clip": clip,
        "mode": mode,
        "per_joint_mm": per,
        "arm_mean_mm": err + 2.5,
        "torso_yaw_error_deg": yaw,
    }


def test_accuracy_means_per_mode():
    from mocapkit.pipelines.stereo import ARM_JOINTS, accuracy_means

    rows = [_row("a", "skin", 10.0, 1.0), _row("a", "keypoints", 4.0, 3.0)]
    rows += [_row("b", "skin", 20.0, 2.0), _row("b", "keypoints", 6.0, 5.0)]
    means = accuracy_means(rows)
    assert [(m["clip"], m["mode"]) for m in means] == [("mean", "skin"), ("mean", "keypoints")]
    assert means[0]["per_joint_mm"] == {j: 15.0 + k for k, j in enumerate(ARM_JOINTS)}
    assert (means[0]["arm_mean_mm"], means[0]["torso_yaw_error_deg"]) == (17.5, 1.5)
    assert (means[1]["arm_mean_mm"], means[1]["torso_yaw_error_deg"]) == (7.5, 4.0)


def test_cli_takes_the_clip_set_and_prints_the_mean(tmp_path, monkeypatch, capsys):
    from mocapkit.cli.main import main
    from mocapkit.pipelines import stereo
    from mocapkit.pipelines.harness import REPORT_CLIPS

    asked = []

    def fake(mocap, work, clips=None, **kwargs):
        asked.append(clips)
        return [_row("x", "keypoints+torso", 10.0, 1.0), _row("y", "keypoints+torso", 30.0, 3.0)]

    monkeypatch.setattr(stereo, "stereo_accuracy", fake)
    args = ["accuracy", "stereo", "--mocap", str(tmp_path), "--work", str(tmp_path / "w")]
    assert main(args) == 0
    assert main([*args, "--clip-set", "report"]) == 0
    assert asked == [None, list(REPORT_CLIPS)]
    out = capsys.readouterr().out.splitlines()
    assert out[-1].split()[:2] == ["mean", "keypoints+torso"]
    assert out[-1].split()[-2:] == ["22.5", "2.0"]


def test_detector_option_is_passed_on_and_an_unknown_one_refused(tmp_path, monkeypatch, capsys):
    from mocapkit.cli.main import main
    from mocapkit.errors import UnknownNameError
    from mocapkit.pipelines import stereo

    # refused before any session is rendered, with the valid choices
    with pytest.raises(UnknownNameError, match=r"unknown detector 'openpose' in --detector; "
                       r"expected one of: mediapipe"):  # fmt: skip
        stereo.stereo_accuracy(tmp_path, tmp_path / "w", detector="openpose")
    with pytest.raises(ConfigError, match=r"--detector: the modes \['skin'\] track from the video"):
        stereo.stereo_accuracy(tmp_path, tmp_path / "w", modes=("skin",), detector="mediapipe")
    assert not (tmp_path / "w").exists()
    args = ["accuracy", "stereo", "--mocap", str(tmp_path), "--work", str(tmp_path / "w")]
    assert main([*args, "--detector", "openpose"]) == 2
    assert "expected one of: mediapipe" in capsys.readouterr().err
    assert main([*args, "--detector", "mediapipe", "--ablations"]) == 2
    assert "--detector: not with --ablations" in capsys.readouterr().err

    asked = []

    def fake(mocap, work, clips=None, **kwargs):
        asked.append(kwargs.get("detector"))
        return [{**_row("x", "keypoints+torso", 10.0, 1.0), "keypoints": "mediapipe"}]

    monkeypatch.setattr(stereo, "stereo_accuracy", fake)
    assert main(args) == 0
    assert main([*args, "--detector", "mediapipe"]) == 0
    assert asked == [None, "mediapipe"]
    assert capsys.readouterr().out.splitlines()[-1].split()[:3] == [
        "mean",
        "keypoints+torso",
        "mediapipe",
    ]


def test_detected_keypoints_replace_the_true_ones_and_are_kept(tmp_path):
    pytest.importorskip("mediapipe", reason="MediaPipe not installed (mocapkit[detect])")
    from mocapkit.io.session import load_session
    from mocapkit.pipelines.stereo import _with_keypoints
    from mocapkit.synth.session_writer import SynthOptions, synthesize_session

    path = tmp_path / "s"
    synthesize_session(
        "builtin:table-tennis", path, SynthOptions(rig="stereo", seconds=0.3, sleeve="long")
    )
    true = load_session(path)
    views = ("stereo_left", "stereo_right")
    session = _with_keypoints(path, ",".join(views), "mediapipe")
    csv = path / "detect_mediapipe" / "keypoints" / f"{views[0]}.csv"
    kept = csv.stat().st_mtime_ns
    for c in views:
        kp, tk = session.keypoints[c], true.keypoints[c]
        assert kp.source.endswith("(detected: mediapipe)")
        assert kp.joint_names == tk.joint_names and kp.pixels.shape == tk.pixels.shape
        err = np.linalg.norm(kp.pixels - tk.pixels, axis=-1)
        # a real detection: near the truth but not it
        wrists = [list(kp.joint_names).index(j) for j in ("left_wrist", "right_wrist")]
        assert 0.0 < np.nanmedian(err[:, wrists]) < 20.0
    assert (
        _with_keypoints(path, None, None).keypoints[views[0]].source
        == true.keypoints[views[0]].source
    )
    _with_keypoints(path, ",".join(views), "mediapipe")  # reused, not detected again
    assert csv.stat().st_mtime_ns == kept
