"""The clip split stated once: the harnesses' default clips are the tuning set."""

from __future__ import annotations

import pytest

from mocapkit.cli.args import chosen_clips
from mocapkit.cli.main import build_parser
from mocapkit.pipelines.accuracy import HYBRID_CLIPS
from mocapkit.pipelines.harness import CLIP_SETS, REPORT_CLIPS, TUNING_CLIPS
from mocapkit.pipelines.mono_accuracy import MONO_CLIPS


def test_the_split_is_disjoint_and_the_defaults_are_the_tuning_set() -> None:
    assert not set(TUNING_CLIPS) & set(REPORT_CLIPS)
    assert set(CLIP_SETS) == {"tuning", "report"}
    assert tuple(HYBRID_CLIPS) == TUNING_CLIPS
    assert tuple(MONO_CLIPS) == TUNING_CLIPS


@pytest.mark.parametrize("method", ["hybrid", "mono"])
def test_clip_set_names_the_clips(method: str) -> None:
    parser = build_parser()
    args = parser.parse_args(["accuracy", method, "--clip-set", "report"])
    assert chosen_clips(args) == list(REPORT_CLIPS)
    args = parser.parse_args(["accuracy", method, "--clips", "13_26.bvh"])
    assert chosen_clips(args) == ["13_26.bvh"]
    assert chosen_clips(parser.parse_args(["accuracy", method])) is None


def test_clips_and_clip_set_exclude_each_other(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        build_parser().parse_args(
            ["accuracy", "hybrid", "--clips", "a.bvh", "--clip-set", "report"]
        )
    assert "not allowed with argument" in capsys.readouterr().err
