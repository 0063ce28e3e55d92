"""The demo's comparison table: one aligned row per tracker with its rate (the run itself is
tested end to end in tests/cli/test_cli.py)."""

from __future__ import annotations

import math
from pathlib import Path

from mocapkit.eval.metrics import EvalReport
from mocapkit.pipelines.demo import TrackerRow, format_table


def _report(mpjpe_mm: float, pa_mpjpe_mm: float, elbow_mm: float) -> EvalReport:
    return EvalReport({}, mpjpe_mm, pa_mpjpe_mm, elbow_mm, 0.0, 0.0, 1.0, 10, 10, ("head",))


def _row(name: str, n_frames: int, wall_s: float) -> TrackerRow:
    return TrackerRow(
        name,
        f"{name} inputs",
        Path(name),
        _report(12.34, 5.0, 250.06),
        n_frames,
        wall_s,
        1.0,
        Path(name) / "index.html",
    )


def test_frames_per_s_is_frames_over_wall_time() -> None:
    assert _row("hybrid", 120, 4.0).frames_per_s == 30.0
    assert math.isnan(_row("hybrid", 120, 0.0).frames_per_s)


def test_table_has_one_aligned_row_per_tracker() -> None:
    rows = {n: _row(n, 120, 4.0) for n in ("hybrid", "stereo", "mono")}
    lines = format_table(rows)
    assert lines[0].split()[:5] == ["tracker", "MPJPE", "PA-MPJPE", "elbow", "frames/s"]
    body = lines[2:]
    assert [line.split()[0] for line in body] == ["hybrid", "stereo", "mono"]
    assert body[0].split()[1:5] == ["12.3", "5.0", "250.1", "30.0"]
    assert body[2].endswith("mono inputs")
    # the numbers end in the same columns as their headers
    header = lines[0]
    for title in ("MPJPE", "PA-MPJPE", "elbow", "frames/s"):
        end = header.index(title) + len(title)
        assert all(line[end - 1].isdigit() for line in body), (title, lines)
