"""Option values refused by the configuration they set, whichever way they come in (the
CLI or the library): issue 30's weak cases outside `io/`."""

from __future__ import annotations

import math

import pytest

from mocapkit.cli.main import main
from mocapkit.errors import ConfigError
from mocapkit.tracking.mono.tracker import MonoConfig


@pytest.mark.parametrize("value", [-5.0, math.nan, math.inf])
def test_mono_arm_prior_weight_must_be_a_finite_weight(value, tmp_path, capsys):
    """`--arm-prior-weight -5` and `nan` were accepted."""
    with pytest.raises(
        ConfigError,
        match=r"MonoConfig.arm_prior_weight: expected a finite weight >= 0 \(0: off\), found",
    ):
        MonoConfig(arm_prior_weight=value)
    from tests.pipelines.test_mono import _session

    session = _session(tmp_path / "s", lengths=True)
    out = tmp_path / "r"
    code = main(
        ["track", "mono", str(session), "--out", str(out), "--arm-prior-weight", str(value)]
    )
    assert code == 2 and not out.exists()
    assert "error: MonoConfig.arm_prior_weight: expected a finite weight" in (
        capsys.readouterr().err
    )


@pytest.mark.parametrize(
    "name",
    ["clavicle_weight", "arm_prior_weight", "girdle_weight"],
)
def test_every_mono_weight_is_checked(name):
    with pytest.raises(ConfigError, match=rf"MonoConfig.{name}: expected a finite weight"):
        MonoConfig(**{name: -1.0})
    assert getattr(MonoConfig(**{name: 0.0}), name) == 0.0
