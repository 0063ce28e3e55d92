"""C3D reading through ezc3d: real recordings (units, rates, labels) and synthetic edge cases."""

from __future__ import annotations

from pathlib import Path

import ezc3d
import numpy as np
import pytest

from mocapkit.errors import FormatError
from mocapkit.io.c3d import read_c3d
from mocapkit.io.marker_files import read_markers


def _c3d_file(shared_data: Path, name: str) -> Path:
    return shared_data / "c3d" / name


def test_tennis_serve_metres_to_mm_and_vicon_names(shared_data: Path) -> None:
    m = read_markers(_c3d_file(shared_data, "kinematics_tennis_serve.c3d"))
    assert (m.n_frames, m.n_markers, m.rate_hz) == (1092, 39, 50.0)
    assert m.names[0] == "Derrick:C7"
    assert all(n.startswith("Derrick:") for n in m.names)
    np.testing.assert_allclose(m.time_s[[0, 1, -1]], [0.0, 0.02, 21.82])
    # Name matching with and without the subject prefix.
    assert m.index("LFHD") == m.index("Derrick:LFHD") == m.names.index("Derrick:LFHD")
    # Metres became mm: the lab's vertical axis is Z; the head band sits 1.5-1.7 m up
    # when the player stands (median over the trial), the toes a few cm above the floor.
    head = m.select(["LFHD", "RFHD", "LBHD", "RBHD"]).positions_mm[:, :, 2]
    assert 1400.0 < float(np.median(head)) < 1800.0
    assert 1500.0 < float(np.percentile(head, 95)) < 2000.0
    toe = m.trajectory("LTOE")[:, 2]
    assert -50.0 < float(np.median(toe)) < 100.0
    # Shoulder width (acromion markers) of an adult: 300-450 mm.
    width = np.linalg.norm(m.trajectory("LSHO") - m.trajectory("RSHO"), axis=1)
    assert 250.0 < float(np.median(width)) < 450.0
    # This file is gap-filled: no occluded sample.
    assert m.occlusions().total_missing == 0


def test_qualisys_mm_with_analogs_and_first_frame(shared_data: Path) -> None:
    m = read_c3d(_c3d_file(shared_data, "ezc3d_Qualisys.c3d"))
    assert (m.n_frames, m.n_markers, m.rate_hz) == (340, 55, 200.0)
    assert m.names[:4] == ("L_IAS", "L_IPS", "R_IPS", "R_IAS")
    # The stored data start at 0-based frame 704 of the capture.
    np.testing.assert_allclose(m.time_s[[0, -1]], [704 / 200.0, 1043 / 200.0])
    # Already in mm: head markers about 1.4-1.6 m up, heel markers a few cm.
    assert 1300.0 < float(np.median(m.trajectory("L_HDF")[:, 2])) < 1700.0
    assert 0.0 < float(np.median(m.trajectory("L_FCC")[:, 2])) < 100.0
    assert m.occlusions().total_missing == 0


def test_basket_sprint_invalid_residuals_become_nan(shared_data: Path) -> None:
    path = _c3d_file(shared_data, "kinematics_basket_sprint.c3d")
    m = read_markers(path)
    assert (m.n_frames, m.n_markers, m.rate_hz) == (3678, 26, 120.0)
    raw = ezc3d.c3d(str(path))
    invalid = raw["data"]["meta_points"]["residuals"][0].T < 0  # (T, M)
    np.testing.assert_array_equal(m.missing, invalid)
    assert int(invalid.sum()) == 37068 == m.occlusions().total_missing
    # Never zero-filled; visible samples are in mm (seated forehead about 1.2 m up).
    assert not np.any(np.all(m.positions_mm == 0.0, axis=2))
    assert 1000.0 < float(np.nanmedian(m.trajectory("Forehead")[:, 2])) < 1500.0
    assert m.index("C7") == m.names.index("BodyL:C7")
    rep = m.occlusions().get("BodyL:HandL")
    assert (rep.n_missing, rep.longest_gap_frames) == (3144, 1622)
    assert rep.longest_gap_s == pytest.approx(1622 / 120.0)


def _write_synthetic(
    path: Path,
    points_xyz: np.ndarray,
    labels: list[str],
    units: str,
    rate: float = 100.0,
    residuals: np.ndarray | None = None,
    first_frame: int = 0,
    trial_start: list[int] | None = None,
) -> None:
    """Write a C3D with ezc3d; points_xyz is (T, M, 3) in the file's units."""
    t, n, _ = points_xyz.shape
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [rate]
    c["parameters"]["POINT"]["LABELS"]["value"] = labels
    c["parameters"]["POINT"]["UNITS"]["value"] = [units]
    pts = np.ones((4, n, t))
    pts[:3] = points_xyz.transpose(2, 1, 0)
    c["data"]["points"] = pts
    res = np.zeros((1, n, t)) if residuals is None else residuals.T[None]
    c["data"]["meta_points"] = {"residuals": res, "camera_masks": np.zeros((7, n, t), dtype=bool)}
    c["header"]["points"]["first_frame"] = first_frame
    if trial_start is not None:
        c.add_parameter("TRIAL", "ACTUAL_START_FIELD", trial_start)
    c.write(str(path))


def test_synthetic_units_zero_points_residuals_and_first_frame(
    tmp_path: Path, rng: np.random.Generator
) -> None:
    xyz = rng.uniform(1.0, 50.0, size=(6, 3, 3))
    xyz[2, 0] = 0.0  # an exporter's zero-filled gap
    res = np.zeros((6, 3))
    res[4, 2] = -1.0  # invalid residual
    path = tmp_path / "syn.c3d"
    _write_synthetic(path, xyz, ["A", "B", "C"], "cm", residuals=res, first_frame=9)
    m = read_markers(path)
    expected = xyz * 10.0
    expected[2, 0] = np.nan
    expected[4, 2] = np.nan
    np.testing.assert_allclose(m.positions_mm, expected, rtol=1e-6)  # float32 in the file
    np.testing.assert_allclose(m.time_s, (9 + np.arange(6)) / 100.0)
    assert [o.n_missing for o in m.occlusions().markers] == [1, 0, 1]


def test_synthetic_trial_start_field_and_labels2(tmp_path: Path, rng: np.random.Generator) -> None:
    n = 300  # more than the 255 labels one C3D parameter holds: ezc3d writes LABELS2
    labels = [f"S:M{i:03d}" for i in range(n)]
    xyz = rng.uniform(-1.0, 1.0, size=(4, n, 3))
    path = tmp_path / "many.c3d"
    # Vicon's ACTUAL_START_FIELD is a 1-based 32-bit frame number in two 16-bit words.
    _write_synthetic(path, xyz, labels, "m", rate=250.0, trial_start=[5, 1])
    raw = ezc3d.c3d(str(path))
    assert len(raw["parameters"]["POINT"]["LABELS2"]["value"]) == n - 255
    m = read_c3d(path)
    assert m.names == tuple(labels)
    assert m.index("M299") == 299
    first = 5 + 65536 - 1
    np.testing.assert_allclose(m.time_s, (first + np.arange(4)) / 250.0)
    np.testing.assert_allclose(m.positions_mm, xyz * 1000.0, rtol=1e-6)


def test_unknown_units_rejected(tmp_path: Path) -> None:
    path = tmp_path / "inch.c3d"
    _write_synthetic(path, np.ones((2, 1, 3)), ["A"], "in")
    with pytest.raises(FormatError, match=r"inch.c3d: POINT:UNITS: expected one of mm, cm, m"):
        read_c3d(path)


def test_truncated_c3d_is_a_format_error(shared_data: Path, tmp_path: Path) -> None:
    data = _c3d_file(shared_data, "kinematics_tennis_serve.c3d").read_bytes()
    cut = tmp_path / "cut.c3d"
    # Cut in the middle of the frames: ezc3d reads what is there without complaint.
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(FormatError, match=r"cut.c3d: truncated C3D: header declares 1092 frames"):
        read_markers(cut)
    # Cut inside the parameter section: ezc3d itself fails.
    head = tmp_path / "head.c3d"
    head.write_bytes(data[:600])
    with pytest.raises(FormatError, match=r"head.c3d: not a readable C3D file \(ezc3d: "):
        read_markers(head)


def test_garbage_c3d_is_a_format_error(tmp_path: Path) -> None:
    path = tmp_path / "junk.c3d"
    path.write_bytes(b"definitely not a c3d file" * 4)
    with pytest.raises(FormatError, match=r"junk\.c3d: not a readable C3D file"):
        read_markers(path)


def test_missing_c3d(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match=r"none\.c3d"):
        read_c3d(tmp_path / "none.c3d")
