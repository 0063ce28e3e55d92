"""Algorithm 1 (errata A10): ordering across the minimum radius, no division by zero, the cap."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.tracking.stereo.fusion import (
    FusionParams,
    check_fusion,
    default_fusion,
    fused_weight_nb,
    fused_weights_nb,
)


def _weights(eg, d2, prev, params):
    out = np.empty(len(eg))
    fused_weights_nb(np.asarray(eg, float), np.asarray(d2, float), float(prev), params, out)
    return out


def test_any_particle_inside_the_radius_outweighs_any_outside():
    p = default_fusion()
    rng = np.random.default_rng(0)
    t2 = p.t_d_mm**2
    for prev in (0.0, 1.0, t2, 10 * t2, 1e6):
        eg = rng.uniform(0, 1, 2000)
        d2 = np.concatenate([rng.uniform(0, t2 * 0.999, 1000), rng.uniform(t2, 1e7, 1000)])
        w = _weights(eg, d2, prev, p)
        inside, outside = w[:1000], w[1000:]
        assert inside.min() > outside.max()
        assert inside.min() >= math.exp(-p.s_g)
        # inside, only the edge error ranks the particles
        order = np.argsort(eg[:1000])
        assert np.all(np.diff(inside[order]) <= 0)


def test_previous_error_of_zero_does_not_divide_by_zero():
    p = default_fusion()
    w = _weights([0.5, 0.5], [2000.0, 5000.0], 0.0, p)
    assert np.all(np.isfinite(w)) and np.all(w > 0)
    # the floor is t_d^2: same as passing t_d^2 itself
    np.testing.assert_allclose(w, _weights([0.5, 0.5], [2000.0, 5000.0], p.t_d_mm**2, p))


def test_cap_holds():
    p = default_fusion()
    w = fused_weight_nb(0.3, 1e12, 900.0, p)
    assert w == pytest.approx(math.exp(-(p.cap + p.s_g * 1.0)))
    # below the cap the normalised distance enters linearly
    w2 = fused_weight_nb(0.3, 1800.0, 900.0, p)
    assert w2 == pytest.approx(math.exp(-(p.s_d * 2.0 + p.s_g)))


def test_known_value_inside():
    p = default_fusion()
    assert fused_weight_nb(0.25, 100.0, 5e4, p) == pytest.approx(math.exp(-2.5))


def test_no_measurement_leaves_the_edge_cue_alone():
    p = default_fusion()
    assert fused_weight_nb(0.4, math.nan, 900.0, p) == pytest.approx(math.exp(-4.0))


def test_conventional_fusion_multiplies():
    p = default_fusion(conventional=True)
    w = fused_weight_nb(0.4, 1800.0, 900.0, p)
    assert w == pytest.approx(math.exp(-4.0) * math.exp(-20.0))


def test_refusals():
    with pytest.raises(ConfigError, match="t_d_mm"):
        check_fusion(FusionParams(10.0, 10.0, 0.0, 50.0, False))
