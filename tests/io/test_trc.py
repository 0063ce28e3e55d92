"""TRC marker files: write/read round trip, units, missing fields, malformed files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import ConfigError, FormatError, ShapeError
from mocapkit.io.marker_files import read_markers
from mocapkit.io.trc import read_trc, write_trc

# Printed with 1e-6 mm resolution: half a unit of the last digit, plus the double rounding
# of the unit conversion (relative 1e-12 is far below it and far above machine epsilon).
ROUND_TRIP = {"rtol": 1e-12, "atol": 5e-7}

# An OpenSim-style file in metres: blank line after the header, trailing tabs, gaps.
_OPENSIM_M = (
    "PathFileType\t4\t(X/Y/Z)\twalk.trc\n"
    "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame"
    "\tOrigNumFrames\n"
    "60.00\t60.00\t3\t2\tm\t60.00\t1\t3\n"
    "Frame#\tTime\tRASI\t\t\tLASI\t\t\t\n"
    "\t\tX1\tY1\tZ1\tX2\tY2\tZ2\t\n"
    "\n"
    "1\t0.000000\t0.1\t0.2\t0.9\t-0.1\t0.2\t0.9\t\n"
    "2\t0.016667\t0.1005\t0.2\t0.9\t\t\t\n"
    "3\t0.033333\t0.101\t0.2\t0.9\tNaN\tNaN\tNaN\n"
)


def _header(n_frames: int = 2, n_markers: int = 2, units: str = "mm") -> str:
    return (
        "PathFileType\t4\t(X/Y/Z)\tbad.trc\n"
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\n"
        f"100\t100\t{n_frames}\t{n_markers}\t{units}\n"
        "Frame#\tTime\tA\t\t\tB\t\t\n"
        "\t\tX1\tY1\tZ1\tX2\tY2\tZ2\n"
    )


def test_round_trip_mm_exact_to_printed_precision(tmp_path: Path, rng: np.random.Generator) -> None:
    t = np.arange(25) / 120.0
    pos = rng.normal(0.0, 1000.0, size=(25, 3, 3))
    pos[rng.random((25, 3)) < 0.25] = np.nan
    names = ["Derrick:C7", "LFHD", "R_IAS"]
    path = tmp_path / "sub" / "take.trc"
    write_trc(path, t, names, pos)  # the exact positional signature other modules call
    m = read_trc(path)
    assert m.names == tuple(names)
    assert m.rate_hz == pytest.approx(120.0)
    np.testing.assert_array_equal(np.isnan(m.positions_mm), np.isnan(pos))
    np.testing.assert_allclose(m.positions_mm, pos, **ROUND_TRIP)
    np.testing.assert_allclose(m.time_s, t, rtol=0, atol=5e-9)
    assert [p.name for p in path.parent.iterdir()] == ["take.trc"]


@pytest.mark.parametrize("units", ["m", "cm"])
def test_round_trip_other_units_keeps_micrometre_precision(
    tmp_path: Path, rng: np.random.Generator, units: str
) -> None:
    t = np.arange(10) / 50.0
    pos = rng.normal(0.0, 900.0, size=(10, 2, 3))
    path = tmp_path / "take.trc"
    write_trc(path, t, ["A", "B"], pos, units)
    lines = path.read_text().splitlines()
    assert lines[2].split("\t")[4] == units
    m = read_markers(path)
    np.testing.assert_allclose(m.positions_mm, pos, **ROUND_TRIP)


def test_written_header_layout(tmp_path: Path) -> None:
    path = tmp_path / "h.trc"
    write_trc(path, [0.0, 0.01], ["A", "B"], np.ones((2, 2, 3)), rate_hz=100.0)
    lines = path.read_text().split("\n")
    assert lines[0] == "PathFileType\t4\t(X/Y/Z)\th.trc"
    keys = ["DataRate", "CameraRate", "NumFrames", "NumMarkers", "Units"]
    assert lines[1].split("\t")[:5] == keys
    assert lines[2].split("\t")[2:5] == ["2", "2", "mm"]
    assert lines[3].split("\t") == ["Frame#", "Time", "A", "", "", "B"]
    assert lines[4].split("\t") == ["", "", "X1", "Y1", "Z1", "X2", "Y2", "Z2"]
    assert lines[6].split("\t")[:3] == ["1", "0.00000000", "1.000000"]


def test_reads_opensim_file_in_metres_with_gaps(tmp_path: Path) -> None:
    path = tmp_path / "walk.trc"
    path.write_text(_OPENSIM_M)
    m = read_markers(path)
    assert m.names == ("RASI", "LASI")
    assert m.rate_hz == 60.0
    np.testing.assert_allclose(m.positions_mm[0], [[100.0, 200.0, 900.0], [-100.0, 200.0, 900.0]])
    np.testing.assert_allclose(m.positions_mm[2, 0], [101.0, 200.0, 900.0])
    assert np.isnan(m.positions_mm[1:, 1]).all()
    assert m.occlusions().get("LASI").longest_gap_frames == 2
    np.testing.assert_allclose(m.time_s, [0.0, 0.016667, 0.033333])


@pytest.mark.parametrize(
    ("text", "pattern"),
    [
        (
            _header() + "1\t0.00\t1\t2\t3\t4\t5\t6\n2\t0.01\t1\t2\t3\t4\t5\n",
            r"bad.trc line 7: expected 8 tab-separated columns .* found 7",
        ),
        (
            _header() + "1\t0.00\t1\t2\t3\t4\t5\t6\t7\t8\n2\t0.01\t1\t2\t3\t4\t5\t6\n",
            r"bad.trc line 6: expected 8 tab-separated columns",
        ),
        (
            _header() + "1\t0.00\t1\t2\t3\t4\t5\t6\n2\t0.01\t1\t2\t3\tfoo\t5\t6\n",
            r"bad.trc line 7 column 6 \(B X\): expected a number or an empty field, found 'foo'",
        ),
        (
            _header() + "1\t\t1\t2\t3\t4\t5\t6\n2\t0.01\t1\t2\t3\t4\t5\t6\n",
            r"line 6 column 2 \(Time\): expected a time stamp",
        ),
        (
            _header() + "1\t0.02\t1\t2\t3\t4\t5\t6\n2\t0.01\t1\t2\t3\t4\t5\t6\n",
            r"line 7 column 2 \(Time\): expected strictly increasing",
        ),
        (
            _header(units="inch") + "1\t0\t1\t2\t3\t4\t5\t6\n",
            r"line 3 \(Units\): expected one of mm, cm, m, found 'inch'",
        ),
        (
            _header(n_markers=3) + "1\t0\t1\t2\t3\t4\t5\t6\n",
            r"line 4: expected NumMarkers = 3 marker names, found 2",
        ),
        (
            _header(n_frames=3) + "1\t0\t1\t2\t3\t4\t5\t6\n2\t0.01\t1\t2\t3\t4\t5\t6\n",
            r"header NumFrames = 3, found 2 data rows",
        ),
        (
            "Hello\n" + _header()[_header().index("\n") + 1 :],
            r"line 1: expected a TRC header starting with 'PathFileType'",
        ),
        ("PathFileType\t4\n", r"expected at least 5 header lines"),
        (_header().replace("DataRate", "Rate"), r"expected header field 'DataRate'"),
        (_header().replace("Frame#", "Frame"), r"line 4: expected the columns 'Frame#' and 'Time'"),
    ],
)
def test_bad_trc(tmp_path: Path, text: str, pattern: str) -> None:
    path = tmp_path / "bad.trc"
    path.write_text(text)
    with pytest.raises(FormatError, match=pattern):
        read_markers(path)


def test_writer_validates_input(tmp_path: Path) -> None:
    path = tmp_path / "w.trc"
    with pytest.raises(FormatError, match="units: expected one of mm, cm, m, found 'in'"):
        write_trc(path, [0.0, 1.0], ["A"], np.zeros((2, 1, 3)), "in")
    with pytest.raises(ShapeError, match=r"positions_mm: expected shape \(T=2, M=2, 3\)"):
        write_trc(path, [0.0, 1.0], ["A", "B"], np.zeros((2, 1, 3)))
    with pytest.raises(FormatError, match="marker name 'A\\\\tB'"):
        write_trc(path, [0.0, 1.0], ["A\tB"], np.zeros((2, 1, 3)))
    with pytest.raises(ConfigError, match="rate_hz: required"):
        write_trc(path, [0.0], ["A"], np.zeros((1, 1, 3)))
    with pytest.raises(FormatError, match="strictly increasing"):
        write_trc(path, [0.0, 0.0], ["A"], np.zeros((2, 1, 3)))
    assert not path.exists()
    write_trc(path, [0.0], ["A"], np.zeros((1, 1, 3)), rate_hz=30.0)
    assert read_trc(path).rate_hz == 30.0


def test_c3d_to_trc_round_trip(shared_data: Path, tmp_path: Path) -> None:
    m = read_markers(shared_data / "c3d" / "kinematics_tennis_serve.c3d")
    path = tmp_path / "serve.trc"
    write_trc(path, m.time_s, m.names, m.positions_mm, "m", rate_hz=m.rate_hz)
    back = read_markers(path)
    assert back.names == m.names
    assert back.rate_hz == m.rate_hz
    np.testing.assert_allclose(back.positions_mm, m.positions_mm, **ROUND_TRIP)


def test_negative_data_rate_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "m.trc"
    write_trc(path, np.arange(3) / 50.0, ["A"], np.zeros((3, 1, 3)), rate_hz=50.0)
    lines = path.read_text().splitlines(keepends=True)
    values = lines[2].split("\t")
    values[0] = "-50"
    lines[2] = "\t".join(values)
    path.write_text("".join(lines))
    with pytest.raises(FormatError, match=r"line 3 \(DataRate\): expected a positive rate"):
        read_trc(path)
