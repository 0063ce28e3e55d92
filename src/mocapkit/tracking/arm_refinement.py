"""Video refinement of the arms: per-arm downhill simplex on the chamfer of projected limb outlines.

Zhang et al. 2011 §5: after IK, each arm's 4 DoFs (3 shoulder + elbow) are refined
separately (§5.2) by a downhill-simplex search (Nelder & Mead) from the IK pose,
minimising eq. 14, ``C = chamfer + lambda * ||t - s||``, over the edge distance map of
the arm's region of interest (:mod:`mocapkit.cues.edges`).

Cost (errata Z11). The literal eq. 13 sums the distance map over the *filled*
silhouette, which rewards poses that cover fewer pixels (foreshortened limbs, limbs
leaving the RoI). By default the cost is instead the mean truncated distance over
points sampled every ``sample_step_px`` along the projected **outlines** of the
upper-arm, forearm and hand cones; points outside the RoI or behind the camera count
at the cap. ``literal_sum=True`` runs the paper's sum over the filled silhouette
(inside the RoI, as §5.2 defines W and H). The hand term is ``lambda`` (px per mm)
times the distance of the hand effector from its marker target (recipe Z:
lambda about 1-5 px/mm with the normalised chamfer).

Outlines. A limb segment is a truncated cone (radii ``skeleton.radii_mm``). Its
silhouette sides are its true *contour generators* with respect to the camera
centre: the two rulings where the viewing ray is tangent to the surface. For a cone
with axis ``u``, slope ``k = (r_B - r_A)/L`` and camera-relative axis start ``A``
(camera at the origin), the tangency condition reduces to ``e . w = k (u . A) - r_A``
for the radial unit vector ``e`` (``w`` the part of ``A`` orthogonal to ``u``), the same
for every point along the axis, so each generator is a straight ruling from
``A + r_A e`` to ``B + r_B e``. This is exact under perspective, unlike offsetting the
projected axis by ``r f / z``. End caps are not part of the outline.

Optimiser. The cost is compiled with Numba (one-arm FK from the fixed parent
transform, projection with the camera's K and OpenCV distortion, bilinear look-up).
The simplex search is `nelder_mead_arm_nb`, a Numba transcription of SciPy's
``minimize(method="Nelder-Mead")`` (non-adaptive coefficients, bounds by clipping,
the same stopping tests on ``xatol``/``fatol``/``maxfev``), tested to give SciPy's
iterates on smooth functions and on the arm cost; it calls `arm_cost_nb` as a global
so that Numba caches it on disk (see the notes above `_nelder_mead_core`). It exists
because SciPy's pure-Python loop costs tens of microseconds per evaluation, about ten
times the cost itself, which alone would break the frame budget of the hybrid tracker
(>= 120 fps with both arms). ``solver="scipy"`` runs SciPy itself on the same compiled cost.
Recipe Z step 4: explicit initial simplex of +-``simplex_step_rad`` (0.1 rad) per
DoF (SciPy's default 5 % steps are far too small for angles), ``xatol=1e-3``,
``maxfev`` about 300, joint-limit bounds.

Swivel seeding (a deviation, on by default). The outline chamfer's basin along the
IK ambiguity, the swivel of the arm about the shoulder-wrist axis, is only about
half a limb width wide (about +-15 deg in the tests' scene): beyond it the other
side line of the cone locks onto the wrong image edge, and no local search from the
IK pose recovers. Before the simplex, the cost is therefore evaluated at
``swivel_scan_steps`` swivel angles over +-``swivel_scan_rad`` with the hand held
exactly on its marker (Azad's 1-D swivel, recipe Z "better, hold the hand exactly");
the simplex starts from the best. ``swivel_scan_rad=0`` runs the paper's plain search.
The default scans the whole circle in 5 deg steps: on sessions rendered from CMU clips
the IK swivel is often 90 deg or more off (an elbow raised sideways while the relaxed
pose hangs it down), and a +-40 deg scan left those arms where IK put them. The region
of interest covers the elbow's scanned arc (`arm_roi`).

Elbow-jump penalty (a deviation, on by default, off in the paper mode). One view's
outlines leave some swivels ambiguous: an arm pointing at the camera is a short blob
whose outline also fits the torso's inner edges, and a folded arm's elbow towards or
away from the camera projects alike. The per-frame search then jumps between such
minima from one frame to the next, 200-500 mm at a time. The cost therefore adds
``elbow_jump_weight_per_mm`` times how far the elbow lies beyond
``elbow_speed_mm_per_s * dt`` from the previous frame's elbow (a hinge: free within a
plausible speed, so it does not hold on to an old swivel the way a quadratic prior on
the angles did). 3 m/s covers the clips' true elbow speeds (99th percentiles
0.5-3.7 m/s); sports with faster arms (a serve, a throw) need a higher speed or the
weight 0. Measured in ``docs/hybrid.md``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.cues.edges import (
    DistanceMap,
    EdgeConfig,
    PreparedFrame,
    Roi,
    prepare_frame,
    roi_around_points,
    roi_distance_map,
)
from mocapkit.errors import ConfigError, ShapeError, unknown_name
from mocapkit.geometry.rotations import axis_angle_matrix_nb
from mocapkit.skeleton.kinematics import forward_kinematics
from mocapkit.skeleton.model import REVOLUTE, Skeleton

FloatArray = NDArray[np.float64]

SIDES: tuple[str, ...] = ("left", "right")
_PREFIX = {"left": "l_", "right": "r_"}
#: Keys accepted in ``hand_targets_mm``: the side, or the hybrid tracker's marker-set name.
_SIDE_OF_KEY = {"left": "left", "right": "right", "left_hand": "left", "right_hand": "right"}

# ------------------------------------------------------------------ packed problem layout
# One flat float64 vector ``geo`` holds everything the compiled cost needs about one arm.
_G_PARENT_R = 0  # (3, 3) world_from_parent rotation (parent of the shoulder joint)
_G_PARENT_T = 9  # (3,) world_from_parent origin, mm
_G_OFFSETS = 12  # (3, 3) offsets of shoulder, elbow, hand joints in their parents, mm
_G_AXES = 21  # (4, 3) DoF axes: 3 shoulder (product order) + elbow
_G_HAND_R = 33  # (3, 3) fixed rotation of the hand joint in the forearm frame
_G_SEG_END = 42  # (3, 3) bone ends of upper arm, forearm, hand in their frames, mm
_G_RADII = 51  # (3, 2) proximal/distal cone radii, mm
_G_EFFECTOR = 57  # (3,) hand effector point in the hand frame, mm
_G_TARGET = 60  # (3,) hand target in the world, mm
_G_CAM_R = 63  # (3, 3) camera_from_world rotation
_G_CAM_T = 72  # (3,) camera_from_world translation, mm
_G_INTR = 75  # fx, fy, cx, cy, skew (K[0, 1])
_G_DIST = 80  # (8,) k1 k2 p1 p2 k3 k4 k5 k6
_G_ORIGIN = 88  # x0, y0 of the distance map in the image
_G_CAP = 90
_G_STEP = 91
_G_LAMBDA = 92
_G_LITERAL = 93
_G_NSEG = 94
_G_USE_TARGET = 95
_G_EULER = 96  # shoulder axes as signed basis vectors: 3 axis indices, 3 signs (-1 if not)
_G_MAP_STEP = 102  # grid spacing of the distance maps (px; 2 for the oriented ones)
_G_ELBOW_PREV = 103  # (3,) the elbow of the previous frame, world mm
_G_ELBOW_W = 106  # weight of the elbow-jump penalty, cost per mm (0: off)
_G_ELBOW_FREE = 107  # elbow displacement from the previous frame that is free, mm
_G_SIZE = 108

_MAX_SEG = 3
_MIN_Z_MM = 1.0  # points closer than this to the camera plane count as off-image


@dataclass(frozen=True)
class RefineConfig:
    """Parameters of the per-arm video refinement (Zhang §5, recipe Z steps 3-4).

    Parameters
    ----------
    edges : EdgeConfig
        Edge distance transform (cap, Canny thresholds, equalisation). By default an
        oriented chamfer with 8 orientation bins (an extension of the paper's plain
        chamfer, which ``EdgeConfig()`` gives and ``paper=True`` uses): on the five
        accuracy clips with marker positions only and no elbow-jump penalty, the mean
        elbow error with video is 97 mm against 136 mm with the plain chamfer (144 mm IK
        only; docs/hybrid.md).
        8 bins was chosen on an earlier version of the tracker, where 4 bins gave
        116 mm and 8 or 12 bins 100 mm.
    hand_weight_px_per_mm : float
        ``lambda`` of eq. 14: cost (px of mean chamfer) per mm of hand displacement.
    sample_step_px : float
        Spacing of outline samples along each projected contour generator.
    include_hand : bool
        Also score the hand cone's outline (its pose follows the forearm).
    literal_sum : bool
        Use the paper's literal eq. 13 (sum over the filled silhouette) instead of the
        normalised outline chamfer (errata Z11). Needs a much larger ``lambda``.
    simplex_step_rad : float
        Size of the explicit initial simplex around the IK pose.
    xatol, fatol : float
        Stopping tolerances (rad, cost units), as SciPy's Nelder-Mead.
    maxfev : int
        Evaluation budget per arm.
    roi_pad_px : float
        Padding of the bounding box of the projected shoulder, elbow, wrist and hand end.
    effector_points_mm : ((3,), (3,)) floats
        Left and right hand effector in the hand joint's frame (the point IK puts on the
        hand target, `mocapkit.ik.sdls.Effector.point_mm`; the origin is the wrist).
    solver : {"numba", "scipy"}
        `nelder_mead_arm_nb` or `scipy.optimize.minimize(method="Nelder-Mead")`.
    swivel_scan_rad : float
        Half-range of the 1-D swivel scan that seeds the simplex (0 disables it and
        runs the paper's plain search from the IK pose).
    swivel_scan_steps : int
        Number of swivel angles scanned (including 0 when odd).
    elbow_jump_weight_per_mm : float
        Cost per mm that the elbow lies beyond the free distance from the previous
        frame's elbow (the module's "elbow-jump penalty"); 0 turns it off. Applies only
        where `refine_arms` is given ``previous_elbows_mm``.
    elbow_speed_mm_per_s : float
        Elbow speed that costs nothing: the free distance is this times the time since
        the previous frame.
    """

    edges: EdgeConfig = field(default_factory=lambda: EdgeConfig(orientation_bins=8))
    hand_weight_px_per_mm: float = 2.0
    sample_step_px: float = 3.0
    include_hand: bool = True
    literal_sum: bool = False
    simplex_step_rad: float = 0.1
    xatol: float = 1e-3
    fatol: float = 1e-4
    maxfev: int = 300
    roi_pad_px: float = 40.0
    effector_points_mm: tuple[tuple[float, float, float], tuple[float, float, float]] = (
        (0.0, 0.0, 0.0),
        (0.0, 0.0, 0.0),
    )
    solver: Literal["numba", "scipy"] = "numba"
    swivel_scan_rad: float = math.pi
    swivel_scan_steps: int = 73
    elbow_jump_weight_per_mm: float = 0.1
    elbow_speed_mm_per_s: float = 3000.0

    def __post_init__(self) -> None:
        checks = {
            "hand_weight_px_per_mm": self.hand_weight_px_per_mm >= 0,
            "sample_step_px": self.sample_step_px > 0,
            "simplex_step_rad": self.simplex_step_rad > 0,
            "xatol": self.xatol >= 0,
            "fatol": self.fatol >= 0,
            "maxfev": self.maxfev >= 5,
            "roi_pad_px": self.roi_pad_px >= 0,
            "swivel_scan_rad": 0 <= self.swivel_scan_rad <= math.pi,
            "swivel_scan_steps": self.swivel_scan_steps >= 1,
            "elbow_jump_weight_per_mm": self.elbow_jump_weight_per_mm >= 0,
            "elbow_speed_mm_per_s": self.elbow_speed_mm_per_s >= 0,
        }
        for name, ok in checks.items():
            if not ok:
                raise ConfigError(
                    f"RefineConfig.{name}: expected a positive value (maxfev >= 5), found "
                    f"{getattr(self, name)!r}"
                )
        pts = np.asarray(self.effector_points_mm, dtype=float)
        if pts.shape != (2, 3) or not np.all(np.isfinite(pts)):
            raise ConfigError(
                "RefineConfig.effector_points_mm: expected ((x, y, z), (x, y, z)) for the left "
                f"and right hands, found {self.effector_points_mm!r}"
            )
        if self.solver not in ("numba", "scipy"):
            raise ConfigError(
                f"RefineConfig.solver: expected 'numba' or 'scipy', found {self.solver!r}"
            )


@dataclass
class ArmDiagnostics:
    """What one arm's refinement did (filled by `refine_arms` when asked).

    Attributes
    ----------
    side : str
    refined : bool
        False when the arm was skipped (no hand target, empty RoI).
    cost_before, cost_after : float
        Eq. 14 at the IK pose and at the result.
    chamfer_before, chamfer_after : float
        Image term alone (px, or the literal sum).
    hand_offset_before_mm, hand_offset_after_mm : float
        ``||t - s||`` at the IK pose and at the result.
    n_evaluations, n_iterations : int
    converged : bool
        Stopped on the tolerances rather than on ``maxfev``.
    roi : (x0, y0, x1, y1)
    elapsed_ms : float
        Wall time of the distance map plus the search for this arm.
    reason : str
        Why the arm was skipped, empty otherwise.
    """

    side: str
    refined: bool = False
    cost_before: float = math.nan
    cost_after: float = math.nan
    chamfer_before: float = math.nan
    chamfer_after: float = math.nan
    hand_offset_before_mm: float = math.nan
    hand_offset_after_mm: float = math.nan
    n_evaluations: int = 0
    n_iterations: int = 0
    converged: bool = False
    roi: Roi = (0, 0, 0, 0)
    elapsed_ms: float = 0.0
    reason: str = ""


# ------------------------------------------------------------------ compiled kernels


@numba.njit(cache=True)
def project_points_nb(points_in_world: FloatArray, geo: FloatArray, out: FloatArray) -> None:
    """Project world points (N, 3) with the camera packed in ``geo`` into ``out`` (N, 2) px.

    OpenCV's model (``cv2.projectPoints``): ``x = X/Z``, rational radial and tangential
    distortion, then ``K``. Points with ``Z < 1 mm`` give NaN.
    """
    for i in range(points_in_world.shape[0]):
        u, v, ok = _project_one(
            points_in_world[i, 0], points_in_world[i, 1], points_in_world[i, 2], geo, True
        )
        if ok:
            out[i, 0] = u
            out[i, 1] = v
        else:
            out[i, 0] = np.nan
            out[i, 1] = np.nan


@numba.njit(cache=True, inline="always")
def _project_one(
    x: float, y: float, z: float, geo: FloatArray, world: bool
) -> tuple[float, float, bool]:
    if world:
        r = geo[_G_CAM_R : _G_CAM_R + 9]
        t = geo[_G_CAM_T : _G_CAM_T + 3]
        xc = r[0] * x + r[1] * y + r[2] * z + t[0]
        yc = r[3] * x + r[4] * y + r[5] * z + t[1]
        zc = r[6] * x + r[7] * y + r[8] * z + t[2]
    else:
        xc, yc, zc = x, y, z
    if zc < _MIN_Z_MM:
        return 0.0, 0.0, False
    xn = xc / zc
    yn = yc / zc
    d = geo[_G_DIST : _G_DIST + 8]
    r2 = xn * xn + yn * yn
    radial = (1.0 + r2 * (d[0] + r2 * (d[1] + r2 * d[4]))) / (
        1.0 + r2 * (d[5] + r2 * (d[6] + r2 * d[7]))
    )
    xd = xn * radial + 2.0 * d[2] * xn * yn + d[3] * (r2 + 2.0 * xn * xn)
    yd = yn * radial + d[2] * (r2 + 2.0 * yn * yn) + 2.0 * d[3] * xn * yn
    fx = geo[_G_INTR]
    fy = geo[_G_INTR + 1]
    u = fx * xd + geo[_G_INTR + 4] * yd + geo[_G_INTR + 2]
    v = fy * yd + geo[_G_INTR + 3]
    return u, v, True


@numba.njit(cache=True, inline="always")
def _lookup(u: float, v: float, geo: FloatArray, dmap: NDArray[np.float32]) -> float:
    """Bilinear distance at image point (u, v); the cap outside the map (same rule as
    `DistanceMap.lookup`)."""
    step = geo[_G_MAP_STEP]
    x = (u - geo[_G_ORIGIN] - 0.5 * (step - 1.0)) / step
    y = (v - geo[_G_ORIGIN + 1] - 0.5 * (step - 1.0)) / step
    h = dmap.shape[0]
    w = dmap.shape[1]
    if not (x >= 0.0 and y >= 0.0 and x < w - 1 and y < h - 1):
        return geo[_G_CAP]
    c0 = int(x)
    r0 = int(y)
    fx = x - c0
    fy = y - r0
    top = (1.0 - fx) * dmap[r0, c0] + fx * dmap[r0, c0 + 1]
    bot = (1.0 - fx) * dmap[r0 + 1, c0] + fx * dmap[r0 + 1, c0 + 1]
    return (1.0 - fy) * top + fy * bot


@numba.njit(cache=True)
def arm_fk_nb(x: FloatArray, geo: FloatArray, seg: FloatArray) -> None:
    """One-arm forward kinematics from the fixed parent transform.

    Writes ``seg`` (4, 3): shoulder, elbow, wrist origins and the hand effector, in
    world mm, followed by nothing else; rotations are recomputed by `_arm_frames_nb`.
    """
    rots = np.empty((3, 3, 3))
    orig = np.empty((3, 3))
    eff = np.empty(3)
    _arm_frames_nb(x, geo, rots, orig, eff)
    seg[0] = orig[0]
    seg[1] = orig[1]
    seg[2] = orig[2]
    seg[3] = eff


@numba.njit(cache=True, inline="always")
def _mat3(a: FloatArray, b: FloatArray, out: FloatArray) -> None:
    """``out = a @ b`` for 3x3 (explicit loops: Numba's ``@`` calls BLAS, too slow here)."""
    for i in range(3):
        for j in range(3):
            out[i, j] = a[i, 0] * b[0, j] + a[i, 1] * b[1, j] + a[i, 2] * b[2, j]


@numba.njit(cache=True, inline="always")
def _affine3(r: FloatArray, v: FloatArray, t: FloatArray, out: FloatArray) -> None:
    """``out = r @ v + t`` for a 3x3 ``r``."""
    for i in range(3):
        out[i] = r[i, 0] * v[0] + r[i, 1] * v[1] + r[i, 2] * v[2] + t[i]


@numba.njit(cache=True)
def _arm_frames_nb(
    x: FloatArray, geo: FloatArray, rots: FloatArray, orig: FloatArray, eff: FloatArray
) -> None:
    """World rotation (3, 3, 3) and origin (3, 3) of upper arm, forearm, hand; effector (3,)."""
    pr = geo[_G_PARENT_R : _G_PARENT_R + 9].reshape(3, 3)
    pt = geo[_G_PARENT_T : _G_PARENT_T + 3]
    off = geo[_G_OFFSETS : _G_OFFSETS + 9].reshape(3, 3)
    axes = geo[_G_AXES : _G_AXES + 12].reshape(4, 3)
    step = np.empty((3, 3))
    acc = np.empty((3, 3))
    # shoulder: R_parent @ R_1(x0) @ R_2(x1) @ R_3(x2)  (DoF product order, skeleton/model.py)
    rots[0] = pr
    for k in range(3):
        axis_angle_matrix_nb(axes[k], x[k], step)
        acc[:, :] = rots[0]
        _mat3(acc, step, rots[0])
    _affine3(pr, off[0], pt, orig[0])
    axis_angle_matrix_nb(axes[3], x[3], step)
    _mat3(rots[0], step, rots[1])
    _affine3(rots[0], off[1], orig[0], orig[1])
    hand_r = geo[_G_HAND_R : _G_HAND_R + 9].reshape(3, 3)
    _mat3(rots[1], hand_r, rots[2])
    _affine3(rots[1], off[2], orig[1], orig[2])
    _affine3(rots[2], geo[_G_EFFECTOR : _G_EFFECTOR + 3], orig[2], eff)


@numba.njit(cache=True)
def cone_contour_generators_nb(
    a: FloatArray, b: FloatArray, ra: float, rb: float, out: FloatArray
) -> None:
    """The two contour generators of a truncated cone seen from the origin (the camera).

    Parameters
    ----------
    a, b : ndarray, shape (3,)
        Axis start and end in camera coordinates (mm).
    ra, rb : float
        Radii at ``a`` and ``b`` (mm).
    out : ndarray, shape (2, 2, 3)
        Per side, the ruling's start (at ``a``) and end (at ``b``) points (mm).
    """
    # scalar arithmetic throughout: this runs three times per cost evaluation
    ax, ay, az = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    length = math.sqrt(ax * ax + ay * ay + az * az)
    if length < 1e-9:
        for side in range(2):
            for i in range(3):
                out[side, 0, i] = a[i]
                out[side, 1, i] = b[i]
        return
    ux, uy, uz = ax / length, ay / length, az / length
    slope = (rb - ra) / length
    t0 = ux * a[0] + uy * a[1] + uz * a[2]
    wx, wy, wz = a[0] - t0 * ux, a[1] - t0 * uy, a[2] - t0 * uz
    d = math.sqrt(wx * wx + wy * wy + wz * wz)
    if d < 1e-9:  # looking straight down the axis: any perpendicular will do
        if abs(uz) < 0.9:
            wx, wy, wz = uy, -ux, 0.0
        else:
            wx, wy, wz = 0.0, uz, -uy
        n = math.sqrt(wx * wx + wy * wy + wz * wz)
        wx, wy, wz = wx / n, wy / n, wz / n
        c = 0.0
    else:
        wx, wy, wz = wx / d, wy / d, wz / d
        # tangency e . w = k (u . A) - r_A (module notes); |c| >= 1 means the camera is
        # inside the cone's extension (limb seen end-on): clamp
        c = min(max((slope * t0 - ra) / d, -0.999), 0.999)
    vx, vy, vz = uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx
    sn = math.sqrt(1.0 - c * c)
    for side in range(2):
        sgn = 1.0 if side == 0 else -1.0
        ex, ey, ez = c * wx + sgn * sn * vx, c * wy + sgn * sn * vy, c * wz + sgn * sn * vz
        out[side, 0, 0] = a[0] + ra * ex
        out[side, 0, 1] = a[1] + ra * ey
        out[side, 0, 2] = a[2] + ra * ez
        out[side, 1, 0] = b[0] + rb * ex
        out[side, 1, 1] = b[1] + rb * ey
        out[side, 1, 2] = b[2] + rb * ez


@numba.njit(cache=True)
def _segment_outlines_nb(x: FloatArray, geo: FloatArray, lines: FloatArray, eff: FloatArray) -> int:
    """Contour generators of the arm cones in CAMERA coordinates.

    Writes ``lines`` (n_seg, 2, 2, 3): per segment, per side, the ruling's start and
    end points (mm, camera frame); returns the number of segments. See the module
    notes for the tangency condition.
    """
    rots = np.empty((3, 3, 3))
    orig = np.empty((3, 3))
    _arm_frames_nb(x, geo, rots, orig, eff)
    cr = geo[_G_CAM_R : _G_CAM_R + 9].reshape(3, 3)
    ct = geo[_G_CAM_T : _G_CAM_T + 3]
    ends = geo[_G_SEG_END : _G_SEG_END + 9].reshape(3, 3)
    radii = geo[_G_RADII : _G_RADII + 6].reshape(3, 2)
    n_seg = int(geo[_G_NSEG])
    a = np.empty(3)
    b = np.empty(3)
    end_w = np.empty(3)
    for s in range(n_seg):
        _affine3(cr, orig[s], ct, a)
        _affine3(rots[s], ends[s], orig[s], end_w)
        _affine3(cr, end_w, ct, b)
        cone_contour_generators_nb(a, b, radii[s, 0], radii[s, 1], lines[s])
    return n_seg


@numba.njit(cache=True)
def _n_samples(p0u: float, p0v: float, p1u: float, p1v: float, step: float) -> int:
    length = math.sqrt((p1u - p0u) ** 2 + (p1v - p0v) ** 2)
    if not length < 1e9:  # near the camera plane (or NaN): callers cap the count
        length = 1e9
    n = math.ceil(length / step) + 1
    return max(n, 2)


@numba.njit(cache=True)
def arm_cost_terms_nb(
    x: FloatArray, geo: FloatArray, dmap: NDArray[np.float32]
) -> tuple[float, float]:
    """Image term and hand offset (mm) of eq. 14 for arm parameters ``x`` (4,).

    ``dmap`` holds K distance maps (K, h, w): one (the paper's chamfer) or one per edge
    orientation bin, each outline line then read in the map of its own image direction
    (`mocapkit.cues.edges.oriented_distance_maps`).
    """
    lines = np.empty((_MAX_SEG, 2, 2, 3))
    eff = np.empty(3)
    n_seg = _segment_outlines_nb(x, geo, lines, eff)
    tgt = geo[_G_TARGET : _G_TARGET + 3]
    hand = math.sqrt((eff[0] - tgt[0]) ** 2 + (eff[1] - tgt[1]) ** 2 + (eff[2] - tgt[2]) ** 2)
    if geo[_G_LITERAL] != 0.0:
        return _literal_sum_nb(lines, n_seg, geo, dmap[0]), hand
    cap = geo[_G_CAP]
    step = geo[_G_STEP]
    n_bins = dmap.shape[0]
    # A limb close to the camera plane projects to lines millions of px long; every
    # sample off the map costs the cap anyway, so a line gets at most as many samples
    # as twice the map's perimeter needs (a 131_03 hop otherwise spent a minute on
    # one evaluation).
    max_n = int(4.0 * (dmap.shape[1] + dmap.shape[2]) * geo[_G_MAP_STEP] / step) + 2
    total = 0.0
    count = 0
    for s in range(n_seg):
        for side in range(2):
            p0 = lines[s, side, 0]
            p1 = lines[s, side, 1]
            u0, v0, ok0 = _project_one(p0[0], p0[1], p0[2], geo, False)
            u1, v1, ok1 = _project_one(p1[0], p1[1], p1[2], geo, False)
            if not (ok0 and ok1):
                n = 2
                b = 0
            else:
                n = min(_n_samples(u0, v0, u1, v1, step), max_n)
                b = 0
                if n_bins > 1:
                    ang = math.atan2(v1 - v0, u1 - u0) % math.pi
                    b = int(ang * n_bins / math.pi + 0.5) % n_bins  # ang >= 0
            d2 = dmap[b]
            for j in range(n):
                f = j / (n - 1)
                px = p0[0] + f * (p1[0] - p0[0])
                py = p0[1] + f * (p1[1] - p0[1])
                pz = p0[2] + f * (p1[2] - p0[2])
                u, v, ok = _project_one(px, py, pz, geo, False)
                total += _lookup(u, v, geo, d2) if ok else cap
                count += 1
    return total / count, hand


@numba.njit(cache=True)
def _literal_sum_nb(
    lines: FloatArray, n_seg: int, geo: FloatArray, dmap: NDArray[np.float32]
) -> float:
    """Eq. 13 literally: sum of the distance map over RoI pixels inside the projected
    silhouette (union of the cones' side quadrilaterals)."""
    quads = np.empty((_MAX_SEG, 4, 2))
    valid = np.zeros(_MAX_SEG, dtype=np.bool_)
    x0 = geo[_G_ORIGIN]
    y0 = geo[_G_ORIGIN + 1]
    h = dmap.shape[0]
    w = dmap.shape[1]
    lo_u = 1e300
    lo_v = 1e300
    hi_u = -1e300
    hi_v = -1e300
    for s in range(n_seg):
        ok_all = True
        # quad order: side 0 start -> side 0 end -> side 1 end -> side 1 start
        for k, (side, end) in enumerate(((0, 0), (0, 1), (1, 1), (1, 0))):
            p = lines[s, side, end]
            u, v, ok = _project_one(p[0], p[1], p[2], geo, False)
            ok_all = ok_all and ok
            quads[s, k, 0] = u - x0
            quads[s, k, 1] = v - y0
        valid[s] = ok_all
        if ok_all:
            for k in range(4):
                lo_u = min(lo_u, quads[s, k, 0])
                hi_u = max(hi_u, quads[s, k, 0])
                lo_v = min(lo_v, quads[s, k, 1])
                hi_v = max(hi_v, quads[s, k, 1])
    if not np.any(valid[:n_seg]):
        return 0.0
    c_lo = max(math.floor(max(lo_u, -1.0)), 0)
    c_hi = min(math.ceil(min(hi_u, w + 1.0)), w - 1)
    r_lo = max(math.floor(max(lo_v, -1.0)), 0)
    r_hi = min(math.ceil(min(hi_v, h + 1.0)), h - 1)
    total = 0.0
    for r in range(r_lo, r_hi + 1):
        for c in range(c_lo, c_hi + 1):
            for s in range(n_seg):
                if valid[s] and _in_quad(quads[s], c + 0.0, r + 0.0):
                    total += dmap[r, c]
                    break
    return total


@numba.njit(cache=True, inline="always")
def _in_quad(q: FloatArray, px: float, py: float) -> bool:
    """Point in a convex quadrilateral of either orientation (inclusive)."""
    pos = False
    neg = False
    for k in range(4):
        ax, ay = q[k, 0], q[k, 1]
        bx, by = q[(k + 1) % 4, 0], q[(k + 1) % 4, 1]
        cr = (bx - ax) * (py - ay) - (by - ay) * (px - ax)
        if cr > 0:
            pos = True
        elif cr < 0:
            neg = True
    return not (pos and neg)


@numba.njit(cache=True)
def arm_cost_nb(x: FloatArray, geo: FloatArray, dmap: NDArray[np.float32]) -> float:
    """Eq. 14: image term plus ``lambda * ||t - s||`` for arm parameters ``x`` (4,)."""
    image, hand = arm_cost_terms_nb(x, geo, dmap)
    cost = image + geo[_G_LAMBDA] * hand if geo[_G_USE_TARGET] != 0.0 else image
    if geo[_G_ELBOW_W] > 0.0:
        cost += geo[_G_ELBOW_W] * _elbow_jump_mm_nb(x, geo)
    return cost


@numba.njit(cache=True)
def _elbow_jump_mm_nb(x: FloatArray, geo: FloatArray) -> float:
    """How far (mm) the elbow of ``x`` lies beyond the free distance from the previous one."""
    rots = np.empty((3, 3, 3))
    orig = np.empty((3, 3))
    eff = np.empty(3)
    _arm_frames_nb(x, geo, rots, orig, eff)
    d = math.sqrt(
        (orig[1, 0] - geo[_G_ELBOW_PREV]) ** 2
        + (orig[1, 1] - geo[_G_ELBOW_PREV + 1]) ** 2
        + (orig[1, 2] - geo[_G_ELBOW_PREV + 2]) ** 2
    )
    return max(0.0, d - geo[_G_ELBOW_FREE])


@numba.njit(cache=True)
def arm_outline_px_nb(x: FloatArray, geo: FloatArray, out: FloatArray) -> int:
    """Projected outline sample points (px) the chamfer cost reads, into ``out`` (M, 2).

    Returns how many were written (at most M); off-image (behind camera) points are NaN.
    """
    lines = np.empty((_MAX_SEG, 2, 2, 3))
    eff = np.empty(3)
    n_seg = _segment_outlines_nb(x, geo, lines, eff)
    step = geo[_G_STEP]
    m = 0
    for s in range(n_seg):
        for side in range(2):
            p0 = lines[s, side, 0]
            p1 = lines[s, side, 1]
            u0, v0, ok0 = _project_one(p0[0], p0[1], p0[2], geo, False)
            u1, v1, ok1 = _project_one(p1[0], p1[1], p1[2], geo, False)
            n = _n_samples(u0, v0, u1, v1, step) if (ok0 and ok1) else 2
            for j in range(n):
                if m >= out.shape[0]:
                    return m
                f = j / (n - 1)
                pp = p0 + f * (p1 - p0)
                u, v, ok = _project_one(pp[0], pp[1], pp[2], geo, False)
                out[m, 0] = u if ok else np.nan
                out[m, 1] = v if ok else np.nan
                m += 1
    return m


@numba.njit(cache=True)
def swivel_x_nb(x: FloatArray, alpha: float, geo: FloatArray, out: FloatArray) -> bool:
    """Arm parameters after a swivel of ``alpha`` rad about the shoulder->effector axis.

    The upper arm's rotation is pre-multiplied by the swivel (elbow unchanged, so the
    effector stays put; Azad's 1-D swivel angle, recipe Z) and decomposed back onto
    the shoulder's axes (intrinsic Tait-Bryan angles about distinct signed basis
    axes). Writes ``out`` (4,); returns False when the axes do not allow it.
    """
    if geo[_G_EULER] < 0:
        return False
    rots = np.empty((3, 3, 3))
    orig = np.empty((3, 3))
    eff = np.empty(3)
    _arm_frames_nb(x, geo, rots, orig, eff)
    pr = geo[_G_PARENT_R : _G_PARENT_R + 9].reshape(3, 3)
    n = eff - orig[0]
    nn = math.sqrt(n[0] ** 2 + n[1] ** 2 + n[2] ** 2)
    if nn < 1e-9:
        return False
    # swivel axis in the parent frame: R_local(alpha) = Rot(P^T n, alpha) @ R_local(0)
    npar = np.empty(3)
    for i in range(3):
        npar[i] = (pr[0, i] * n[0] + pr[1, i] * n[1] + pr[2, i] * n[2]) / nn
    sw = np.empty((3, 3))
    axis_angle_matrix_nb(npar, alpha, sw)
    local = np.empty((3, 3))
    tmp = np.empty((3, 3))
    prt = np.ascontiguousarray(pr.T)
    _mat3(prt, rots[0], tmp)  # R_local(0) = P^T R_upper
    _mat3(sw, tmp, local)
    i = int(geo[_G_EULER])
    j = int(geo[_G_EULER + 1])
    k = int(geo[_G_EULER + 2])
    eps = 1.0 if (j - i) % 3 == 1 else -1.0  # parity of the axis permutation
    phi2 = math.asin(min(max(eps * local[i, k], -1.0), 1.0))
    phi1 = math.atan2(-eps * local[j, k], local[k, k])
    phi3 = math.atan2(-eps * local[i, j], local[i, i])
    out[0] = phi1 * geo[_G_EULER + 3]
    out[1] = phi2 * geo[_G_EULER + 4]
    out[2] = phi3 * geo[_G_EULER + 5]
    out[3] = x[3]
    return True


@numba.njit(cache=True)
def swivel_scan_nb(
    x0: FloatArray,
    geo: FloatArray,
    dmap: NDArray[np.float32],
    half_range: float,
    steps: int,
    lb: FloatArray,
    ub: FloatArray,
) -> tuple[FloatArray, float, int]:
    """Best of ``x0`` and ``steps`` swivels evenly spread over ``[-half_range, half_range]``.

    Candidates are clipped to the joint limits. Returns ``(x, cost, evaluations)``.
    """
    best = x0.copy()
    fbest = arm_cost_nb(x0, geo, dmap)
    nfev = 1
    cand = np.empty(4)
    for m in range(steps):
        alpha = -half_range + 2.0 * half_range * m / (steps - 1) if steps > 1 else 0.0
        if alpha == 0.0:
            continue
        if not swivel_x_nb(x0, alpha, geo, cand):
            break
        _clip(cand, lb, ub)
        f = arm_cost_nb(cand, geo, dmap)
        nfev += 1
        if f < fbest:
            fbest = f
            best[:] = cand
    return best, fbest, nfev


@numba.njit(cache=True)
def arm_cost_many_nb(xs: FloatArray, geo: FloatArray, dmap: NDArray[np.float32]) -> FloatArray:
    """`arm_cost_nb` at each row of ``xs`` (N, 4); used for timing and grids."""
    out = np.empty(xs.shape[0])
    for i in range(xs.shape[0]):
        out[i] = arm_cost_nb(xs[i], geo, dmap)
    return out


# ------------------------------------------------------------------ Nelder-Mead


@numba.njit(cache=True)
def _sort_simplex(sim: FloatArray, fsim: FloatArray) -> None:
    """Stable sort of the vertices by value (insertion sort: SciPy's argsort on <= 16
    items is an insertion sort too, so ties keep the same order)."""
    n = fsim.shape[0]
    row = np.empty(sim.shape[1])
    for i in range(1, n):
        f = fsim[i]
        _row_to(sim, i, row)
        j = i - 1
        while j >= 0 and fsim[j] > f:
            fsim[j + 1] = fsim[j]
            _row_to(sim, j, sim[j + 1])
            j -= 1
        fsim[j + 1] = f
        _to_row(row, sim, j + 1)


# Element loops for the row copies of the simplex: slice assignment (``a[:] = b``)
# compiles to a broadcasting check with a formatted error path, several times the
# code of the loop, in every one of the dozen places the search copies a vertex.
# Plain calls, not ``inline="always"``: Numba's IR inlining re-runs its front end per
# call site (the search compiled in ~8 s instead of ~3 s), and LLVM inlines them anyway.
@numba.njit(cache=True)
def _row_to(m: FloatArray, i: int, out: FloatArray) -> None:
    """``out[:] = m[i]``."""
    for j in range(out.shape[0]):
        out[j] = m[i, j]


@numba.njit(cache=True)
def _to_row(v: FloatArray, m: FloatArray, i: int) -> None:
    """``m[i] = v``."""
    for j in range(v.shape[0]):
        m[i, j] = v[j]


@numba.njit(cache=True)
def _vec_to(v: FloatArray, out: FloatArray) -> None:
    """``out[:] = v``."""
    for j in range(v.shape[0]):
        out[j] = v[j]


@numba.njit(cache=True)
def _clip(x: FloatArray, lb: FloatArray, ub: FloatArray) -> None:
    for i in range(x.shape[0]):
        x[i] = min(max(x[i], lb[i]), ub[i])


# Caching. A jitted function that receives another dispatcher as an argument cannot
# be cached: the dispatcher's type differs in every process, so Numba saves a new
# entry each run and never finds it again (numba issue #9237), and a cached caller
# that passes one is refused as "uses dynamic globals". The simplex logic therefore
# lives once, in `_nelder_mead_core`, inlined at the IR level (``inline="always"``)
# into each caller before typing: there the cost argument is just the caller's
# module-level global. `nelder_mead_arm_nb` (production, the arm cost) has a plain
# signature and is cached; `nelder_mead_nb` (any cost, for tests against SciPy)
# cannot be and is compiled per process.


@numba.njit(inline="always")
def _nelder_mead_core(
    fun: Any,
    a: Any,
    b: Any,
    initial_simplex: FloatArray,
    lb: FloatArray,
    ub: FloatArray,
    xatol: float,
    fatol: float,
    maxfev: int,
) -> tuple[FloatArray, float, int, int, bool]:
    """Downhill simplex with SciPy's semantics; see `nelder_mead_nb` (never called from Python).

    Scalar loops throughout: NumPy array expressions here multiply the generated code
    (and compile time) several-fold. Each loop computes, element by element, the same
    expression in the same order as the SciPy line it transcribes (quoted), so the
    iterates are bit-identical.
    """
    rho = 1.0
    chi = 2.0
    psi = 0.5
    sigma = 0.5
    n = initial_simplex.shape[1]
    sim = initial_simplex.copy()
    # SciPy: reflect vertices above the upper bound into the interior, then clip
    for i in range(n + 1):
        for j in range(n):
            if sim[i, j] > ub[j]:
                sim[i, j] = 2.0 * ub[j] - sim[i, j]
            sim[i, j] = min(max(sim[i, j], lb[j]), ub[j])
    fsim = np.full(n + 1, np.inf)
    xt = np.empty(n)  # SciPy hands the cost a copy of the point
    nfev = 0
    for k in range(n + 1):
        if nfev >= maxfev:
            break
        _row_to(sim, k, xt)
        fsim[k] = fun(xt, a, b)
        nfev += 1
    _sort_simplex(sim, fsim)
    iterations = 1
    converged = False
    xbar = np.empty(n)
    xr = np.empty(n)
    xe = np.empty(n)
    xc = np.empty(n)
    while nfev < maxfev:
        # convergence test, as SciPy's: max |sim[1:] - sim[0]| <= xatol and
        # max |fsim[0] - fsim[1:]| <= fatol
        dx = 0.0
        df = 0.0
        for i in range(1, n + 1):
            for j in range(n):
                dx = max(dx, abs(sim[i, j] - sim[0, j]))
            df = max(df, abs(fsim[0] - fsim[i]))
        if dx <= xatol and df <= fatol:
            converged = True
            break
        # "xbar = np.add.reduce(sim[:-1], 0) / N": row after row, as NumPy's axis-0 reduce
        for j in range(n):
            acc = sim[0, j]
            for i in range(1, n):
                acc += sim[i, j]
            xbar[j] = acc / n
        # "xr = (1 + rho) * xbar - rho * sim[-1]"
        for j in range(n):
            xr[j] = (1 + rho) * xbar[j] - rho * sim[n, j]
        _clip(xr, lb, ub)
        _vec_to(xr, xt)
        fxr = fun(xt, a, b)
        nfev += 1
        doshrink = False
        if fxr < fsim[0]:
            if nfev >= maxfev:
                break
            # "xe = (1 + rho * chi) * xbar - rho * chi * sim[-1]"
            for j in range(n):
                xe[j] = (1 + rho * chi) * xbar[j] - rho * chi * sim[n, j]
            _clip(xe, lb, ub)
            _vec_to(xe, xt)
            fxe = fun(xt, a, b)
            nfev += 1
            if fxe < fxr:
                _to_row(xe, sim, n)
                fsim[n] = fxe
            else:
                _to_row(xr, sim, n)
                fsim[n] = fxr
        elif fxr < fsim[n - 1]:
            _to_row(xr, sim, n)
            fsim[n] = fxr
        else:
            if nfev >= maxfev:
                break
            if fxr < fsim[n]:
                # outside contraction: "xc = (1 + psi * rho) * xbar - psi * rho * sim[-1]"
                for j in range(n):
                    xc[j] = (1 + psi * rho) * xbar[j] - psi * rho * sim[n, j]
                _clip(xc, lb, ub)
                _vec_to(xc, xt)
                fxc = fun(xt, a, b)
                nfev += 1
                if fxc <= fxr:
                    _to_row(xc, sim, n)
                    fsim[n] = fxc
                else:
                    doshrink = True
            else:
                # inside contraction: "xcc = (1 - psi) * xbar + psi * sim[-1]"
                for j in range(n):
                    xc[j] = (1 - psi) * xbar[j] + psi * sim[n, j]
                _clip(xc, lb, ub)
                _vec_to(xc, xt)
                fxcc = fun(xt, a, b)
                nfev += 1
                if fxcc < fsim[n]:
                    _to_row(xc, sim, n)
                    fsim[n] = fxcc
                else:
                    doshrink = True
            if doshrink:
                for i in range(1, n + 1):
                    # "sim[j] = sim[0] + sigma * (sim[j] - sim[0])", then clipped
                    for j in range(n):
                        sim[i, j] = sim[0, j] + sigma * (sim[i, j] - sim[0, j])
                    _clip(sim[i], lb, ub)
                    if nfev >= maxfev:
                        # SciPy: the vertex has moved but its value is stale
                        break
                    _row_to(sim, i, xt)
                    fsim[i] = fun(xt, a, b)
                    nfev += 1
        iterations += 1
        _sort_simplex(sim, fsim)
    _sort_simplex(sim, fsim)
    return sim[0].copy(), fsim[0], nfev, iterations, converged


# not cache=True: a dispatcher argument defeats the on-disk cache (notes above) and
# would only add a new cache entry per process
@numba.njit
def nelder_mead_nb(
    fun: Any,
    a: Any,
    b: Any,
    initial_simplex: FloatArray,
    lb: FloatArray,
    ub: FloatArray,
    xatol: float,
    fatol: float,
    maxfev: int,
) -> tuple[FloatArray, float, int, int, bool]:
    """Downhill simplex with SciPy's semantics (``adaptive=False``, bounds by clipping).

    Generic in the cost; compiled anew in every process (a function argument defeats
    Numba's cache). The arm refinement uses `nelder_mead_arm_nb`, the same search on
    `arm_cost_nb`, which is cached.

    Parameters
    ----------
    fun : numba-compiled callable ``fun(x, a, b) -> float``
    a, b : any
        Extra arguments passed to ``fun``.
    initial_simplex : ndarray, shape (N + 1, N)
    lb, ub : ndarray, shape (N,)
        Bounds (``-inf``/``inf`` for none).
    xatol, fatol : float
        Stop when every vertex is within ``xatol`` of the best in every coordinate and
        every value within ``fatol`` of the best value.
    maxfev : int
        Evaluation budget.

    Returns
    -------
    x : ndarray (N,)
    fx : float
    nfev : int
    nit : int
    converged : bool
        Stopped on the tolerances.
    """
    return _nelder_mead_core(fun, a, b, initial_simplex, lb, ub, xatol, fatol, maxfev)


@numba.njit(cache=True)
def nelder_mead_arm_nb(
    geo: FloatArray,
    dmap: NDArray[np.float32],
    initial_simplex: FloatArray,
    lb: FloatArray,
    ub: FloatArray,
    xatol: float,
    fatol: float,
    maxfev: int,
) -> tuple[FloatArray, float, int, int, bool]:
    """`nelder_mead_nb` on `arm_cost_nb` (eq. 14) of one arm, cached on disk.

    Parameters
    ----------
    geo : ndarray, shape (102,)
        Packed arm geometry (`ArmProblem.geo`).
    dmap : ndarray of float32, shape (H, W)
        Truncated edge distance map of the arm's RoI, px.
    initial_simplex, lb, ub, xatol, fatol, maxfev
        As `nelder_mead_nb`, with ``N = 4`` (rad).

    Returns
    -------
    x, fx, nfev, nit, converged
        As `nelder_mead_nb`.
    """
    return _nelder_mead_core(arm_cost_nb, geo, dmap, initial_simplex, lb, ub, xatol, fatol, maxfev)


# ------------------------------------------------------------------ Python side


@dataclass(frozen=True, eq=False)
class ArmProblem:
    """One arm's refinement problem: the packed geometry and its distance map.

    Build with `arm_problem`. ``x`` vectors are the arm's 4 joint parameters
    (3 shoulder DoFs in product order, then the elbow), radians.

    Attributes
    ----------
    side : str
    dofs : ndarray of int, shape (4,)
        Indices of the arm's DoFs in the skeleton's ``q``.
    geo : ndarray, shape (102,)
        Packed geometry for the compiled kernels.
    distance : DistanceMap
    lower, upper : ndarray, shape (4,)
        Joint limits.
    x0 : ndarray, shape (4,)
        Start (the IK pose), clipped into the limits.
    maps : ndarray of float32, shape (K, h, w)
        The distance maps the cost reads (``geo`` holds their origin and grid step):
        the oriented ones when the frame has them, else the plain map as one bin.
    """

    side: str
    dofs: NDArray[np.int64]
    geo: FloatArray
    distance: DistanceMap
    lower: FloatArray
    upper: FloatArray
    x0: FloatArray
    maps: NDArray[np.float32]

    def cost(self, x: ArrayLike) -> float:
        """Eq. 14 at arm parameters ``x`` (4,)."""
        return float(arm_cost_nb(self._x(x), self.geo, self.maps))

    def cost_terms(self, x: ArrayLike) -> tuple[float, float]:
        """``(image term, hand offset mm)`` at ``x`` (4,)."""
        image, hand = arm_cost_terms_nb(self._x(x), self.geo, self.maps)
        return float(image), float(hand)

    def joints_mm(self, x: ArrayLike) -> FloatArray:
        """World shoulder, elbow, wrist and hand effector (4, 3) at ``x``."""
        out = np.empty((4, 3))
        arm_fk_nb(self._x(x), self.geo, out)
        return out

    def outline_px(self, x: ArrayLike, max_points: int = 4096) -> FloatArray:
        """The outline sample points (M, 2) px the chamfer reads at ``x``."""
        out = np.empty((max_points, 2))
        m = arm_outline_px_nb(self._x(x), self.geo, out)
        return out[:m]

    @staticmethod
    def _x(x: ArrayLike) -> FloatArray:
        xa = np.ascontiguousarray(x, dtype=np.float64)
        if xa.shape != (4,):
            raise ShapeError(f"arm parameters: expected shape (4,), found {xa.shape}")
        return xa


def arm_joint_names(side: str) -> tuple[str, str, str, str]:
    """Joint names ``(shoulder, elbow, hand, hand end)`` of an arm of the zhang21 layout."""
    if side not in _PREFIX:
        raise unknown_name("arm side", side, SIDES, "refine_arms")
    p = _PREFIX[side]
    return (f"{p}humerus", f"{p}radius", f"{p}hand", f"{p}hand_end")


def arm_dofs(skeleton: Skeleton, side: str) -> NDArray[np.int64]:
    """Indices (4,) of an arm's shoulder (3 revolute) and elbow (1 revolute) DoFs."""
    shoulder, elbow, _hand, _end = arm_joint_names(side)
    sd = skeleton.dofs_of_joint(shoulder)
    ed = skeleton.dofs_of_joint(elbow)
    kinds = skeleton.dof_kind
    if len(sd) != 3 or len(ed) != 1 or np.any(kinds[sd] != REVOLUTE) or kinds[ed[0]] != REVOLUTE:
        raise ShapeError(
            f"skeleton {skeleton.name!r}: arm refinement needs 3 revolute DoFs at {shoulder!r} and "
            f"1 at {elbow!r}; found {len(sd)} and {len(ed)} (kinds {kinds[sd].tolist()}, "
            f"{kinds[ed].tolist()})"
        )
    return np.concatenate([sd, ed]).astype(np.int64)


def pack_arm_geometry(
    skeleton: Skeleton,
    camera: Camera,
    q: ArrayLike,
    side: str,
    hand_target_mm: ArrayLike | None,
    config: RefineConfig,
    distance_origin_px: tuple[int, int] = (0, 0),
    world: FloatArray | None = None,
) -> FloatArray:
    """The flat geometry vector (102,) of one arm for the compiled kernels.

    Parameters
    ----------
    skeleton : Skeleton
    camera : Camera
    q : array_like, shape (D,)
        Full pose; fixes everything above the shoulder and the hand's own rotation.
    side : {"left", "right"}
    hand_target_mm : array_like, shape (3,), or None
        Hand target (world mm); None drops the hand term.
    config : RefineConfig
    distance_origin_px : (int, int)
        Image position of the distance map's first pixel.
    world : ndarray, shape (J, 4, 4), optional
        ``forward_kinematics(skeleton, q)`` if already computed.
    """
    shoulder, elbow, hand, _end = arm_joint_names(side)
    dofs = arm_dofs(skeleton, side)
    js = skeleton.joint_index(shoulder)
    je = skeleton.joint_index(elbow)
    jh = skeleton.joint_index(hand)
    if skeleton.parents[je] != js or skeleton.parents[jh] != je:
        raise ShapeError(
            f"skeleton {skeleton.name!r}: expected the chain {shoulder} -> {elbow} -> {hand}"
        )
    if world is None:
        world = forward_kinematics(skeleton, q)
    geo = np.zeros(_G_SIZE)
    parent = world[skeleton.parents[js]]
    geo[_G_PARENT_R : _G_PARENT_R + 9] = parent[:3, :3].ravel()
    geo[_G_PARENT_T : _G_PARENT_T + 3] = parent[:3, 3]
    geo[_G_OFFSETS : _G_OFFSETS + 9] = skeleton.offsets_mm[[js, je, jh]].ravel()
    geo[_G_AXES : _G_AXES + 12] = skeleton.dof_axis[dofs].ravel()
    hand_local = world[je, :3, :3].T @ world[jh, :3, :3]
    geo[_G_HAND_R : _G_HAND_R + 9] = hand_local.ravel()
    geo[_G_SEG_END : _G_SEG_END + 9] = skeleton.bone_end_mm[[js, je, jh]].ravel()
    geo[_G_RADII : _G_RADII + 6] = skeleton.radii_mm[[js, je, jh]].ravel()
    geo[_G_EFFECTOR : _G_EFFECTOR + 3] = np.asarray(
        config.effector_points_mm[SIDES.index(side)], dtype=float
    )
    if hand_target_mm is not None:
        t = np.asarray(hand_target_mm, dtype=float)
        if t.shape != (3,) or not np.all(np.isfinite(t)):
            raise ShapeError(
                f"hand_targets_mm[{side!r}]: expected 3 finite numbers (mm), found "
                f"shape {t.shape} {t.tolist()}"
            )
        geo[_G_TARGET : _G_TARGET + 3] = t
        geo[_G_USE_TARGET] = 1.0
    geo[_G_CAM_R : _G_CAM_R + 9] = camera.camera_from_world[:3, :3].ravel()
    geo[_G_CAM_T : _G_CAM_T + 3] = camera.camera_from_world[:3, 3]
    k = camera.K
    geo[_G_INTR : _G_INTR + 5] = (k[0, 0], k[1, 1], k[0, 2], k[1, 2], k[0, 1])
    dist = np.zeros(8)
    dd = np.asarray(camera.dist, dtype=float)
    if dd.shape[0] > 8 and np.any(dd[8:] != 0):
        raise ShapeError(
            f"camera {camera.name!r} dist: thin-prism/tilt terms are not supported by the arm "
            f"refinement; found {dd.tolist()}"
        )
    dist[: min(8, dd.shape[0])] = dd[:8]
    geo[_G_DIST : _G_DIST + 8] = dist
    geo[_G_ORIGIN : _G_ORIGIN + 2] = distance_origin_px
    geo[_G_CAP] = config.edges.cap_px
    geo[_G_MAP_STEP] = 1.0
    geo[_G_STEP] = config.sample_step_px
    geo[_G_LAMBDA] = config.hand_weight_px_per_mm
    geo[_G_LITERAL] = 1.0 if config.literal_sum else 0.0
    geo[_G_NSEG] = 3.0 if config.include_hand else 2.0
    axes = skeleton.dof_axis[dofs[:3]]
    basis = np.argmax(np.abs(axes), axis=1)
    if np.allclose(np.abs(axes[np.arange(3), basis]), 1.0) and len(set(basis.tolist())) == 3:
        geo[_G_EULER : _G_EULER + 3] = basis
        geo[_G_EULER + 3 : _G_EULER + 6] = np.sign(axes[np.arange(3), basis])
    else:
        geo[_G_EULER : _G_EULER + 6] = -1.0
    return geo


def arm_roi(
    skeleton: Skeleton,
    camera: Camera,
    world: FloatArray,
    side: str,
    pad_px: float,
    swivel_rad: float = 0.0,
) -> Roi:
    """Bounding box of the projected shoulder, elbow, wrist and hand end, padded (§5.2, Fig. 5).

    With a swivel scan of half-range ``swivel_rad`` the box also covers the elbow
    positions the scan visits: the arc of the circle the elbow describes about the
    shoulder-wrist axis (sampled every 15 deg), so no scanned pose falls outside it.
    """
    idx = [skeleton.joint_index(n) for n in arm_joint_names(side)]
    points = world[idx, :3, 3]
    if swivel_rad > 0:
        shoulder, elbow, wrist = points[0], points[1], points[2]
        axis = wrist - shoulder
        n = float(np.linalg.norm(axis))
        if n > 1e-9:
            axis /= n
            foot = shoulder + float((elbow - shoulder) @ axis) * axis
            u = elbow - foot
            v = np.cross(axis, u)
            angles = np.linspace(-swivel_rad, swivel_rad, max(3, int(swivel_rad / 0.26) * 2 + 1))
            arc = foot + np.cos(angles)[:, None] * u + np.sin(angles)[:, None] * v
            points = np.vstack([points, arc])
    return roi_around_points(camera.project(points), camera.image_size, pad_px)


def arm_problem(
    skeleton: Skeleton,
    camera: Camera,
    q: ArrayLike,
    side: str,
    frame: PreparedFrame | ArrayLike,
    hand_target_mm: ArrayLike | None,
    config: RefineConfig | None = None,
    world: FloatArray | None = None,
    previous_elbow_mm: ArrayLike | None = None,
    elbow_free_mm: float = 0.0,
) -> ArmProblem:
    """Build one arm's problem: RoI from the pose, its distance map, the packed geometry.

    Parameters
    ----------
    skeleton, camera : Skeleton, Camera
    q : array_like, shape (D,)
    side : {"left", "right"}
    frame : PreparedFrame or image array (H, W[, 3]) uint8
    hand_target_mm : array_like (3,) or None
    config : RefineConfig, optional
    world : ndarray (J, 4, 4), optional
        FK of ``q`` if already computed.
    previous_elbow_mm : array_like (3,), optional
        The previous frame's elbow (world mm) for the elbow-jump penalty; ignored when
        None, not finite, or ``config.elbow_jump_weight_per_mm`` is 0.
    elbow_free_mm : float
        Elbow displacement from ``previous_elbow_mm`` that costs nothing (mm).
    """
    cfg = config or RefineConfig()
    qa = np.asarray(q, dtype=float)
    skeleton.check_q(qa)
    if qa.ndim != 1:
        raise ShapeError(f"q: expected one pose of shape ({skeleton.n_dofs},), found {qa.shape}")
    if not isinstance(frame, PreparedFrame):
        frame = prepare_frame(frame, cfg.edges)
    if frame.image_size != camera.image_size:
        raise ShapeError(
            f"image: expected size {camera.image_size} (w, h) of camera {camera.name!r}, found "
            f"{frame.image_size}"
        )
    if world is None:
        world = forward_kinematics(skeleton, qa)
    roi = arm_roi(skeleton, camera, world, side, cfg.roi_pad_px, cfg.swivel_scan_rad)
    dmap = roi_distance_map(frame, roi, cfg.edges)
    geo = pack_arm_geometry(
        skeleton, camera, qa, side, hand_target_mm, cfg, dmap.origin_px, world=world
    )
    if previous_elbow_mm is not None and cfg.elbow_jump_weight_per_mm > 0:
        prev = np.asarray(previous_elbow_mm, dtype=float)
        if prev.shape == (3,) and np.all(np.isfinite(prev)):
            geo[_G_ELBOW_PREV : _G_ELBOW_PREV + 3] = prev
            geo[_G_ELBOW_W] = cfg.elbow_jump_weight_per_mm
            geo[_G_ELBOW_FREE] = elbow_free_mm
    dofs = arm_dofs(skeleton, side)
    lower = np.ascontiguousarray(skeleton.lower[dofs], dtype=float)
    upper = np.ascontiguousarray(skeleton.upper[dofs], dtype=float)
    x0 = np.clip(qa[dofs], lower, upper)
    if dmap.oriented_px is not None and not cfg.literal_sum:
        maps = dmap.oriented_px
        geo[_G_ORIGIN : _G_ORIGIN + 2] = dmap.oriented_origin_px
        geo[_G_MAP_STEP] = float(dmap.oriented_step_px)
    else:
        maps = np.ascontiguousarray(dmap.distance_px[None])
    return ArmProblem(side, dofs, geo, dmap, lower, upper, x0, maps)


def initial_simplex(x0: FloatArray, step_rad: float) -> FloatArray:
    """Recipe Z step 4: ``x0`` and ``x0 + step * e_k`` for each DoF, shape (N + 1, N)."""
    n = x0.shape[0]
    sim = np.repeat(x0[None, :], n + 1, axis=0)
    sim[1:] += step_rad * np.eye(n)
    return sim


def solve_arm(problem: ArmProblem, config: RefineConfig) -> tuple[FloatArray, ArmDiagnostics]:
    """Run the downhill simplex on one arm problem; returns the best ``x`` (4,) and diagnostics."""
    diag = ArmDiagnostics(side=problem.side, roi=problem.distance.roi)
    dmap = problem.maps
    x0 = problem.x0
    diag.cost_before = problem.cost(x0)
    diag.chamfer_before, diag.hand_offset_before_mm = problem.cost_terms(x0)
    start, n_scan = x0, 0
    if config.swivel_scan_rad > 0 and config.swivel_scan_steps > 1:
        start, _f, n_scan = swivel_scan_nb(
            x0,
            problem.geo,
            dmap,
            config.swivel_scan_rad,
            config.swivel_scan_steps,
            problem.lower,
            problem.upper,
        )
    sim = initial_simplex(start, config.simplex_step_rad)
    if config.solver == "scipy":
        from scipy.optimize import Bounds, minimize

        geo = problem.geo
        res = minimize(
            lambda x: arm_cost_nb(x, geo, dmap),
            start,
            method="Nelder-Mead",
            bounds=Bounds(problem.lower, problem.upper),
            options={
                "initial_simplex": sim,
                "xatol": config.xatol,
                "fatol": config.fatol,
                "maxfev": config.maxfev,
            },
        )
        x = np.asarray(res.x, dtype=float)
        nfev, nit, conv = int(res.nfev), int(res.nit), bool(res.status == 0)
    else:
        x, _fx, nfev, nit, conv = nelder_mead_arm_nb(
            problem.geo,
            dmap,
            sim,
            problem.lower,
            problem.upper,
            config.xatol,
            config.fatol,
            config.maxfev,
        )
    diag.refined = True
    diag.cost_after = problem.cost(x)
    diag.chamfer_after, diag.hand_offset_after_mm = problem.cost_terms(x)
    diag.n_evaluations, diag.n_iterations, diag.converged = nfev + n_scan, nit, conv
    return x, diag


def refine_arms(
    skeleton: Skeleton,
    camera: Camera,
    q: ArrayLike,
    image: ArrayLike | PreparedFrame,
    hand_targets_mm: Mapping[str, ArrayLike | None],
    config: RefineConfig | None = None,
    *,
    diagnostics: dict[str, ArmDiagnostics] | None = None,
    previous_elbows_mm: Mapping[str, ArrayLike] | None = None,
    elapsed_s: float = 0.0,
) -> FloatArray:
    """Refine both arms of an IK pose against one video frame (Zhang et al. §5).

    Each arm present in ``hand_targets_mm`` is refined on its own (§5.2): RoI around its
    projected joints, truncated edge distance map inside it, downhill simplex over its
    4 DoFs from the IK pose. The rest of ``q`` is returned unchanged.

    Parameters
    ----------
    skeleton : Skeleton
        A zhang21-layout model (joints ``l_humerus``/``l_radius``/``l_hand``, ``r_...``).
    camera : Camera
        Calibrated camera of the frame.
    q : array_like, shape (D,)
        Joint parameters after IK (rad, mm).
    image : array_like of uint8, shape (H, W) or (H, W, 3), or PreparedFrame
        Grey or BGR video frame nearest the marker sample.
    hand_targets_mm : mapping {"left"|"right": array (3,) or None}
        Hand effector targets (world mm). A side that is absent or None is not refined.
        The marker-set names ``"left_hand"``/``"right_hand"`` are accepted as well.
    config : RefineConfig, optional
    diagnostics : dict, optional
        When given, receives one `ArmDiagnostics` per side.
    previous_elbows_mm : mapping {"left"|"right": array (3,)}, optional
        Each side's elbow in the previous frame (world mm), for the elbow-jump penalty
        (`RefineConfig.elbow_jump_weight_per_mm`); a side that is absent has none.
    elapsed_s : float
        Time since that frame (s); the free distance is
        ``config.elbow_speed_mm_per_s * elapsed_s``.

    Returns
    -------
    ndarray, shape (D,)
        The refined pose.
    """
    cfg = config or RefineConfig()
    qa = np.array(q, dtype=float)
    skeleton.check_q(qa)
    if qa.ndim != 1:
        raise ShapeError(f"q: expected one pose of shape ({skeleton.n_dofs},), found {qa.shape}")
    by_side: dict[str, ArrayLike | None] = {}
    for key, value in hand_targets_mm.items():
        if key not in _SIDE_OF_KEY:
            raise unknown_name("arm side", key, _SIDE_OF_KEY, "hand_targets_mm")
        by_side[_SIDE_OF_KEY[key]] = value
    frame = image if isinstance(image, PreparedFrame) else prepare_frame(image, cfg.edges)
    world = forward_kinematics(skeleton, qa)
    out = qa.copy()
    for side in SIDES:
        t0 = time.perf_counter()
        target = by_side.get(side)
        if target is None:
            if diagnostics is not None:
                diagnostics[side] = ArmDiagnostics(side=side, reason="no hand target")
            continue
        prev = None if previous_elbows_mm is None else previous_elbows_mm.get(side)
        problem = arm_problem(
            skeleton,
            camera,
            qa,
            side,
            frame,
            target,
            cfg,
            world=world,
            previous_elbow_mm=prev,
            elbow_free_mm=cfg.elbow_speed_mm_per_s * elapsed_s,
        )
        if problem.distance.distance_px.size == 0:
            if diagnostics is not None:
                diagnostics[side] = ArmDiagnostics(
                    side=side, roi=problem.distance.roi, reason="arm RoI outside the image"
                )
            continue
        x, diag = solve_arm(problem, cfg)
        out[problem.dofs] = x
        diag.elapsed_ms = (time.perf_counter() - t0) * 1e3
        if diagnostics is not None:
            diagnostics[side] = diag
    return out


def swivel_arm(skeleton: Skeleton, q: ArrayLike, side: str, angle_rad: float) -> FloatArray:
    """Rotate an arm about its shoulder-wrist axis, keeping the wrist in place (the IK ambiguity).

    The upper arm's world rotation is pre-multiplied by the rotation of ``angle_rad``
    about the shoulder->wrist axis; the elbow angle is unchanged, so the wrist stays
    put (Azad's swivel angle). The new shoulder rotation is decomposed back onto the
    shoulder's three revolute axes, which must be distinct signed basis vectors.

    Parameters
    ----------
    skeleton : Skeleton
    q : array_like, shape (D,)
    side : {"left", "right"}
    angle_rad : float
        Right-handed rotation about the shoulder->wrist direction.

    Returns
    -------
    ndarray, shape (D,)
        Not clipped to joint limits.
    """
    from scipy.spatial.transform import Rotation

    qa = np.array(q, dtype=float)
    skeleton.check_q(qa)
    dofs = arm_dofs(skeleton, side)
    shoulder, _elbow, hand, _end = arm_joint_names(side)
    js, jh = skeleton.joint_index(shoulder), skeleton.joint_index(hand)
    world = forward_kinematics(skeleton, qa)
    s, h = world[js, :3, 3], world[jh, :3, 3]
    axis = h - s
    if np.linalg.norm(axis) < 1e-9:
        raise ShapeError(f"swivel_arm: the {side} wrist coincides with the shoulder")
    swivel = Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle_rad).as_matrix()
    parent_r = world[skeleton.parents[js], :3, :3]
    local = parent_r.T @ swivel @ world[js, :3, :3]
    axes = skeleton.dof_axis[dofs[:3]]
    letters, signs = "", np.empty(3)
    for k, a in enumerate(axes):
        i = int(np.argmax(np.abs(a)))
        if not np.isclose(abs(a[i]), 1.0):
            raise ShapeError(f"swivel_arm: shoulder axis {a.tolist()} is not a basis vector")
        letters += "XYZ"[i]
        signs[k] = np.sign(a[i])
    if len(set(letters)) != 3:
        raise ShapeError(f"swivel_arm: shoulder axes {letters!r} are not three distinct axes")
    qa[dofs[:3]] = Rotation.from_matrix(local).as_euler(letters) * signs
    return qa


__all__ = [
    "SIDES",
    "ArmDiagnostics",
    "ArmProblem",
    "RefineConfig",
    "arm_cost_many_nb",
    "arm_cost_nb",
    "arm_cost_terms_nb",
    "arm_dofs",
    "arm_fk_nb",
    "arm_joint_names",
    "arm_outline_px_nb",
    "arm_problem",
    "arm_roi",
    "cone_contour_generators_nb",
    "initial_simplex",
    "nelder_mead_arm_nb",
    "nelder_mead_nb",
    "pack_arm_geometry",
    "project_points_nb",
    "refine_arms",
    "solve_arm",
    "swivel_arm",
    "swivel_scan_nb",
    "swivel_x_nb",
]
