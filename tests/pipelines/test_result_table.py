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
