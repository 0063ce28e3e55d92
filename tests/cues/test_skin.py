"""Skin colour, shirt-colour figure-ground and the [0, 1] gradient map (Azad §II-B)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from mocapkit.cues.skin import (
    DEFAULT_SKIN,
    ColourModel,
    GradientConfig,
    colour_mask,
    figure_mask,
    fit_shirt_model,
    gradient_map,
    gradient_vector_map,
    shirt_mask,
    skin_mask,
    ycrcb_from_bgr,
)
from mocapkit.errors import ConfigError, ShapeError
from mocapkit.io.session import load_session
from mocapkit.synth.realism import RealismOptions
from mocapkit.synth.render import _NAMED_COLOURS_BGR, _SKIN_TONES_BGR
from mocapkit.synth.session_writer import SynthOptions, synthesize_session


def test_ycrcb_matches_opencv():
    rng = np.random.default_rng(0)
    colours = rng.integers(0, 256, size=(500, 3)).astype(np.uint8)
    ours = ycrcb_from_bgr(colours)
    cv = cv2.cvtColor(colours.reshape(-1, 1, 3), cv2.COLOR_BGR2YCrCb).reshape(-1, 3)
    assert np.max(np.abs(ours - cv)) <= 1.0


@pytest.mark.parametrize("shade", [0.7, 1.0, 1.15])
def test_default_skin_accepts_every_rendered_tone_and_shading(shade):
    tones = np.clip(np.asarray(_SKIN_TONES_BGR, float) * shade, 0, 255)
    assert np.all(DEFAULT_SKIN.accepts(tones))


def test_default_skin_refuses_shirts_and_achromatic_colours():
    shirts = np.asarray(list(_NAMED_COLOURS_BGR.values()), float)
    for shade in (0.7, 1.0):
        assert not np.any(DEFAULT_SKIN.accepts(shirts * shade))


def test_mask_equals_accepts_per_pixel():
    rng = np.random.default_rng(1)
    img = rng.integers(0, 256, size=(40, 50, 3)).astype(np.uint8)
    # a patch of skin so that both classes occur
    img[10:20, 10:20] = _SKIN_TONES_BGR[1]
    m = colour_mask(img, DEFAULT_SKIN)
    # OpenCV's integer YCrCb rounds; the pixels whose float chroma lies within half a
    # level of the acceptance border may differ, so compare with OpenCV's own values
    ycc = cv2.cvtColor(img, cv2.COLOR_BGR2YCrCb).astype(int)
    lo, hi = DEFAULT_SKIN.luma_range
    expect = (
        (DEFAULT_SKIN.table[ycc[..., 1], ycc[..., 2]] > 0)
        & (ycc[..., 0] >= lo)
        & (ycc[..., 0] <= hi)
    )
    np.testing.assert_array_equal(m > 0, expect)
    assert np.all(m[10:20, 10:20] == 255)


def test_roi_restricts_the_work():
    img = np.full((30, 30, 3), _SKIN_TONES_BGR[0], dtype=np.uint8)
    m = skin_mask(img, roi=(5, 6, 20, 25), open_px=0)
    assert m[6:25, 5:20].all() and m.sum() == 255 * 19 * 15


def test_fit_learns_a_colour_and_its_spread():
    rng = np.random.default_rng(2)
    base = np.array([170.0, 90.0, 40.0])  # blue shirt (BGR)
    samples = base + rng.normal(0, 6, size=(2000, 3))
    model = ColourModel.fit(samples)
    ycc = ycrcb_from_bgr(samples)
    np.testing.assert_allclose(model.mean_crcb, ycc[:, 1:].mean(axis=0), atol=1e-9)
    assert model.accepts(samples).mean() > 0.95
    assert not model.accepts(np.asarray(_SKIN_TONES_BGR, float)).any()


def test_model_refusals():
    with pytest.raises(ConfigError, match="positive definite"):
        ColourModel((150.0, 110.0), ((1.0, 2.0), (2.0, 1.0)))
    with pytest.raises(ConfigError, match="luma_range"):
        ColourModel((150.0, 110.0), ((1.0, 0.0), (0.0, 1.0)), luma_range=(200.0, 100.0))
    with pytest.raises(ShapeError, match="BGR uint8"):
        skin_mask(np.zeros((4, 4), np.uint8))
    with pytest.raises(ShapeError, match="at least 3"):
        ColourModel.fit(np.zeros((2, 3)))
    with pytest.raises(ConfigError, match="saturation"):
        GradientConfig(saturation=0.0)


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """One 320x240 textured, noisy frame of the built-in wave with a blue shirt."""
    out = tmp_path_factory.mktemp("skin") / "s"
    synthesize_session(
        "builtin:wave",
        out,
        SynthOptions(
            rig="mono",
            seconds=0.05,
            image_size=(320, 240),
            shirt_colour="blue",
            video_format="png",
            seed=3,
            realism=RealismOptions(blur=0.0),
        ),
    )
    s = load_session(out)
    image = next(iter(s.samples())).image()
    kp = s.keypoints["mono"]
    return image, dict(zip(kp.joint_names, kp.pixels[0]))


def _patch(mask, p, r=2):
    x, y = np.round(p).astype(int)
    return mask[y - r : y + r + 1, x - r : x + r + 1]


def test_rendered_skin_is_found_and_the_shirt_is_not(rendered):
    image, kp = rendered
    m = skin_mask(image)
    face = kp["head"] + 0.5 * (kp["neck"] - kp["head"])  # below the glasses
    assert _patch(m, face, 1).mean() > 0.8 * 255
    for side in ("left", "right"):  # the forearms (short sleeves) just above the wrists
        arm = kp[f"{side}_wrist"] + 0.2 * (kp[f"{side}_elbow"] - kp[f"{side}_wrist"])
        assert _patch(m, arm, 1).mean() > 0.5 * 255
    chest = kp["neck"] + 0.4 * (kp["pelvis"] - kp["neck"])
    assert _patch(m, chest, 4).max() == 0
    # most of the image (background, clothes) is not skin
    assert (m > 0).mean() < 0.1


def test_rendered_shirt_segments_the_figure(rendered):
    image, kp = rendered
    chest = kp["neck"] + 0.4 * (kp["pelvis"] - kp["neck"])
    region = np.zeros(image.shape[:2], np.uint8)
    x, y = np.round(chest).astype(int)
    region[y - 3 : y + 4, x - 3 : x + 4] = 1
    model = fit_shirt_model(image, region)
    sm = shirt_mask(image, model)
    below = kp["neck"] + 0.55 * (kp["pelvis"] - kp["neck"])
    assert _patch(sm, below, 3).mean() > 0.9 * 255
    assert _patch(sm, kp["head"]).max() == 0
    fig = figure_mask(sm, skin_mask(image))
    assert (fig > 0).mean() < 0.5  # the background stays out of the figure
    assert _patch(fig, kp["head"]).min() == 255


def test_gradient_map_is_in_unit_range_and_finds_a_step():
    img = np.full((60, 80), 50, np.uint8)
    img[:, 40:] = 200
    sharp = gradient_map(img, config=GradientConfig(post_blur_sigma_px=0.0))
    assert sharp[30, 39:41].max() == 1.0  # 150 grey levels saturate
    g = gradient_map(img)
    assert g.dtype == np.float32 and g.min() >= 0.0 and g.max() <= 1.0
    assert g[30, 39:41].max() > 0.5  # the blur spreads the edge into a basin
    assert np.argmax(g[30]) in (39, 40)
    assert g[30, 10] == 0.0 and g[30, 70] == 0.0


def test_gradient_map_roi_equals_full_map_inside_and_zero_outside():
    rng = np.random.default_rng(4)
    img = cv2.GaussianBlur(rng.integers(0, 256, (80, 100)).astype(np.uint8), (0, 0), 2)
    full = gradient_map(img)
    roi = (20, 15, 70, 60)
    part = gradient_map(img, roi=roi)
    np.testing.assert_allclose(part[15:60, 20:70], full[15:60, 20:70], atol=1e-6)
    outside = np.ones_like(part, bool)
    outside[15:60, 20:70] = False
    assert np.all(part[outside] == 0)


def test_gradient_map_keeps_only_the_figure():
    img = np.full((60, 80), 50, np.uint8)
    img[:, 20:25] = 200  # background edge
    img[:, 55:] = 200  # figure edge
    fig = np.zeros((60, 80), np.uint8)
    fig[:, 45:] = 255
    g = gradient_map(img, figure=fig, config=GradientConfig(post_blur_sigma_px=0.0))
    assert g[:, 15:30].max() == 0.0
    assert g[30, 54:56].max() > 0.9


def test_gradient_vector_points_across_the_edge_with_the_maps_length():
    rng = np.random.default_rng(5)
    img = cv2.GaussianBlur(rng.integers(0, 256, (60, 80)).astype(np.uint8), (0, 0), 3)
    cfg = GradientConfig(post_blur_sigma_px=0.0)
    gx, gy = gradient_vector_map(img, config=cfg)
    mag = np.hypot(gx, gy)
    np.testing.assert_allclose(mag, gradient_map(img, config=cfg), atol=1e-5)
    step = np.full((40, 60), 40, np.uint8)
    step[:, 30:] = 200  # brighter to the right: the gradient points along +x
    sx, sy = gradient_vector_map(step, config=cfg)
    assert sx[20, 29:31].max() == pytest.approx(1.0) and np.abs(sy).max() < 1e-6
