"""The stereo accuracy and ablation studies' argument checks."""

from __future__ import annotations

import pytest

from mocapkit.errors import ConfigError
from mocapkit.pipelines.stereo import stereo_ablations


def test_ablations_refuse_a_reset_outside_the_excerpt(tmp_path):
    # checked before any session is rendered: nothing is written
    with pytest.raises(ConfigError, match=r"expected the reset time within the excerpt .* 0.5 s"):
        stereo_ablations(tmp_path / "mocap", tmp_path / "work", seconds=0.5, reset_s=1.0)
    with pytest.raises(ConfigError, match=r"found reset_s = 0 s"):
        stereo_ablations(tmp_path / "mocap", tmp_path / "work", reset_s=0.0)
    assert not (tmp_path / "work").exists()
