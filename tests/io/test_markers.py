"""MarkerData (name matching, selection, occlusion report), read_markers dispatch, marker CSV."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import FormatError, ShapeError, UnknownNameError
from mocapkit.io.marker_csv import read_markers_csv, write_markers_csv
from mocapkit.io.marker_files import read_markers, write_markers
from mocapkit.io.markers import MarkerData, bare_marker_name, longest_true_run, true_runs


def _data(names: tuple[str, ...], n_frames: int = 6, rate_hz: float = 100.0) -> MarkerData:
    pos = np.arange(n_frames * len(names) * 3, dtype=float).reshape(n_frames, len(names), 3)
    return MarkerData(
        time_s=np.arange(n_frames) / rate_hz,
        names=names,
        positions_mm=pos,
        rate_hz=rate_hz,
        source="test.c3d",
    )


def test_marker_data_is_immutable_and_copies_inputs() -> None:
    pos = np.zeros((3, 2, 3))
    m = MarkerData(np.arange(3) / 10.0, ("A", "B"), pos, 10.0, "x.csv")
    pos[0, 0, 0] = 5.0
    assert m.positions_mm[0, 0, 0] == 0.0
    with pytest.raises(ValueError, match="read-only"):
        m.positions_mm[0, 0, 0] = 1.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.rate_hz = 5.0  # type: ignore[misc]
    assert (m.n_frames, m.n_markers) == (3, 2)


def test_index_matches_with_and_without_subject_prefix() -> None:
    m = _data(("Derrick:C7", "Derrick:LFHD", "Derrick:RFHD"))
    assert m.index("LFHD") == 1
    assert m.index("Derrick:LFHD") == 1
    assert bare_marker_name("Derrick:LFHD") == "LFHD"
    np.testing.assert_array_equal(m.trajectory("RFHD"), m.positions_mm[:, 2])
    # A prefixed query also finds a bare name in a file written without subjects.
    plain = _data(("C7", "LFHD"))
    assert plain.index("Derrick:LFHD") == 1


def test_index_ambiguous_across_subjects_lists_candidates() -> None:
    m = _data(("Anna:LFHD", "Bob:LFHD", "Bob:RFHD"))
    with pytest.raises(UnknownNameError, match=r"ambiguous marker 'LFHD'.*Anna:LFHD, Bob:LFHD"):
        m.index("LFHD")
    assert m.index("RFHD") == 2
    assert m.index("Bob:LFHD") == 1


def test_index_unknown_lists_valid_names_and_is_a_key_error() -> None:
    m = _data(("Derrick:C7", "Derrick:LFHD"))
    with pytest.raises(UnknownNameError, match=r"unknown marker 'LFHX' in test.c3d.*Derrick:C7"):
        m.index("LFHX")
    with pytest.raises(KeyError):
        m.index("Other:LFHD")


def test_select_keeps_file_names_in_requested_order() -> None:
    m = _data(("S:A", "S:B", "S:C"))
    sub = m.select(["C", "S:A"])
    assert sub.names == ("S:C", "S:A")
    np.testing.assert_array_equal(sub.positions_mm, m.positions_mm[:, [2, 0]])
    assert sub.select("C").names == ("S:C",)
    with pytest.raises(UnknownNameError, match="unknown marker 'D'"):
        m.select(["A", "D"])


def test_occlusion_report_counts_and_longest_gaps() -> None:
    pos = np.ones((10, 3, 3))
    pos[[1, 2, 3, 6], 0, :] = np.nan  # gaps of 3 and 1 frames
    pos[9, 1, 2] = np.nan  # one coordinate missing counts as missing
    m = MarkerData(np.arange(10) / 50.0, ("A", "B", "C"), pos, 50.0, "t.trc")
    rep = m.occlusions()
    a, b, c = rep.markers
    assert (a.n_missing, a.longest_gap_frames, a.longest_gap_s) == (4, 3, pytest.approx(0.06))
    assert (b.n_missing, b.longest_gap_frames) == (1, 1)
    assert (c.n_missing, c.longest_gap_frames, c.longest_gap_s) == (0, 0, 0.0)
    assert rep.total_missing == 5
    assert rep.get("B") is b
    assert a.fraction_missing == pytest.approx(0.4)
    text = m.summary()
    assert "3 markers x 10 frames at 50 Hz; 5 missing samples; 1/3 markers complete" in text
    assert "3 frames = 0.060 s" in text
    # Worst marker first; complete markers are not listed.
    assert text.index("  A ") < text.index("  B ")
    assert "  C " not in text
    # NaNs are kept, never filled.
    assert np.isnan(m.positions_mm[1, 0]).all()


def test_longest_true_run() -> None:
    mask = np.array([[1, 0], [1, 0], [0, 1], [1, 1], [1, 0], [1, 0]], dtype=bool)
    np.testing.assert_array_equal(longest_true_run(mask), [3, 2])


def test_true_runs_are_half_open_and_in_order() -> None:
    assert true_runs([1, 1, 0, 1, 0, 0, 1]) == [(0, 2), (3, 4), (6, 7)]
    assert true_runs(np.zeros(4, dtype=bool)) == []
    assert true_runs(np.array([0.0, 2.5, 1.0])) == [(1, 3)]
    with pytest.raises(ShapeError, match=r"true_runs: expected a 1-D mask, found shape \(2, 2\)"):
        true_runs(np.ones((2, 2), dtype=bool))


@pytest.mark.parametrize(
    ("kwargs", "error", "pattern"),
    [
        ({"time_s": np.array([0.0, 0.1, 0.1])}, FormatError, r"strictly increasing.*frame 2"),
        ({"time_s": np.array([0.0, 0.2, 0.1])}, FormatError, r"src.csv: time stamps"),
        ({"time_s": np.array([0.0, np.nan, 0.3])}, FormatError, "finite"),
        ({"positions_mm": np.zeros((3, 2, 2))}, ShapeError, r"expected shape \(T=3, M, 3\)"),
        ({"names": ("A",)}, ShapeError, "expected 2 names"),
        ({"names": ("A", "A")}, FormatError, "unique names, found 'A'"),
        ({"rate_hz": 0.0}, FormatError, "rate_hz: expected a positive"),
    ],
)
def test_marker_data_validation(kwargs: dict, error: type, pattern: str) -> None:
    args = {
        "time_s": np.array([0.0, 0.1, 0.2]),
        "names": ("A", "B"),
        "positions_mm": np.zeros((3, 2, 3)),
        "rate_hz": 10.0,
        "source": "src.csv",
    }
    args.update(kwargs)
    with pytest.raises(error, match=pattern):
        MarkerData(**args)


# ---------------------------------------------------------------------- CSV
def test_csv_round_trip_is_exact(tmp_path: Path, rng: np.random.Generator) -> None:
    t = np.arange(40) / 120.0 + 0.5
    pos = rng.normal(0.0, 800.0, size=(40, 4, 3))
    pos[rng.random((40, 4)) < 0.2] = np.nan
    names = ("Derrick:LFHD", "L_IAS", "x_y", "RWRB")
    path = tmp_path / "out" / "markers.csv"
    write_markers_csv(path, t, names, pos)
    m = read_markers(path)
    assert m.names == names
    np.testing.assert_array_equal(m.time_s, t)
    np.testing.assert_array_equal(m.positions_mm, pos)  # NaN where NaN, bit-exact elsewhere
    assert m.rate_hz == pytest.approx(120.0)
    assert m.source == str(path)
    header = path.read_text().splitlines()[0]
    assert header.startswith("time_s,Derrick:LFHD_x,Derrick:LFHD_y,Derrick:LFHD_z,L_IAS_x")
    assert [p.name for p in path.parent.iterdir()] == ["markers.csv"]  # no temp file left


def test_write_markers_dispatch(tmp_path: Path) -> None:
    m = _data(("A", "B"))
    write_markers(tmp_path / "m.csv", m)
    write_markers(tmp_path / "m.trc", m, units="m")
    for name in ("m.csv", "m.trc"):
        back = read_markers(tmp_path / name)
        np.testing.assert_allclose(back.positions_mm, m.positions_mm, atol=1e-6)
        assert back.rate_hz == pytest.approx(100.0)
    with pytest.raises(FormatError, match=r"cannot write markers with extension '.c3d'.*\.trc"):
        write_markers(tmp_path / "m.c3d", m)


def test_csv_reads_empty_and_nan_cells_as_missing(tmp_path: Path) -> None:
    path = tmp_path / "m.csv"
    path.write_text("time_s,A_x,A_y,A_z,B_x,B_y,B_z\n0.0,1,2,3,,,\n0.01,4,5,6,NaN,nan,7\n\n")
    m = read_markers_csv(path)
    assert m.names == ("A", "B")
    assert np.isnan(m.positions_mm[:, 1, :2]).all()
    assert m.positions_mm[1, 1, 2] == 7.0
    assert m.occlusions().get("B").n_missing == 2
    assert m.rate_hz == pytest.approx(100.0)


def test_csv_columns_in_any_axis_order(tmp_path: Path) -> None:
    path = tmp_path / "m.csv"
    path.write_text("time_s,A_z,A_x,A_y\n0,3,1,2\n1,6,4,5\n")
    np.testing.assert_array_equal(read_markers(path).positions_mm[:, 0], [[1, 2, 3], [4, 5, 6]])


@pytest.mark.parametrize(
    ("text", "pattern"),
    [
        ("A_x,A_y,A_z\n0,1,2\n", r"line 1 column 1: expected the time column 'time_s', found"),
        ("time_s,A_x,A_y,A_w\n0,1,2,3\n", r"line 1 column 4: expected a column .*NAME_x.*'A_w'"),
        ("time_s,A_x,A_y,x\n0,1,2,3\n", r"line 1 column 4: .*found 'x'"),
        ("time_s,A_x,A_y\n0,1,2\n1,1,2\n", r"marker 'A' lacks column\(s\) A_z"),
        ("time_s,A_x,A_y,A_z,A_x\n", r"line 1 column 5: duplicate column 'A_x'"),
        ("time_s,A_x,A_y,A_z\n0,1,2,3\n1,1,abc,3\n", r"line 3 column 3 \(A_y\): expected a number"),
        ("time_s,A_x,A_y,A_z\n0,1,2,3\n1,1,2\n", r"line 3: expected 4 cells as in the header"),
        ("time_s,A_x,A_y,A_z\n0,1,2,3\n,1,2,3\n", r"line 3 column 1 \(time_s\): expected a number"),
        ("time_s,A_x,A_y,A_z\n0,1,2,3\n1,1,2,3\n0.5,1,2,3\n", r"line 4.*strictly increasing"),
        ("time_s,A_x,A_y,A_z\n0,1,2,3\n", r"at least 2 frames"),
        ("", "empty file"),
    ],
)
def test_csv_bad_input(tmp_path: Path, text: str, pattern: str) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(FormatError, match=pattern) as info:
        read_markers(path)
    assert "bad.csv" in str(info.value)


def test_csv_writer_rejects_bad_arrays(tmp_path: Path) -> None:
    with pytest.raises(ShapeError, match=r"positions_mm: expected shape \(T=2, M=1, 3\)"):
        write_markers_csv(tmp_path / "m.csv", [0.0, 1.0], ["A"], np.zeros((2, 2, 3)))
    with pytest.raises(FormatError, match="marker name 'A,B'"):
        write_markers_csv(tmp_path / "m.csv", [0.0, 1.0], ["A,B"], np.zeros((2, 1, 3)))
    with pytest.raises(FormatError, match="strictly increasing"):
        write_markers_csv(tmp_path / "m.csv", [1.0, 0.0], ["A"], np.zeros((2, 1, 3)))
    assert not (tmp_path / "m.csv").exists()


def test_read_markers_rejects_unsupported_extension(tmp_path: Path) -> None:
    path = tmp_path / "take.mat"
    path.write_text("x")
    with pytest.raises(FormatError, match=r"take.mat: unsupported .*'.mat'.*\.c3d, \.trc, \.csv"):
        read_markers(path)


def test_read_markers_missing_file(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match=r"nothere\.trc"):
        read_markers(tmp_path / "nothere.trc")


def test_read_markers_extension_is_case_insensitive(tmp_path: Path) -> None:
    path = tmp_path / "M.CSV"
    write_markers_csv(path, [0.0, 0.5], ["A"], np.ones((2, 1, 3)))
    assert read_markers(path).rate_hz == pytest.approx(2.0)
