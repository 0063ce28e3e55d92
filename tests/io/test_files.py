"""Binary garbage and truncated archives are refused as FormatError naming the file."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mocapkit.errors import FormatError
from mocapkit.io.files import load_npz, read_text
from mocapkit.io.joints_csv import read_joints_csv
from mocapkit.io.marker_files import read_markers
from mocapkit.io.motion_npz import load_motion_npz
from mocapkit.io.session import load_session
from mocapkit.io.truth import load_truth

GARBAGE = bytes([0xFF, 0xFE, 0x00, 0x9C, 0x81, 0xC3, 0x28]) * 40


@pytest.mark.parametrize(
    ("name", "reader"),
    [
        ("markers.csv", read_markers),
        ("markers.trc", read_markers),
        ("joints.csv", read_joints_csv),
    ],
)
def test_binary_garbage_is_a_format_error(tmp_path, name, reader):
    path = tmp_path / name
    path.write_bytes(GARBAGE)
    with pytest.raises(FormatError, match=rf"{name}: expected a .* as utf-8 text, found a byte"):
        reader(path)


def test_binary_session_json_is_a_format_error(tmp_path):
    (tmp_path / "session.json").write_bytes(GARBAGE)
    with pytest.raises(FormatError, match=r"session.json: expected a session.json as utf-8"):
        load_session(tmp_path)


def test_read_text_drops_the_byte_order_mark_and_names_a_missing_file(tmp_path):
    path = tmp_path / "a.csv"
    path.write_bytes("\ufefftime_s\r\n1\r\n".encode())
    assert read_text(path) == "time_s\n1\n"
    with pytest.raises(FormatError, match=r"nope.csv: marker CSV not found"):
        read_text(tmp_path / "nope.csv", "marker CSV")


@pytest.mark.parametrize("reader", [load_motion_npz, load_truth, load_npz])
def test_truncated_npz_is_a_format_error(tmp_path, reader):
    path = tmp_path / "cut.npz"
    np.savez(path, time_s=np.arange(1000.0), joints_mm=np.zeros((1000, 2, 3)))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(FormatError, match=r"cut.npz: cannot read as .npz"):
        reader(path)
    path.write_bytes(json.dumps({"not": "a zip"}).encode())
    with pytest.raises(FormatError, match=r"cut.npz: cannot read as .npz"):
        reader(path)
    # garbage that np.load would take for a pickle: no allow_pickle advice (issue 14)
    path.write_bytes(np.random.default_rng(4).bytes(3000))
    with pytest.raises(FormatError, match=r"cut.npz: cannot read as .npz \(expected a ") as exc:
        reader(path)
    assert "pickle" not in str(exc.value)
    folder = tmp_path / "folder.npz"
    folder.mkdir()
    with pytest.raises(FormatError, match=r"folder.npz: expected a .*, found a folder"):
        reader(folder)
