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
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.errors import ConfigError, SessionError, ShapeError
from mocapkit.io.motion import Motion
from mocapkit.io.openpose import (
    BODY_25,
    DIRECT,
    MAPPED_JOINTS,
    NECK_BELOW_SHOULDERS,
    PELVIS_ABOVE_HIPS,
)
from mocapkit.io.session import Session, load_session
from mocapkit.io.session_csv import Keypoints, read_keypoints_csv
from mocapkit.pipelines.camera_check import check_session_cameras, warn_placed_subject
from mocapkit.pipelines.input_speeds import pixel_input_speeds
from mocapkit.pipelines.mono_frames import MonoFrames, camera_joints
from mocapkit.pipelines.result_table import ResultTable
from mocapkit.pipelines.run import check_result_folder, run_tracker
from mocapkit.progress import Progress
from mocapkit.tracking.base import FrameResult
from mocapkit.tracking.mono.lengths import (
    ANTHROPOMETRIC_RATIOS,
    DEFAULT_HEIGHT_MM,
    estimate_link_lengths,
    pixels_per_mm,
    raise_short_links,
)
from mocapkit.tracking.mono.placement import (
    ANKLE_JOINTS,
    FloorConfig,
    FloorDepth,
    detector_ankle_lift_mm,
)
from mocapkit.tracking.mono.smoother import smooth_keypoints
from mocapkit.tracking.mono.stick import StickModel, stick_model
from mocapkit.tracking.mono.stream import (
    MonoResult,
    MonoSample,
    MonoStream,
    output_skeleton,
)
from mocapkit.tracking.mono.tracker import MonoConfig, MonoFrame, MonoTracker
from mocapkit.tracking.multiview.detector_offsets import detector_offsets, offset_segments

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
#: head (no belt). docs/design-notes/mono.md.
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
    frames : MonoFrames
        The last pass's `MonoFrame` answers in compact columns, in frame order.
    lengths : (L,) float
        Link lengths used (mm; px for the orthographic model).
    model : StickModel
    px_per_mm : float
        Image scale used to turn orthographic px into mm (NaN for the other models).
    results : ResultTable
        The last pass's per-frame results, as written to ``fit.csv``.
    input_px : (T, K, 2) float
        The 2-D joints of ``model`` the tracker was given (px), NaN where unseen.
    """

    motion: Motion
    frames: MonoFrames
    lengths: FloatArray
    model: StickModel
    px_per_mm: float
    results: ResultTable = field(default_factory=ResultTable)
    input_px: FloatArray = field(default_factory=lambda: np.zeros((0, 0, 2)))

    def summary(self) -> dict[str, float]:
        """Mean survivors, candidates, share pruned, residual (px), frames with a pose
        and the share of frames placed by the feet on the floor."""
        f = self.frames
        posed = f.code >= 0
        cand = f.n_candidates[posed].astype(float)
        surv = f.n_survivors[posed].astype(float)
        share = 1.0 - surv / np.maximum(cand, 1.0)
        any_posed = bool(posed.any())
        return {
            "frames": float(len(f)),
            "posed_frames": float(posed.sum()),
            "candidates_mean": float(cand.mean()) if any_posed else float("nan"),
            "survivors_mean": float(surv.mean()) if any_posed else float("nan"),
            "pruned_share_mean": float(share.mean()) if any_posed else float("nan"),
            "all_pruned_frames": float(sum(f.pruned_all[posed].tolist())),
            "residual_px_mean": float(np.nanmean(f.residual_px[posed].tolist()))
            if any_posed
            else float("nan"),
            "on_floor_share": float(np.mean(self.results.fit_column("on_floor")))
            if len(self.results)
            else float("nan"),
        }


def load_keypoints(
    session: Session, camera: str, keypoints: str | os.PathLike[str] | None
) -> Keypoints:
    """The 2-D keypoints of one camera: the session's, a CSV file, or an OpenPose folder.

    An OpenPose folder takes the frame times of the camera's video (one JSON per frame).
    """
    if keypoints is None:
        from mocapkit.detect.run import ensure_keypoints

        ensure_keypoints(session, [camera])  # detected into the session when missing
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
        return session.checked_keypoints(camera, read_openpose_folder(p, times), str(p))
    return session.checked_keypoints(camera, read_keypoints_csv(p), str(p))


def canonical_from_body25_world(world_mm: FloatArray) -> tuple[tuple[str, ...], FloatArray]:
    """A detector's own 3-D points (BODY_25 order, (T, 25, 3) mm) on canonical joints.

    The same mapping as the 2-D keypoints' (`mocapkit.io.openpose`): the limbs' joints
    directly, the head between the ears (the face's mean without both), the neck
    ``NECK_BELOW_SHOULDERS`` and the pelvis ``PELVIS_ABOVE_HIPS`` shoulder widths from the
    shoulder and hip midpoints along the trunk (the girdle rule, in 3-D).

    Returns
    -------
    names : tuple of str
        `mocapkit.io.openpose.MAPPED_JOINTS`.
    joints : (T, len(names), 3) float
        NaN where the detector gave nothing.
    """
    w = np.asarray(world_mm, dtype=float)
    if w.ndim != 3 or w.shape[1:] != (len(BODY_25), 3):
        raise ShapeError(f"detector 3-D: expected (T, {len(BODY_25)}, 3), found {w.shape}")
    out = np.full((w.shape[0], len(MAPPED_JOINTS), 3), np.nan)
    col = {n: i for i, n in enumerate(MAPPED_JOINTS)}

    def kp(name: str) -> FloatArray:
        return w[:, BODY_25.index(name)]

    for joint, det in DIRECT.items():
        out[:, col[joint]] = kp(det)
    ears = np.stack([kp("LEar"), kp("REar")], axis=1)
    face = np.stack([kp("LEar"), kp("REar"), kp("LEye"), kp("REye")], axis=1)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "Mean of empty slice", RuntimeWarning)
        both = np.asarray(np.isfinite(ears).all(axis=(1, 2)), dtype=bool)
        out[:, col["head"]] = np.where(both[:, None], ears.mean(axis=1), np.nanmean(face, axis=1))
    m_s = 0.5 * (kp("LShoulder") + kp("RShoulder"))
    m_h = 0.5 * (kp("LHip") + kp("RHip"))
    width = np.linalg.norm(kp("LShoulder") - kp("RShoulder"), axis=-1, keepdims=True)
    up = m_s - m_h
    with np.errstate(invalid="ignore", divide="ignore"):
        up = up / np.linalg.norm(up, axis=-1, keepdims=True)
    out[:, col["neck"]] = m_s - NECK_BELOW_SHOULDERS * width * up
    out[:, col["pelvis"]] = m_h + PELVIS_ABOVE_HIPS * width * up
    return MAPPED_JOINTS, out


def detector_link_sines(
    world_npz: str | os.PathLike[str], time_s: FloatArray, model: StickModel
) -> FloatArray:
    """A detector's depth order per frame and link: ``dz / L`` (T, L) of its own 3-D
    (``keypoints3d/<camera>.npz`` of `mocapkit.detect.run`: MediaPipe's world landmarks,
    whose z points away from the camera like the camera frame's), on the frames of
    ``time_s`` (the nearest within half a frame); NaN where it has none.

    Raises
    ------
    SessionError
        The file cannot be read or lacks ``time_s`` / ``world_mm``.
    """
    path = Path(world_npz)
    try:
        with np.load(path) as z:
            det_t = np.asarray(z["time_s"], dtype=float)
            world = np.asarray(z["world_mm"], dtype=float)
    except (OSError, KeyError, ValueError) as exc:
        raise SessionError(
            f"{path}: expected a detector's 3-D (time_s, world_mm), could not read it: {exc}"
        ) from exc
    names, joints = canonical_from_body25_world(world)
    missing = [n for n in model.joint_names if n not in names]
    if missing:
        raise SessionError(f"{path}: the detector's 3-D gives no {missing}")
    q = joints[:, [names.index(n) for n in model.joint_names]]
    v = q[:, model.child] - q[:, model.parent]
    with np.errstate(invalid="ignore", divide="ignore"):
        sines = v[..., 2] / np.linalg.norm(v, axis=-1)
    t = np.asarray(time_s, dtype=float)
    out = np.full((t.shape[0], model.n_links), np.nan)
    if det_t.shape[0] == 0:
        return out
    dt = float(np.median(np.diff(t))) if t.shape[0] > 1 else 1.0 / 30.0
    n = det_t.shape[0]
    j = np.clip(np.searchsorted(det_t, t), 1, n - 1) if n > 1 else np.zeros(t.shape[0], int)
    lo = np.maximum(j - 1, 0)
    j = np.where(np.abs(det_t[lo] - t) <= np.abs(det_t[j] - t), lo, j)
    near = np.abs(det_t[j] - t) <= 0.5 * dt
    out[near] = sines[j[near]]
    return out


def detector_config(config: MonoConfig) -> MonoConfig:
    """``config`` for 2-D whose neck and pelvis are rebuilt from the shoulders and hips.

    A detector (OpenPose JSON, `mocapkit.io.openpose`) marks neither our neck nor our
    pelvis; both are placed on the hip-to-shoulder midpoint line, so the two clavicles are
    mirror images of each other in the image and a few px of the neck's error (its offset
    across the line, its fraction along it) change their 40 px projected lengths by up to
    10 %, which decides their flips near the image plane (docs/design-notes/mono.md).
    The tracker then widens the reach band of the clavicles
    (``rebuilt_reach_tolerance``: both flips kept, each some way out of the plane) and
    lets the rigid girdle choose between them (``girdle_weight``, the angle between the
    clavicles that the placement assumes, `mocapkit.io.openpose.GIRDLE_COSINE`; in the
    length passes too, the band there off as ``reach_tolerance`` is).
    """
    from mocapkit.io.openpose import GIRDLE_COSINE, REBUILT_JOINTS

    return replace(config, rebuilt_joints=REBUILT_JOINTS, girdle_cosine=GIRDLE_COSINE)


def known_lengths_config(config: MonoConfig) -> MonoConfig:
    """``config`` for link lengths that are known (the session's measured ones), not read
    off the video: no trunk lean states (``trunk_lean_sines``), which stand for a trunk
    longer than its video estimate; with its true length the search's own lean is right
    (on the synthetic stick with exact lengths the lean states cost 8 -> 21 mm)."""
    return replace(config, trunk_lean_sines=())


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


def _run(
    lengths: FloatArray,
    cam: Camera | None,
    dt: float,
    cfg: MonoConfig,
    model: StickModel,
    t: FloatArray,
    px: FloatArray,
) -> MonoFrames:
    tracker = MonoTracker(lengths, cam, dt, cfg, model)
    frames = MonoFrames()
    with Progress(len(t), "track mono") as prog:
        for ti, p in zip(t, px):
            frames.extend(tracker.push(float(ti), p))
            prog.update()
    frames.extend(tracker.finish())
    frames.sort()
    return frames


#: The joints whose image points place the subject by the feet on the floor (left, right).
ANKLES = ANKLE_JOINTS


def keypoints_backend(
    session: Session, camera: str, keypoints: str | os.PathLike[str] | None = None
) -> str | None:
    """The detector backend that wrote the keypoints tracked, as the detection's
    ``keypoints/detect.json`` records it (`mocapkit.detect.run.detected_backend`): the
    session's own keypoints of ``camera``, or a keypoints file or folder given in
    `mocapkit.detect.run.detect_session`'s layout (``OUT/keypoints/<camera>.csv``,
    ``OUT/keypoints/openpose/<camera>/``); None for keypoints of unknown origin."""
    from mocapkit.detect.run import detected_backend

    if keypoints is None:
        return detected_backend(session.path, [camera])
    p = Path(keypoints)
    if p.parent.name == "keypoints" and p.suffix == ".csv":
        return detected_backend(p.parent.parent, [p.stem])
    if p.parent.name == "openpose" and p.parent.parent.name == "keypoints":
        return detected_backend(p.parent.parent.parent, [p.name])
    return None


def online_mono_stream(
    session: Session,
    camera: str,
    config: MonoConfig,
    dt_s: float,
    ankles: bool = False,
    placement: FloorConfig | None = None,
    backend: str | None = None,
) -> MonoStream:
    """The online mono tracker on a session's camera with its measured link lengths
    (``session.json`` ``subject.bone_lengths_mm``): what ``track mono --session-lengths
    --lag L`` runs, for samples that come one at a time (`mocapkit.pipelines.live`).
    With ``ankles`` (the samples carry them) the subject is placed by the feet on the
    floor as `track_mono` places it (``placement``, default `FloorConfig()``; the ankle
    points of the detector ``backend`` that gives them, None: unknown, at the joint).

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
    floor = _floor(session, cam, config, ankles, placement, backend)
    tracker = MonoTracker(
        lengths,
        cam,
        dt_s,
        known_lengths_config(config),
        model,
        ankle_floor_mm=None if floor is None else floor.ankle_height_mm,
    )
    return MonoStream(tracker, output_skeleton(model, lengths), cam, float("nan"), floor=floor)


def _floor(
    session: Session,
    cam: Camera,
    config: MonoConfig,
    ankles: bool,
    placement: FloorConfig | None,
    backend: str | None,
) -> FloorDepth | None:
    """The placement by the feet on the floor, where it applies: asked for (the default),
    the perspective model, the ankles seen; the session's stature, else the default; the
    ankle points where ``backend``'s known offsets put them (`detector_ankle_lift_mm`)."""
    place = placement or FloorConfig()
    if not (place.on_floor and ankles and config.camera_model == "perspective"):
        return None
    lift = detector_ankle_lift_mm(detector_offsets(backend))
    return FloorDepth(cam, session.height_mm or DEFAULT_HEIGHT_MM, place, lift)


def detector_corrected_lengths(
    lengths_mm: FloatArray, model: StickModel, backend: str | None
) -> FloatArray:
    """Video link lengths (mm) with ``backend``'s known keypoint offsets taken out of the
    limbs (`mocapkit.tracking.multiview.detector_offsets.offset_segments`, the multi-view
    fit's table: a link from ``a`` to ``b`` reads its true length plus ``o_b - o_a``
    along it; MediaPipe's elbow point lies some 26 mm up the upper arm, so its upper arms
    read short and its forearms long). The links from the neck keep the lengths their 2-D
    points show: the tracker's depth is the bound at which they reach their children's
    rays (`mocapkit.tracking.mono.tracker`), and where the feet do not place the subject
    a longer trunk put it too far. Unchanged for keypoints of unknown origin."""
    offsets = detector_offsets(backend)
    if not offsets:
        return lengths_mm
    from mocapkit.tracking.multiview.tracker import multiview_skeleton  # a detector's only

    fixed, _ = offset_segments(
        multiview_skeleton(), dict(zip(model.segments, map(float, lengths_mm))), {}, offsets
    )
    out = np.array([fixed[s] for s in model.segments], dtype=float)
    from_neck = model.parent == 0
    out[from_neck] = lengths_mm[from_neck]
    return out


def refined_lengths(
    frames: Sequence[MonoFrame],
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
    pos = camera_joints(frames)
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
    ankles_px: FloatArray | None = None,
    placement: FloorConfig | None = None,
    length_passes: int = 2,
    skin: bool = False,
    initial_pose: FloatArray | None = None,
    skin_options: SkinOptions | None = None,
    keypoints3d: str | os.PathLike[str] | None = None,
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
    placement : FloorConfig, optional
        Default `FloorConfig()`: with the perspective model and the ankles, each pose is
        placed at the neck depth of the feet on the world's floor (z = 0, z up) where
        they are seen standing on it and that depth agrees with the tracker's
        (`MonoStream`'s ``floor``, `mocapkit.tracking.mono.placement`; the stature of
        session.json, else `DEFAULT_HEIGHT_MM`; the ankle points where the detector
        that wrote the keypoints, `keypoints_backend`, is known to put them); elsewhere,
        and with ``on_floor`` False, the tracker's depth from the link lengths.
    ankles_px : (T, 2, 2) float, optional
        The left and right ankles (px, NaN where unseen) for the placement; default:
        the keypoints' ankles where they have them.
    skin : bool
        Read the 2-D joints off the camera's video by skin blobs (`skin_keypoints`)
        instead of keypoints.
    skin_options : SkinOptions, optional
        With ``skin``: how the blobs are read (`skin_keypoints`; default `SkinOptions()`,
        the paper's rules; `SKIN_SETTINGS` per costume).
    keypoints3d : path-like, optional
        A detector's own 3-D (``keypoints3d/<camera>.npz``, `detector_link_sines`) whose
        depth order softly costs each link's flip (``config.depth_order_weight``; the last
        pass only) and whose depth offsets are blended into the placed poses'
        (``config.depth_fusion_weight``, `mocapkit.tracking.mono.depth_fusion`). Default:
        the session's ``keypoints3d/<camera>.npz`` where the session's own keypoints are
        tracked and it exists.
    length_passes : int
        With video lengths and the perspective model: track this many times, each pass
        measuring the lengths again from the previous pass's poses (`refined_lengths`,
        with ``config.short_link_weight``); the first lengths have the detector's known
        offsets taken out of the limbs (`detector_corrected_lengths`).
        Every pass but the last runs without the soft priors of `MonoConfig`
        (`mocapkit.tracking.mono.priors`) and without its ``reach_tolerance`` (M5
        exactly; with it there too the five accuracy clips got worse, 45.2 -> 46.4 mm,
        `git log -p docs/design-notes/mono.md`); the last one with them.
    initial_pose : (K, 3) float, optional
        The subject's known pose in the first posed frame (the paper's assumption 3):
        the stick's joints (``stick_model(config.legs).joint_names``, e.g. picked by
        `initial_pose_from`) in the world frame, mm, NaN where unknown. The last pass
        starts from the candidate nearest to it (`MonoTracker`); the length passes, like
        the priors, leave it out (given to them too, it changed one clip's refined lengths
        online and cost 16 mm there, `git log -p docs/design-notes/mono.md`). None: the
        start is free.
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
    check_session_cameras(session, [cam_name], keypoints={cam_name: kp})  # before the work
    if kp.rebuilt_joints and not cfg.rebuilt_joints:
        cfg = detector_config(cfg)
    px = stick_pixels(kp, model) if pixels is None else np.asarray(pixels, dtype=float)
    t = np.asarray(kp.time_s, dtype=float)
    dt = float(np.median(np.diff(t))) if t.shape[0] > 1 else 1.0 / 30.0
    ortho = cfg.camera_model == "orthographic"
    if use_session_lengths:
        cfg = known_lengths_config(cfg)
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
    backend = None if skin else keypoints_backend(session, cam_name, keypoints)
    if not use_session_lengths and not ortho:  # once (after the passes too: worse)
        lengths = detector_corrected_lengths(lengths, model, backend)
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
    # changed one clip's online lengths, 36 -> 52 mm): the refined lengths follow
    # the first pass's poses, and with the clavicle prior there they changed enough to
    # turn one clip from OpenPose JSON from 62 to 113 mm (docs/design-notes/mono.md). The
    # reach tolerance too (in every pass it changed the refined lengths: 45.2 -> 46.4 mm), and
    # the clavicles' wider band for a rebuilt neck with it; the girdle cost of a rebuilt
    # neck stays (a rigid bone triangle, not a prior on the pose: without it in the length
    # passes a detector's input lost flips; docs/design-notes/mono.md). One neck depth a
    # frame there (no trunk leans): the lengths come from the depth estimate's poses.
    paper_cfg = replace(
        cfg,
        clavicle_weight=0.0,
        arm_prior_weight=0.0,
        reach_tolerance=0.0,
        rebuilt_reach_tolerance=0.0,
        trunk_lean_sines=(),
    )
    for _ in range(n_refine):
        pass_frames = _run(lengths, cam, dt, paper_cfg, model, t, px)
        lengths = refined_lengths(pass_frames, model, lengths, cfg.short_link_weight)
        del pass_frames
    lengths_mm = lengths / scale if ortho else lengths
    skeleton = output_skeleton(model, lengths_mm)
    feet = ankles_px
    if feet is None and set(ANKLES) <= set(kp.joint_names):
        feet = kp.pixels[:, [kp.joint_names.index(n) for n in ANKLES]]
    floor = _floor(session, cam, cfg, feet is not None, placement, backend)
    tracker = MonoTracker(
        lengths,
        cam,
        dt,
        cfg,
        model,
        initial_pose=initial,
        ankle_floor_mm=None if floor is None else floor.ankle_height_mm,
    )
    stream = MonoStream(tracker, skeleton, cam, scale, floor=floor)
    if feet is None:
        feet = np.full((t.shape[0], 2, 2), np.nan)
    own3d = session.path / "keypoints3d" / f"{cam_name}.npz"
    if keypoints3d is None and keypoints is None and not skin and own3d.is_file():
        keypoints3d = own3d
    sines: Sequence[FloatArray | None] = [None] * t.shape[0]
    if keypoints3d is not None and (cfg.depth_order_weight > 0 or cfg.depth_fusion_weight > 0):
        sines = list(detector_link_sines(keypoints3d, t, model))
    recorded = _FrameRecorder(stream)
    run = run_tracker(
        recorded,
        (MonoSample(float(ti), p, a, s) for ti, p, a, s in zip(t, px, feet, sines)),
        len(t),
        out_dir,
        label="track mono",
        source=f"mono tracker (camera {cam_name}) on {session.path}",
        joint_names=stream.joint_names,
        keep_results=False,
        input_speeds=partial(pixel_input_speeds, [cam], [px], model.joint_names),
    )
    recorded.frames.sort()
    warn_placed_subject(session, cam_name, run.motion.joints_mm, run.motion.joint_names)
    assert run.table is not None  # kept as a table (keep_results False)
    return MonoRun(run.motion, recorded.frames, lengths, model, scale, run.table, px)


class _FrameRecorder:
    """A `MonoStream` whose results' `MonoFrame` are kept in compact columns as they pass
    (the runner keeps only the results' common fields)."""

    def __init__(self, stream: MonoStream) -> None:
        self.stream = stream
        self.skeleton = stream.skeleton
        self.frames = MonoFrames()

    def push(self, sample: MonoSample) -> list[FrameResult]:
        return self._record(self.stream.push(sample))

    def finish(self) -> list[FrameResult]:
        return self._record(self.stream.finish())

    def _record(self, results: list[FrameResult]) -> list[FrameResult]:
        for r in results:
            if isinstance(r, MonoResult) and r.frame is not None:
                self.frames.append(r.frame)
        return results
