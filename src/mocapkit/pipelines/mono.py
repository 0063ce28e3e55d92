"""File runner of the monocular tracker: a session's 2-D keypoints (or OpenPose JSON) in,
a result folder out (``motion.npz``, ``joints.csv``, ``motion.bvh``, ``fit.csv``).

The runner reads the keypoints of one camera, estimates the link lengths from the whole
2-D sequence (§4.1; or takes the session's measured lengths with ``session_lengths``),
feeds `mocapkit.tracking.mono.tracker.MonoTracker` frame by frame, places the poses in
the camera's world frame and writes the result. ``fit.csv`` holds per frame the 2-D
residual (px), the candidates before pruning, the survivors, whether all were pruned and
the neck's depth.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.errors import ConfigError, SessionError, ShapeError
from mocapkit.io.motion import Motion
from mocapkit.io.session import Session, load_session
from mocapkit.io.session_csv import Keypoints, read_keypoints_csv
from mocapkit.pipelines.run import check_result_folder, run_tracker
from mocapkit.progress import Progress
from mocapkit.skeleton.model import CANONICAL_JOINTS, Skeleton
from mocapkit.skeleton.presets import load_preset
from mocapkit.skeleton.scaling import fit_segments
from mocapkit.tracking.base import BRIDGE_S, FrameResult, unobserved_part
from mocapkit.tracking.mono.lengths import (
    ANTHROPOMETRIC_RATIOS,
    estimate_link_lengths,
    pixels_per_mm,
    raise_short_links,
)
from mocapkit.tracking.mono.pose_fit import fit_stick_pose
from mocapkit.tracking.mono.smoother import smooth_keypoints
from mocapkit.tracking.mono.stick import StickModel, stick_model
from mocapkit.tracking.mono.tracker import MonoConfig, MonoFrame, MonoTracker

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SkinOptions:
    """How `skin_keypoints` reads the stick's 2-D joints off a video by skin blobs.

    Attributes
    ----------
    bare_from : {None, "elbow", "mid_upper_arm", "shoulder"}
        Where the arms' skin starts (`SkinTracker`'s ``bare_from``); None: the paper's
        rule, the arm ellipse's ends are the elbow and wrist.
    trunk_from_head : bool
        In frames without a waist blob (the paper's belt), draw an upright trunk from
        the head ellipse (`SkinTracker`'s ``trunk_from_head``); False: those frames have
        no pelvis and shoulders.
    belt, reacquire : bool
        The subject wears the paper's belt, and lost hand labels are taken up again
        (`SkinTracker`'s ``belt`` and ``reacquire``).
    girdle_neck : bool
        The neck moved from the head blob's lower end down to the stick's neck base
        (`girdle_neck_px`, where the shoulders and pelvis are seen).
    """

    bare_from: str | None = None
    trunk_from_head: bool = True
    belt: bool = False
    reacquire: bool = False
    girdle_neck: bool = False


#: The `SkinOptions` each costume implies (``mocapkit track mono --skin --costume``,
#: ``mocapkit accuracy mono --skin``). Paper (its §3.3 costume: a dress to the elbows,
#: bare forearms, a golden belt): the skin runs from the elbow to the fingertips
#: (``bare_from`` elbow: the elbow and wrist on the blob at the visible lengths'
#: fractions); the trunk from the belt, no drawn trunk (``trunk_from_head`` off: frames
#: without the belt have none); the waist labelled among fewer than four blobs and taken
#: up again (``belt``); lost hands given to blobs on their side (``reacquire``); the neck
#: moved from the shoulders' level to the stick's neck base (``girdle_neck``). Everyday:
#: the skin from the middle of the upper arm (short sleeves) and the trunk drawn from the
#: head (no belt). docs/mono.md, eighth round.
SKIN_SETTINGS: dict[str, SkinOptions] = {
    "paper": SkinOptions(
        bare_from="elbow", trunk_from_head=False, belt=True, reacquire=True, girdle_neck=True
    ),
    "everyday": SkinOptions(bare_from="mid_upper_arm", trunk_from_head=True),
}


def costume_skin_options(costume: str, **overrides: Any) -> SkinOptions:
    """A costume's `SKIN_SETTINGS` with ``overrides`` (fields of `SkinOptions`, e.g.
    ``bare_from="shoulder"``) on top.

    Raises
    ------
    ConfigError
        ``costume`` is not a key of `SKIN_SETTINGS`.
    """
    if costume not in SKIN_SETTINGS:
        raise ConfigError(f"costume: expected one of {', '.join(SKIN_SETTINGS)}, found {costume!r}")
    return replace(SKIN_SETTINGS[costume], **overrides)


@dataclass
class MonoRun:
    """What `track_mono` produced.

    Attributes
    ----------
    motion : Motion
    frames : list of MonoFrame
    lengths : (L,) float
        Link lengths used (mm; px for the orthographic model).
    model : StickModel
    px_per_mm : float
        Image scale used to turn orthographic px into mm (NaN for the other models).
    results : list of MonoResult
        The last pass's per-frame results, as written to ``fit.csv``.
    input_px : (T, K, 2) float
        The 2-D joints of ``model`` the tracker was given (px), NaN where unseen.
    """

    motion: Motion
    frames: list[MonoFrame]
    lengths: FloatArray
    model: StickModel
    px_per_mm: float
    results: list[MonoResult] = field(default_factory=list)
    input_px: FloatArray = field(default_factory=lambda: np.zeros((0, 0, 2)))

    def summary(self) -> dict[str, float]:
        """Mean survivors, candidates, share pruned, residual (px) and frames with a pose."""
        posed = [f for f in self.frames if f.code >= 0]
        cand = np.array([f.n_candidates for f in posed], dtype=float)
        surv = np.array([f.n_survivors for f in posed], dtype=float)
        share = 1.0 - surv / np.maximum(cand, 1.0)
        return {
            "frames": float(len(self.frames)),
            "posed_frames": float(len(posed)),
            "candidates_mean": float(cand.mean()) if posed else float("nan"),
            "survivors_mean": float(surv.mean()) if posed else float("nan"),
            "pruned_share_mean": float(share.mean()) if posed else float("nan"),
            "all_pruned_frames": float(sum(f.pruned_all for f in posed)),
            "residual_px_mean": float(np.nanmean([f.residual_px for f in posed]))
            if posed
            else float("nan"),
        }


def load_keypoints(
    session: Session, camera: str, keypoints: str | os.PathLike[str] | None
) -> Keypoints:
    """The 2-D keypoints of one camera: the session's, a CSV file, or an OpenPose folder.

    An OpenPose folder takes the frame times of the camera's video (one JSON per frame).
    """
    if keypoints is None:
        session.require(keypoints=True, cameras=[camera])
        return session.keypoints[camera]
    p = Path(keypoints)
    if p.is_dir():
        from mocapkit.io.openpose import read_openpose_folder

        if camera in session.video_cameras:
            times = session.video(camera).time_s
        elif camera in session.keypoints:
            times = session.keypoints[camera].time_s
        else:
            raise SessionError(
                f"{session.path}: no frame times for camera {camera!r} (no video, no keypoints "
                "CSV) to stamp the OpenPose frames with"
            )
        return read_openpose_folder(p, times)
    return read_keypoints_csv(p)


def detector_config(config: MonoConfig) -> MonoConfig:
    """``config`` for 2-D whose neck and pelvis are rebuilt from the shoulders and hips.

    A detector (OpenPose JSON, `mocapkit.io.openpose`) marks neither our neck nor our
    pelvis; both are placed on the hip-to-shoulder midpoint line, so the two clavicles are
    mirror images of each other in the image and a few px of the neck's error (its offset
    across the line, its fraction along it) change their 40 px projected lengths by up to
    10 %, which decides their flips near the image plane (docs/mono.md, seventh round).
    The tracker then widens the reach band of the clavicles
    (``rebuilt_reach_tolerance``: both flips kept, each some way out of the plane) and
    lets the rigid girdle choose between them (``girdle_weight``, the angle between the
    clavicles that the placement assumes, `mocapkit.io.openpose.GIRDLE_COSINE`; in the
    length passes too, the band there off as ``reach_tolerance`` is).
    """
    from mocapkit.io.openpose import GIRDLE_COSINE, REBUILT_JOINTS

    return replace(config, rebuilt_joints=REBUILT_JOINTS, girdle_cosine=GIRDLE_COSINE)


def skin_keypoints(session: Session, camera: str, options: SkinOptions | None = None) -> Keypoints:
    """2-D joints of the stick from the camera's video by skin blobs (paper §3.3).

    `mocapkit.tracking.mono.skin_tracking.SkinTracker` on every frame, set by ``options``
    (default `SkinOptions()`: the paper's rules, and without a waist blob an upright
    trunk drawn from the head; the synthetic sessions in everyday clothing and the real
    videos have no belt).
    """
    from mocapkit.tracking.mono.skin_tracking import SKIN_JOINTS, SkinTracker

    opt = options or SkinOptions()
    video = session.video(camera)
    tracker = SkinTracker(
        trunk_from_head=opt.trunk_from_head,
        bare_from=opt.bare_from,
        belt=opt.belt,
        reacquire=opt.reacquire,
    )
    px = np.full((video.n_frames, len(SKIN_JOINTS), 2), np.nan)
    stream = video.open()
    try:
        with Progress(video.n_frames, "skin blobs") as prog:
            for k in range(video.n_frames):
                stream.advance_to(k)
                px[k] = tracker.update(stream.retrieve(k)).joints_px
                prog.update()
    finally:
        stream.close()
    if opt.girdle_neck:
        px[:, SKIN_JOINTS.index("neck")] = girdle_neck_px(px, SKIN_JOINTS)
    return Keypoints(video.time_s, SKIN_JOINTS, px, f"{video.path} (skin blobs)")


def girdle_neck_px(pixels: FloatArray, joint_names: Sequence[str]) -> FloatArray:
    """The stick's neck (T, 2) px from the paper's shoulders and pelvis (§3.3).

    The paper's shoulders lie "in horizontal line with the lower end of the neck" (the
    head blob's lower end), so its neck is the shoulders' level; the stick's neck is the
    base of the neck, `mocapkit.io.openpose.NECK_BELOW_SHOULDERS` d = 0.205 shoulder
    widths W below the shoulder midpoint M_s along the trunk (the CMU clips' rigid
    girdle). With the clavicle c = sqrt(1/4 + d^2) W and the trunk T (neck to pelvis) of
    `ANTHROPOMETRIC_RATIOS`, the neck lies the fraction d W / (T + d W) = 0.178 of the way
    from M_s to the pelvis, in the image too (orthographic ratios along a line), so the
    offset shortens as the trunk does. Frames without both shoulders and the pelvis keep
    the input's neck.

    Parameters
    ----------
    pixels : (T, K, 2) float
        Joints px, NaN where unseen, with neck, pelvis and both shoulders among them.
    joint_names : sequence of str
    """
    from mocapkit.io.openpose import NECK_BELOW_SHOULDERS as d

    px = np.asarray(pixels, dtype=float)
    i = {n: joint_names.index(n) for n in ("neck", "pelvis", "left_shoulder", "right_shoulder")}
    r = ANTHROPOMETRIC_RATIOS
    width = r["left_clavicle"] / math.sqrt(0.25 + d * d)
    frac = d * width / (r["trunk"] + d * width)
    m_s = 0.5 * (px[:, i["left_shoulder"]] + px[:, i["right_shoulder"]])
    neck = m_s + frac * (px[:, i["pelvis"]] - m_s)
    return np.where(np.isfinite(neck), neck, px[:, i["neck"]])


def stick_pixels(keypoints: Keypoints, model: StickModel) -> FloatArray:
    """The stick's joints (T, K, 2) out of a keypoints table (refused when one is absent)."""
    missing = [n for n in model.joint_names if n not in keypoints.joint_names]
    if missing:
        raise SessionError(
            f"{keypoints.source}: keypoints lack joints {missing} that the mono tracker needs "
            f"(found {list(keypoints.joint_names)})"
        )
    idx = [keypoints.joint_names.index(n) for n in model.joint_names]
    return np.asarray(keypoints.pixels[:, idx], dtype=float)


def _image_coordinates(pixels: FloatArray, camera: Camera | None, orthographic: bool) -> FloatArray:
    if orthographic or camera is None:
        return pixels
    out = np.full_like(pixels, np.nan)
    ok = np.isfinite(pixels).all(axis=-1)
    out[ok] = camera.undistort_pixels(pixels[ok])
    return out


def video_lengths(
    pixels: FloatArray,
    model: StickModel,
    camera: Camera | None,
    config: MonoConfig,
    dt_s: float,
    height_mm: float | None,
) -> tuple[FloatArray, float]:
    """Link lengths from the video (§4.1) and the image scale.

    Returns lengths in mm (px for the orthographic model) and, for the orthographic
    model, px per mm (else NaN). The 2-D points are smoothed first, as the tracker sees
    them. Calibrated models measure in undistorted normalised coordinates and reach mm
    through the stature (``height_mm``, else `DEFAULT_HEIGHT_MM`).
    """
    ortho = config.camera_model == "orthographic" or camera is None
    sm = smooth_keypoints(
        pixels, dt_s, config.smooth_lag, config.noise_px, config.accel_px_s2, config.max_gap
    )
    xy = _image_coordinates(sm, camera, ortho)
    proj = np.linalg.norm(xy[:, model.child] - xy[:, model.parent], axis=-1)
    lengths, stature = estimate_link_lengths(proj, model.segments)
    scale = pixels_per_mm(stature, height_mm)  # image units per mm
    if ortho:
        return lengths, scale
    return lengths / scale, float("nan")


def initial_pose_from(
    joint_names: Sequence[str], joints_mm: FloatArray, model: StickModel
) -> FloatArray:
    """The stick's joints (K, 3) out of one pose of named joints (world frame, mm).

    For `track_mono`'s ``initial_pose``: e.g. the first row of a ``joints.csv``
    (`mocapkit.io.joints_csv.read_joints_csv`) or of a session's truth. Joints of the
    stick that the pose lacks are NaN; the neck is required.
    """
    p = np.asarray(joints_mm, dtype=float)
    if p.shape != (len(joint_names), 3):
        raise ShapeError(
            f"initial pose: expected ({len(joint_names)}, 3) positions of {list(joint_names)}, "
            f"found {p.shape}"
        )
    names = list(joint_names)
    if model.joint_names[0] not in names:
        raise SessionError(
            f"initial pose: expected the joint {model.joint_names[0]!r} (the stick's root), "
            f"found {names}"
        )
    out = np.full((model.n_joints, 3), np.nan)
    for k, n in enumerate(model.joint_names):
        if n in names:
            out[k] = p[names.index(n)]
    return out


def session_lengths(session: Session, model: StickModel) -> FloatArray:
    """The session's measured link lengths (mm), refused when one is missing."""
    missing = [s for s in model.segments if s not in session.bone_lengths_mm]
    if missing:
        raise SessionError(
            f"{session.path}: session.json subject.bone_lengths_mm lacks {missing} "
            f"(the mono tracker's links: {list(model.segments)})"
        )
    return np.array([session.bone_lengths_mm[s] for s in model.segments])


def output_skeleton(model: StickModel, lengths_mm: FloatArray) -> Skeleton:
    """``upper_stick`` fitted to the tracked link lengths (mm)."""
    sk = load_preset("upper_stick")
    fitted = {s: float(v) for s, v in zip(model.segments, lengths_mm) if s in _UPPER_SEGMENTS}
    return fit_segments(sk, fitted)


_UPPER_SEGMENTS = (
    "trunk", "head", "left_clavicle", "right_clavicle", "left_upper_arm", "right_upper_arm",
    "left_forearm", "right_forearm",
)  # fmt: skip


def to_world(
    frames: list[MonoFrame],
    model: StickModel,
    camera: Camera | None,
    config: MonoConfig,
    px_per_mm: float,
) -> FloatArray:
    """Tracked joints (T, K, 3) in the world frame (mm).

    Calibrated models are already in the camera frame (mm). The orthographic model's px
    are scaled to mm and, with a camera, placed at the depth where the scale holds
    (``f / px_per_mm``) on the camera's axis; without one, in a frame with x right, y the
    depth and z up.
    """
    cam_pts = np.stack([f.joints_in_camera for f in frames])
    if config.camera_model != "orthographic" and camera is not None:
        return _apply(camera, cam_pts)
    mm = cam_pts / px_per_mm
    if camera is None:
        return np.stack([mm[..., 0], mm[..., 2], -mm[..., 1]], axis=-1)
    k = camera.K
    depth = k[0, 0] / px_per_mm
    pts = np.stack(
        [
            (cam_pts[..., 0] - k[0, 2]) / px_per_mm,
            (cam_pts[..., 1] - k[1, 2]) / px_per_mm,
            depth + mm[..., 2],
        ],
        axis=-1,
    )
    return _apply(camera, pts)


def _apply(camera: Camera, points_in_camera: FloatArray) -> FloatArray:
    from mocapkit.geometry.transforms import transform_points

    flat = points_in_camera.reshape(-1, 3)
    return transform_points(camera.world_from_camera, flat).reshape(points_in_camera.shape)


def _run(
    lengths: FloatArray,
    cam: Camera | None,
    dt: float,
    cfg: MonoConfig,
    model: StickModel,
    t: FloatArray,
    px: FloatArray,
) -> list[MonoFrame]:
    tracker = MonoTracker(lengths, cam, dt, cfg, model)
    frames: list[MonoFrame] = []
    with Progress(len(t), "track mono") as prog:
        for ti, p in zip(t, px):
            frames += tracker.push(float(ti), p)
            prog.update()
    frames += tracker.finish()
    frames.sort(key=lambda f: f.index)
    return frames


@dataclass
class MonoSample:
    """One frame for `MonoStream`: the stick's joints (K, 2) px, NaN where unseen."""

    time_s: float
    points_px: FloatArray


#: Limbs whose status a `MonoResult` reports, by the stick joint at their end.
MONO_LIMBS: dict[str, str] = {
    "head": "head",
    "left_arm": "left_wrist",
    "right_arm": "right_wrist",
    "left_leg": "left_ankle",
    "right_leg": "right_ankle",
}


@dataclass
class MonoResult(FrameResult):
    """A `FrameResult` of the mono tracker, keeping its `MonoFrame`.

    ``status`` per limb of `MONO_LIMBS` the stick has, from the joints that the limb
    alone places (`mocapkit.tracking.base.unobserved_part`: elbow and wrist of an arm,
    knee and ankle of a leg, the head): ``seen`` (all of them in this frame's 2-D points
    and posed), ``bridged`` (posed, one of them read off the smoother over a gap of at
    most ``bridge_s`` since the limb was last seen whole), ``released`` (no pose for them
    after having one, or unseen for longer than ``bridge_s``), ``missing`` (never posed
    yet). The runner sets the joints of a released or missing limb to NaN, as for every
    tracker (`mocapkit.pipelines.run.unobserved_to_nan`). ``fit``: ``residual_px`` (mean
    2-D distance of the chosen pose's projection to the input points), ``candidates``
    and ``survivors`` (poses before and after pruning), ``all_pruned`` (1 where every
    pose was pruned and the unpruned set kept), ``depth_mm`` (neck depth; NaN
    orthographic) and ``flips`` (the chosen flip code, -1 without a pose).
    """

    frame: MonoFrame | None = None


class MonoStream:
    """`MonoTracker` as a `mocapkit.tracking.base.DelayedTracker` of world results.

    Each frame the tracker makes final is placed in the world (`to_world`), its
    ``upper_stick`` pose fitted (`mocapkit.tracking.mono.pose_fit.fit_stick_pose`) and
    returned as a `MonoResult`. Offline (``config.lag`` None) every result comes from
    ``finish``; online, the result of frame k comes with frame k + ``smooth_lag + lag``.

    Parameters
    ----------
    tracker : MonoTracker
    skeleton : Skeleton
        `output_skeleton` of the tracker's lengths.
    camera : Camera or None
    px_per_mm : float
        Image scale (orthographic model; NaN otherwise).
    bridge_s : float
        Longest gap (s) in a limb's 2-D points that its status calls ``bridged``
        (`mocapkit.tracking.base.BRIDGE_S`, as the hybrid and stereo trackers).
    """

    def __init__(
        self,
        tracker: MonoTracker,
        skeleton: Skeleton,
        camera: Camera | None,
        px_per_mm: float,
        bridge_s: float = BRIDGE_S,
    ) -> None:
        self.tracker = tracker
        self.skeleton = skeleton
        self.camera = camera
        self.px_per_mm = px_per_mm
        model = tracker.model
        self.joint_names = tuple(n for n in CANONICAL_JOINTS if n in model.joint_names)
        self._order = [model.joint_names.index(n) for n in self.joint_names]
        self._rows = [CANONICAL_JOINTS.index(n) for n in self.joint_names]
        self._limbs: dict[str, list[int]] = {}
        for limb, end in MONO_LIMBS.items():
            part = unobserved_part(limb)
            if end in model.joint_names and part is not None:
                self._limbs[limb] = [
                    model.joint_names.index(j) for j in part[1] if j in model.joint_names
                ]
        self.bridge_s = bridge_s
        self._raw: list[FloatArray] = []
        self._times: list[float] = []
        self._posed: set[str] = set()

    def push(self, sample: MonoSample) -> list[FrameResult]:
        """Track one frame; returns the results it makes final."""
        self._raw.append(np.asarray(sample.points_px, dtype=float))
        self._times.append(float(sample.time_s))
        return [self._result(f) for f in self.tracker.push(sample.time_s, sample.points_px)]

    def finish(self) -> list[FrameResult]:
        """The results still pending (all of them offline)."""
        return [self._result(f) for f in self.tracker.finish()]

    def _result(self, f: MonoFrame) -> MonoResult:
        t = self.tracker
        world = to_world([f], t.model, self.camera, t.config, self.px_per_mm)[0]
        joints = world[self._order]
        q = fit_stick_pose(self.skeleton, self.joint_names, joints[None])[0]
        canonical = np.full((len(CANONICAL_JOINTS), 3), np.nan)
        canonical[self._rows] = joints
        status = {}
        for limb, js in self._limbs.items():
            if f.code >= 0 and np.all(np.isfinite(world[js])):
                self._posed.add(limb)
                unseen_s = self._unseen_s(f.index, js)
                status[limb] = (
                    "seen"
                    if unseen_s == 0.0
                    else "bridged"
                    if unseen_s <= self.bridge_s
                    else "released"
                )
            else:
                status[limb] = "released" if limb in self._posed else "missing"
        fit = {
            "residual_px": f.residual_px,
            "candidates": float(f.n_candidates),
            "survivors": float(f.n_survivors),
            "all_pruned": float(f.pruned_all),
            "depth_mm": f.depth_mm,
            "flips": float(f.code),
        }
        return MonoResult(f.time_s, q, canonical, status, fit, "", frame=f)

    def _unseen_s(self, k: int, joints: list[int]) -> float:
        """Time (s) since frame ``k``'s limb ``joints`` were last all in the 2-D points
        (0 when they are in frame k's; inf when never before)."""
        i = k
        while i >= 0 and not np.all(np.isfinite(self._raw[i][joints])):
            if self._times[k] - self._times[i] > self.bridge_s:
                return math.inf
            i -= 1
        return math.inf if i < 0 else self._times[k] - self._times[i]


def online_mono_stream(
    session: Session, camera: str, config: MonoConfig, dt_s: float
) -> MonoStream:
    """The online mono tracker on a session's camera with its measured link lengths
    (``session.json`` ``subject.bone_lengths_mm``): what ``track mono --session-lengths
    --lag L`` runs, for samples that come one at a time (`mocapkit.pipelines.live`).

    Raises
    ------
    ConfigError
        ``config.lag`` is None (offline) or the model is orthographic (its scale is read
        off the whole video).
    """
    if config.lag is None:
        raise ConfigError("online mono: expected MonoConfig.lag (frames), found None (offline)")
    if config.camera_model == "orthographic":
        raise ConfigError("online mono: the orthographic model needs the whole video's scale")
    model = stick_model(config.legs, config.limits)
    lengths = session_lengths(session, model)
    cam = session.camera(camera)
    tracker = MonoTracker(lengths, cam, dt_s, config, model)
    return MonoStream(tracker, output_skeleton(model, lengths), cam, float("nan"))


def refined_lengths(
    frames: list[MonoFrame],
    model: StickModel,
    lengths: FloatArray,
    short_link_weight: float = 0.0,
) -> FloatArray:
    """Link lengths measured again at each link's own depth from tracked poses (mm).

    The first estimate (`video_lengths`) reads every link in normalised image units and
    scales them by one stature, as if all links lay at one depth; a forearm reaching
    towards the camera then looks long. Here each link's extent across its own viewing
    direction (the link vector minus its component along the ray through its midpoint) is
    taken from the tracked poses, in mm, and the same statistic as `video_lengths` (90th
    percentile, left and right sharing the longer, fallback for links never near
    parallel) gives new lengths, rescaled so that their sum equals the old one (the
    absolute scale stays tied to the stature). Links then shorter than the body's
    proportions at the video's stature are moved the share ``short_link_weight`` of the
    way up (`mocapkit.tracking.mono.lengths.raise_short_links`; 0: off).
    """
    pos = np.stack([f.joints_in_camera for f in frames])
    vec = pos[:, model.child] - pos[:, model.parent]
    mid = 0.5 * (pos[:, model.child] + pos[:, model.parent])
    ray = mid / np.linalg.norm(mid, axis=-1, keepdims=True)
    lateral = vec - (vec * ray).sum(axis=-1, keepdims=True) * ray
    new, _ = estimate_link_lengths(np.linalg.norm(lateral, axis=-1), model.segments)
    new = new * (lengths.sum() / new.sum())
    if short_link_weight > 0:
        new = raise_short_links(new, model.segments, short_link_weight)
    return np.asarray(new, dtype=float)


def track_mono(
    session_path: str | os.PathLike[str],
    out_dir: str | os.PathLike[str] | None,
    camera: str | None = None,
    keypoints: str | os.PathLike[str] | None = None,
    config: MonoConfig | None = None,
    use_session_lengths: bool = False,
    pixels: FloatArray | None = None,
    length_passes: int = 2,
    skin: bool = False,
    initial_pose: FloatArray | None = None,
    skin_options: SkinOptions | None = None,
) -> MonoRun:
    """Track a session with the monocular tracker and write the result folder.

    Parameters
    ----------
    session_path : path-like
    out_dir : path-like or None
        Result folder; nothing written when None.
    camera : str, optional
        Default: the first camera with keypoints (or the first camera, with ``keypoints``).
    keypoints : path-like, optional
        A keypoints CSV file or an OpenPose JSON folder instead of the session's keypoints.
    config : MonoConfig, optional
        Default: perspective with a camera, exact offline pair-state Viterbi.
    use_session_lengths : bool
        Take link lengths from session.json instead of the video.
    pixels : (T, K, 2) float, optional
        Replace the keypoints' pixels of the stick's joints (e.g. with noise added).
    skin : bool
        Read the 2-D joints off the camera's video by skin blobs (`skin_keypoints`)
        instead of keypoints.
    skin_options : SkinOptions, optional
        With ``skin``: how the blobs are read (`skin_keypoints`; default `SkinOptions()`,
        the paper's rules; `SKIN_SETTINGS` per costume).
    length_passes : int
        With video lengths and the perspective model: track this many times, each pass
        measuring the lengths again from the previous pass's poses (`refined_lengths`,
        with ``config.short_link_weight``).
        Every pass but the last runs without the soft priors of `MonoConfig`
        (`mocapkit.tracking.mono.priors`) and without its ``reach_tolerance`` (M5
        exactly; with it there too the five accuracy clips got worse, 45.2 -> 46.4 mm,
        docs/mono.md sixth round); the last one with them.
    initial_pose : (K, 3) float, optional
        The subject's known pose in the first posed frame (the paper's assumption 3):
        the stick's joints (``stick_model(config.legs).joint_names``, e.g. picked by
        `initial_pose_from`) in the world frame, mm, NaN where unknown. The last pass
        starts from the candidate nearest to it (`MonoTracker`); the length passes, like
        the priors, leave it out (given to them too, it changed 01_09's refined lengths
        online and cost 16 mm there, docs/mono.md fifth round). None: the start is free.
    """
    if out_dir is not None:
        check_result_folder(out_dir)  # before the work (the length passes), not after it
    session = load_session(session_path)
    cam_name = (
        camera
        or next(iter(session.keypoints), None)
        or (session.camera_names[0] if session.camera_names else None)
    )
    if cam_name is None:
        raise SessionError(f"{session.path}: no camera to track (cameras.json lists none)")
    cam = session.camera(cam_name)
    cfg = config or MonoConfig()
    model = stick_model(cfg.legs, cfg.limits)
    if skin and keypoints is not None:
        raise ConfigError("track mono: give either --skin or --keypoints, not both")
    if skin:
        session.require(video=True, cameras=[cam_name])
    kp = (
        skin_keypoints(session, cam_name, skin_options)
        if skin
        else load_keypoints(session, cam_name, keypoints)
    )
    if kp.rebuilt_joints and not cfg.rebuilt_joints:
        cfg = detector_config(cfg)
    px = stick_pixels(kp, model) if pixels is None else np.asarray(pixels, dtype=float)
    t = np.asarray(kp.time_s, dtype=float)
    dt = float(np.median(np.diff(t))) if t.shape[0] > 1 else 1.0 / 30.0
    ortho = cfg.camera_model == "orthographic"
    if use_session_lengths:
        lengths = session_lengths(session, model)
        scale = float("nan")
        if ortho:
            _, stature = estimate_link_lengths(
                np.linalg.norm(px[:, model.child] - px[:, model.parent], axis=-1), model.segments
            )
            scale = pixels_per_mm(stature, session.height_mm)
            lengths = lengths * scale
    else:
        lengths, scale = video_lengths(px, model, cam, cfg, dt, session.height_mm)
    seen = np.isfinite(px[:, [0, model.child[model.link_index("trunk")]]]).all(axis=(1, 2))
    if not seen.any():
        raise SessionError(
            f"{kp.source}: neck and pelvis are seen together in no frame, so no pose can be "
            "built (with --skin: the waist cue, the paper's golden belt, was never found)"
        )
    initial = None
    if initial_pose is not None:
        q = np.asarray(initial_pose, dtype=float)
        if q.shape != (model.n_joints, 3):
            raise ShapeError(
                f"track_mono: expected an initial pose of shape ({model.n_joints}, 3) for "
                f"{model.joint_names}, found {q.shape}"
            )
        initial = cam.to_camera(q)  # camera frame, mm; the tracker uses it neck-relative
        if ortho:
            initial = initial * scale  # the orthographic model works in px
    refine = length_passes > 1 and not use_session_lengths and cfg.camera_model == "perspective"
    n_refine = length_passes - 1 if refine else 0
    # every pass but the last runs here; the last one streams through the runner below.
    # The length passes run the paper's graph (no soft priors, no initial pose, which
    # changed 01_09's online lengths, 36 -> 52 mm): the refined lengths follow
    # the first pass's poses, and with the clavicle prior there they changed enough to
    # turn 01_09 from OpenPose JSON from 62 to 113 mm (docs/mono.md). The reach tolerance
    # too (in every pass it changed the refined lengths: 45.2 -> 46.4 mm, sixth round), and
    # the clavicles' wider band for a rebuilt neck with it; the girdle cost of a rebuilt
    # neck stays (a rigid bone triangle, not a prior on the pose: without it in the length
    # passes, at girdle weight 300, 01_09 from OpenPose JSON 41.5 -> 42.6 mm, 91.2 -> 86.6 %,
    # seventh round).
    paper_cfg = replace(
        cfg,
        residual_weight=0.0,
        elbow_flex_weight=0.0,
        depth_velocity_weight=0.0,
        joint_acceleration_weight=0.0,
        clavicle_weight=0.0,
        arm_prior_weight=0.0,
        reach_tolerance=0.0,
        rebuilt_reach_tolerance=0.0,
    )
    for _ in range(n_refine):
        frames = _run(lengths, cam, dt, paper_cfg, model, t, px)
        lengths = refined_lengths(frames, model, lengths, cfg.short_link_weight)
    lengths_mm = lengths / scale if ortho else lengths
    skeleton = output_skeleton(model, lengths_mm)
    tracker = MonoTracker(lengths, cam, dt, cfg, model, initial_pose=initial)
    stream = MonoStream(tracker, skeleton, cam, scale)
    run = run_tracker(
        stream,
        (MonoSample(float(ti), p) for ti, p in zip(t, px)),
        len(t),
        out_dir,
        label="track mono",
        source=f"mono tracker on {session.path}",
        joint_names=stream.joint_names,
    )
    results = [r for r in run.results if isinstance(r, MonoResult)]
    frames = [r.frame for r in results if r.frame is not None]
    return MonoRun(run.motion, frames, lengths, model, scale, results, px)
