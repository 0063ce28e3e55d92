"""Accuracy of the monocular tracker on synthetic mono sessions rendered from real clips.

For each clip a mono session is rendered (`mocapkit synth --rig mono`), the true 2-D
keypoints get seeded Gaussian noise (2 px per coordinate by default), and the session is
tracked from them (or from OpenPose BODY_25 JSON written from those noisy keypoints with
a second, smaller person added beside the subject, or from the rendered video by skin
blobs, ``skin``). Reported per clip: the upper-body error (with legs tracked,
``MonoConfig.legs``: the whole stick's, legs included) after a per-frame similarity
(Procrustes) alignment (``pa_mpjpe_mm``), MPJPE, the
share of link-frames whose flip (towards or away from the camera) is right, the mean
survivors and share pruned per frame, and the 2-D error of the tracker's input points
against the true keypoints (``input_px_median``: median over the seen joint-frames,
``input_seen``: the share of joint-frames seen; per joint in ``input_px_by_joint``), and
the frames whose input arms are swapped left for right (`arm_swaps`) with the share of
them the tracker's answer has on the right sides, and the placement's part of the world
error (`depth_error`: the neck's depth error, the MPJPE at the true depth).

A link-frame counts for the flip figure when the true link leaves the image plane by at
least ``FLIP_MIN_SINE`` (0.2, about 12 deg): nearer the plane both flips give nearly the
same pose (errata M5) and the sign says little.
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import ConfigError, SessionError
from mocapkit.eval.metrics import evaluate_joints, evaluate_result
from mocapkit.io.openpose import openpose_from_canonical, write_openpose_frame
from mocapkit.io.session import Session, load_session
from mocapkit.io.truth import Truth
from mocapkit.pipelines.harness import detector_keypoints
from mocapkit.pipelines.mono import (
    MonoRun,
    canonical_from_body25_world,
    costume_skin_options,
    initial_pose_from,
    track_mono,
)
from mocapkit.skeleton.model import UPPER_BODY_JOINTS
from mocapkit.synth.session_writer import SynthOptions, synthesize_session
from mocapkit.tracking.mono.placement import FloorConfig
from mocapkit.tracking.mono.stick import StickModel
from mocapkit.tracking.mono.tracker import MonoConfig

FloatArray = NDArray[np.float64]

FLIP_MIN_SINE = 0.2
#: Sleeves of the sessions rendered in everyday clothing (the renderer's default): the
#: lower half of the upper arm, the forearm and the hand are skin.
SKIN_SLEEVE = "short"
#: Costume of the sessions that ``skin`` tracks by default: the paper's
#: (`mocapkit.synth.render.COSTUMES`). Mamania et al.'s 2-D tracker (§3.3) is defined
#: for it: its labels are head, forearms and the golden belt, the forearm ellipse's ends
#: are the elbow and wrist because the dress covers the upper arms, and the shoulders
#: come from the belt's ends. In everyday clothing (short sleeves, no belt, trousers of
#: any colour) those rules do not hold and the tracker needs stand-ins
#: (`mocapkit.pipelines.mono.SKIN_SETTINGS`);
#: its figures are reported apart (``costume="everyday"``).
SKIN_COSTUME = "paper"


#: Clips of ``shared/data/mocap`` and the excerpt (start s, length s) rendered from each.
MONO_CLIPS: dict[str, tuple[float, float]] = {
    "13_26.bvh": (0.0, 8.0),
    "01_09.amc": (27.0, 6.0),
    "lambada.amc": (11.0, 6.0),
    "charleston1.amc": (0.0, 4.0),
    "zombie.amc": (0.0, 6.0),
}


@dataclass(frozen=True)
class MonoClipAccuracy:
    """Figures of one clip."""

    clip: str
    source: str
    pa_mpjpe_mm: float
    mpjpe_mm: float
    flips_right: float
    survivors_mean: float
    candidates_mean: float
    pruned_share_mean: float
    all_pruned_frames: int
    residual_px_mean: float
    coverage: float
    input_px_median: float = float("nan")
    input_seen: float = float("nan")
    input_px_by_joint: dict[str, float] = field(default_factory=dict)
    costume: str = ""
    arm_pa_mpjpe_mm: float = float("nan")
    detector3d_pa_mpjpe_mm: float = float("nan")
    detector3d_arm_pa_mm: float = float("nan")
    swapped_frames: int = 0
    swaps_handled: int = 0
    neck_depth_error_mm: float = float("nan")
    mpjpe_at_true_depth_mm: float = float("nan")


#: The arm joints of the arm figures (PA-aligned on these six alone).
ARM_JOINTS: tuple[str, ...] = (
    "left_shoulder", "left_elbow", "left_wrist", "right_shoulder", "right_elbow", "right_wrist",
)  # fmt: skip


def detector3d_accuracy(
    world_npz: Path, truth: Truth | None, joints: Sequence[str] = UPPER_BODY_JOINTS
) -> tuple[float, float]:
    """PA-MPJPE (mm) of a detector's own 3-D (``keypoints3d/<camera>.npz``) against the
    truth, per frame aligned as the tracker's (`mocapkit.eval.metrics.evaluate_joints`):
    over ``joints`` (default the upper body) and over the arms alone. NaN, NaN without
    the file."""
    if not world_npz.is_file() or truth is None:
        return float("nan"), float("nan")
    with np.load(world_npz) as z:
        time_s, world = np.asarray(z["time_s"], dtype=float), np.asarray(z["world_mm"])
    names, points = canonical_from_body25_world(world)
    tr = truth
    upper, arms = (
        evaluate_joints(
            time_s, names, points, tr.time_s, tr.joint_names, tr.joints_mm, joints=sel
        ).pa_mpjpe_mm
        for sel in (tuple(joints), ARM_JOINTS)
    )
    return upper, arms


def truth_in_camera(session: Session, camera: str, model: StickModel) -> FloatArray:
    """The truth's joints of ``model`` (T, K, 3) in ``camera``'s frame (mm).

    Raises
    ------
    SessionError
        The session has no truth (``truth.npz``).
    """
    truth = session.truth
    if truth is None:
        raise SessionError(f"{session.path}: expected truth.npz to measure against, found none")
    idx = [truth.joint_names.index(n) for n in model.joint_names]
    return session.camera(camera).to_camera(truth.joints_mm[:, idx])


def flip_accuracy(run: MonoRun, truth_in_camera: FloatArray) -> tuple[float, FloatArray]:
    """Share of link-frames with the right flip, overall and per link.

    Parameters
    ----------
    run : MonoRun
    truth_in_camera : (T, K, 3) float
        True stick joints in the camera frame, frames aligned with ``run.frames``.
    """
    model: StickModel = run.model
    est = run.frames.joints_in_camera
    dz_true = truth_in_camera[:, model.child, 2] - truth_in_camera[:, model.parent, 2]
    length = np.linalg.norm(model.link_vectors(truth_in_camera), axis=-1)
    dz_est = est[:, model.child, 2] - est[:, model.parent, 2]
    counted = np.abs(dz_true) >= FLIP_MIN_SINE * length
    right = counted & (np.sign(dz_true) == np.sign(dz_est))
    per_link = right.sum(axis=0) / np.maximum(counted.sum(axis=0), 1)
    return float(right.sum() / max(int(counted.sum()), 1)), per_link


def depth_error(
    run: MonoRun, truth_in_camera: FloatArray, joints: Sequence[str]
) -> tuple[float, float]:
    """How much of the world error is the placement along the camera's rays.

    Parameters
    ----------
    run : MonoRun
    truth_in_camera : (T, K, 3) float
        True stick joints in the camera frame, frames aligned with ``run.frames``.
    joints : sequence of str
        The joints measured (those of the stick among them).

    Returns
    -------
    neck_depth_error_mm : float
        Median over the posed frames of the answer's neck depth minus the truth's (mm;
        positive: placed too far).
    mpjpe_at_true_depth_mm : float
        MPJPE over ``joints`` with each posed frame's answer scaled about the camera to
        the truth's neck depth (its image unchanged): the world error no placement can
        remove (NaN without a posed frame).
    """
    names = list(run.model.joint_names)
    idx = [names.index(n) for n in joints if n in names]
    neck = names.index("neck")
    est = run.frames.joints_in_camera
    posed = np.isfinite(est[:, idx]).all(axis=(1, 2)) & (est[:, neck, 2] > 0)
    if not posed.any():
        return float("nan"), float("nan")
    e, t = est[posed], truth_in_camera[posed]
    dz = float(np.median(e[:, neck, 2] - t[:, neck, 2]))
    placed = e[:, idx] * (t[:, neck, 2] / e[:, neck, 2])[:, None, None]
    return dz, float(np.linalg.norm(placed - t[:, idx], axis=-1).mean())


def input_error(run: MonoRun, true_px: FloatArray) -> tuple[float, float, dict[str, float]]:
    """2-D error of the tracker's input against the true keypoints of its joints.

    Parameters
    ----------
    run : MonoRun
    true_px : (T, K, 2) float
        True pixels of ``run.model.joint_names``.

    Returns
    -------
    median_px : float
        Median distance over the seen joint-frames (NaN when none is seen).
    seen : float
        Share of joint-frames with an input point.
    by_joint : dict of str to float
        Median distance per joint (NaN for a joint never seen).
    """
    d = np.linalg.norm(run.input_px - true_px, axis=-1)
    ok = np.isfinite(d)
    by_joint = {
        n: float(np.median(d[ok[:, k], k])) if ok[:, k].any() else float("nan")
        for k, n in enumerate(run.model.joint_names)
    }
    med = float(np.median(d[ok])) if ok.any() else float("nan")
    return med, float(ok.mean()), by_joint


def arm_swaps(
    input_px: FloatArray, output_px: FloatArray, true_px: FloatArray, names: Sequence[str]
) -> tuple[int, int]:
    """Frames whose input arms are swapped left for right, and how many of them the
    tracker's answer has on the right sides.

    An arm pair is swapped in a frame when its left and right shoulder, elbow and wrist
    lie nearer the other side's true points than their own (summed distances, px).

    Parameters
    ----------
    input_px, output_px, true_px : (T, K, 2) float
        The tracker's input points, its answer projected into the image and the true
        keypoints, of the joints ``names`` (NaN where unknown: such a frame counts as
        not swapped).
    names : sequence of str
        Needs the six arm joints (`ARM_JOINTS`).

    Returns
    -------
    swapped : int
        Frames whose input is swapped.
    handled : int
        Of those, the frames whose answer is not.
    """
    left = [list(names).index(n) for n in ARM_JOINTS[:3]]
    right = [list(names).index(n) for n in ARM_JOINTS[3:]]

    def swapped(px: FloatArray) -> NDArray[np.bool_]:
        def dist(a: list[int], b: list[int]) -> FloatArray:
            return np.asarray(np.linalg.norm(px[:, a] - true_px[:, b], axis=-1).sum(axis=1))

        with np.errstate(invalid="ignore"):
            return np.asarray(
                dist(left, right) + dist(right, left) < dist(left, left) + dist(right, right)
            )

    was = swapped(np.asarray(input_px, dtype=float))
    still = swapped(np.asarray(output_px, dtype=float))
    return int(was.sum()), int((was & ~still).sum())


def noisy_keypoints(session_path: Path, model: StickModel, noise_px: float, seed: int) -> tuple:
    """Session keypoints of the stick's joints plus seeded Gaussian noise (T, K, 2)."""
    s = load_session(session_path)
    cam = s.cameras[0].name
    kp = s.keypoints[cam]
    rng = np.random.default_rng(seed)
    px = kp.pixels + rng.normal(scale=noise_px, size=kp.pixels.shape)
    return s, cam, kp.joint_names, px


def write_openpose_with_bystander(
    folder: Path, joint_names: Sequence[str], pixels: FloatArray, seed: int
) -> None:
    """BODY_25 JSON per frame: the subject and a smaller second person 220 px to the side.

    The bystander is the subject's own keypoints shrunk to 60 % about the subject's
    centre and moved sideways (towards the image's wider free side), listed first in every
    other frame, so a reader that took the first or a fixed person would be caught.
    """
    rng = np.random.default_rng(seed)
    det = openpose_from_canonical(pixels, joint_names, "BODY_25")
    with warnings.catch_warnings():
        # A frame where the subject is out of view has no keypoints: its centre is
        # NaN and so is its bystander, which is what a detector would write there.
        warnings.filterwarnings("ignore", "Mean of empty slice", RuntimeWarning)
        centre = np.nanmean(pixels, axis=1, keepdims=True)
    side = 220.0 if float(np.nanmedian(centre[..., 0])) < 320 else -220.0
    other_px = (pixels - centre) * 0.6 + centre + [side, 20.0]
    other_px = other_px + rng.normal(scale=1.0, size=other_px.shape)
    other = openpose_from_canonical(other_px, joint_names, "BODY_25")
    folder.mkdir(parents=True, exist_ok=True)
    for t in range(pixels.shape[0]):
        people = [det[t], other[t]] if t % 2 else [other[t], det[t]]
        write_openpose_frame(folder / f"video_{t:012d}_keypoints.json", people)


def mono_session(
    mocap_dir: str | os.PathLike[str],
    work_dir: str | os.PathLike[str],
    clip: str,
    seed: int = 0,
    reuse: bool = True,
    costume: str = "everyday",
) -> Path:
    """The mono session of one clip, rendered unless present.

    ``WORK/<clip stem>/session`` in everyday clothing (sleeves `SKIN_SLEEVE`),
    ``WORK/<clip stem>/session_<costume>`` in another costume
    (`mocapkit.synth.render.COSTUMES`), so two costumes never share a session. The
    clip's window is `MONO_CLIPS`' (other clips: their first 6 s). Both costumes draw
    the same seeded numbers, so their cameras, truth and keypoints are the same. With
    ``reuse`` an existing session (its ``truth.npz``) is kept when its ``session.json``
    records the same seed and costume (a session without a costume entry is everyday).

    Returns
    -------
    Path
        The session folder.
    """
    start, seconds = MONO_CLIPS.get(clip, (0.0, 6.0))
    folder = "session" if costume == "everyday" else f"session_{costume}"
    session = Path(work_dir) / Path(clip).stem / folder
    if not (reuse and _cached(session, seed, costume)):
        synthesize_session(
            str(Path(mocap_dir) / clip),
            session,
            SynthOptions(
                rig="mono",
                start_s=start,
                seconds=seconds,
                seed=seed,
                overwrite=True,
                sleeve=SKIN_SLEEVE if costume == "everyday" else None,
                costume=costume,
            ),
        )
    return session


def _cached(session: Path, seed: int, costume: str) -> bool:
    """Whether ``session`` holds a finished rendering with this seed and costume."""
    if not (session / "truth.npz").is_file():
        return False
    try:
        synthetic = json.loads((session / "session.json").read_text())["synthetic"]
    except (OSError, ValueError, KeyError, TypeError):
        return False
    return bool(synthetic.get("seed") == seed and synthetic.get("costume", "everyday") == costume)


def mono_accuracy(
    mocap_dir: str | os.PathLike[str],
    work_dir: str | os.PathLike[str],
    clips: Sequence[str] | None = None,
    seed: int = 0,
    noise_px: float = 2.0,
    openpose: bool = False,
    config: MonoConfig | None = None,
    say: Callable[[str], None] = lambda _line: None,
    reuse: bool = True,
    skin: bool = False,
    initial_pose: bool = False,
    skin_bare_from: str | None = "costume",
    costume: str | None = None,
    placement: FloorConfig | None = None,
    detector: str | None = None,
) -> list[MonoClipAccuracy]:
    """Render (or reuse), track from noisy true keypoints (or OpenPose JSON, or the video
    by skin blobs with ``skin``), and evaluate each clip.

    With ``skin`` the sessions are rendered in ``costume`` (default `SKIN_COSTUME`, the
    paper's; ``"everyday"``: shirt with `SKIN_SLEEVE` sleeves and trousers) and the skin
    tracker runs with that costume's settings (`mocapkit.pipelines.mono.SKIN_SETTINGS`);
    ``skin_bare_from`` overrides where it takes the arms' skin to start
    (`mocapkit.pipelines.mono.track_mono`;
    ``"costume"``: the costume's; None: the paper's rule, the arm ellipse's ends). The
    other inputs take the everyday sessions (the keypoints are the same in both).

    With ``initial_pose`` the tracker is given the true pose of the first frame (the
    paper's assumption 3; `mocapkit.pipelines.mono.track_mono`), so those figures are
    to be reported apart from the default ones. ``placement`` is
    `mocapkit.pipelines.mono.track_mono`'s (from the keypoints: the noisy ankles).

    With ``detector`` (a `mocapkit.detect` backend, e.g. ``"mediapipe"``) the rendered
    video is given to that detector (its detections kept in ``WORK/<clip>/detect_<name>``
    and reused), the session is tracked from its OpenPose JSON, and the detector's own
    3-D (where it gives one) is measured beside the tracker, aligned the same way.
    """
    if sum((skin, openpose, detector is not None)) > 1:
        raise ConfigError("mono_accuracy: give one of skin, openpose and detector")
    if costume is not None and not skin:
        raise ConfigError("mono_accuracy: a costume is chosen for skin tracking only")
    dress = (costume or SKIN_COSTUME) if skin else "everyday"
    own_arms = {} if skin_bare_from == "costume" else {"bare_from": skin_bare_from}
    skin_options = costume_skin_options(dress, **own_arms)
    cfg = config or MonoConfig()
    source = "skin" if skin else "openpose" if openpose else detector or "keypoints"
    measured = _model(cfg).joint_names if cfg.legs else UPPER_BODY_JOINTS
    rows = []
    for clip in clips or tuple(MONO_CLIPS):
        base = Path(work_dir) / Path(clip).stem
        session = mono_session(mocap_dir, work_dir, clip, seed=seed, reuse=reuse, costume=dress)
        s, cam, names, px = noisy_keypoints(session, _model(cfg), noise_px, seed)
        tag = f"skin_{dress}" if skin else source
        out = base / (tag + ("_initial" if initial_pose else ""))
        first_pose = None
        world_npz = None
        if initial_pose:
            assert s.truth is not None
            first_pose = initial_pose_from(s.truth.joint_names, s.truth.joints_mm[0], _model(cfg))
        if skin:
            run = track_mono(
                session,
                out,
                camera=cam,
                config=cfg,
                skin=True,
                initial_pose=first_pose,
                skin_options=skin_options,
            )
        elif openpose or detector is not None:
            if detector is not None:
                found = detector_keypoints(base, session, detector, overwrite=not reuse)
                folder = found / "keypoints" / "openpose" / cam
                world_npz = found / "keypoints3d" / f"{cam}.npz"
            else:
                folder = base / "openpose_json"
                write_openpose_with_bystander(folder, names, px, seed)
            run = track_mono(
                session,
                out,
                camera=cam,
                keypoints=folder,
                config=cfg,
                initial_pose=first_pose,
                placement=placement,
                keypoints3d=world_npz,
            )
        else:
            idx = [names.index(n) for n in _model(cfg).joint_names]
            feet = [names.index(n) for n in ("left_ankle", "right_ankle") if n in names]
            run = track_mono(
                session,
                out,
                camera=cam,
                config=cfg,
                pixels=px[:, idx],
                ankles_px=px[:, feet] if len(feet) == 2 else None,
                placement=placement,
                initial_pose=first_pose,
            )
        rep = evaluate_result(out, session, joints=measured)
        arm = evaluate_result(out, session, joints=ARM_JOINTS).pa_mpjpe_mm
        det3d = (
            detector3d_accuracy(world_npz, s.truth, measured)
            if world_npz is not None
            else (np.nan, np.nan)
        )
        true_cam = truth_in_camera(s, cam, run.model)
        flips, _ = flip_accuracy(run, true_cam)
        depth = (
            depth_error(run, true_cam, measured)
            if cfg.camera_model != "orthographic"  # the orthographic answer is not in mm
            else (np.nan, np.nan)
        )
        true_px = s.keypoints[cam].pixels[:, [names.index(n) for n in run.model.joint_names]]
        med, seen, by_joint = input_error(run, true_px)
        swaps = (0, 0)
        if cfg.camera_model != "orthographic":  # the orthographic answer is not in mm
            answer_px = s.camera(cam).project_camera_points(
                np.stack([f.joints_in_camera for f in run.frames])
            )
            swaps = arm_swaps(run.input_px, answer_px, true_px, run.model.joint_names)
        summ = run.summary()
        row = MonoClipAccuracy(
            clip,
            source,
            rep.pa_mpjpe_mm,
            rep.mpjpe_mm,
            flips,
            summ["survivors_mean"],
            summ["candidates_mean"],
            summ["pruned_share_mean"],
            int(summ["all_pruned_frames"]),
            summ["residual_px_mean"],
            rep.coverage,
            med,
            seen,
            by_joint,
            dress if skin else "",
            arm,
            float(det3d[0]),
            float(det3d[1]),
            *swaps,
            *depth,
        )
        say(format_rows([row]).splitlines()[-1])
        rows.append(row)
    return rows


def _model(cfg: MonoConfig) -> StickModel:
    from mocapkit.tracking.mono.stick import stick_model

    return stick_model(cfg.legs, cfg.limits)


def format_rows(rows: Sequence[MonoClipAccuracy]) -> str:
    """A table: one line per clip (the header alone for no rows)."""
    lines = [
        f"{'clip':<18}{'input':<15}{'PA mm':>8}{'MPJPE':>8}{'flips':>7}{'surv':>7}"
        f"{'cand':>7}{'pruned':>8}{'allpr':>6}{'res px':>8}{'cover':>7}{'in px':>7}{'seen':>7}"
        f"{'arm PA':>8}{'det3D':>7}{'d3 arm':>8}{'swaps':>7}{'dz mm':>7}{'@depth':>7}"
    ]
    for r in rows:
        what = f"{r.source} {r.costume}" if r.costume else r.source
        lines.append(
            f"{r.clip:<18}{what:<15}{r.pa_mpjpe_mm:8.1f}{r.mpjpe_mm:8.1f}"
            f"{100 * r.flips_right:6.1f}%{r.survivors_mean:7.1f}{r.candidates_mean:7.1f}"
            f"{100 * r.pruned_share_mean:7.1f}%{r.all_pruned_frames:6d}{r.residual_px_mean:8.2f}"
            f"{r.coverage:7.3f}{r.input_px_median:7.2f}{100 * r.input_seen:6.1f}%"
            f"{r.arm_pa_mpjpe_mm:8.1f}{r.detector3d_pa_mpjpe_mm:7.1f}{r.detector3d_arm_pa_mm:8.1f}"
            f"{f'{r.swaps_handled}/{r.swapped_frames}':>7}"
            f"{r.neck_depth_error_mm:7.0f}{r.mpjpe_at_true_depth_mm:7.0f}"
        )
    return "\n".join(lines)


def to_json(rows: Sequence[MonoClipAccuracy]) -> str:
    """Rows as JSON."""
    return json.dumps([asdict(r) for r in rows], indent=2)
