"""Link lengths from the video (Mamania et al. 2004 §4.1)."""

import numpy as np
import pytest

from mocapkit.errors import ConfigError, ShapeError
from mocapkit.tracking.mono.lengths import (
    anthropometric_ratios,
    estimate_link_lengths,
    pixels_per_mm,
    raise_short_links,
)
from mocapkit.tracking.mono.stick import stick_model


def _projected(rng: np.random.Generator, true: np.ndarray, t: int, parallel: bool) -> np.ndarray:
    """Projected lengths of links turning out of the image plane by random angles."""
    ang = rng.uniform(0.2, 1.2, size=(t, true.shape[0]))
    if parallel:
        ang[rng.integers(0, t, size=true.shape[0]), np.arange(true.shape[0])] = 0.0
    return true * np.cos(ang)


def test_length_is_exact_when_the_link_is_ever_parallel() -> None:
    rng = np.random.default_rng(50)
    model = stick_model()
    true = anthropometric_ratios(model.segments) * 900.0  # px
    d = _projected(rng, true, 200, parallel=True)
    lengths, stature = estimate_link_lengths(d, model.segments, percentile=100.0)
    np.testing.assert_allclose(lengths, true)
    assert stature == pytest.approx(900.0)


def test_left_and_right_share_the_longer_and_unseen_links_take_anthropometry() -> None:
    rng = np.random.default_rng(51)
    model = stick_model()
    true = anthropometric_ratios(model.segments) * 900.0
    d = _projected(rng, true, 200, parallel=True)
    i_l, i_r = model.link_index("left_forearm"), model.link_index("right_forearm")
    d[:, i_r] *= 0.95  # the right forearm never quite parallel
    i_h = model.link_index("head")
    d[:, i_h] = np.nan  # the head is never seen
    i_ul, i_ur = model.link_index("left_upper_arm"), model.link_index("right_upper_arm")
    d[:, [i_ul, i_ur]] *= 0.5  # both upper arms always point far out of the image
    i_t = model.link_index("trunk")
    d[:, i_t] *= 0.8  # the trunk keeps what the video shows
    lengths, stature = estimate_link_lengths(d, model.segments, percentile=100.0, slack=0.15)
    assert lengths[i_r] == pytest.approx(true[i_l])
    assert lengths[i_h] == pytest.approx(true[i_h])
    assert lengths[i_ul] == pytest.approx(true[i_ul])
    assert lengths[i_t] == pytest.approx(0.8 * true[i_t])
    assert stature == pytest.approx(900.0)
    assert pixels_per_mm(stature, 1800.0) == pytest.approx(0.5)


def test_bad_arguments_are_refused() -> None:
    model = stick_model()
    with pytest.raises(ShapeError, match="projected"):
        estimate_link_lengths(np.ones((5, 3)), model.segments)
    with pytest.raises(ConfigError, match="percentile"):
        estimate_link_lengths(np.ones((5, model.n_links)), model.segments, percentile=0.0)


def test_short_links_move_part_of_the_way_to_the_proportions() -> None:
    model = stick_model()
    segs = model.segments
    ratios = anthropometric_ratios(segs)
    stature = 1600.0
    lengths = ratios * stature
    i_fore = segs.index("left_forearm")
    i_upper = segs.index("right_upper_arm")
    i_trunk = segs.index("trunk")
    lengths[i_fore] *= 0.8  # too short: raised
    lengths[i_upper] *= 1.1  # too long: kept
    lengths[i_trunk] *= 0.8  # steady: kept
    got = raise_short_links(lengths, segs, weight=0.5)
    # the median of lengths / ratios is still the stature (6 of 8 links are exact)
    want = lengths.copy()
    want[i_fore] = ratios[i_fore] * stature * 0.9
    want *= lengths.sum() / want.sum()
    np.testing.assert_allclose(got, want, rtol=1e-12)
    np.testing.assert_allclose(got.sum(), lengths.sum(), rtol=1e-12)
    np.testing.assert_array_equal(raise_short_links(lengths, segs, weight=0.0), lengths)
    with pytest.raises(ConfigError, match="weight"):
        raise_short_links(lengths, segs, weight=1.5)
    with pytest.raises(ShapeError, match="positive lengths"):
        raise_short_links(lengths[:3], segs)
