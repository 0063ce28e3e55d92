"""Camera plausibility before tracking (issue 30, cause 2): the probe's cases on `track
stereo` and `track mono`, each refused or warned with the camera, the check and the numbers."""

from __future__ import annotations

import json
import re
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mocapkit.cli.main import main
from mocapkit.errors import SessionError
from mocapkit.io.session import load_session
from mocapkit.pipelines.camera_check import check_session_cameras, warn_placed_subject
from mocapkit.pipelines.stereo import track_stereo_session
from mocapkit.tracking.stereo.tracker import azad_skeleton


def _render(folder: Path, rig: str) -> Path:
    from mocapkit.synth.session_writer import SynthOptions, synthesize_session

    options = SynthOptions(rig=rig, start_s=0.5, seconds=0.2, image_size=(320, 240), seed=3)
    synthesize_session("builtin:wave", folder, options)
    return folder


@pytest.fixture(scope="module")
def rendered(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("camera_check")
    return {rig: _render(root / rig, rig) for rig in ("stereo", "mono")}


Cameras = list[dict[str, Any]]


def _variant(
    src: Path, dst: Path, edit: Callable[[Cameras], None] | None = None, swap_kp: bool = False
) -> Path:
    shutil.copytree(src, dst)
    doc = json.loads((dst / "cameras.json").read_text())
    if edit is not None:
        edit(doc["cameras"])
    (dst / "cameras.json").write_text(json.dumps(doc))
    if swap_kp:
        a, b = sorted((dst / "keypoints").glob("*.csv"))
        text = a.read_text()
        a.write_text(b.read_text())
        b.write_text(text)
    return dst


def _metres(cams: Cameras) -> None:
    for c in cams:
        for row in c["camera_from_world"][:3]:
            row[3] /= 1000.0


def _turned_round(cams: Cameras) -> None:  # about its own vertical axis: it looks away
    m = np.array(cams[0]["camera_from_world"])
    m[:3] = np.diag([-1.0, 1.0, -1.0]) @ m[:3]
    cams[0]["camera_from_world"] = m.tolist()


def _swap_extrinsics(cams: Cameras) -> None:
    cams[0]["camera_from_world"], cams[1]["camera_from_world"] = (
        cams[1]["camera_from_world"],
        cams[0]["camera_from_world"],
    )


def _world_1m_up(cams: Cameras) -> None:  # the world 1 m lower: the subject 1 m up
    for c in cams:
        m = np.array(c["camera_from_world"])
        m[:3, 3] += m[:3, :3] @ np.array([0.0, 0.0, -1000.0])
        c["camera_from_world"] = m.tolist()


def _world_upside_down(cams: Cameras) -> None:  # a board's frame lying face up: z down
    for c in cams:
        m = np.array(c["camera_from_world"])
        m[:3, :3] = m[:3, :3] @ np.diag([1.0, -1.0, -1.0])
        c["camera_from_world"] = m.tolist()


def _cx_5000(cams: Cameras) -> None:
    for c in cams:
        c["K"][0][2] = 5000.0


def _focal_doubled(cams: Cameras) -> None:
    for c in cams:
        c["K"][0][0] *= 2.0
        c["K"][1][1] *= 2.0


BEHIND = r"camera 'stereo_left' \(in front\): the joints triangulated from cameras stereo_left, "
STEREO_REFUSED = [
    # translation in metres (the probe: error 1.7e8 mm)
    ("metres", _metres, False, r"\(limb lengths\): limbs seen by cameras stereo_left, "
     r"stereo_right at the depth triangulated from them are 0.00(09|10)\d* times the subject's "
     r".*expected 0.6-1.5 \(translations in metres"),
    # a camera behind the subject (2.5e5 mm)
    ("behind", _turned_round, False, BEHIND + r"stereo_right lie behind it \(\d+ of \d+"),
    # left and right extrinsics swapped (5.5 m)
    ("swapped extrinsics", _swap_extrinsics, False, BEHIND + r".*median depth -\d+ mm"),
    # cx = 5000 px (2.7 m)
    ("cx 5000", _cx_5000, False, r"camera 'stereo_left' \(intrinsics\): principal point "
     r"\(cx, cy\) = \(5000.0, [\d.]+\) px lies outside its 320x240 image; expected inside it"),
    # the two cameras' keypoint files swapped (5.5 m, torso yaw 178 deg)
    ("swapped keypoints", None, True, BEHIND + r".*keypoint files swapped"),
]  # fmt: skip


@pytest.mark.parametrize(("case", "edit", "swap_kp", "message"), STEREO_REFUSED)
def test_track_stereo_refuses_implausible_cameras_before_tracking(
    rendered, tmp_path, capsys, case, edit, swap_kp, message
):
    session = _variant(rendered["stereo"], tmp_path / "s", edit, swap_kp)
    with pytest.raises(SessionError, match=message):
        track_stereo_session(session, tmp_path / "out", use_keypoints=True)
    assert not (tmp_path / "out").exists()
    # the CLI: one line per refusal, exit 2, with or without --keypoints (the session's
    # keypoints are checked even when the tracker reads skin blobs)
    assert main(["track", "stereo", str(session), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "the cameras do not fit the data" in err and "Traceback" not in err


def test_track_stereo_focal_lengths_doubled_is_warned(rendered, tmp_path, capsys):
    """fx and fy doubled (2.6 m): on a parallel pair the views still agree and give the
    limb lengths (depth doubles, the width does not), so the subject stands far below
    the floor: a warning, not a refusal (a floor need not be at 0)."""
    session = _variant(rendered["stereo"], tmp_path / "s", _focal_doubled)
    s = load_session(session)
    lines: list[str] = []
    sk = azad_skeleton(s.bone_lengths_mm, s.segment_vectors_mm)
    check_session_cameras(s, s.video_cameras, skeleton=sk, warn=lines.append)
    assert len(lines) == 1
    assert (
        "(floor): the subject's ankles, placed from cameras stereo_left, stereo_right, lie "
        "at z = -" in lines[0]
    )
    # the unchanged session: no finding at all
    good = load_session(rendered["stereo"])
    assert check_session_cameras(good, good.video_cameras, skeleton=sk, warn=lines.append) == []
    assert len(lines) == 1


def test_track_mono_refuses_cx_outside_the_image(rendered, tmp_path, capsys):
    """mono with cx outside the image (163 mm worse in pose): refused before the work."""
    session = _variant(rendered["mono"], tmp_path / "s", _cx_5000)
    assert main(["track", "mono", str(session), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "camera 'mono' (intrinsics): principal point (cx, cy) = (5000.0, " in err
    assert not (tmp_path / "o").exists()


def test_track_mono_warns_of_a_camera_in_metres(rendered, tmp_path):
    """mono with the translation in metres placed the subject 3.5 m off: one view cannot
    tell, so the camera 3 mm from the world origin is warned about."""
    session = _variant(rendered["mono"], tmp_path / "s", _metres)
    s = load_session(session)
    lines: list[str] = []
    check_session_cameras(s, ["mono"], warn=lines.append)
    assert len(lines) == 1
    assert "camera 'mono' (scale): its centre lies" in lines[0]
    assert "translations in metres instead of mm?" in lines[0]
    good = load_session(rendered["mono"])
    assert check_session_cameras(good, ["mono"], warn=lines.append) == []


def test_the_floor_from_several_views_and_from_one(rendered, tmp_path):
    """The subject on the floor (z = 0): no finding; the calibration's world 1 m lower:
    the ankles, triangulated from both views, 1 m up, warned naming both cameras. One
    view: no floor before tracking (no depth), after it the placed ankles, saying so. The
    world upside down: the subject's up is warned."""
    s = load_session(_variant(rendered["stereo"], tmp_path / "s", _world_1m_up))
    sk = azad_skeleton(s.bone_lengths_mm, s.segment_vectors_mm)
    lines: list[str] = []
    check_session_cameras(s, s.video_cameras, skeleton=sk, warn=lines.append)
    assert len(lines) == 1
    assert re.search(
        r": cameras 'stereo_left', 'stereo_right' \(floor\): the subject's ankles, placed from "
        r"cameras stereo_left, stereo_right, lie at z = 1[01]\d\d mm \(median of \d+, ",
        lines[0],
    ), lines[0]
    assert check_session_cameras(s, ["stereo_left"], warn=lines.append) == []
    turned = load_session(_variant(rendered["stereo"], tmp_path / "t", _world_upside_down))
    check_session_cameras(turned, turned.video_cameras, skeleton=sk, warn=lines.append)
    assert len(lines) == 2  # the ankles stay near z = 0: only the subject's up tells
    assert "cameras 'stereo_left', 'stereo_right' (up): the subject, triangulated from " in lines[1]
    del lines[1]
    truth = np.load(rendered["stereo"] / "truth.npz")
    names = [str(n) for n in truth["joint_names"]]
    warn_placed_subject(s, "stereo_left", truth["joints_mm"], names, lines.append)
    assert len(lines) == 1  # the truth's ankles are on the floor
    up = truth["joints_mm"] + np.array([0.0, 0.0, 1000.0])
    warn_placed_subject(s, "stereo_left", up, names, lines.append)
    assert (
        "camera 'stereo_left' (floor): the subject's ankles, as placed from this one " in lines[1]
    )
    assert "its depth from the feet on the floor or the subject's limb lengths" in lines[1]
