"""The option rules of a hybrid run, stated once in `HybridRunOptions`."""

from __future__ import annotations

import pytest

from mocapkit.errors import SessionError
from mocapkit.pipelines.hybrid_options import HybridRunOptions


def test_a_run_takes_one_input_and_only_its_options() -> None:
    with pytest.raises(SessionError, match="found neither"):
        HybridRunOptions()
    with pytest.raises(SessionError, match="not both"):
        HybridRunOptions(session="s", markers="m.c3d")
    with pytest.raises(SessionError, match=r"--paper, --max-elbow-speed apply to a SESSION"):
        HybridRunOptions(markers="m.c3d", paper=True, max_elbow_speed_mm_per_s=1.0)
    with pytest.raises(SessionError, match=r"--up, --static apply to --markers"):
        HybridRunOptions(session="s", up="z", static="still.c3d")


def test_contradicting_options_are_refused() -> None:
    with pytest.raises(SessionError, match="which --paper and --no-video do not run"):
        HybridRunOptions(session="s", no_video=True, max_elbow_speed_mm_per_s=0.0)
    with pytest.raises(SessionError, match="--positions-only or --oriented-sets"):
        HybridRunOptions(session="s", positions_only=True, oriented_sets="head")
    with pytest.raises(SessionError, match="found --calibration dynamic with it"):
        HybridRunOptions(markers="m.c3d", no_static_calibration=True, calibration="dynamic")


def test_derived_settings() -> None:
    assert HybridRunOptions(markers="m.c3d").member_calibration == "auto"
    assert HybridRunOptions(markers="m.c3d", no_static_calibration=True).member_calibration == (
        "none"
    )
    assert HybridRunOptions(session="s").oriented is None
    assert HybridRunOptions(session="s", positions_only=True).oriented == ()
    assert HybridRunOptions(session="s", oriented_sets="head,left_hand").oriented == (
        "head",
        "left_hand",
    )
