"""The keypoints' age and place rules: old rows are no observation, clocks that never
overlap are refused, points far outside the image are dropped and counted."""

from __future__ import annotations

import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import InputWarning, SessionError
from mocapkit.io.keypoint_checks import OUTSIDE_IMAGE_MARGIN, keypoints_at, max_age_s
from mocapkit.io.session import load_session
from mocapkit.io.session_csv import Keypoints, read_keypoints_csv, write_keypoints_csv
from mocapkit.synth.session_writer import SynthOptions, synthesize_session
from mocapkit.tracking.base import BRIDGE_S


@pytest.fixture(scope="module")
def session_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("kp") / "wave"
    synthesize_session(
        "builtin:wave",
        out,
        SynthOptions(rig="stereo", seconds=1.0, image_size=(160, 120), seed=5),
    )
    return out


@pytest.fixture
def copy(session_dir: Path, tmp_path: Path) -> Path:
    dst = tmp_path / "s"
    shutil.copytree(session_dir, dst)
    return dst


def _rewrite(folder: Path, cam: str, keep: slice | None = None, shift_s: float = 0.0) -> Path:
    path = folder / "keypoints" / f"{cam}.csv"
    kp = read_keypoints_csv(path)
    sel = keep if keep is not None else slice(None)
    write_keypoints_csv(path, kp.time_s[sel] + shift_s, kp.joint_names, kp.pixels[sel])
    return path


def test_age_rule_known_values() -> None:
    kp = Keypoints(np.array([0.0, 0.1, 0.2]), ("head",), np.arange(6.0).reshape(3, 1, 2))
    assert max_age_s(kp.time_s, np.arange(10) / 30.0) == pytest.approx(0.1)
    np.testing.assert_array_equal(keypoints_at(kp, 0.26, 0.1), [[4.0, 5.0]])
    assert np.isnan(keypoints_at(kp, 0.31, 0.1)).all()
    assert np.isnan(keypoints_at(kp, -0.2, 0.1)).all()


def test_keypoints_ending_halfway_are_not_held_as_seen(copy: Path) -> None:
    """Keypoints that end at half the video: later frames have no keypoint observation."""
    s0 = load_session(copy)
    n = s0.video("stereo_right").n_frames
    _rewrite(copy, "stereo_right", slice(0, n // 2))
    with pytest.warns(InputWarning, match=r"stereo_right\.csv .*: the keypoints span 0\.000-"):
        s = load_session(copy)
    end = float(s.keypoints["stereo_right"].time_s[-1])
    step = float(np.median(np.diff(s.video("stereo_right").time_s)))
    for smp in s.samples(["stereo_left", "stereo_right"]):
        right = smp.keypoints_px["stereo_right"]
        assert np.isfinite(smp.keypoints_px["stereo_left"]).any()
        if smp.time_s <= end + step + 1e-9:
            assert np.isfinite(right).any(), smp.time_s
        else:
            assert np.isnan(right).all(), smp.time_s


def test_keypoints_ending_halfway_release_the_stereo_hands(copy: Path) -> None:
    """Tracked: the right view's keypoints end halfway; the hands are bridged for
    BRIDGE_S, then released (NaN wrists), never tracked as seen on a held row."""
    from mocapkit.pipelines.stereo import track_stereo_session
    from mocapkit.skeleton.model import CANONICAL_JOINTS
    from mocapkit.tracking.stereo.arm_filter import ArmFilterConfig
    from mocapkit.tracking.stereo.tracker import StereoConfig

    n = load_session(copy).video("stereo_right").n_frames
    _rewrite(copy, "stereo_right", slice(0, n // 2))
    cfg = StereoConfig(arm=ArmFilterConfig(n_particles=20), use_keypoints=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", InputWarning)
        run = track_stereo_session(copy, None, config=cfg)
    t = run.motion.time_s
    end = t[n // 2 - 1]
    wrist = CANONICAL_JOINTS.index("right_wrist")
    for ti, r in zip(t, run.results):
        if ti <= end:
            assert r.status["right_hand"] == "seen"
        elif ti > end + BRIDGE_S + 0.05:
            assert r.status["right_hand"] == "released", (ti, r.status)
            assert np.isnan(r.joints_mm[wrist]).all()


def test_keypoints_on_a_clock_that_never_overlaps_are_refused(copy: Path) -> None:
    _rewrite(copy, "stereo_left", shift_s=10.0)
    with pytest.raises(
        SessionError,
        match=r"stereo_left\.csv \(video of camera 'stereo_left'\): the keypoints span "
        r"10\.000-1[01]\.\d{3} s and the video 0\.000-[01]\.\d{3} s; expected clocks that overlap",
    ):
        load_session(copy)


def test_points_far_outside_the_image_are_no_observation(copy: Path) -> None:
    path = copy / "keypoints" / "stereo_left.csv"
    kp = read_keypoints_csv(path)
    px = kp.pixels.copy()
    px[3:13, kp.joint_names.index("right_wrist")] = 1e9  # 10 frames
    px[20, kp.joint_names.index("head")] = [-0.2 * 160, 60.0]  # just outside: kept
    write_keypoints_csv(path, kp.time_s, kp.joint_names, px)
    with pytest.warns(
        InputWarning,
        match=r"stereo_left\.csv: 10 points in 10 frames lie more than 25 % of the image size "
        r"outside its 160x120 px \(first: right_wrist at \(1e\+09, 1e\+09\) px, 0\.100 s\); "
        r"taken as no observation",
    ):
        s = load_session(copy)
    got = s.keypoints["stereo_left"].pixels
    assert np.isnan(got[3:13, kp.joint_names.index("right_wrist")]).all()
    assert np.isfinite(got[20, kp.joint_names.index("head")]).all()
    assert OUTSIDE_IMAGE_MARGIN == 0.25
    # the other points and the other camera are untouched
    np.testing.assert_array_equal(np.isnan(got).sum(), np.isnan(kp.pixels).sum() + 10 * 2)
    np.testing.assert_array_equal(
        s.keypoints["stereo_right"].pixels, read_keypoints_csv(copy / "keypoints" /
                                                                "stereo_right.csv").pixels
    )  # fmt: skip
