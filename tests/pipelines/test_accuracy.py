"""The accuracy study's jittered repeats: the session copies and the summary over repeats."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.io.session import load_session
from mocapkit.pipelines.accuracy import (
    ClipAccuracy,
    hybrid_accuracy_repeats,
    jitter_session,
    repeat_summary,
    summary,
)


@pytest.fixture(scope="module")
def small_session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny rendered session (0.25 s, 320x240)."""
    from mocapkit.synth.session_writer import SynthOptions, synthesize_session

    folder = tmp_path_factory.mktemp("acc") / "session"
    options = SynthOptions(
        rig="mono", start_s=0.5, seconds=0.25, image_size=(320, 240), overwrite=True
    )
    synthesize_session("builtin:wave", folder, options)
    return folder


def test_jitter_session_moves_every_marker_by_at_most_the_jitter(
    small_session: Path, tmp_path: Path
) -> None:
    orig = load_session(small_session)
    assert orig.markers is not None
    out = jitter_session(small_session, tmp_path / "j", 1e-6, np.random.default_rng([0, 1]))
    copy = load_session(out)
    assert copy.markers is not None
    assert copy.markers.names == orig.markers.names
    np.testing.assert_array_equal(copy.markers.time_s, orig.markers.time_s)
    a, b = orig.markers.positions_mm, copy.markers.positions_mm
    np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
    d = (b - a)[np.isfinite(a)]
    # every coordinate moved, by at most the jitter (plus the rounding of the sum,
    # 1.1e-13 mm at 1 m), and the offsets fill the interval
    assert np.all(d != 0.0)
    assert np.max(np.abs(d)) <= 1e-6 + 1e-12
    assert d.min() < -0.9e-6 and d.max() > 0.9e-6
    # the rest of the session is the same (linked): cameras, video, truth
    assert sorted(p.name for p in out.iterdir()) == sorted(
        p.name for p in small_session.iterdir() if p.name != "markers.c3d"
    )
    assert [c.name for c in copy.cameras] == [c.name for c in orig.cameras]
    assert (out / "session.json").read_text() == (small_session / "session.json").read_text()


def test_jitter_session_is_seeded_and_replaces_an_old_copy(
    small_session: Path, tmp_path: Path
) -> None:
    def positions(seed: list[int]) -> np.ndarray:
        out = jitter_session(small_session, tmp_path / "j", 1e-6, np.random.default_rng(seed))
        markers = load_session(out).markers
        assert markers is not None
        return np.array(markers.positions_mm)

    first = positions([0, 1])
    np.testing.assert_array_equal(positions([0, 1]), first)  # written over the old copy
    assert np.any(positions([0, 2]) != first)


def _row(clip: str, elbow_ik: float, elbow_video: float, mpjpe: float) -> ClipAccuracy:
    return ClipAccuracy(clip, 0.0, 4.0, elbow_ik, elbow_video, mpjpe, mpjpe - 1.0, 30.0, 1.0)


def test_repeat_summary_means_and_spread_of_the_repeats_means() -> None:
    runs = [
        [_row("a", 10.0, 8.0, 40.0), _row("b", 20.0, 18.0, 50.0)],  # means 15, 13, 45
        [_row("a", 12.0, 8.0, 41.0), _row("b", 24.0, 18.0, 51.0)],  # means 18, 13, 46
        [_row("a", 9.0, 8.0, 42.0), _row("b", 24.0, 18.0, 52.0)],  # means 16.5, 13, 47
    ]
    rs = repeat_summary(runs)
    assert rs["elbow_ik_mm"]["mean"] == pytest.approx(16.5)
    assert rs["elbow_ik_mm"]["min"] == pytest.approx(15.0)
    assert rs["elbow_ik_mm"]["max"] == pytest.approx(18.0)
    assert rs["elbow_ik_mm"]["std"] == pytest.approx(1.5)  # sample std of 15, 18, 16.5
    assert rs["elbow_ik_mm"]["sem"] == pytest.approx(1.5 / np.sqrt(3.0))
    assert rs["elbow_video_mm"] == pytest.approx(
        {"mean": 13.0, "min": 13.0, "max": 13.0, "std": 0.0, "sem": 0.0}
    )
    assert rs["mpjpe_video_mm"]["mean"] == pytest.approx(45.0)
    assert rs.keys() == summary(runs[0]).keys()
    one = repeat_summary(runs[:1])
    assert one["elbow_ik_mm"] == pytest.approx(
        {"mean": 15.0, "min": 15.0, "max": 15.0, "std": 0.0, "sem": 0.0}
    )
    with pytest.raises(ConfigError, match="expected at least one run, found none"):
        repeat_summary([])


def test_hybrid_accuracy_repeats_refuses_bad_counts_and_jitters(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"repeats: expected a count >= 0, found -1"):
        hybrid_accuracy_repeats(tmp_path, tmp_path, repeats=-1)
    with pytest.raises(ConfigError, match=r"jitter_mm: expected a positive length, found 0.0"):
        hybrid_accuracy_repeats(tmp_path, tmp_path, repeats=2, jitter_mm=0.0)
