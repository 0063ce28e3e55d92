"""Is a camera plausible for the data it comes with? Checked before any tracker runs.

One set of checks for every tracker (hybrid, stereo / multi-view, mono); each looks only at
what the data allow:

- **intrinsics** (`intrinsic_findings`): the principal point inside the image, square-ish
  pixels (``fx`` and ``fy`` within a factor `MAX_PIXEL_ASPECT`);
- **the subject in front of the camera and inside its image** (`sees_findings`), from 3-D
  points of the subject that the session gives independently of the camera (the
  hybrid's marker sets);
- **2-D detections inside the image** (`keypoint_findings`);
- **views that agree** (`view_findings`, two or more cameras with 2-D keypoints): the
  confident joints of the first frames are triangulated from all views; the points must
  lie in front of every camera, reproject onto every view's keypoints (a pair of swapped
  keypoint files or swapped extrinsics gives errors of tens to hundreds of px, or points
  behind the cameras) and give the subject's limb lengths (a translation in metres makes
  the subject a thousand times smaller, doubled ``fx`` and ``fy`` about half as tall);
- **the floor** (`view_floor_findings`, two or more views; `floor_findings` on the mono
  result): the ankles near the world's z = 0, a warning only (doubled ``fx`` and ``fy``
  on a parallel pair agree with every other check, and sink the subject below it);
- **the subject upright** (`view_up_findings`, two or more views): the neck above the
  ankles along the world's +z, a warning only (a world whose z points down or along the
  floor).

Each check returns `CameraFinding` items; `refuse_or_warn` raises `SessionError` for the
refusals and hands the warnings to a callback. Thresholds are wide: they catch a wrong
unit, a swap or a turned camera, never a calibration that is merely imperfect.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.camera.triangulation import reprojection_errors_px, triangulate_views
from mocapkit.errors import SessionError

FloatArray = NDArray[np.float64]

#: Largest ratio between ``fx`` and ``fy`` taken as square pixels (anamorphic lenses
#: aside, calibrations give 1.00-1.02).
MAX_PIXEL_ASPECT = 1.25
#: Share of 2-D detections (or marker-set positions) that must fall inside the image
#: (with `IMAGE_MARGIN` of its size around it) and of triangulated points in front of a
#: camera.
MIN_SHARE = 0.5
#: Margin around the image, as a share of its width and height, within which a detection
#: still counts as inside (a detector may place a joint just off the frame).
IMAGE_MARGIN = 0.1
#: Frames (from the first with keypoints in two views) over which the views are compared.
VIEW_CHECK_FRAMES = 30
#: Largest median reprojection error of triangulated joints, as a share of the image
#: width (2.5 % = 16 px at 640 px; detectors err by a few px, a swap by 100s).
MAX_REPROJECTION_SHARE = 0.025
#: Plausible ratio of limb lengths seen by the views (across the line of sight, at the
#: triangulated depth) to the subject's (outside it: translations in the wrong unit, a
#: baseline or a subject's height far off).
LIMB_RATIO_RANGE = (0.6, 1.5)
#: Near-rigid pairs of canonical joints whose distance is compared with the subject's.
RIGID_PAIRS: tuple[tuple[str, str], ...] = (
    ("left_shoulder", "left_elbow"),
    ("left_elbow", "left_wrist"),
    ("right_shoulder", "right_elbow"),
    ("right_elbow", "right_wrist"),
    ("left_shoulder", "right_shoulder"),
    ("left_hip", "right_hip"),
    ("left_hip", "left_knee"),
    ("left_knee", "left_ankle"),
    ("right_hip", "right_knee"),
    ("right_knee", "right_ankle"),
    ("neck", "pelvis"),
)


@dataclass(frozen=True)
class CameraFinding:
    """One implausible thing found about a camera.

    Attributes
    ----------
    camera : str or tuple of str
        The camera's name; the names of the cameras concerned, for a check of several
        views together.
    check : str
        ``intrinsics``, ``in front``, ``in image``, ``views agree``, ``limb lengths``,
        ``floor``, ``up`` or ``scale``.
    text : str
        What was found and what was expected, with the numbers.
    refuse : bool
        True: tracking would give garbage, refuse; False: ambiguous, warn.
    """

    camera: str | tuple[str, ...]
    check: str
    text: str
    refuse: bool = True


def intrinsic_findings(camera: Camera) -> list[CameraFinding]:
    """Principal point outside the image (refused); non-square pixels (warned)."""
    k = np.asarray(camera.K)
    fx, fy, cx, cy = float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2])
    w, h = camera.image_size
    out: list[CameraFinding] = []
    if not (0.0 <= cx <= w and 0.0 <= cy <= h):
        out.append(
            CameraFinding(
                camera.name,
                "intrinsics",
                f"principal point (cx, cy) = ({cx:.1f}, {cy:.1f}) px lies outside its {w}x{h} "
                f"image; expected inside it, near ({w / 2:.0f}, {h / 2:.0f}) (K in px of this "
                "image size?)",
            )
        )
    aspect = max(fx, fy) / min(fx, fy) if min(fx, fy) > 0 else np.inf
    if aspect > MAX_PIXEL_ASPECT:
        out.append(
            CameraFinding(
                camera.name,
                "intrinsics",
                f"fx = {fx:.1f} px and fy = {fy:.1f} px differ by a factor {aspect:.2f}; "
                f"expected square pixels (within {MAX_PIXEL_ASPECT})",
                refuse=False,
            )
        )
    return out


def sees_findings(camera: Camera, points_mm: ArrayLike, what: str) -> list[CameraFinding]:
    """The subject's 3-D points (any shape (..., 3), NaN where unseen) in front of the
    camera and inside its image for at least `MIN_SHARE` of them; else refused.

    ``what`` names the points for the message (e.g. "marker-set positions in the first
    1 s"). A camera behind the subject, or whose translation was written in metres, fails.
    """
    pts = np.asarray(points_mm, dtype=float).reshape(-1, 3)
    seen = pts[np.all(np.isfinite(pts), axis=1)]
    if seen.shape[0] == 0:
        return []
    depth = camera.to_camera(seen)[:, 2]
    px = camera.project(seen)
    inside = camera.in_image(px) & (depth > 0)
    if np.count_nonzero(inside) >= MIN_SHARE * seen.shape[0]:
        return []
    w, h = camera.image_size
    shown = np.nanmedian(px, axis=0) if np.any(np.isfinite(px)) else np.full(2, np.nan)
    return [
        CameraFinding(
            camera.name,
            "in front",
            f"does not see the subject: of {seen.shape[0]} {what}, "
            f"{np.count_nonzero(depth > 0)} lie in front of it (median depth "
            f"{np.median(depth):.0f} mm) and {np.count_nonzero(inside)} inside its {w}x{h} "
            f"image (median pixel ({shown[0]:.0f}, {shown[1]:.0f})); expected at least half. "
            "Check its pose (translations in mm, camera_from_world)",
        )
    ]


def keypoint_findings(camera: Camera, pixels: ArrayLike) -> list[CameraFinding]:
    """2-D detections (..., 2) of this camera inside its image (with `IMAGE_MARGIN`) for
    at least `MIN_SHARE` of them; else refused (keypoints of another image size or
    camera, or an image size wrong in cameras.json)."""
    px = np.asarray(pixels, dtype=float).reshape(-1, 2)
    px = px[np.all(np.isfinite(px), axis=1)]
    if px.shape[0] == 0:
        return []
    w, h = camera.image_size
    mx, my = IMAGE_MARGIN * w, IMAGE_MARGIN * h
    inside = (px[:, 0] >= -mx) & (px[:, 0] <= w + mx) & (px[:, 1] >= -my) & (px[:, 1] <= h + my)
    if np.count_nonzero(inside) >= MIN_SHARE * px.shape[0]:
        return []
    med = np.median(px, axis=0)
    return [
        CameraFinding(
            camera.name,
            "in image",
            f"{px.shape[0] - np.count_nonzero(inside)} of {px.shape[0]} keypoints lie outside "
            f"its {w}x{h} image (median ({med[0]:.0f}, {med[1]:.0f}) px); expected at least "
            "half inside (keypoints of another camera or image size?)",
        )
    ]


def view_findings(
    cameras: Sequence[Camera],
    pixels: ArrayLike,
    joint_names: Sequence[str],
    rest_joints_mm: Mapping[str, ArrayLike],
) -> list[CameraFinding]:
    """Do two or more views agree on the subject? Triangulate and check.

    Parameters
    ----------
    cameras : sequence of Camera, length V
    pixels : array_like, shape (V, T, K, 2)
        Each view's keypoints of the same frames (NaN where unseen), the first frames of
        the recording (`VIEW_CHECK_FRAMES` are enough).
    joint_names : sequence of str, length K
        Canonical names of the keypoints.
    rest_joints_mm : mapping of str to (3,)
        The subject's canonical joints in any one pose (the body model at rest): the
        limb lengths the views must give.

    Returns
    -------
    list of CameraFinding
        Refused: triangulated points behind a camera, a view's median reprojection error
        above `MAX_REPROJECTION_SHARE` of its width, limb lengths outside
        `LIMB_RATIO_RANGE` of the subject's.
    """
    px = np.asarray(pixels, dtype=float)
    names = list(joint_names)
    pts = triangulate_views(cameras, px)  # (T, K, 3); NaN where fewer than 2 views see it
    ok = np.all(np.isfinite(pts), axis=-1)
    if np.count_nonzero(ok) < 3:
        return []
    out: list[CameraFinding] = []
    all_names = ", ".join(c.name for c in cameras)
    for c in cameras:
        depth = c.to_camera(pts[ok])[:, 2]
        if np.count_nonzero(depth > 0) < MIN_SHARE * depth.shape[0]:
            out.append(
                CameraFinding(
                    c.name,
                    "in front",
                    f"the joints triangulated from cameras {all_names} lie behind it "
                    f"({np.count_nonzero(depth <= 0)} of {depth.shape[0]}, median depth "
                    f"{np.median(depth):.0f} mm); expected the subject in front of every "
                    "camera (left and right extrinsics or keypoint files swapped? a camera "
                    "turned round?)",
                )
            )
    if out:
        return out
    err = reprojection_errors_px(cameras, pts, px)  # (V, T, K)
    for i, c in enumerate(cameras):
        e = err[i][ok & np.isfinite(err[i])]
        limit = MAX_REPROJECTION_SHARE * c.image_size[0]
        if e.size and float(np.median(e)) > limit:
            out.append(
                CameraFinding(
                    c.name,
                    "views agree",
                    f"its keypoints disagree with the other views: joints triangulated from "
                    f"cameras {all_names} reproject {np.median(e):.1f} px (median) from its "
                    f"keypoints; expected at most {limit:.0f} px (keypoint files of two "
                    "cameras swapped? extrinsics or intrinsics of another camera?)",
                )
            )
    if out:
        return out
    # limb lengths across the line of sight: each view's limb in normalised image
    # coordinates times the subject's median depth there. The depth of one joint from a
    # narrow baseline is noisy (4 px of detector noise on a 90 mm pair at 3 m doubles
    # the limbs triangulated in 3-D), the median depth of all of them is not; a limb
    # seen foreshortened is shorter, so the 90th percentile over the frames is compared,
    # over the frames where both keypoints agree with the other views (a detector's wild
    # points, a few per cent, would otherwise be that percentile)
    ratios = []
    for i, c in enumerate(cameras):
        subject_depth = float(np.median(c.to_camera(pts[ok])[:, 2]))
        norm = c.undistort_pixels(px[i])  # (T, K, 2)
        with np.errstate(invalid="ignore"):
            agree = err[i] <= MAX_REPROJECTION_SHARE * c.image_size[0]  # (T, K)
        for a, b in RIGID_PAIRS:
            if a in names and b in names and a in rest_joints_mm and b in rest_joints_mm:
                ia, ib = names.index(a), names.index(b)
                d = np.linalg.norm(norm[:, ia] - norm[:, ib], axis=-1)
                both = np.isfinite(d) & agree[:, ia] & agree[:, ib]
                d = (d[both] if np.count_nonzero(both) >= 3 else d[np.isfinite(d)]) * subject_depth
                rest = float(np.linalg.norm(np.subtract(rest_joints_mm[a], rest_joints_mm[b])))
                if d.size and rest > 0:
                    ratios.append(float(np.percentile(d, 90.0)) / rest)
    if ratios:
        r = float(np.median(ratios))
        lo, hi = LIMB_RATIO_RANGE
        if not lo <= r <= hi:
            out.append(
                CameraFinding(
                    tuple(c.name for c in cameras),
                    "limb lengths",
                    f"limbs seen by cameras {all_names} at the depth triangulated from them "
                    f"are {r:.3g} times the subject's (median over {len(ratios)} limbs and "
                    f"views); expected {lo}-{hi} "
                    "(translations in metres instead of mm? fx and fy of another image "
                    "size? the subject's height in session.json?)",
                )
            )
    return out


#: Largest distance (mm) of the subject's ankles (their median height) from the world's
#: z = 0 before a warning: a session's floor is usually at 0 (`docs/conventions.md`), and
#: a subject placed too far or too near (doubled focal lengths, a floor 1 m off) stands
#: below or above it. A subject off the floor for the whole take (climbing, hanging,
#: seated on a table) is above it too: the warning says so.
MAX_FLOOR_OFFSET_MM = 300.0
#: Multiples of the ankles' height uncertainty (how far the views' parallax and keypoint
#: noise may misplace one triangulated ankle) added to `MAX_FLOOR_OFFSET_MM`: on a narrow
#: pair with a detector's noise the triangulated ankles scatter and their median moves by
#: about that uncertainty (the linear triangulation of nearly parallel rays is biased).
FLOOR_CONFIDENCE = 2.0
#: Most frames, spread evenly over the take, whose ankles the floor check triangulates.
FLOOR_CHECK_FRAMES = 600
#: Camera centres nearer than this to the world origin (mm) are taken for translations
#: written in metres (a camera 3 m away read as 3 mm).
MIN_CAMERA_DISTANCE_MM = 50.0


def floor_findings(
    camera: str | tuple[str, ...],
    ankles_mm: ArrayLike,
    how: str,
    note: str = "",
    uncertainty_mm: float = 0.0,
) -> list[CameraFinding]:
    """Warn when the subject's ankles (..., 3), as placed by ``how``, lie far from z = 0.

    The ankles' median height (+-infinity counts as beyond either end) is compared with
    `MAX_FLOOR_OFFSET_MM` plus `FLOOR_CONFIDENCE` times ``uncertainty_mm``, how far the
    placement may misplace one ankle; ``note`` follows the numbers.
    """
    a = np.asarray(ankles_mm, dtype=float).reshape(-1, 3)
    z = a[~np.isnan(a[:, 2]), 2]
    if z.size == 0:
        return []
    median = float(np.median(z))
    if not np.isfinite(median):  # most of them turned round: nothing to tell
        return []
    limit = MAX_FLOOR_OFFSET_MM + FLOOR_CONFIDENCE * uncertainty_mm
    if abs(median) <= limit:
        return []
    low, high = np.percentile(z, [5.0, 95.0], method="nearest")
    within = (
        f"{limit:.0f} mm of z = 0, the floor ({MAX_FLOOR_OFFSET_MM:.0f} mm plus "
        f"{FLOOR_CONFIDENCE:g} x {uncertainty_mm:.0f} mm, the uncertainty of one ankle)"
        if uncertainty_mm >= 1.0
        else f"{limit:.0f} mm of z = 0, the floor"
    )
    return [
        CameraFinding(
            camera,
            "floor",
            f"the subject's ankles, {how}, lie at z = {median:.0f} mm (median of {z.size}, "
            f"5-95 % {low:.0f} to {high:.0f} mm{note}); expected within {within}. Focal "
            "lengths or translations in the wrong unit? Ignore it if the floor is not at "
            "z = 0 or the subject is off it throughout (climbing, hanging, seated)",
            refuse=False,
        )
    ]


def _relative_depth_error(
    cameras: Sequence[Camera], pixels: FloatArray, points_mm: FloatArray
) -> tuple[NDArray[np.bool_], FloatArray]:
    """Which views see each triangulated point (V, M), and how far (as a share of its
    distance) its depth may be off (M,): the keypoints' angular noise (twice the median
    reprojection error, over the focal length; two views each show about half of it)
    times sqrt(2), over the widest angle between the views that see it."""
    sees = np.all(np.isfinite(pixels), axis=-1)  # (V, M)
    err = reprojection_errors_px(cameras, points_mm, pixels)
    noise_rad = 2.0 * float(np.nanmedian(err)) / float(np.median([c.K[0, 0] for c in cameras]))
    centres = np.stack([np.asarray(c.center_in_world, dtype=float) for c in cameras])
    rays = centres[:, None, :] - points_mm[None]  # (V, M, 3): from each point to each camera
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    rays[~sees] = np.nan
    cos = np.einsum("imk,jmk->ijm", rays, rays).reshape(-1, points_mm.shape[0])
    with np.errstate(invalid="ignore", divide="ignore"):
        parallax = np.arccos(np.clip(np.nanmin(cos, axis=0), -1.0, 1.0))
        return sees, np.sqrt(2.0) * noise_rad / parallax


def view_floor_findings(cameras: Sequence[Camera], ankle_pixels: ArrayLike) -> list[CameraFinding]:
    """The subject's ankles triangulated from two or more views and compared with the
    floor (`floor_findings`).

    Parameters
    ----------
    cameras : sequence of Camera, length V
    ankle_pixels : array_like, shape (V, T, A, 2)
        Each view's ankle keypoints of the same frames (NaN where unseen), spread over
        the take (`FLOOR_CHECK_FRAMES` are enough).

    Each ankle is triangulated where two or more views see it, at its own depth. A
    point that lands behind a camera that sees it (a narrow pair's noise turned the
    disparity round) lies beyond the far end of that camera's ray: its height is taken as
    that end's (+-infinity), so that the median is not pulled up by leaving it out. The
    uncertainty of one ankle's height is its relative depth error (the keypoint noise,
    twice the median reprojection error, over the widest angle between the views that
    see it) times its height below or above the cameras: a few mm on a wide rig, hundreds
    on a narrow pair with a detector's noise.
    """
    px = np.asarray(ankle_pixels, dtype=float)
    flat = px.reshape(len(cameras), -1, 2)
    pts = triangulate_views(cameras, flat)  # (M, 3)
    keep = np.all(np.isfinite(pts), axis=1)
    if not np.any(keep):
        return []
    flat, pts = flat[:, keep], pts[keep]
    sees, rel = _relative_depth_error(cameras, flat, pts)
    centres = np.stack([np.asarray(c.center_in_world, dtype=float) for c in cameras])
    each_mm = rel * np.abs(np.median(centres[:, 2]) - pts[:, 2])
    uncertainty = float(np.nanmedian(each_mm)) if np.any(np.isfinite(each_mm)) else 0.0
    z = pts[:, 2].copy()
    for i, c in enumerate(cameras):
        behind = sees[i] & (c.to_camera(pts)[:, 2] <= 0)
        if np.any(behind):
            n = c.undistort_pixels(flat[i, behind])
            ray_z = (
                np.column_stack([n, np.ones(n.shape[0])]) @ np.asarray(c.world_from_camera)[2, :3]
            )
            z[behind] = np.copysign(np.inf, ray_z)  # the far end of the ray it sees
    names = tuple(c.name for c in cameras)
    return floor_findings(
        names,
        np.column_stack([np.zeros((z.size, 2)), z]),
        f"placed from cameras {', '.join(names)}",
        "; each triangulated from the views that see it",
        uncertainty,
    )


#: Largest angle (deg) between the subject's up (from the mid-ankles to the neck, median
#: over the frames) and the world's +z before a warning: a subject leans, bends and sits
#: well within it; a world whose z points down (a calibration board lying face up) or
#: along the floor (a board on a wall) is 90-180 deg from it.
MAX_UP_TILT_DEG = 60.0
#: Largest uncertainty of a triangulated joint, as a share of the neck-to-ankle length,
#: for the up check to run (a narrow pair with a detector's noise: not at all).
MAX_UP_UNCERTAINTY = 0.25


def view_up_findings(
    cameras: Sequence[Camera], pixels: ArrayLike, joint_names: Sequence[str]
) -> list[CameraFinding]:
    """Warn when the subject, triangulated from two or more views, does not stand along
    the world's +z (`MAX_UP_TILT_DEG`): the floor check alone passes a world turned
    upside down (the ankles stay near z = 0, the head goes below them).

    Parameters
    ----------
    cameras : sequence of Camera, length V
    pixels : array_like, shape (V, T, K, 2)
        Each view's keypoints of the same frames (NaN where unseen), spread over the take.
    joint_names : sequence of str, length K
        Canonical names; ``neck`` and one or both ankles are used.
    """
    names = list(joint_names)
    ankles = [names.index(n) for n in ("left_ankle", "right_ankle") if n in names]
    if "neck" not in names or not ankles:
        return []
    px = np.asarray(pixels, dtype=float)[:, :, [names.index("neck"), *ankles]]
    n_views, n_frames, n_joints = px.shape[:3]
    flat = px.reshape(n_views, -1, 2)
    pts = triangulate_views(cameras, flat)  # (T * J, 3)
    keep = np.all(np.isfinite(pts), axis=1)
    if np.count_nonzero(keep) < 3:
        return []
    _, rel = _relative_depth_error(cameras, flat[:, keep], pts[keep])
    centres = np.stack([np.asarray(c.center_in_world, dtype=float) for c in cameras])
    distance = np.linalg.norm(pts[keep][:, None] - centres[None], axis=-1).min(axis=1)
    joints = pts.reshape(n_frames, n_joints, 3)
    feet = np.isfinite(joints[:, 1:, 0])  # (T, A)
    mid = np.where(feet[..., None], joints[:, 1:], 0.0).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        up = joints[:, 0] - mid / feet.sum(axis=1)[:, None]
        length = np.linalg.norm(up, axis=1)
    ok = np.isfinite(length) & (length > 0)
    if np.count_nonzero(ok) < 3:
        return []
    if not np.nanmedian(rel * distance) <= MAX_UP_UNCERTAINTY * np.median(length[ok]):
        return []
    tilt = float(np.degrees(np.arccos(np.clip(np.median(up[ok, 2] / length[ok]), -1, 1))))
    if tilt <= MAX_UP_TILT_DEG:
        return []
    cams = tuple(c.name for c in cameras)
    return [
        CameraFinding(
            cams,
            "up",
            f"the subject, triangulated from cameras {', '.join(cams)}, stands {tilt:.0f} deg "
            f"from the world's +z (from the ankles to the neck, median of "
            f"{np.count_nonzero(ok)} frames); expected within {MAX_UP_TILT_DEG:.0f} deg of "
            "it. A world whose z is not up (a calibration board's frame: z down, or y up)? "
            "Ignore it if the subject lies or hangs upside down throughout",
            refuse=False,
        )
    ]


def pose_findings(camera: Camera) -> list[CameraFinding]:
    """Warnings on a camera's pose alone (one camera and no 3-D data to check it by): a
    centre within `MIN_CAMERA_DISTANCE_MM` of the world origin (translations in metres?),
    the world origin behind the camera (a lab's origin usually lies in the capture
    volume: a camera turned round?)."""
    out: list[CameraFinding] = []
    centre = np.asarray(camera.center_in_world, dtype=float)
    dist = float(np.linalg.norm(centre))
    if 0.0 < dist < MIN_CAMERA_DISTANCE_MM:
        out.append(
            CameraFinding(
                camera.name,
                "scale",
                f"its centre lies {dist:.3g} mm from the world origin; expected a camera "
                f"at least {MIN_CAMERA_DISTANCE_MM:.0f} mm away (translations in metres "
                "instead of mm?)",
                refuse=False,
            )
        )
    elif dist > 0.0:
        depth = float(camera.to_camera(np.zeros((1, 3)))[0, 2])
        if depth <= 0.0:
            out.append(
                CameraFinding(
                    camera.name,
                    "in front",
                    f"the world origin lies behind it (depth {depth:.0f} mm); expected the "
                    "capture volume, where a lab's origin usually is, in front of it (a "
                    "camera turned round, camera_from_world inverted?)",
                    refuse=False,
                )
            )
    return out


def _named(camera: str | tuple[str, ...]) -> str:
    """``camera 'a'`` for one camera, ``cameras 'a', 'b'`` for several."""
    if isinstance(camera, str):
        return f"camera {camera!r}"
    if len(camera) == 1:
        return f"camera {camera[0]!r}"
    return "cameras " + ", ".join(repr(c) for c in camera)


def refuse_or_warn(
    findings: Sequence[CameraFinding],
    where: str,
    warn: Callable[[str], None] = lambda line: None,
) -> None:
    """Raise `SessionError` listing every refusal; pass each warning to ``warn``."""
    refusals = [f for f in findings if f.refuse]
    for f in findings:
        if not f.refuse:
            warn(f"{where}: {_named(f.camera)} ({f.check}): {f.text}")
    if refusals:
        lines = [f"{_named(f.camera)} ({f.check}): {f.text}" for f in refusals]
        raise SessionError(
            f"{where}: the cameras do not fit the data; check cameras.json and the keypoints "
            "before tracking:\n  " + "\n  ".join(lines)
        )


__all__ = [
    "FLOOR_CHECK_FRAMES",
    "FLOOR_CONFIDENCE",
    "IMAGE_MARGIN",
    "LIMB_RATIO_RANGE",
    "MAX_FLOOR_OFFSET_MM",
    "MAX_PIXEL_ASPECT",
    "MAX_REPROJECTION_SHARE",
    "MAX_UP_TILT_DEG",
    "MAX_UP_UNCERTAINTY",
    "MIN_CAMERA_DISTANCE_MM",
    "MIN_SHARE",
    "RIGID_PAIRS",
    "VIEW_CHECK_FRAMES",
    "CameraFinding",
    "floor_findings",
    "intrinsic_findings",
    "keypoint_findings",
    "pose_findings",
    "refuse_or_warn",
    "sees_findings",
    "view_findings",
    "view_floor_findings",
    "view_up_findings",
]
