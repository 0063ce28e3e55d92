"""The multi-view fit pipeline: the default of ``track stereo`` and ``batch`` with keypoints."""

from __future__ import annotations

import csv
import math
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from mocapkit.cli.main import main
from mocapkit.eval.metrics import evaluate_result
from mocapkit.pipelines.multiview import (
    far_spans,
    far_spans_in_folder,
    resolve_stereo_method,
    track_multiview_session,
    track_stereo_auto,
)
from mocapkit.skeleton.model import CANONICAL_JOINTS
from mocapkit.tracking.base import FrameResult
from mocapkit.tracking.multiview.config import MultiviewRunConfig

ARMS_LEGS = tuple(j for j in CANONICAL_JOINTS if j not in ("head", "neck", "pelvis"))


@pytest.fixture(scope="module")
def ring_session(tmp_path_factory) -> Path:
    from mocapkit.synth.session_writer import SynthOptions, synthesize_session

    folder = tmp_path_factory.mktemp("ring") / "session"
    options = SynthOptions(rig="ring", start_s=0.5, seconds=1.0, image_size=(160, 120), seed=3)
    synthesize_session("builtin:wave", folder, options)
    return folder


def _count_loads(monkeypatch) -> list[Path]:
    """The folders of every `Session` built from now on (each one reads the whole folder)."""
    from mocapkit.io.session import Session

    loads: list[Path] = []
    init = Session.__init__

    def counted(self, path) -> None:  # type: ignore[no-untyped-def]
        loads.append(Path(path))
        init(self, path)

    monkeypatch.setattr(Session, "__init__", counted)
    return loads


def test_fit_is_the_default_with_keypoints(ring_session, tmp_path, capsys, monkeypatch) -> None:
    assert resolve_stereo_method(ring_session) == "fit"
    out = tmp_path / "result"
    loads = _count_loads(monkeypatch)
    assert main(["track", "stereo", str(ring_session), "--out", str(out)]) == 0
    # the session is read once for the choice of method and the fit (the evaluation
    # against the truth reads it once more)
    assert loads == [ring_session] * 2
    said = capsys.readouterr().out
    assert "fitted 31 frames" in said and "smoothing butterworth" in said
    rep = evaluate_result(out, ring_session, joints=ARMS_LEGS)
    assert rep.mpjpe_mm < 20.0  # the truth's own projections: the model's fit alone
    with (out / "fit.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 31
    assert {r["left_arm_status"] for r in rows} == {"seen"}
    assert max(float(r["left_wrist_ring2_px"]) for r in rows) < 3.0
    assert {r["left_wrist_views"] for r in rows} == {"4.000000"}
    assert far_spans_in_folder(out) == []


def test_lengths_and_smoothing_choices(ring_session) -> None:
    from mocapkit.io.session import load_session

    truth = load_session(ring_session).truth
    names = list(truth.joint_names)
    runs = {
        s: track_multiview_session(ring_session, config=MultiviewRunConfig(smoothing=s))
        for s in ("none", "one-euro")
    }
    for seg, (a, b) in (
        ("left_forearm", ("left_elbow", "left_wrist")),
        ("right_thigh", ("right_hip", "right_knee")),
    ):
        true_len = np.median(
            np.linalg.norm(
                truth.joints_mm[:, names.index(b)] - truth.joints_mm[:, names.index(a)], axis=1
            )
        )
        assert runs["none"].lengths_mm[seg] == pytest.approx(true_len, abs=5.0)
    # the online filter lags: it differs from the raw fit, but not by much
    d = np.abs(runs["none"].motion.joints_mm - runs["one-euro"].motion.joints_mm)
    assert 0.0 < np.nanmax(d) < 100.0


def test_without_keypoints_or_detector_auto_is_skin(ring_session, tmp_path, monkeypatch) -> None:
    monkeypatch.setattr("mocapkit.detect.backend.default_backend", lambda: None)
    bare = tmp_path / "bare"
    shutil.copytree(ring_session, bare)
    shutil.rmtree(bare / "keypoints")
    assert resolve_stereo_method(bare) == "skin"
    assert resolve_stereo_method(bare, "filter") == "filter"
    out = tmp_path / "r"
    loads = _count_loads(monkeypatch)
    track_stereo_auto(ring_session, out)
    assert loads == [ring_session]  # once, for the choice of method and the tracker
    assert far_spans_in_folder(out) == []
    assert (out / "fit.csv").is_file()


def test_far_spans_need_most_views_and_a_stretch() -> None:
    def frame(t: float, errs: tuple[float, ...]) -> FrameResult:
        fit = {f"left_wrist_c{i}_px": e for i, e in enumerate(errs)}
        return FrameResult(t, np.zeros(1), np.zeros((15, 3)), {}, fit, "")

    far = (80.0, 90.0, 5.0, math.nan)  # 2 of 3 views with a detection: most
    near = (80.0, 5.0, 5.0, 5.0)  # 1 of 4
    res = [frame(k / 30, near) for k in range(3)] + [frame(k / 30, far) for k in range(3, 9)]
    res += [frame(9 / 30, near)] + [frame(k / 30, far) for k in range(10, 13)]
    spans = far_spans(res, ["left_wrist"])
    assert spans == [("left_wrist", 0.1, 8 / 30, 6)]


def test_track_stereo_refuses_options_of_another_method(ring_session, tmp_path, capsys) -> None:
    out = str(tmp_path / "r")
    args = ["track", "stereo", str(ring_session), "--out", out]
    assert main([*args, "--method", "skin", "--keypoints"]) == 2
    assert "--keypoints is --method filter" in capsys.readouterr().err
    assert main([*args, "--method", "fit", "--particles", "50"]) == 2
    assert "--particles belongs to --method filter or skin" in capsys.readouterr().err


def test_batch_fits_a_session_with_keypoints_and_marks_a_poor_take(ring_session, tmp_path) -> None:
    from mocapkit.pipelines.batch import Take, TakeJob, run_take

    study = tmp_path / "study"
    shutil.copytree(ring_session, study / "take")
    (study / "take" / "markers.csv").unlink(missing_ok=True)
    opts = {"method": "auto", "joints": "upper"}
    row = run_take(
        TakeJob(Take("take", "session", (study / "take").resolve()), tmp_path / "o", opts)
    )
    assert (row.method, row.status) == ("stereo", "done") and row.mpjpe_mm < 20.0
    # one view's right wrist far off for a third of a second in most views: poor
    kp_dir = study / "take" / "keypoints"
    for cam in ("ring1", "ring2", "ring3"):
        path = kp_dir / f"{cam}.csv"
        lines = path.read_text().splitlines()
        head = lines[0].split(",")
        col = head.index("right_wrist_x_px")
        for i in range(5, 16):
            cells = lines[i].split(",")
            cells[col] = f"{float(cells[col]) + 90.0 * (1 if cam != 'ring2' else -1):.3f}"
            lines[i] = ",".join(cells)
        path.write_text("\n".join(lines) + "\n")
    row = run_take(
        TakeJob(Take("take", "session", (study / "take").resolve()), tmp_path / "o2", opts)
    )
    spans = far_spans_in_folder(tmp_path / "o2" / "take")
    assert row.status == "poor" and [s[0] for s in spans] == ["right_wrist"]


def test_auto_keeps_the_papers_tracker_on_a_narrow_pair(tmp_path) -> None:
    """On a narrow stereo pair (axes a few degrees apart) ``auto`` takes the paper's
    tracker on the keypoints, not the fit, which places the body poorly there."""
    from mocapkit.synth.session_writer import SynthOptions, synthesize_session

    folder = tmp_path / "pair"
    options = SynthOptions(rig="stereo", seconds=0.3, image_size=(160, 120), seed=1)
    synthesize_session("builtin:wave", folder, options)
    assert resolve_stereo_method(folder) == "filter"
    assert resolve_stereo_method(folder, "fit") == "fit"


def test_track_stereo_on_a_narrow_pair_says_what_a_detector_costs(tmp_path, capsys) -> None:
    """`track stereo` on a narrow pair says it keeps the paper's tracker and what the
    narrow baseline costs with a detector's keypoints (docs/stereo.md's figures)."""
    from mocapkit.synth.session_writer import SynthOptions, synthesize_session

    folder = tmp_path / "pair"
    options = SynthOptions(rig="stereo", seconds=0.3, image_size=(160, 120), seed=1)
    synthesize_session("builtin:wave", folder, options)
    assert main(["track", "stereo", str(folder), "--out", str(tmp_path / "r")]) == 0
    out = capsys.readouterr().out
    assert re.search(
        r"narrow pair \(optical axes less than 20 deg apart\): the paper's tracker.*"
        r"expect arm errors near 200 mm.*three or more cameras or a wide pair",
        out,
        flags=re.DOTALL,
    ), out


def test_auto_detects_missing_keypoints_when_a_detector_is_installed(
    ring_session, tmp_path, monkeypatch
) -> None:
    """Without keypoints but with a 2-D detector, ``auto`` detects them into the session
    (here a stand-in detector that restores the rendered keypoints) and fits."""
    from mocapkit.io.session_csv import read_keypoints_csv

    bare = tmp_path / "bare"
    shutil.copytree(ring_session, bare)
    shutil.rmtree(bare / "keypoints")
    asked: list[tuple[str, ...]] = []

    def detect(session, cameras, detector=None, say=None):
        asked.append(tuple(cameras))
        shutil.copytree(ring_session / "keypoints", bare / "keypoints")
        for cam in cameras:
            session.keypoints[cam] = read_keypoints_csv(bare / "keypoints" / f"{cam}.csv")
        return tuple(cameras)

    monkeypatch.setattr("mocapkit.detect.backend.default_backend", lambda: "mediapipe")
    monkeypatch.setattr("mocapkit.detect.run.ensure_keypoints", detect)
    assert resolve_stereo_method(bare) == "fit"
    assert len(asked) == 1 and len(asked[0]) == 4
    assert resolve_stereo_method(bare) == "fit"  # kept in the session: not detected again
    assert len(asked) == 1


def test_keypoints_of_a_backend_with_offsets_get_them(ring_session, tmp_path) -> None:
    import json

    from mocapkit.tracking.multiview.detector_offsets import detector_offsets, offset_segments
    from mocapkit.tracking.multiview.tracker import multiview_skeleton

    detected = tmp_path / "session"
    shutil.copytree(ring_session, detected, symlinks=True)
    cams = sorted(p.stem for p in (detected / "keypoints").glob("*.csv"))
    (detected / "keypoints" / "detect.json").write_text(
        json.dumps({c: {"backend": "mediapipe"} for c in cams})
    )
    cfg = MultiviewRunConfig(smoothing="none")
    plain = track_multiview_session(ring_session, config=cfg, max_frames=8)
    mp = track_multiview_session(detected, config=cfg, max_frames=8)
    off = detector_offsets("mediapipe")
    want, _ = offset_segments(multiview_skeleton(), plain.lengths_mm, {}, off)
    assert mp.lengths_mm == pytest.approx(want)
    assert mp.lengths_mm["left_shank"] > plain.lengths_mm["left_shank"] + 30.0
    # the joints move off the detections by about the offsets (the ankles' ~60 mm)
    d = np.linalg.norm(mp.motion.joints_mm - plain.motion.joints_mm, axis=-1)
    ankle = list(mp.motion.joint_names).index("left_ankle")
    assert 30.0 < float(np.median(d[:, ankle])) < 120.0
    # offsets given explicitly (none) win over the recorded backend
    none = track_multiview_session(detected, config=cfg, max_frames=8, point_offsets_mm={})
    assert none.lengths_mm == plain.lengths_mm
