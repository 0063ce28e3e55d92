"""OpenPose JSON folders: layouts, joint mapping, confidence, following one person."""

import json
from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import FormatError, SessionError
from mocapkit.io.openpose import (
    BODY_25,
    COCO_18,
    MAPPED_JOINTS,
    NECK_FRACTION,
    PELVIS_FRACTION,
    follow_person,
    openpose_from_canonical,
    read_openpose_folder,
    read_openpose_frame,
    to_canonical,
    write_openpose_frame,
)


def _person(rng: np.random.Generator, centre: tuple[float, float], scale: float) -> np.ndarray:
    """Canonical keypoints (15, 2) of a standing figure around an image point."""
    base = {
        "head": (0, -0.9), "neck": (0, -0.6), "pelvis": (0, 0.0), "left_shoulder": (0.2, -0.65),
        "left_elbow": (0.25, -0.35), "left_wrist": (0.27, -0.1), "right_shoulder": (-0.2, -0.65),
        "right_elbow": (-0.25, -0.35), "right_wrist": (-0.27, -0.1), "left_hip": (0.1, 0.05),
        "left_knee": (0.1, 0.5), "left_ankle": (0.1, 0.95), "right_hip": (-0.1, 0.05),
        "right_knee": (-0.1, 0.5), "right_ankle": (-0.1, 0.95),
    }  # fmt: skip
    pts = np.array([base[n] for n in MAPPED_JOINTS], dtype=float) * scale + centre
    return pts + rng.normal(scale=0.5, size=pts.shape)


def _write_frames(folder: Path, frames: list[list[np.ndarray]], layout: str) -> None:
    folder.mkdir()
    for t, people in enumerate(frames):
        write_openpose_frame(folder / f"clip_{t:012d}_keypoints.json", people, layout)


@pytest.mark.parametrize("layout", ["BODY_25", "COCO-18"])
def test_mapping_round_trip_and_confidence(tmp_path: Path, layout: str) -> None:
    rng = np.random.default_rng(60)
    can = _person(rng, (320, 240), 200)[None]
    det = openpose_from_canonical(can, MAPPED_JOINTS, layout)
    assert det.shape == (1, len(BODY_25 if layout == "BODY_25" else COCO_18), 3)
    det[0, 4, 2] = 0.1  # RWrist below the confidence threshold
    write_openpose_frame(tmp_path / "f.json", [det[0]], layout)
    got_layout, people = read_openpose_frame(tmp_path / "f.json")
    assert got_layout == layout
    out = to_canonical(people, layout, min_confidence=0.3)[0]
    direct = [n for n in MAPPED_JOINTS if n not in ("head", "neck", "pelvis", "right_wrist")]
    idx = [MAPPED_JOINTS.index(n) for n in direct]
    np.testing.assert_allclose(out[idx], can[0, idx], atol=1e-9)
    assert np.isnan(out[MAPPED_JOINTS.index("right_wrist")]).all()
    np.testing.assert_allclose(out[MAPPED_JOINTS.index("head")], can[0, 0], atol=1e-9)
    m_s = can[0, [3, 6]].mean(axis=0)
    m_h = can[0, [9, 12]].mean(axis=0)
    np.testing.assert_allclose(out[1], m_h + NECK_FRACTION * (m_s - m_h), atol=1e-9)
    np.testing.assert_allclose(out[2], m_h + PELVIS_FRACTION * (m_s - m_h), atol=1e-9)


def test_follows_the_largest_person_through_crossings_and_gaps(tmp_path: Path) -> None:
    rng = np.random.default_rng(61)
    n = 12
    subject = [_person(rng, (200 + 10 * t, 240), 220) for t in range(n)]
    other = [_person(rng, (420 - 10 * t, 250), 150) for t in range(n)]
    frames = []
    for t in range(n):
        people = [
            openpose_from_canonical(p[None], MAPPED_JOINTS)[0] for p in (other[t], subject[t])
        ]
        if t % 2:
            people = people[::-1]  # detector order changes from frame to frame
        if t == 5:
            # the subject is not detected; the other person is near but not near enough
            people = [openpose_from_canonical(other[t][None], MAPPED_JOINTS)[0]]
        if t == 7:
            people = []
        frames.append(people)
    _write_frames(tmp_path / "op", frames, "BODY_25")
    kp = read_openpose_folder(tmp_path / "op", np.arange(n) / 30.0)
    assert kp.joint_names == MAPPED_JOINTS and kp.pixels.shape == (n, 15, 2)
    wrist = MAPPED_JOINTS.index("left_wrist")
    for t in range(n):
        if t in (5, 7):
            assert np.isnan(kp.pixels[t]).all()
        else:
            np.testing.assert_allclose(kp.pixels[t, wrist], subject[t][wrist], atol=1e-3)
    # asking for the other person by an image point follows them instead
    kp2 = read_openpose_folder(tmp_path / "op", np.arange(n) / 30.0, start_px=(420, 250))
    np.testing.assert_allclose(kp2.pixels[0, wrist], other[0][wrist], atol=1e-3)


def test_follow_person_rejects_a_far_jump() -> None:
    rng = np.random.default_rng(62)
    a = _person(rng, (200, 240), 200)
    b = _person(rng, (600, 240), 200)
    out = follow_person([a[None], b[None], a[None]], max_jump=0.2)
    assert np.isnan(out[1]).all() and np.isfinite(out[2]).all()


def test_bad_files_are_refused(tmp_path: Path) -> None:
    (tmp_path / "a.json").write_text(json.dumps({"people": [{"pose_keypoints_2d": [1, 2]}]}))
    with pytest.raises(FormatError, match="75 \\(BODY_25\\) or 54"):
        read_openpose_frame(tmp_path / "a.json")
    (tmp_path / "b.json").write_text("{not json")
    with pytest.raises(FormatError, match="not valid JSON"):
        read_openpose_frame(tmp_path / "b.json")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(SessionError, match="found none"):
        read_openpose_folder(empty, np.zeros(1))
    one = tmp_path / "one"
    one.mkdir()
    write_openpose_frame(one / "x.json", [])
    with pytest.raises(SessionError, match="one JSON file per video frame"):
        read_openpose_folder(one, np.zeros(3))
