"""Tests of the end-of-run fit report and its warnings."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.pipelines.fit_report import summarize_fit
from mocapkit.tracking.base import FrameResult, fit_summary


def _result(i: int, distances: dict[str, float]) -> FrameResult:
    fit, worst = fit_summary(distances)
    return FrameResult(i / 10.0, np.zeros(3), np.zeros((15, 3)), {}, fit, worst)


def test_known_values_and_flags():
    # head 10 mm on 19 frames and 50 mm on 1 (5 %: not flagged, the limit is "more than");
    # left hand 40 mm on 2 of its 10 seen frames (20 %: flagged); right hand never seen
    results = [
        _result(
            i,
            {
                "head": 50.0 if i == 0 else 10.0,
                "left_hand": (40.0 if i < 2 else 5.0) if i < 10 else math.nan,
                "right_hand": math.nan,
            },
        )
        for i in range(20)
    ]
    report = summarize_fit(results, warn_mm=30.0, warn_fraction=0.05)
    by = {s.name: s for s in report.sets}
    assert set(by) == {"head", "left_hand", "right_hand"}
    assert (by["head"].n_seen, by["head"].n_over) == (20, 1)
    assert by["head"].mean_mm == pytest.approx((50.0 + 19 * 10.0) / 20)
    assert by["head"].max_mm == 50.0
    assert (by["left_hand"].n_seen, by["left_hand"].n_over) == (10, 2)
    assert by["left_hand"].fraction_over == pytest.approx(0.2)
    assert by["right_hand"].n_seen == 0 and math.isnan(by["right_hand"].mean_mm)
    assert [s.name for s in report.flagged] == ["left_hand"]
    (warning,) = report.warnings()
    assert warning.startswith("WARNING: 'left_hand' is more than 30 mm from the model on 20.0 %")
    assert len(report.lines()) == 2 + 3
    # a stricter fraction flags the head too
    assert len(summarize_fit(results, 30.0, 0.04).flagged) == 2


def test_columns_align_with_long_member_names():
    # member names longer than the 12-character column used to push their rows right
    results = [_result(i, {"head": 5.0, "right_hand_side": 7.0}) for i in range(3)]
    lines = summarize_fit(results, warn_mm=30.0, warn_fraction=0.05).lines()
    header, head_row, member_row = lines[1], lines[2], lines[3]
    ends = [line.index("frames") + len("frames") for line in (header,)]
    ends += [line.index(" 3 ") + 2 for line in (head_row, member_row)]
    assert len(set(ends)) == 1  # the frames counts end under the header's "frames"
    assert member_row.startswith("  right_hand_side ")


def test_bad_thresholds():
    with pytest.raises(ConfigError, match="--warn-mm: expected a distance > 0 mm, found 0"):
        summarize_fit([], warn_mm=0.0)
    with pytest.raises(ConfigError, match=r"--warn-fraction: expected a share in \[0, 1\]"):
        summarize_fit([], warn_fraction=1.5)


def test_short_stature_warns_on_tennis_serve(shared_data):
    """A 900 mm stature for an adult player: the head set is out of the model's reach."""
    from mocapkit.io.marker_files import read_markers
    from mocapkit.io.markers import MarkerData
    from mocapkit.pipelines.hybrid_markers import track_hybrid_marker_file

    m = read_markers(shared_data / "c3d" / "kinematics_tennis_serve.c3d")
    n = 100
    part = MarkerData(m.time_s[:n], m.names, m.positions_mm[:n], m.rate_hz, m.source)
    sets = ["head=LFHD+RFHD+LBHD+RBHD", "left_hand=LWRA+LWRB", "right_hand=RWRA+RWRB"]
    run = track_hybrid_marker_file(part, sets, height_mm=900.0)
    flagged = {s.name for s in summarize_fit(run.results).flagged}
    assert "head" in flagged


def test_implausible_motion_round_trips_through_fit_csv_and_is_warned_about(
    tmp_path, capsys
) -> None:
    from mocapkit.eval.plausibility import FRAME_COLUMNS, SpeedBound, check_motion
    from mocapkit.pipelines.fit_report import (
        ImplausibleSpan,
        implausible_spans_in_folder,
        implausible_warnings,
        warn_implausible,
    )
    from mocapkit.pipelines.run import FIT_FILE, read_fit_csv, speed_bound, write_fit_csv
    from mocapkit.tracking.base import UNSEEN_SPEED_MM_S
    from mocapkit.tracking.hybrid.tracker import HybridConfig

    # one rule for every tracker: the hybrid re-plant's bound
    assert speed_bound() == SpeedBound(
        HybridConfig().replant_speed_factor, HybridConfig().replant_min_speed_mm_s
    )
    assert speed_bound().floor_mm_s == UNSEEN_SPEED_MM_S
    rng = np.random.default_rng(7)
    t = np.arange(30) / 10.0  # the times of `_result`
    joints = np.cumsum(rng.uniform(-2.0, 2.0, (30, 2, 3)), axis=0)
    inp = np.full((30, 2), 500.0)  # the inputs near both joints: 0.5 m/s
    inp[0] = np.nan
    joints[10:, 0] += [1180.0, 0, 0]  # 11.8 m/s on frames 10 and 11
    joints[11:, 0] += [1180.0, 0, 0]
    joints[20:, 1] += [0.0, 500.0, 0.0]  # 5 m/s on frame 20
    check = check_motion(t, ("left_shoulder", "right_knee"), joints, inp, speed_bound(), 1200.0)
    results = [_result(i, {"head": 5.0}) for i in range(30)]
    (tmp_path / "r").mkdir()
    write_fit_csv(tmp_path / "r" / FIT_FILE, results, check.columns())
    rows, columns = read_fit_csv(tmp_path / "r" / FIT_FILE)
    assert list(rows[0])[-len(FRAME_COLUMNS) :] == list(FRAME_COLUMNS)
    assert [rows[i]["worst_joint"] for i in (10, 11, 20)] == ["left_shoulder"] * 2 + ["right_knee"]
    np.testing.assert_array_equal(
        np.flatnonzero(np.nan_to_num(columns["implausible_joints"])), [10, 11, 20]
    )
    np.testing.assert_allclose(columns["worst_input_speed_mm_per_s"][10], 500.0)
    np.testing.assert_allclose(columns["worst_joint_speed_mm_per_s"][10], 11800.0, rtol=0.01)
    assert np.isnan(columns["worst_speed_ratio"][0]) and rows[0]["worst_joint"] == ""
    spans = implausible_spans_in_folder(tmp_path / "r")
    assert [(s.name, s.start_s, s.end_s, s.n_frames) for s in spans] == [
        ("left_shoulder", 1.0, 1.1, 2),
        ("right_knee", 2.0, 2.0, 1),
    ]
    lines = implausible_warnings(spans, shown=1)
    assert lines[0].startswith("WARNING: implausible motion in 2 spans (3 frames)")
    assert lines[1] == (
        "  left_shoulder moves 11.8 m/s at 1.00-1.10 s (2 frames) where the inputs near it "
        "move at most 0.5 m/s"
    )
    assert lines[2] == "  ... and 1 more (fit.csv)"
    warn_implausible(tmp_path / "r")
    assert "right_knee moves 5.0 m/s at 2.00 s" in capsys.readouterr().err
    assert implausible_warnings([]) == []
    # joints and rolls: their frames counted apart (a frame may have both), the worst of each
    roll = ImplausibleSpan("roll", "r_elbow", 1.0, 1.2, 3, 1500.0, np.nan, 1.25)
    lines = implausible_warnings([*spans, roll], shown=1)
    assert lines[0].startswith(
        "WARNING: implausible motion in 3 spans (3 frames of joints, 3 of rolls): faster"
    )
    assert lines[2] == (
        "  the r_elbow bone rolls 1500 deg/s about its axis at 1.00-1.20 s (3 frames) "
        "(limit 1200 deg/s)"
    )
    assert lines[3] == "  ... and 1 more (fit.csv)"
