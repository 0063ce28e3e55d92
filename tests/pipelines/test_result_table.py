"""`ResultTable`: a column read over all frames equals the rows' own values."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import UnknownNameError
from mocapkit.pipelines.result_table import ResultTable
from mocapkit.tracking.base import FrameResult


def test_fit_column_reads_the_rows_values_nan_where_a_frame_has_none(
    rng: np.random.Generator,
) -> None:
    table = ResultTable(2)  # grows past its capacity
    rows = []
    for t in range(5):
        fit = {"rms_mm": float(rng.uniform(0, 10))}
        if t != 2:
            fit["on_floor"] = float(t % 2)
        rows.append(FrameResult(0.1 * t, rng.normal(size=4), rng.normal(size=(15, 3)), {}, fit, ""))
        table.append(rows[-1])
    on_floor = table.fit_column("on_floor")
    assert on_floor.shape == (5,)
    np.testing.assert_array_equal(on_floor, [0.0, 1.0, np.nan, 1.0, 0.0])
    np.testing.assert_array_equal(table.fit_column("rms_mm"), [r.fit["rms_mm"] for r in rows])
    np.testing.assert_array_equal(
        table.fit_column("rms_mm"), [r.fit["rms_mm"] for r in table]
    )  # the rows the table rebuilds agree
    with pytest.raises(UnknownNameError, match=r"unknown fit figure 'edge_px'.*on_floor, rms_mm"):
        table.fit_column("edge_px")


def test_status_column_and_gaps_read_from_columns_equal_the_rows(
    rng: np.random.Generator,
) -> None:
    """A status over all frames (None where a frame lacks it) and the gaps found on the
    columns equal those of the rows the table rebuilds."""
    from mocapkit.pipelines.run import find_gaps

    left = ["seen", "bridged", "released", "released", "seen", "missing", "missing", "seen"]
    table = ResultTable(3)
    rows = []
    for t, st in enumerate(left):
        status = {"head": "seen", "left_hand": st}
        if t >= 2:
            status["right_hand"] = "missing" if t < 4 else "seen"
        rows.append(
            FrameResult(0.5 * t, rng.normal(size=4), rng.normal(size=(15, 3)), status, {}, "")
        )
        table.append(rows[-1])
    assert table.status_column("left_hand") == left
    assert table.status_column("right_hand") == [None, None, "missing", "missing"] + ["seen"] * 4
    gaps = find_gaps(table)
    assert gaps == find_gaps(list(table)) == find_gaps(rows)
    assert [(g.name, g.status, g.start_s, g.end_s, g.n_frames) for g in gaps] == [
        ("left_hand", "released", 1.0, 1.5, 2),
        ("right_hand", "missing", 1.0, 1.5, 2),
        ("left_hand", "missing", 2.5, 3.0, 2),
    ]
    with pytest.raises(UnknownNameError, match=r"unknown status 'right_foot'.*head, left_hand"):
        table.status_column("right_foot")
