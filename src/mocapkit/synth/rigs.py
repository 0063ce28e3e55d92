"""Camera rigs of synthetic sessions: a mono camera and a robot-head stereo pair facing the subject.

Every rig is placed relative to the subject at the start of the excerpt: ``subject_mm`` is
the pelvis position on the floor plane and ``forward`` the horizontal direction the subject
faces. Cameras are built with `look_at` and `intrinsics_from_fov` and get a mild barrel
distortion typical of small machine-vision lenses (k1 about -0.1), which the renderer
applies consistently (see `mocapkit.synth.render`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from mocapkit.camera.pinhole import Camera, intrinsics_from_fov, look_at
from mocapkit.errors import ShapeError, unknown_name
from mocapkit.synth.options import RIG_NAMES

#: Horizontal field of view (degrees): a 1.8 m subject fills about 3/4 of a 4:3 image at 3 m.
HORIZONTAL_FOV_DEG = 62.0
#: Mono camera: distance in front of the subject (mm), as in a single-webcam set-up.
MONO_DISTANCE_MM = 3000.0
#: Stereo pair: distance (mm) and baseline (mm) of a humanoid robot head (Azad et al. 2008).
STEREO_DISTANCE_MM = 2700.0
STEREO_BASELINE_MM = 90.0
#: The stereo head sits this far (degrees) around the subject from the mono camera, so that
#: the ``all`` rig gives two distinct viewpoints.
STEREO_AZIMUTH_DEG = 15.0
#: The ``multi`` rig's fourth camera, ``side``: this far (degrees) around the subject on the
#: other side of the mono camera, at the mono camera's distance and height.
SIDE_AZIMUTH_DEG = -45.0
#: The ``ring`` rig: cameras ``ring1`` ... around the subject as a lab rings a capture
#: volume: this many, evenly spaced, the first this far (degrees) around from the front,
#: at this distance (mm) and lens height (mm), each aimed at the subject's hips.
RING_CAMERAS = 4
RING_FIRST_AZIMUTH_DEG = 45.0
RING_DISTANCE_MM = 4000.0
RING_HEIGHT_MM = 1700.0
#: Nominal lens distortion ``k1, k2, p1, p2, k3`` (mild barrel), jittered per camera.
NOMINAL_DIST = np.array([-0.10, 0.03, 0.0, 0.0, 0.0])


def _distortion(rng: np.random.Generator) -> np.ndarray:
    d = NOMINAL_DIST.copy()
    d[0] += rng.uniform(-0.02, 0.02)
    d[1] += rng.uniform(-0.01, 0.01)
    d[2:4] = rng.uniform(-5e-4, 5e-4, size=2)
    return d


def make_rig(
    rig: str,
    subject_mm: ArrayLike,
    forward: ArrayLike,
    chest_height_mm: float,
    image_size: tuple[int, int] = (640, 480),
    rng: np.random.Generator | None = None,
) -> list[Camera]:
    """Cameras of a named rig looking at a subject.

    Parameters
    ----------
    rig : {"mono", "stereo", "all", "multi", "ring"}
        ``mono``: one camera named ``mono`` about 3 m in front of the subject at chest
        height. ``stereo``: ``stereo_left`` and ``stereo_right``, 90 mm apart with parallel
        optical axes, about 2.7 m away at head height. ``all``: both. ``multi``: both and
        a fourth camera ``side`` like ``mono`` but 45 degrees around the subject the other
        way (for trackers over more than three views). ``ring``: `RING_CAMERAS` cameras
        ``ring1``, ``ring2``, ... evenly around the subject (`RING_DISTANCE_MM` away,
        `RING_HEIGHT_MM` high, the first `RING_FIRST_AZIMUTH_DEG` from the front), each
        aimed at the hips.
    subject_mm : array_like, shape (3,)
        Subject position (pelvis) in the world, mm; only x and y are used.
    forward : array_like, shape (3,)
        Direction the subject faces; its horizontal part is used.
    chest_height_mm : float
        Height of the chest above the floor (z = 0), mm.
    image_size : (int, int)
        Width and height in pixels.
    rng : numpy.random.Generator, optional
        Jitters the lens distortion per camera; the nominal lens when omitted.

    Returns
    -------
    list of Camera
    """
    if rig not in RIG_NAMES:
        raise unknown_name("rig", rig, RIG_NAMES, "--rig")
    base = np.array([float(v) for v in np.ravel(subject_mm)[:2]] + [0.0])
    fwd = np.asarray(forward, dtype=float).copy()
    fwd[2] = 0.0
    n = np.linalg.norm(fwd)
    if not np.isfinite(n) or n < 1e-9:
        raise ShapeError(f"make_rig: forward direction {forward!r} has no horizontal part")
    fwd /= n
    k = intrinsics_from_fov(image_size, HORIZONTAL_FOV_DEG)
    cams: list[Camera] = []

    def dist() -> np.ndarray:
        return _distortion(rng) if rng is not None else NOMINAL_DIST.copy()

    if rig in ("mono", "all", "multi"):
        eye = base + MONO_DISTANCE_MM * fwd + np.array([0.0, 0.0, chest_height_mm])
        target = base + np.array([0.0, 0.0, chest_height_mm - 150.0])
        cams.append(Camera("mono", image_size, k, dist(), look_at(eye, target)))
    if rig in ("stereo", "all", "multi"):
        a = np.radians(STEREO_AZIMUTH_DEG)
        c, s = np.cos(a), np.sin(a)
        dirn = np.array([c * fwd[0] - s * fwd[1], s * fwd[0] + c * fwd[1], 0.0])
        height = chest_height_mm + 200.0
        centre = base + STEREO_DISTANCE_MM * dirn + np.array([0.0, 0.0, height])
        target = base + np.array([0.0, 0.0, chest_height_mm - 250.0])
        view = look_at(centre, target)
        right_axis = view[0, :3]  # camera x axis in the world
        for name, side in (("stereo_left", -0.5), ("stereo_right", 0.5)):
            eye = centre + side * STEREO_BASELINE_MM * right_axis
            m = view.copy()
            m[:3, 3] = -view[:3, :3] @ eye  # parallel axes, shifted along the baseline
            cams.append(Camera(name, image_size, k, dist(), m))
    if rig == "multi":
        a = np.radians(SIDE_AZIMUTH_DEG)
        c, s = np.cos(a), np.sin(a)
        dirn = np.array([c * fwd[0] - s * fwd[1], s * fwd[0] + c * fwd[1], 0.0])
        eye = base + MONO_DISTANCE_MM * dirn + np.array([0.0, 0.0, chest_height_mm])
        target = base + np.array([0.0, 0.0, chest_height_mm - 150.0])
        cams.append(Camera("side", image_size, k, dist(), look_at(eye, target)))
    if rig == "ring":
        target = base + np.array([0.0, 0.0, chest_height_mm - 400.0])
        for i in range(RING_CAMERAS):
            a = np.radians(RING_FIRST_AZIMUTH_DEG + 360.0 * i / RING_CAMERAS)
            c, s = np.cos(a), np.sin(a)
            dirn = np.array([c * fwd[0] - s * fwd[1], s * fwd[0] + c * fwd[1], 0.0])
            eye = base + RING_DISTANCE_MM * dirn + np.array([0.0, 0.0, RING_HEIGHT_MM])
            cams.append(Camera(f"ring{i + 1}", image_size, k, dist(), look_at(eye, target)))
    return cams
