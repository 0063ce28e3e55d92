"""Imperfections that make synthetic sessions look like recordings: scene, optics, sensor, markers.

All randomness comes from an explicit seeded `numpy.random.Generator`. The scene is a
room drawn in 3-D once per camera (tiled floor at z = 0, a back wall with posters and
shelves, boxes on the floor) so that stereo views agree; then per frame a lighting
gradient, mild motion blur, a slight defocus and Gaussian sensor noise. Markers get
Gaussian noise, runs of drop-outs (NaN) and jittered time stamps.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.camera.projection import project
from mocapkit.synth.options import RealismOptions
from mocapkit.synth.render import CameraRenderer

FloatArray = NDArray[np.float64]
# ====================================================================== time stamps


def jittered_times(
    n: int, rate_hz: float, jitter_s: float, rng: np.random.Generator, start_s: float = 0.0
) -> FloatArray:
    """``n`` strictly increasing time stamps near ``start_s + k / rate_hz`` (s).

    The jitter is Gaussian, clipped to a quarter of the interval so order is kept.
    """
    dt = 1.0 / rate_hz
    t: FloatArray = start_s + np.arange(n, dtype=np.float64) * dt
    if jitter_s > 0:
        t = t + np.clip(rng.normal(0.0, jitter_s, n), -0.25 * dt, 0.25 * dt)
    return t


# ====================================================================== markers


def corrupt_markers(
    markers_mm: FloatArray,
    rate_hz: float,
    opts: RealismOptions,
    rng: np.random.Generator,
) -> FloatArray:
    """Noisy markers (T, M, 3) with drop-out runs set to NaN.

    Parameters
    ----------
    markers_mm : (T, M, 3) float array
        Clean marker positions (mm).
    rate_hz : float
        Marker rate, to turn ``opts.dropout_s`` into frames.
    """
    out = markers_mm + rng.normal(0.0, opts.marker_noise_mm, markers_mm.shape)
    n_t, n_m = markers_mm.shape[:2]
    if opts.dropout > 0 and opts.dropout_s > 0:
        mean_len = max(1.0, opts.dropout_s * rate_hz)
        starts = rng.random((n_t, n_m)) < opts.dropout
        for t0, m in zip(*np.nonzero(starts)):
            length = int(rng.geometric(1.0 / mean_len))
            out[t0 : t0 + length, m] = np.nan
    return out


# ====================================================================== background


def _room_polygons(
    rng: np.random.Generator, centre: FloatArray, fwd: FloatArray
) -> list[tuple[FloatArray, tuple[int, int, int]]]:
    """3-D polygons (N, 3) with colours: back wall, posters and boxes behind the subject."""
    right = np.cross(fwd, np.array([0.0, 0.0, 1.0]))
    up = np.array([0.0, 0.0, 1.0])
    wall_d = 2200.0 + rng.uniform(0, 800)
    wall_c = centre - wall_d * fwd
    polys: list[tuple[FloatArray, tuple[int, int, int]]] = []

    def rgb(values: ArrayLike) -> tuple[int, int, int]:
        a, b, c = (int(v) for v in np.ravel(values)[:3])
        return (a, b, c)

    def quad(c: FloatArray, u: FloatArray, v: FloatArray) -> FloatArray:
        return np.array([c - u - v, c + u - v, c + u + v, c - u + v])

    wall_col = rgb(rng.integers(150, 215, 3))
    polys.append((quad(wall_c + 2500 * up, 6000 * right, 2500 * up), wall_col))
    # side walls so that wide views do not see the void
    for s in (-1.0, 1.0):
        c = centre + s * 4500 * right + 3000 * fwd - wall_d * 0.5 * fwd
        polys.append(
            (
                quad(c + 2500 * up, (3000 + wall_d) * fwd, 2500 * up),
                rgb(0.85 * np.array(wall_col)),
            )
        )
    # posters and shelves on the back wall
    for _ in range(int(rng.integers(6, 11))):
        x = rng.uniform(-3500, 3500)
        z = rng.uniform(900, 2300)
        w, h = rng.uniform(150, 600), rng.uniform(150, 600)
        poster = rgb(rng.integers(20, 240, 3))
        c = wall_c - 5 * fwd + x * right + z * up
        polys.append((quad(c, 0.5 * w * right, 0.5 * h * up), poster))
    # boxes and cabinets on the floor, in front of the wall
    for _ in range(int(rng.integers(3, 7))):
        x = rng.uniform(-3500, 3500)
        if abs(x) < 700:
            x += np.sign(x + 1e-9) * 900  # keep the area right behind the subject clearer
        w, d, h = rng.uniform(300, 900), rng.uniform(300, 600), rng.uniform(300, 1400)
        col = np.array(rng.integers(30, 200, 3), dtype=float)
        base = wall_c + (0.5 * d + 10) * fwd + x * right
        front = base + 0.5 * d * fwd
        top = base + h * up
        polys.append((quad(front + 0.5 * h * up, 0.5 * w * right, 0.5 * h * up), rgb(col)))
        polys.append(
            (
                quad(top, 0.5 * w * right, 0.5 * d * fwd),
                rgb(np.minimum(255, col * 1.25)),
            )
        )
    return polys


def render_background(
    renderer: CameraRenderer,
    centre_mm: FloatArray,
    forward: FloatArray,
    kind: str,
    rng: np.random.Generator,
) -> NDArray[np.uint8]:
    """The static scene for one camera, as an ideal-camera canvas (H', W', 3) uint8.

    Parameters
    ----------
    renderer : CameraRenderer
    centre_mm : (3,) float array
        Subject position on the floor (mm).
    forward : (3,) float array
        Horizontal direction the subject faces (towards the cameras).
    kind : {"textured", "plain"}
    rng : numpy.random.Generator
        Seeds the room; the same generator state gives the same room in every view when
        the caller passes a generator made from the same seed.
    """
    w, h = renderer.canvas_size
    fwd = np.asarray(forward, dtype=float)
    if kind == "plain":
        return np.full((h, w, 3), 170, np.uint8)
    canvas = np.empty((h, w, 3), np.uint8)
    canvas[:] = (150, 150, 150)
    # tiled floor: a chequer of 500 mm tiles drawn as 3-D quads
    right = np.cross(fwd, np.array([0.0, 0.0, 1.0]))
    floor_a = np.array(rng.integers(90, 150, 3), dtype=float)
    floor_b = floor_a * 0.82
    tile = 500.0
    for i in range(-12, 13):
        for j in range(-10, 14):
            c = (
                np.asarray(centre_mm, dtype=float) * np.array([1, 1, 0])
                + i * tile * right
                + j * tile * fwd
            )
            corners = np.array([c, c + tile * right, c + tile * right + tile * fwd, c + tile * fwd])
            _fill_world_polygon(
                renderer,
                canvas,
                corners,
                tuple(int(v) for v in (floor_a if (i + j) % 2 else floor_b)),
            )
    for poly, col in _room_polygons(
        rng, np.asarray(centre_mm, dtype=float) * np.array([1, 1, 0]), fwd
    ):
        _fill_world_polygon(renderer, canvas, poly, col)
    # low-frequency texture (stains, shading) and fine grain
    small = rng.normal(0.0, 1.0, (h // 24 + 2, w // 24 + 2, 1)).astype(np.float32)
    blotch = cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)[..., None]
    grain = rng.normal(0.0, 1.0, (h, w, 1)).astype(np.float32)
    tex = canvas.astype(np.float32) * (1.0 + 0.08 * blotch) + 6.0 * grain
    return np.asarray(np.clip(tex, 0, 255), dtype=np.uint8)


def _fill_world_polygon(
    renderer: CameraRenderer,
    canvas: NDArray[np.uint8],
    corners_mm: FloatArray,
    colour: tuple[int, ...],
) -> None:
    """Fill a planar convex 3-D polygon, clipped against the plane z_camera = 100 mm."""
    pc = renderer.camera.to_camera(corners_mm)
    near = 100.0
    clipped: list[FloatArray] = []
    n = len(pc)
    for i in range(n):
        a, b = pc[i], pc[(i + 1) % n]
        if a[2] >= near:
            clipped.append(a)
        if (a[2] >= near) != (b[2] >= near):
            s = (near - a[2]) / (b[2] - a[2])
            clipped.append(a + s * (b - a))
    if len(clipped) < 3:
        return
    p = np.array(clipped)
    pix = np.clip(project(renderer.canvas_arrays, p, in_world=False), -1e5, 1e5)
    cv2.fillConvexPoly(
        canvas,
        np.round(pix * 4).astype(np.int32),
        tuple(int(c) for c in colour[:3]),
        cv2.LINE_AA,
        2,
    )


# ====================================================================== per-frame optics


def lighting_field(image_size: tuple[int, int], rng: np.random.Generator) -> NDArray[np.float32]:
    """A multiplicative lighting gradient with vignetting, shape (H, W, 1), about 0.75-1.1."""
    w, h = image_size
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    xn = (xs - w / 2) / (w / 2)
    yn = (ys - h / 2) / (h / 2)
    angle = rng.uniform(0, 2 * np.pi)
    grad = 0.12 * (np.cos(angle) * xn + np.sin(angle) * yn)
    vignette = 1.0 - 0.12 * (xn**2 + yn**2) / 2
    return np.asarray((1.0 + grad) * vignette, dtype=np.float32)[..., None]


def finish_frame(
    image: NDArray[np.uint8],
    lighting: NDArray[np.float32],
    noise_sigma: float,
    rng: np.random.Generator,
) -> NDArray[np.uint8]:
    """Lighting, slight defocus and sensor noise on a rendered (distorted) image."""
    soft = cv2.GaussianBlur(image, (3, 3), 0.6)
    f = soft.astype(np.float32) * lighting
    if noise_sigma > 0:
        f += rng.standard_normal(f.shape, dtype=np.float32) * np.float32(noise_sigma)
    return np.asarray(np.clip(f, 0, 255), dtype=np.uint8)
