"""Colour cues of Azad et al. 2008 §II-B: skin colour, shirt-colour figure-ground, gradient map.

The paper's image pipeline (Fig. 1) turns each view into a binarised skin image (for
hand/head tracking), a figure-ground mask from the shirt colour (so that only edges of
the person count) and a gradient image remapped to ``[0, 1]`` (for the edge cue,
eq. (1)). The paper leaves the colour models to its reference [14]; the choices here:

Colour model
------------
One `ColourModel` serves skin and shirt: a 2-D Gaussian over the chroma (Cr, Cb) of
OpenCV's YCrCb (BT.601, 8 bit), accepted within a Mahalanobis radius, plus a luma
interval. Chroma is largely independent of illumination strength (the lighting
gradient and shading of a scene scale Y far more than Cr/Cb), which is why skin
detectors classically work in CrCb (Chai & Ngan 1999 use a box Cr 133-173,
Cb 77-127). A Gaussian instead of a box gives the model an orientation (skin tones
spread along a line in CrCb) and lets `ColourModel.fit` learn a subject's own skin or
shirt from pixel samples. Classification is one look-up in a 256x256 table over
(Cr, Cb) built when the model is made, so a 640x480 frame costs one colour
conversion plus one gather.

The default skin model (`DEFAULT_SKIN`) is written in two chroma axes through grey
(128, 128): *saturation* along (1, -1)/sqrt2 (grey towards skin; shading and
desaturation move skin back along it) and *hue* along (1, 1)/sqrt2. Skin of every
tone lies on a narrow hue band (light to dark skin: hue 0-3, saturation 34-25 at
full light, about 15 at 60 % light), while warm-grey walls have saturation below
about 8 and orange clothing the same hue at saturation near 90. The Gaussian has mean
saturation 35, hue 1.5, standard deviations 10 and 4, radius 2.5 (saturation
10-60, hue within 10); in (Cr, Cb) that is mean (153.8, 104.3), standard deviation
7.6 on each and correlation -0.72. Achromatic pixels (white, grey, black) and
saturated red, orange, yellow, purple clothing are refused. Pixels darker than luma
25 or brighter than 250 are refused (no reliable chroma there).

Shirt-colour segmentation
-------------------------
`fit_shirt_model` fits the same model to pixels known to be shirt (the tracker takes
them below the head at initialisation); its luma interval is the samples' 1-99 %
range widened by 40 grey levels. An achromatic shirt (white, grey, black) has the
chroma of a grey background; the luma interval is then all that separates them, so
such shirts need a background of different brightness (a documented limit).

Gradient map
------------
`gradient_map`: 3x3 Sobel magnitude of the (Gaussian low-passed) grey image divided
by a saturation value and clipped, which remaps it to ``[0, 1]`` as eq. (1) assumes;
optionally multiplied by a figure mask (edges of the person only, §II-B) and blurred
so that the edge cue has a basin a few pixels wide around each contour. Work is
restricted to a region of interest when one is given (zero outside), as the paper
computes the maps only where the arms can be.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.cues.edges import Roi, clip_roi, to_grey
from mocapkit.errors import ConfigError, ShapeError

FloatArray = NDArray[np.float64]
Float32Array = NDArray[np.float32]
UInt8Array = NDArray[np.uint8]


def _bgr(image: ArrayLike, what: str = "image") -> UInt8Array:
    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
        raise ShapeError(
            f"{what}: expected a BGR uint8 image (H, W, 3), found shape {img.shape} {img.dtype}"
        )
    return img


def ycrcb_from_bgr(samples_bgr: ArrayLike) -> FloatArray:
    """BT.601 (Y, Cr, Cb) of BGR colours (..., 3) in 0-255, as `cv2.COLOR_BGR2YCrCb` computes.

    Works on any shape of colour list (not only images), in float.
    """
    c = np.asarray(samples_bgr, dtype=float)
    if c.shape[-1:] != (3,):
        raise ShapeError(f"samples_bgr: expected colours (..., 3), found {c.shape}")
    b, g, r = c[..., 0], c[..., 1], c[..., 2]
    y = 0.299 * r + 0.587 * g + 0.114 * b
    cr = (r - y) * 0.713 + 128.0
    cb = (b - y) * 0.564 + 128.0
    return np.stack([y, cr, cb], axis=-1)


@dataclass(frozen=True, eq=False)
class ColourModel:
    """A Gaussian over chroma (Cr, Cb) with a Mahalanobis radius and a luma interval.

    Parameters
    ----------
    mean_crcb : (float, float)
        Mean chroma.
    cov_crcb : ((float, float), (float, float))
        Chroma covariance (symmetric positive definite).
    radius : float
        Accepted Mahalanobis distance.
    luma_range : (float, float)
        Accepted luma interval (inclusive), 0-255.
    """

    mean_crcb: tuple[float, float]
    cov_crcb: tuple[tuple[float, float], tuple[float, float]]
    radius: float = 2.5
    luma_range: tuple[float, float] = (25.0, 250.0)
    table: UInt8Array = field(init=False, repr=False)

    def __post_init__(self) -> None:
        cov = np.asarray(self.cov_crcb, dtype=float)
        mean = np.asarray(self.mean_crcb, dtype=float)
        if cov.shape != (2, 2) or mean.shape != (2,):
            raise ShapeError(
                f"ColourModel: expected mean (2,) and covariance (2, 2), found {mean.shape} "
                f"and {cov.shape}"
            )
        if not (np.all(np.isfinite(cov)) and np.all(np.isfinite(mean))):
            raise ShapeError("ColourModel: mean and covariance must be finite")
        if abs(cov[0, 1] - cov[1, 0]) > 1e-9 * max(1.0, abs(cov[0, 1])) or not (
            cov[0, 0] > 0 and np.linalg.det(cov) > 0
        ):
            raise ConfigError(
                f"ColourModel.cov_crcb: expected a symmetric positive definite matrix, found "
                f"{cov.tolist()}"
            )
        if not (self.radius > 0 and math.isfinite(self.radius)):
            raise ConfigError(
                f"ColourModel.radius: expected a positive number, found {self.radius}"
            )
        lo, hi = self.luma_range
        if not (0.0 <= lo <= hi <= 255.0):
            raise ConfigError(
                f"ColourModel.luma_range: expected 0 <= low <= high <= 255, found {self.luma_range}"
            )
        # 256x256 acceptance table over (Cr, Cb): one gather per pixel at run time
        grid = np.arange(256, dtype=float)
        d = np.stack(np.meshgrid(grid, grid, indexing="ij"), axis=-1) - mean
        m2 = np.einsum("...i,ij,...j->...", d, np.linalg.inv(cov), d)
        object.__setattr__(self, "table", (m2 <= self.radius**2).astype(np.uint8) * 255)

    @staticmethod
    def fit(
        samples_bgr: ArrayLike,
        radius: float = 2.5,
        luma_margin: float = 40.0,
        min_std: float = 3.0,
    ) -> ColourModel:
        """Fit the model to sample colours (N, 3) BGR.

        The covariance is floored at ``min_std**2`` per axis (noise-free samples of one
        colour would otherwise give a degenerate model), the luma interval is the
        samples' 1-99 % range widened by ``luma_margin``.
        """
        c = np.asarray(samples_bgr, dtype=float).reshape(-1, 3)
        if c.shape[0] < 3:
            raise ShapeError(f"samples_bgr: expected at least 3 colours, found {c.shape[0]}")
        ycc = ycrcb_from_bgr(c)
        chroma = ycc[:, 1:]
        mean = chroma.mean(axis=0)
        cov = np.cov(chroma.T) + np.eye(2) * min_std**2
        lo, hi = np.percentile(ycc[:, 0], [1.0, 99.0])
        return ColourModel(
            (float(mean[0]), float(mean[1])),
            ((float(cov[0, 0]), float(cov[0, 1])), (float(cov[0, 1]), float(cov[1, 1]))),
            radius,
            (float(max(lo - luma_margin, 0.0)), float(min(hi + luma_margin, 255.0))),
        )

    def accepts(self, samples_bgr: ArrayLike) -> NDArray[np.bool_]:
        """Whether each colour (..., 3) BGR is accepted (same rule as `colour_mask`)."""
        ycc = np.clip(np.rint(ycrcb_from_bgr(samples_bgr)), 0, 255).astype(np.int64)
        lo, hi = self.luma_range
        ok = (ycc[..., 0] >= lo) & (ycc[..., 0] <= hi)
        return ok & (self.table[ycc[..., 1], ycc[..., 2]] > 0)


def _skin_default() -> ColourModel:
    # axes of the chroma plane through grey (128, 128): "saturation" along (1, -1)/sqrt2
    # (from grey towards skin; shading moves skin back along it) and "hue" along
    # (1, 1)/sqrt2 (red-purple versus yellow)
    sat_axis = np.array([1.0, -1.0]) / math.sqrt(2.0)
    hue_axis = np.array([1.0, 1.0]) / math.sqrt(2.0)
    mean = 128.0 + 35.0 * sat_axis + 1.5 * hue_axis
    cov = 10.0**2 * np.outer(sat_axis, sat_axis) + 4.0**2 * np.outer(hue_axis, hue_axis)
    return ColourModel(
        (float(mean[0]), float(mean[1])),
        ((float(cov[0, 0]), float(cov[0, 1])), (float(cov[1, 0]), float(cov[1, 1]))),
        2.5,
        (25.0, 250.0),
    )


#: Default skin model (module notes).
DEFAULT_SKIN = _skin_default()


@numba.njit(cache=True)
def _classify_nb(
    ycc: UInt8Array, table: UInt8Array, luma_lo: int, luma_hi: int, out: UInt8Array
) -> None:
    """``out = table[Cr, Cb]`` where ``luma_lo <= Y <= luma_hi``, else 0 (one pass)."""
    for r in range(ycc.shape[0]):
        for c in range(ycc.shape[1]):
            y = ycc[r, c, 0]
            if luma_lo <= y <= luma_hi:
                out[r, c] = table[ycc[r, c, 1], ycc[r, c, 2]]
            else:
                out[r, c] = 0


def colour_mask(
    image_bgr: ArrayLike,
    model: ColourModel,
    roi: Roi | None = None,
    open_px: int = 0,
) -> UInt8Array:
    """Pixels of a colour model: 255 where accepted, 0 elsewhere (and outside ``roi``).

    Parameters
    ----------
    image_bgr : array_like of uint8, shape (H, W, 3)
    model : ColourModel
    roi : (x0, y0, x1, y1), optional
        Only this region is classified.
    open_px : int
        Radius of a morphological opening that removes isolated pixels (0: none).

    Returns
    -------
    ndarray of uint8, shape (H, W)
    """
    img = _bgr(image_bgr)
    h, w = img.shape[:2]
    out = np.zeros((h, w), dtype=np.uint8)
    x0, y0, x1, y1 = (0, 0, w, h) if roi is None else clip_roi(roi, (w, h))
    if x1 <= x0 or y1 <= y0:
        return out
    ycc = np.asarray(cv2.cvtColor(img[y0:y1, x0:x1], cv2.COLOR_BGR2YCrCb), dtype=np.uint8)
    lo, hi = model.luma_range
    m = np.empty(ycc.shape[:2], dtype=np.uint8)
    _classify_nb(ycc, model.table, math.ceil(lo), math.floor(hi), m)
    if open_px > 0:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * open_px + 1, 2 * open_px + 1))
        m = np.asarray(cv2.morphologyEx(m, cv2.MORPH_OPEN, k), dtype=np.uint8)
    out[y0:y1, x0:x1] = m
    return out


def skin_mask(
    image_bgr: ArrayLike,
    model: ColourModel | None = None,
    roi: Roi | None = None,
    open_px: int = 1,
) -> UInt8Array:
    """Binarised skin image ``I_s`` (Azad §II-B): 255 on skin, 0 elsewhere, shape (H, W).

    ``model`` defaults to `DEFAULT_SKIN`; see `colour_mask` for the other parameters.
    """
    return colour_mask(image_bgr, DEFAULT_SKIN if model is None else model, roi, open_px)


def fit_shirt_model(
    image_bgr: ArrayLike, region: ArrayLike, radius: float = 3.0, luma_margin: float = 40.0
) -> ColourModel:
    """Shirt colour model from the pixels of a region known to be shirt.

    Parameters
    ----------
    image_bgr : array_like of uint8, shape (H, W, 3)
    region : array_like, shape (H, W)
        Non-zero on the sample pixels (e.g. a patch below the head).
    radius, luma_margin : float
        See `ColourModel.fit`.
    """
    img = _bgr(image_bgr)
    r = np.asarray(region)
    if r.shape != img.shape[:2]:
        raise ShapeError(f"region: expected shape {img.shape[:2]}, found {r.shape}")
    samples = img[r != 0]
    if samples.shape[0] < 3:
        raise ShapeError(f"region: expected at least 3 shirt pixels, found {samples.shape[0]}")
    return ColourModel.fit(samples, radius=radius, luma_margin=luma_margin)


def shirt_mask(
    image_bgr: ArrayLike, model: ColourModel, roi: Roi | None = None, open_px: int = 1
) -> UInt8Array:
    """Figure-ground segmentation by shirt colour (Azad §II-B): 255 on the shirt, (H, W)."""
    return colour_mask(image_bgr, model, roi, open_px)


def figure_mask(*masks: ArrayLike, grow_px: int = 6) -> UInt8Array:
    """Union of masks (skin, shirt, ...), dilated by ``grow_px`` so that the contour's
    own edge (half inside, half outside the figure) is kept; 255 on the figure."""
    if not masks:
        raise ShapeError("figure_mask: expected at least one mask")
    first = np.asarray(masks[0])
    out = np.zeros(first.shape, dtype=np.uint8)
    for m in masks:
        a = np.asarray(m)
        if a.shape != first.shape:
            raise ShapeError(f"figure_mask: masks differ in shape, {first.shape} and {a.shape}")
        out |= np.where(a != 0, 255, 0).astype(np.uint8)
    if grow_px > 0:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * grow_px + 1, 2 * grow_px + 1))
        out = np.asarray(cv2.dilate(out, k), dtype=np.uint8)
    return out


@dataclass(frozen=True)
class GradientConfig:
    """Parameters of `gradient_map`.

    Parameters
    ----------
    pre_blur_ksize : int
        Odd Gaussian low-pass before Sobel (noise suppression; 1 = none).
    saturation : float
        Magnitude of OpenCV's unnormalised 3x3 Sobel that maps to 1 (a sharp step of
        D grey levels gives 4 D, so 160 is a step of 40 grey levels); larger ones are
        clipped (eq. (1) needs ``[0, 1]``).
    post_blur_sigma_px : float
        Gaussian blur of the remapped map (0 = none): a basin around each contour.
    """

    pre_blur_ksize: int = 3
    saturation: float = 160.0
    post_blur_sigma_px: float = 1.5

    def __post_init__(self) -> None:
        if self.pre_blur_ksize < 1 or self.pre_blur_ksize % 2 == 0:
            raise ConfigError(
                f"GradientConfig.pre_blur_ksize: expected a positive odd size, found "
                f"{self.pre_blur_ksize}"
            )
        if not (self.saturation > 0 and math.isfinite(self.saturation)):
            raise ConfigError(
                f"GradientConfig.saturation: expected a positive number, found {self.saturation}"
            )
        if not (self.post_blur_sigma_px >= 0 and math.isfinite(self.post_blur_sigma_px)):
            raise ConfigError(
                "GradientConfig.post_blur_sigma_px: expected a number >= 0, found "
                f"{self.post_blur_sigma_px}"
            )


@numba.njit(cache=True)
def _remap_nb(
    gx: Float32Array,
    gy: Float32Array,
    keep: UInt8Array,
    masked: bool,
    inv_sat: float,
    oriented: bool,
) -> None:
    """In place: oriented, ``(gx, gy) * inv_sat / max(|g| inv_sat, 1)``; else ``gx :=
    min(|g| inv_sat, 1)``; 0 where ``masked`` and ``keep == 0``."""
    for r in range(gx.shape[0]):
        for c in range(gx.shape[1]):
            if masked and keep[r, c] == 0:
                gx[r, c] = 0.0
                gy[r, c] = 0.0
                continue
            x = gx[r, c] * inv_sat
            y = gy[r, c] * inv_sat
            m = math.sqrt(x * x + y * y)
            if oriented:
                f = 1.0 / m if m > 1.0 else 1.0
                gx[r, c] = x * f
                gy[r, c] = y * f
            else:
                gx[r, c] = m if m < 1.0 else 1.0


def _gradient_core(
    image: ArrayLike,
    roi: Roi | None,
    figure: ArrayLike | None,
    config: GradientConfig,
    oriented: bool,
    out: tuple[Float32Array, ...] | None = None,
) -> tuple[Float32Array, Float32Array | None]:
    cfg = config
    grey = to_grey(np.asarray(image))
    h, w = grey.shape
    n_out = 2 if oriented else 1
    if out is None:
        outs = [np.zeros((h, w), dtype=np.float32) for _ in range(n_out)]
    else:
        if len(out) != n_out or any(o.shape != (h, w) or o.dtype != np.float32 for o in out):
            raise ShapeError(
                f"out: expected {n_out} float32 array(s) of shape {(h, w)}, found "
                f"{[(o.shape, o.dtype) for o in out]}"
            )
        outs = list(out)
        for o in outs:
            o.fill(0.0)
    x0, y0, x1, y1 = (0, 0, w, h) if roi is None else clip_roi(roi, (w, h))
    if x1 <= x0 or y1 <= y0:
        return outs[0], (outs[1] if oriented else None)
    # a margin so that the blurs and Sobel see real neighbours at the RoI's border
    r_post = math.ceil(3 * cfg.post_blur_sigma_px)
    m = cfg.pre_blur_ksize // 2 + 1 + r_post
    cx0, cy0, cx1, cy1 = max(x0 - m, 0), max(y0 - m, 0), min(x1 + m, w), min(y1 + m, h)
    crop = grey[cy0:cy1, cx0:cx1]
    if cfg.pre_blur_ksize > 1:
        k = (cfg.pre_blur_ksize, cfg.pre_blur_ksize)
        crop = np.asarray(cv2.GaussianBlur(crop, k, 0), dtype=np.uint8)
    gx = np.asarray(cv2.Sobel(crop, cv2.CV_32F, 1, 0, ksize=3), dtype=np.float32)
    gy = np.asarray(cv2.Sobel(crop, cv2.CV_32F, 0, 1, ksize=3), dtype=np.float32)
    if figure is not None:
        f = np.asarray(figure)
        if f.shape != (h, w):
            raise ShapeError(f"figure: expected shape {(h, w)}, found {f.shape}")
        keep = np.ascontiguousarray(f[cy0:cy1, cx0:cx1], dtype=np.uint8)
    else:
        keep = np.full((1, 1), 255, np.uint8)
    # one compiled pass: remap to [0, 1] (the vector's length like the magnitude), mask
    _remap_nb(gx, gy, keep, figure is not None, float(1.0 / cfg.saturation), oriented)
    comps = [gx, gy] if oriented else [gx]
    k_post = (2 * r_post + 1, 2 * r_post + 1)
    for c, target in zip(comps, outs):
        if cfg.post_blur_sigma_px > 0:
            c = np.asarray(cv2.GaussianBlur(c, k_post, cfg.post_blur_sigma_px), dtype=np.float32)
        target[y0:y1, x0:x1] = c[y0 - cy0 : y1 - cy0, x0 - cx0 : x1 - cx0]
    if not oriented:
        np.clip(outs[0], 0.0, 1.0, out=outs[0])
    return outs[0], (outs[1] if oriented else None)


def gradient_map(
    image: ArrayLike,
    roi: Roi | None = None,
    figure: ArrayLike | None = None,
    config: GradientConfig | None = None,
    out: Float32Array | None = None,
) -> Float32Array:
    """Gradient image ``I_g`` remapped to ``[0, 1]`` (Azad §II-B, eq. (1)), shape (H, W).

    Parameters
    ----------
    image : array_like of uint8, shape (H, W) or (H, W, 3)
        Grey or BGR frame.
    roi : (x0, y0, x1, y1), optional
        Only this region is computed; 0 elsewhere.
    figure : array_like, shape (H, W), optional
        Figure mask (`figure_mask`): gradients outside it are set to 0 (edges of the
        background do not count).
    config : GradientConfig, optional
    out : ndarray of float32, shape (H, W), optional
        Written in place (and returned) instead of a new array.

    Returns
    -------
    ndarray of float32, shape (H, W), values in [0, 1]
    """
    o = None if out is None else (out,)
    return _gradient_core(image, roi, figure, config or GradientConfig(), False, o)[0]


def gradient_vector_map(
    image: ArrayLike,
    roi: Roi | None = None,
    figure: ArrayLike | None = None,
    config: GradientConfig | None = None,
    out: tuple[Float32Array, Float32Array] | None = None,
) -> tuple[Float32Array, Float32Array]:
    """The gradient as a vector field whose length is remapped like `gradient_map`'s.

    ``(gx, gy)``, each (H, W) float32 with ``|(gx, gy)| <= 1``: the Sobel gradient scaled
    by ``1 / saturation`` and shortened to length 1 where it is longer, masked and
    blurred as `gradient_map` (same parameters). Reading ``|g . n|`` with ``n`` the unit
    normal of a model outline scores only edges that run along it (an extension of
    eq. (1); `mocapkit.tracking.stereo.arm_filter`). ``out``: two (H, W) float32
    arrays written in place instead of new ones.
    """
    gx, gy = _gradient_core(image, roi, figure, config or GradientConfig(), True, out)
    return gx, (np.zeros_like(gx) if gy is None else gy)


__all__ = [
    "DEFAULT_SKIN",
    "ColourModel",
    "GradientConfig",
    "colour_mask",
    "figure_mask",
    "fit_shirt_model",
    "gradient_map",
    "gradient_vector_map",
    "shirt_mask",
    "skin_mask",
    "ycrcb_from_bgr",
]
