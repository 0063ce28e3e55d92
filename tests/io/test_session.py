"""Session folders: loading, streaming samples in time order, and clear refusals."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import FormatError, SessionError
from mocapkit.io.session import load_session
from mocapkit.io.session_csv import (
    read_keypoints_csv,
    read_timestamps_csv,
    write_keypoints_csv,
    write_timestamps_csv,
)
from mocapkit.synth.realism import RealismOptions
from mocapkit.synth.session_writer import SynthOptions, synthesize_session


@pytest.fixture(scope="module")
def session_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("sess") / "wave"
    synthesize_session(
        "builtin:wave",
        out,
        SynthOptions(rig="all", seconds=0.4, start_s=1.0, image_size=(160, 120), seed=3),
    )
    return out


@pytest.fixture
def copy(session_dir, tmp_path) -> Path:
    dst = tmp_path / "s"
    shutil.copytree(session_dir, dst)
    return dst


def test_load_and_stream(session_dir):
    s = load_session(session_dir)
    assert s.video_cameras == ("mono", "stereo_left", "stereo_right")
    assert s.height_mm is not None and 1500 < s.height_mm < 2000
    s.require(
        video=True,
        markers=True,
        keypoints=True,
        truth=True,
        cameras=3,
        marker_sets=("head", "left_hand", "right_hand"),
        height=True,
    )
    assert s.truth is not None and s.markers is not None
    samples = []
    for smp in s.samples():
        assert smp.image("stereo_right").shape == (120, 160, 3)
        samples.append(smp)
    assert len(samples) == len(s.truth.time_s) == s.video("mono").n_frames
    times = np.array([x.time_s for x in samples])
    assert np.all(np.diff(times) > 0)
    np.testing.assert_allclose(times, s.truth.time_s)
    with_markers = [x for x in samples if x.marker_index >= 0]
    assert len(with_markers) >= len(samples) - 1
    for x in with_markers:
        # the newest marker sample at or before the frame (markers at 120 Hz, with jitter)
        assert 0.0 <= x.marker_dt_s <= 1 / 120 + 0.002
        assert x.marker_time_s == s.markers.time_s[x.marker_index]
        if x.marker_index + 1 < s.markers.n_frames:
            assert s.markers.time_s[x.marker_index + 1] > x.time_s
        assert set(x.marker_sets_mm) == {"head", "left_hand", "right_hand"}
        assert x.keypoints_px["mono"].shape == (15, 2)


def test_lazy_frames_expire_after_advancing(session_dir):
    s = load_session(session_dir)
    it = s.samples("mono")
    first = next(it)
    image = first.image()
    second = next(it)
    assert second.image().shape == image.shape
    with pytest.raises(SessionError, match="no longer available"):
        first.image()
    with pytest.raises(SessionError, match="no frame of camera 'stereo_left'"):
        second.image("stereo_left")


def test_random_access_matches_stream(session_dir):
    s = load_session(session_dir)
    v = s.video("stereo_left")
    frames = [smp.image() for smp in s.samples("stereo_left")]
    np.testing.assert_array_equal(v.read(3), frames[3])


def test_require_lists_what_is_missing(copy):
    (copy / "truth.npz").unlink()
    (copy / "markers.csv").unlink()
    s = load_session(copy)
    with pytest.raises(SessionError, match=r"lacks markers\.c3d or markers\.csv; truth\.npz"):
        s.require(markers=True, truth=True)
    with pytest.raises(SessionError, match="camera 'kinect'"):
        s.require(cameras=["kinect"])
    with pytest.raises(SessionError, match="marker set 'pelvis'"):
        s.require(marker_sets=["pelvis"])


def test_refuses_missing_session_json(tmp_path):
    with pytest.raises(SessionError, match="missing session.json"):
        load_session(tmp_path)
    with pytest.raises(SessionError, match="session folder not found"):
        load_session(tmp_path / "nope")


def test_refuses_wrong_format_and_units(copy):
    doc = json.loads((copy / "session.json").read_text())
    (copy / "session.json").write_text(json.dumps({**doc, "format": 2}))
    with pytest.raises(FormatError, match=r"session.json: field 'format': expected 1, found 2"):
        load_session(copy)
    (copy / "session.json").write_text(json.dumps({**doc, "units": "m"}))
    with pytest.raises(FormatError, match="field 'units': expected 'mm'"):
        load_session(copy)
    (copy / "session.json").write_text("{not json")
    with pytest.raises(FormatError, match="not valid JSON"):
        load_session(copy)


def test_refuses_video_of_unknown_camera(copy):
    shutil.copy(copy / "video" / "mono.mp4", copy / "video" / "side.mp4")
    with pytest.raises(SessionError, match="video of camera 'side', which cameras.json does not"):
        load_session(copy)


def test_refuses_timestamp_count_mismatch(copy):
    path = copy / "video" / "mono.timestamps.csv"
    t = read_timestamps_csv(path)
    write_timestamps_csv(path, t[:-2])
    with pytest.raises(
        SessionError,
        match=rf"one time stamp per frame of mono.mp4 \({len(t)} frames\), found {len(t) - 2}",
    ):
        load_session(copy)


def test_refuses_missing_cameras_file_and_marker_members(copy):
    doc = json.loads((copy / "session.json").read_text())
    (copy / "session.json").write_text(json.dumps({**doc, "marker_sets": {"head": ["LFHD"]}}))
    with pytest.raises(SessionError, match=r"marker set 'head' uses markers \['LFHD'\]"):
        load_session(copy)
    (copy / "session.json").write_text(json.dumps(doc))
    (copy / "cameras.json").unlink()
    with pytest.raises(SessionError, match="names cameras file 'cameras.json', which is missing"):
        load_session(copy)


def test_image_folder_video(tmp_path):
    out = tmp_path / "png"
    synthesize_session(
        "builtin:squat",
        out,
        SynthOptions(
            rig="mono",
            seconds=0.2,
            image_size=(96, 72),
            video_format="png",
            realism=RealismOptions(video_jitter_s=0.0),
        ),
    )
    assert not (out / "video" / "mono.timestamps.csv").exists()
    s = load_session(out)
    frames = list(s.samples())
    assert len(frames) == len(list((out / "video" / "mono").glob("*.png")))
    np.testing.assert_allclose([f.time_s for f in frames], np.arange(len(frames)) / 30.0)
    assert frames[-1].image().shape == (72, 96, 3)


def test_keypoints_csv_roundtrip_and_errors(tmp_path):
    t = np.array([0.0, 0.033, 0.067])
    px = np.arange(12, dtype=float).reshape(3, 2, 2)
    px[1, 0] = np.nan
    write_keypoints_csv(tmp_path / "k.csv", t, ["head", "neck"], px)
    k = read_keypoints_csv(tmp_path / "k.csv")
    assert k.joint_names == ("head", "neck")
    np.testing.assert_allclose(k.pixels, px, atol=1e-3)
    (tmp_path / "bad.csv").write_text("time_s,nose_x_px,nose_y_px\n0,1,2\n")
    with pytest.raises(FormatError, match="expected a canonical joint"):
        read_keypoints_csv(tmp_path / "bad.csv")
    (tmp_path / "bad2.csv").write_text("time_s,head_x_px,head_y_px\n0,1\n")
    with pytest.raises(FormatError, match="line 2: expected 3 columns, found 2"):
        read_keypoints_csv(tmp_path / "bad2.csv")


def test_subject_measurements_and_marker_offsets_are_read(session_dir):
    from mocapkit.skeleton import TRUNK_SEGMENTS

    s = load_session(session_dir)
    assert set(s.segment_vectors_mm) == set(TRUNK_SEGMENTS)
    assert s.bone_lengths_mm["left_upper_arm"] > 0
    segment, offset = s.marker_offsets["head"]
    assert segment == "head"
    # the set centre is the mean of the glasses' three markers (bridge and temples)
    np.testing.assert_allclose(offset, [0.0, 73.333, 0.0])
    members = s.marker_member_offsets["head"]
    assert list(members) == s.marker_sets["head"]
    np.testing.assert_allclose(members["head"], [0.0, 100.0, 0.0])
    np.testing.assert_allclose(np.mean(list(members.values()), axis=0), offset, atol=1e-3)
    assert s.marker_offsets["right_hand"][0] == "right_wrist"


def test_bad_subject_measurements_rejected(copy):
    import json

    info = json.loads((copy / "session.json").read_text())
    info["subject"]["bone_lengths_mm"] = {"arm": 300}
    (copy / "session.json").write_text(json.dumps(info))
    with pytest.raises(FormatError, match="unknown segment 'arm'"):
        load_session(copy)
    # a bad length is named by its key, not by dumping the whole table (issue 14)
    info["subject"]["bone_lengths_mm"] = {"left_upper_arm": 300, "left_forearm": -5}
    (copy / "session.json").write_text(json.dumps(info))
    with pytest.raises(
        FormatError, match=r"bone_lengths_mm.left_forearm: expected a positive"
    ) as exc:
        load_session(copy)
    assert "left_upper_arm" not in str(exc.value)
    info["subject"]["bone_lengths_mm"] = {}
    info["subject"]["segment_vectors_mm"] = {"left_forearm": [0, 0, -200]}
    (copy / "session.json").write_text(json.dumps(info))
    with pytest.raises(FormatError, match="'left_forearm' has no fixed rest direction"):
        load_session(copy)
    info["subject"]["segment_vectors_mm"] = {}
    info["marker_offsets_mm"] = {"head": {"segment": "skull", "offset_mm": [0, 100, 0]}}
    (copy / "session.json").write_text(json.dumps(info))
    with pytest.raises(FormatError, match=r"marker_offsets_mm.head.segment: expected a canonical"):
        load_session(copy)


def test_bad_member_offsets_rejected(copy):
    import json

    info = json.loads((copy / "session.json").read_text())
    head = info["marker_offsets_mm"]["head"]
    info["marker_offsets_mm"]["head"] = {**head, "members_mm": {"head": [0, "x", 0]}}
    (copy / "session.json").write_text(json.dumps(info))
    with pytest.raises(FormatError, match=r"members_mm.head: expected 3 finite numbers"):
        load_session(copy)
    info["marker_offsets_mm"]["head"] = {**head, "members_mm": {"LFHD": [0, 100, 0]}}
    (copy / "session.json").write_text(json.dumps(info))
    with pytest.raises(SessionError, match=r"members_mm names \['LFHD'\], which are not members"):
        load_session(copy)
    info["marker_offsets_mm"]["head"] = {**head, "colour": "red"}
    (copy / "session.json").write_text(json.dumps(info))
    with pytest.raises(FormatError, match=r"optionally 'members_mm'"):
        load_session(copy)
    info["marker_offsets_mm"]["head"] = {**head, "offset_mm": [0, "100", 0]}
    (copy / "session.json").write_text(json.dumps(info))
    with pytest.raises(FormatError, match=r"head.offset_mm: expected 3 finite numbers"):
        load_session(copy)


def _set_marker_cell(folder: Path, column: str, row: int, value: str) -> None:
    import csv

    path = folder / "markers.csv"
    with open(path, newline="") as fh:
        header, *body = list(csv.reader(fh))
    body[row][header.index(column)] = value
    with open(path, "w", newline="") as fh:
        csv.writer(fh, lineterminator="\n").writerows([header, *body])


def test_absurd_segment_length_is_refused(copy):
    """A 35 m forearm is finite and positive, but no body has it (issue 14)."""
    info = json.loads((copy / "session.json").read_text())
    info["subject"]["bone_lengths_mm"]["left_forearm"] = 35000.0
    (copy / "session.json").write_text(json.dumps(info))
    with pytest.raises(
        FormatError,
        match=r"subject.bone_lengths_mm.left_forearm: expected at most half the stature "
        r"\(\d+ mm\), found 35000.0 mm",
    ):
        load_session(copy)


def test_absurd_marker_coordinates_are_refused(copy):
    _set_marker_cell(copy, "head_z", 3, "1e9")
    with pytest.raises(
        FormatError, match=r"markers.csv: marker 'head' at .* s: expected coordinates within"
    ):
        load_session(copy)


def test_marker_jump_is_refused(copy):
    """2 m in one 120 Hz step is 240 m/s: a glitch, not a motion."""
    import csv

    with open(copy / "markers.csv", newline="") as fh:
        header, *body = list(csv.reader(fh))
    x = float(body[5][header.index("left_hand_x")])
    _set_marker_cell(copy, "left_hand_x", 5, repr(x + 2000.0))
    with pytest.raises(FormatError, match=r"marker 'left_hand' at .* s: expected a speed below"):
        load_session(copy)


def test_member_far_from_its_siblings_is_refused(copy):
    """members_mm puts the glasses' members ~140 mm apart; one of them 500 mm away in one
    sample (60 m/s, no glitch of speed) is refused with the set, the pair and the time
    named (issue 14)."""
    info = json.loads((copy / "session.json").read_text())
    members = list(info["marker_offsets_mm"]["head"]["members_mm"])
    s = load_session(copy)
    k = s.markers.names.index(members[0])
    moved = float(s.markers.positions_mm[0, k, 0]) + 500.0
    _set_marker_cell(copy, f"{members[0]}_x", 0, repr(moved))
    with pytest.raises(
        SessionError,
        match=r"marker_offsets_mm.head.members_mm: '.*' and '.*' are declared \d+ mm apart, "
        r"found \d+ mm at",
    ):
        load_session(copy)


def test_refuses_streams_of_different_lengths(copy):
    """Videos, truth and markers that cannot be one recording are refused (issue 14)."""
    path = copy / "video" / "stereo_left.timestamps.csv"
    t = read_timestamps_csv(path)
    write_timestamps_csv(path, t * 2.0)
    with pytest.raises(
        SessionError, match=r"video of camera 'stereo_left' spans .* s, the video of camera 'mono'"
    ):
        load_session(copy)
    write_timestamps_csv(path, t)

    truth = dict(np.load(copy / "truth.npz"))
    cut = {
        k: (v[:-3] if k in ("time_s", "joints_mm", "markers_mm") else v) for k, v in truth.items()
    }
    np.savez(copy / "truth.npz", **cut)
    with pytest.raises(
        SessionError, match=rf"truth.npz has {len(t) - 3} samples, the video of camera 'mono' "
    ):
        load_session(copy)
    np.savez(copy / "truth.npz", **truth)

    import csv

    with open(copy / "markers.csv", newline="") as fh:
        header, *body = list(csv.reader(fh))
    for r in body:
        r[0] = repr(float(r[0]) + 100.0)
    with open(copy / "markers.csv", "w", newline="") as fh:
        csv.writer(fh, lineterminator="\n").writerows([header, *body])
    with pytest.raises(SessionError, match=r"the markers span .* s and the video of camera 'mono'"):
        load_session(copy)


def test_lenient_fields_are_refused(copy):
    """``"format": true`` is not 1, reference markers must be in the marker file, a K
    entry must be a number, not the string "532", and k1 = 50 is no lens (issue 14)."""
    doc = json.loads((copy / "session.json").read_text())
    (copy / "session.json").write_text(json.dumps({**doc, "format": True}))
    with pytest.raises(FormatError, match=r"field 'format': expected 1, found True"):
        load_session(copy)
    (copy / "session.json").write_text(json.dumps({**doc, "reference_markers": ["LELB"]}))
    with pytest.raises(SessionError, match=r"reference_markers names \['LELB'\], which markers"):
        load_session(copy)
    (copy / "session.json").write_text(json.dumps(doc))
    cams = json.loads((copy / "cameras.json").read_text())
    good = json.loads(json.dumps(cams))
    cams["cameras"][0]["K"][0][0] = "532"
    (copy / "cameras.json").write_text(json.dumps(cams))
    with pytest.raises(FormatError, match=r"cameras\[0\] \('mono'\).K: expected a \(3, 3\) array"):
        load_session(copy)
    cams = json.loads(json.dumps(good))
    cams["cameras"][0]["dist"][0] = 50.0
    (copy / "cameras.json").write_text(json.dumps(cams))
    with pytest.raises(FormatError, match=r"dist\[0\] \(k1\): expected a radial coefficient"):
        load_session(copy)
