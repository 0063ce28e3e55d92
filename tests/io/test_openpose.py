"""OpenPose JSON folders: layouts, joint mapping, confidence, following one person."""

import json
from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import ConfigError, FormatError, SessionError, ShapeError
from mocapkit.io.openpose import (
    BODY_25,
    COCO_18,
    MAPPED_JOINTS,
    NECK_BELOW_SHOULDERS,
    NECK_FRACTION,
    PELVIS_ABOVE_HIPS,
    PELVIS_FRACTION,
    openpose_from_canonical,
    place_trunk_joints,
    read_openpose_folder,
    read_openpose_frame,
    to_canonical,
    trunk_fractions,
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
    # a folder of per-camera folders (a multi-camera OpenPose export): named, one to pass
    for cam in ("cam02", "cam01"):
        (empty / cam).mkdir()
        write_openpose_frame(empty / cam / f"{cam}_000000_keypoints.json", [])
    (empty / "notes").mkdir()
    with pytest.raises(
        SessionError,
        match=r"found none but subfolders of them, one per camera \(cam01, cam02\): pass one "
        r"camera's folder: .*empty[/\\]cam01$",
    ):
        read_openpose_folder(empty, np.zeros(1))
    one = tmp_path / "one"
    one.mkdir()
    write_openpose_frame(one / "x_0.json", [])
    with pytest.raises(SessionError, match="one JSON file per video frame"):
        read_openpose_folder(one, np.zeros(3))


def _girdle_take(rng: np.random.Generator, n: int = 40) -> tuple[np.ndarray, float, float]:
    """A rigid trunk (shoulder width W = 360 mm, hip-to-shoulder midpoint H = 500 mm, neck
    0.205 W below the shoulder midpoint, pelvis 0.277 W above the hip midpoint) turning
    and leaning in front of an orthographic camera; canonical keypoints (n, 15, 2) px at
    0.5 px/mm (frame 0 faces the camera upright), with W and H."""
    w, h = 360.0, 500.0
    body = {
        "left_shoulder": (w / 2, h, 0), "right_shoulder": (-w / 2, h, 0),
        "left_hip": (90, 0, 0), "right_hip": (-90, 0, 0),
        "neck": (0, h - NECK_BELOW_SHOULDERS * w, 0), "pelvis": (0, PELVIS_ABOVE_HIPS * w, 0),
        "head": (0, h + 200, 0), "left_elbow": (220, 300, 0), "left_wrist": (230, 60, 0),
        "right_elbow": (-220, 300, 0), "right_wrist": (-230, 60, 0),
        "left_knee": (90, -420, 0), "left_ankle": (90, -830, 0),
        "right_knee": (-90, -420, 0), "right_ankle": (-90, -830, 0),
    }  # fmt: skip
    pts = np.array([body[j] for j in MAPPED_JOINTS], dtype=float)
    out = np.empty((n, len(MAPPED_JOINTS), 2))
    for t in range(n):
        yaw = 0.0 if t == 0 else rng.uniform(-1.2, 1.2)  # turning about the vertical
        lean = 0.0 if t == 0 else rng.uniform(-0.8, 0.8)  # towards or away from the camera
        cy, sy, cl, sl = np.cos(yaw), np.sin(yaw), np.cos(lean), np.sin(lean)
        r_yaw = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
        r_lean = np.array([[1, 0, 0], [0, cl, -sl], [0, sl, cl]])
        p = pts @ (r_lean @ r_yaw).T
        out[t] = 0.5 * np.stack([p[:, 0], -p[:, 1]], axis=-1) + [320.0, 300.0]
    return out, w, h


def test_trunk_fractions_put_the_neck_and_pelvis_where_the_rigid_girdle_has_them() -> None:
    rng = np.random.default_rng(63)
    true_px, w, h = _girdle_take(rng)
    f_n, f_p = trunk_fractions(true_px, MAPPED_JOINTS, percentile=100.0)
    # the upright frontal frame shows W and H unshortened: the fractions are exact
    assert f_n == pytest.approx(1.0 - NECK_BELOW_SHOULDERS * w / h, abs=1e-12)
    assert f_p == pytest.approx(PELVIS_ABOVE_HIPS * w / h, abs=1e-12)
    assert (f_n, f_p) == pytest.approx((0.852_4, 0.199_44), abs=1e-12)
    # a detector sees no neck or pelvis: both come back in every frame, turned or leaning
    seen = true_px.copy()
    seen[:, [MAPPED_JOINTS.index("neck"), MAPPED_JOINTS.index("pelvis")]] = np.nan
    rebuilt = place_trunk_joints(seen, MAPPED_JOINTS, (f_n, f_p))
    np.testing.assert_allclose(rebuilt, true_px, atol=1e-9)
    # the fixed fractions of earlier rounds miss this neck by 0.042 H (the lean shortens it)
    fixed = place_trunk_joints(seen, MAPPED_JOINTS, (NECK_FRACTION, PELVIS_FRACTION))
    err = np.linalg.norm(fixed - true_px, axis=-1)[:, MAPPED_JOINTS.index("neck")]
    assert err[0] == pytest.approx((1.0 - NECK_BELOW_SHOULDERS * w / h - 0.81) * h * 0.5)


def test_trunk_fractions_fall_back_to_the_fixed_pair_and_refuse_bad_input() -> None:
    rng = np.random.default_rng(64)
    px, _, _ = _girdle_take(rng, 10)
    no_hips = px.copy()
    no_hips[:, MAPPED_JOINTS.index("left_hip")] = np.nan
    assert trunk_fractions(no_hips, MAPPED_JOINTS) == (NECK_FRACTION, PELVIS_FRACTION)
    # a trunk never seen longer than 0.3 of its length: W / H = 2.4 would put the neck
    # below the pelvis
    sh = [MAPPED_JOINTS.index("left_shoulder"), MAPPED_JOINTS.index("right_shoulder")]
    hp = [MAPPED_JOINTS.index("left_hip"), MAPPED_JOINTS.index("right_hip")]
    m_s = px[:, sh].mean(axis=1, keepdims=True)
    squat = px.copy()
    squat[:, hp] = m_s + 0.3 * (px[:, hp] - m_s)
    w = np.linalg.norm(squat[:, sh[0]] - squat[:, sh[1]], axis=-1)
    h = np.linalg.norm(m_s[:, 0] - squat[:, hp].mean(axis=1), axis=-1)
    ratio = np.percentile(w, 90) / np.percentile(h, 90)
    assert 1.0 - NECK_BELOW_SHOULDERS * ratio < PELVIS_ABOVE_HIPS * ratio
    assert trunk_fractions(squat, MAPPED_JOINTS) == (NECK_FRACTION, PELVIS_FRACTION)
    with pytest.raises(ShapeError, match="expected \\(T, 15, 2\\)"):
        trunk_fractions(px[0], MAPPED_JOINTS)
    with pytest.raises(ConfigError, match="percentile: expected \\(0, 100\\]"):
        trunk_fractions(px, MAPPED_JOINTS, percentile=0.0)
    with pytest.raises(ShapeError, match="expected \\(..., 15, 2\\)"):
        place_trunk_joints(px[..., :1], MAPPED_JOINTS, (0.8, 0.2))


def test_a_folder_gets_its_take_s_own_neck_and_pelvis(tmp_path: Path) -> None:
    rng = np.random.default_rng(65)
    true_px, w, h = _girdle_take(rng, 20)
    det = openpose_from_canonical(true_px, MAPPED_JOINTS)
    _write_frames(tmp_path / "op", [[d] for d in det], "BODY_25")
    kp = read_openpose_folder(tmp_path / "op", np.arange(20) / 30.0)
    f_n, f_p = trunk_fractions(kp.pixels, MAPPED_JOINTS)
    assert f_n == pytest.approx(1.0 - NECK_BELOW_SHOULDERS * w / h, abs=0.01)
    assert f"{f_n:.3f} and {f_p:.3f}" in kp.source
    assert kp.rebuilt_joints == ("neck", "pelvis")  # tells the tracker they are not seen
    np.testing.assert_allclose(kp.pixels, true_px, atol=0.01 * h)
    fixed = read_openpose_folder(
        tmp_path / "op", np.arange(20) / 30.0, fractions=(NECK_FRACTION, PELVIS_FRACTION)
    )
    np.testing.assert_allclose(
        fixed.pixels[:, 1], place_trunk_joints(true_px, MAPPED_JOINTS, (0.81, 0.25))[:, 1]
    )


def test_a_subject_seen_only_in_part_is_followed(tmp_path: Path) -> None:
    """A subject leaving the image down to one arm is still followed (the size is the
    whole body's, not that of the points seen in the frame)."""
    rng = np.random.default_rng(66)
    subject = _person(rng, (300, 240), 200)
    other = _person(rng, (520, 240), 120)
    step = np.array([4.0, 0.0])
    frames, want = [], []
    for t in range(6):
        s = subject + t * step
        if t >= 2:
            keep = ["left_elbow", "left_wrist"] if t < 4 else ["left_wrist"]
            s = np.where(np.isin(MAPPED_JOINTS, keep)[:, None], s, np.nan)
        want.append(s)
        frames.append([openpose_from_canonical(p[None], MAPPED_JOINTS)[0] for p in (other, s)])
    _write_frames(tmp_path / "op", frames, "BODY_25")
    kp = read_openpose_folder(tmp_path / "op", np.arange(6) / 30.0)
    wrist = MAPPED_JOINTS.index("left_wrist")
    for t in range(6):
        np.testing.assert_allclose(kp.pixels[t, wrist], subject[wrist] + t * step)
    assert np.isnan(kp.pixels[4:, MAPPED_JOINTS.index("left_elbow")]).all()


def test_a_folder_written_by_the_detection_keeps_every_frame_it_wrote(tmp_path: Path) -> None:
    """The folder's reader follows by the detection's own rule on the same points: each
    frame that `mocapkit detect` wrote (the person it followed, or nobody) is kept."""
    from mocapkit.cues.follow import PersonFollower, seen_points

    rng = np.random.default_rng(67)
    n = 40
    follower = PersonFollower()
    frames = []
    for t in range(n):
        # a person who jumps about at random, at times further than the rule allows
        p = _person(rng, (300 + rng.normal(scale=30), 240 + rng.normal(scale=30)), 200)
        if t % 9 == 4:
            p = p[None] * 0.0 + [600.0, 100.0] + rng.normal(scale=60, size=p.shape)
            p = p[0]
        det = openpose_from_canonical(p[None], MAPPED_JOINTS)[0]
        frames.append([det] if follower.choose(t, [seen_points(det)]) is not None else [])
    written = np.array([bool(f) for f in frames])
    assert 0 < written.sum() < n  # the detection dropped some frames
    _write_frames(tmp_path / "op", frames, "BODY_25")
    kp = read_openpose_folder(tmp_path / "op", np.arange(n) / 30.0)
    np.testing.assert_array_equal(np.isfinite(kp.pixels).any(axis=(1, 2)), written)
