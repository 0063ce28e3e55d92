"""Streaming stereo / multi-view markerless upper-body tracker (Azad, Asfour, Dillmann 2008).

``StereoTracker.update(sample) -> StereoPose`` (a `mocapkit.tracking.base.FrameResult`) per frame:

1. **Image pipeline** (§II-B, per view): skin mask (`mocapkit.cues.skin`), restricted
   after initialisation to the box the head and both arms can reach; shirt-colour
   figure-ground (the shirt model is fitted once, from a patch below the measured
   head, in every view); the gradient map in [0, 1], only inside the arms' reach
   box and only on the figure (skin or shirt, dilated).
2. **Head and hands in 3-D** (§II-C.2): skin blobs matched across views
   (`mocapkit.tracking.stereo.hands`), or, with ``use_keypoints``, the session's 2-D
   keypoints (head and wrists) triangulated over every view.
3. **Hierarchical search** (§III): the head is the root; the torso rotation ``R_b``
   is a yaw about the vertical (the torso is taken upright).
4. **Arms**: one 7-DoF particle filter per arm (`mocapkit.tracking.stereo.arm_filter`).
5. **Torso orientation** (a separate problem in the paper): by default estimated from
   the adaptive shoulders. After each frame the yaw moves a share ``yaw_gain`` of the way
   towards the direction of the line between the two estimated shoulders (their
   offsets carry what a wrong yaw leaves unexplained); it starts facing the cameras.
   This keeps the paper's 7 DoF per arm and needs no extra cue; its error is reported
   by `mocapkit.pipelines.stereo` (`torso_yaw_error_deg`). With keypoints,
   ``torso="keypoints"`` takes the whole torso rotation from the triangulated shoulder,
   neck and pelvis keypoints and hangs the arms from the neck keypoint instead (an
   option beyond the paper's inputs, for torsos that turn or lean more than the
   adaptive shoulders absorb).

Model-to-measurement offsets (gaps in the paper, chosen here): a hand's skin blob
lies in the hand, beyond the wrist, so the arm's measured point is the wrist plus
``hand_offset_mm`` along the forearm (default 15 mm with skin blobs, 0 with
keypoints); the face blob's 3-D centroid lies ``face_offset_mm`` from the head point
in the torso frame (default 35 mm below it). Both defaults were measured on a
synthetic session (a CMU tuning clip, long sleeves: the hand blob's centroid lay 13 mm from
the wrist, where a hand-held object covers part of the hand; the face blob's 35 mm
below the head joint). The adaptive shoulder offsets absorb what these leave.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.cues.edges import Roi, roi_around_points
from mocapkit.cues.skin import (
    ColourModel,
    GradientConfig,
    figure_mask,
    gradient_map,
    gradient_vector_map,
    shirt_mask,
    skin_mask,
)
from mocapkit.errors import ConfigError, SessionError, ShapeError
from mocapkit.geometry.rotations import rotvec_from_matrix
from mocapkit.skeleton.kinematics import canonical_positions, joint_positions
from mocapkit.skeleton.limbs import arm
from mocapkit.skeleton.model import CANONICAL_JOINTS, Skeleton
from mocapkit.timing import NULL_TIMER, StageTimer
from mocapkit.tracking.base import (
    BRIDGE_S,
    FrameResult,
    canonical_joints_mm,
    fit_summary,
    nan_unobserved,
    observation_status,
)
from mocapkit.tracking.stereo.arm_filter import (
    ArmEstimate,
    ArmFilterConfig,
    ArmModel,
    ArmParticleFilter,
    view_stack,
)
from mocapkit.tracking.stereo.hands import BlobConfig, HeadHandTracker, keypoint_targets

FloatArray = NDArray[np.float64]
SIDES = ("left", "right")

#: Half-size (mm) of the shoulder offset cuboid with a keypoint torso
#: (`ArmFilterConfig.shoulder_box_mm` None). Measured with ``keypoints+torso`` on the six
#: accuracy clips, seeds 0 and 1: arm mean 32.3 and 34.0 mm at recipe A's 50 mm (5 and 4
#: of 6 clips within 40 mm), 22.4 and 24.6 mm at 20 mm (6 of 6 both).
KEYPOINT_TORSO_SHOULDER_BOX_MM = 20.0


@dataclass(frozen=True)
class StereoConfig:
    """Settings of `StereoTracker` (paper defaults; module notes for the gaps).

    Parameters
    ----------
    arm : ArmFilterConfig
    blobs : BlobConfig
    gradient : GradientConfig
    use_keypoints : bool
        Head and hands from 2-D keypoints instead of skin blobs.
    hand_offset_mm : float, optional
        Measured hand point beyond the wrist along the forearm; default 15 (skin) or 0
        (keypoints).
    face_offset_mm : (3,)
        Face-blob centroid relative to the head point, torso frame (skin only).
    figure_ground : bool
        Keep only the figure's gradients (shirt-colour segmentation).
    yaw_gain : float
        Share of the shoulders' yaw taken per frame (0: the yaw stays facing the cameras;
        0.6 measured best of 0.2/0.6/1.0 on two CMU clips).
    torso : {"shoulders", "keypoints"}
        Where the torso comes from: an upright torso whose yaw follows the adaptive
        shoulders, hanging from the head (default, the paper's inputs only); or, with
        ``use_keypoints``, the torso keypoints triangulated over the views each frame
        (rotation from the shoulder line and the pelvis-neck line, the arms hanging
        from the neck keypoint).
    torso_anchor : {"neck", "shoulders"}
        With ``torso="keypoints"``: where the arms hang from. ``"neck"`` (default): the
        model's neck on the neck keypoint, the shoulders at the subject's
        ``segment_vectors_mm`` from it. ``"shoulders"``: the model's shoulders centred on
        the midpoint of the triangulated shoulder keypoints. A detector's neck (mapped
        from the shoulder and hip midpoints, `mocapkit.io.openpose`) lies below the
        shoulders, while the ``azad14`` shoulders sit 40 mm below its neck: on a session
        without the subject's vectors the ``"neck"`` anchor puts the shoulders about 100
        mm too low (Pose2Sim demo: shoulders 153/142 mm from the triangulated keypoints,
        41.6/38.8 mm with ``"shoulders"``, docs/design-notes/stereo.md). On the synthetic accuracy
        clips, whose sessions carry the exact vectors, both are alike (32.3 and 32.1 mm).
    reach_pad_mm : float
        Margin of the arms' reach box.
    gap_limit_s : float
        Longest gap (s) in a measured point that its status calls ``bridged``; longer
        gaps are ``released`` (the hybrid tracker's default, 0.25 s).
    elbow_jump_mm_per_s : float
        The fastest an elbow may move relative to its shoulder from one frame to the
        next: the arm filter's cues at times favour the other side of the elbow circle
        for a frame or a few (the elbow above the head while the hand is right). The
        estimate's swivel about the shoulder-hand axis turns at most this fast along
        the elbow's circle, and a faster move of the estimate is held back a frame and
        taken only when the next frame's cues favour it again
        (`ArmParticleFilter.step`); a move faster than this (the hand's) is flagged as
        a jump (``<side>_elbow_jump`` in fit.csv). About twice the fastest true elbow
        of the tuning clips (3.2 m/s at 30 Hz; their fastest swivel along the circle
        2.8-3.6 m/s).
    seed : int
    """

    arm: ArmFilterConfig = field(default_factory=ArmFilterConfig)
    blobs: BlobConfig = field(default_factory=BlobConfig)
    gradient: GradientConfig = field(default_factory=GradientConfig)
    use_keypoints: bool = False
    hand_offset_mm: float | None = None
    face_offset_mm: tuple[float, float, float] = (0.0, 0.0, -35.0)
    figure_ground: bool = True
    yaw_gain: float = 0.6
    torso: str = "shoulders"
    torso_anchor: str = "neck"
    reach_pad_mm: float = 80.0
    gap_limit_s: float = BRIDGE_S
    elbow_jump_mm_per_s: float = 6000.0
    seed: int = 0

    def __post_init__(self) -> None:
        if self.torso not in ("shoulders", "keypoints"):
            raise ConfigError(f"torso: expected 'shoulders' or 'keypoints', found {self.torso!r}")
        if self.torso_anchor not in ("shoulders", "neck"):
            raise ConfigError(
                f"torso_anchor: expected 'shoulders' or 'neck', found {self.torso_anchor!r}"
            )
        if self.torso == "keypoints" and not self.use_keypoints:
            raise ConfigError("torso='keypoints' needs use_keypoints (the session's 2-D keypoints)")
        if not 0.0 <= self.yaw_gain <= 1.0:
            raise ConfigError(f"yaw_gain: expected a share in [0, 1], found {self.yaw_gain}")
        if not self.gap_limit_s >= 0:
            raise ConfigError(f"gap_limit_s: expected >= 0 s, found {self.gap_limit_s}")
        if not self.elbow_jump_mm_per_s > 0:
            raise ConfigError(
                f"elbow_jump_mm_per_s: expected > 0 mm/s, found {self.elbow_jump_mm_per_s}"
            )
        if self.hand_offset_mm is not None and not self.hand_offset_mm >= 0:
            raise ConfigError(f"hand_offset_mm: expected >= 0 mm, found {self.hand_offset_mm}")

    @property
    def hand_offset(self) -> float:
        """The hand-point offset in use (mm)."""
        if self.hand_offset_mm is not None:
            return float(self.hand_offset_mm)
        return 0.0 if self.use_keypoints else 15.0


@dataclass
class StereoSample:
    """One frame: an image per camera (BGR uint8), optional 2-D keypoints per camera.

    ``images`` may be empty in keypoint mode only when the edge cue is not wanted
    (gradient maps are then all zero).
    """

    time_s: float
    images: Mapping[str, NDArray[np.uint8]]
    keypoints_px: Mapping[str, FloatArray] = field(default_factory=dict)


#: Measured points of the tracker, in the order of ``StereoPose.measured_mm``.
MEASURED = ("head", "left_hand", "right_hand")


@dataclass
class StereoPose(FrameResult):
    """Result of one `StereoTracker.update`: a `FrameResult` with the stereo tracker's details.

    Attributes
    ----------
    time_s : float
    q : (D,) float array
        Pose of the tracker's ``azad14`` skeleton.
    joints_mm : (15, 3) float array
        Canonical joints (`CANONICAL_JOINTS` order, world, mm); NaN where the skeleton has
        none, the head's row NaN while the head is ``released`` or ``missing``, and an
        arm's elbow and wrist rows NaN while its hand is (the filter then runs on the edge
        cue alone, or on nothing in a blackout: its pose is not reported as if seen).
    status : dict of str to str
        ``head``, ``left_hand``, ``right_hand``: ``seen`` (measured this frame),
        ``bridged`` (not measured for at most ``StereoConfig.gap_limit_s``), ``released``
        (longer) or ``missing`` (never measured yet).
    fit : dict of str to float
        ``"<side>_hand_mm"``: distance of the arm's hand point to the measured hand (NaN
        when not measured); ``"rms_mm"``, ``"max_mm"`` over the measured ones;
        ``"<side>_arm_edge_error"``: the arm filter's fused edge error (dimensionless, in
        [0, 1]; 0 when every model point lies on a full gradient);
        ``"<side>_elbow_speed_mm_per_s"``: the elbow's speed relative to its shoulder since
        the previous frame (NaN on the first, or while the elbow is not reported);
        ``"<side>_elbow_jump"``: 1 where that speed is above
        ``StereoConfig.elbow_jump_mm_per_s``, else 0.
    worst : str
        The hand at ``fit["max_mm"]``.
    measured_mm : (3, 3) float array
        Measured head, left hand, right hand (NaN where not measured).
    torso_yaw_rad : float
    arms : mapping of side to ArmEstimate
    """

    measured_mm: FloatArray = field(default_factory=lambda: np.full((3, 3), np.nan))
    torso_yaw_rad: float = math.nan
    arms: dict[str, ArmEstimate] = field(default_factory=dict)


def yaw_matrix(yaw_rad: float) -> FloatArray:
    """Rotation about world z by ``yaw`` (torso x = subject's right = (cos, sin, 0))."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _wrap(a: float) -> float:
    return math.remainder(a, 2.0 * math.pi)


class StereoTracker:
    """Azad et al.'s tracker over any number (>= 2) of calibrated views (module notes).

    Parameters
    ----------
    skeleton : Skeleton
        An ``azad14`` skeleton with the ``adaptive_shoulder`` option (scaled to the subject).
    cameras : sequence of Camera
        Two or more views; the cues average over all of them.
    config : StereoConfig, optional
    keypoint_names : sequence of str, optional
        Joint names of the keypoint rows (needed with ``use_keypoints``).
    timer : StageTimer, optional
        Times the stages of `update` (``skin``, ``head_hands``, ``gradients``, ``arms``);
        attribute ``timer``. The default records nothing.
    """

    def __init__(
        self,
        skeleton: Skeleton,
        cameras: Sequence[Camera],
        config: StereoConfig | None = None,
        keypoint_names: Sequence[str] | None = None,
        timer: StageTimer = NULL_TIMER,
    ) -> None:
        self.timer = timer
        self.config = cfg = config or StereoConfig()
        if len(cameras) < 2:
            raise ConfigError(f"the stereo tracker needs two or more cameras, found {len(cameras)}")
        sizes = {c.image_size for c in cameras}
        if len(sizes) != 1:
            raise ShapeError(f"cameras: expected one image size for every view, found {sizes}")
        if cfg.use_keypoints and not keypoint_names:
            raise ConfigError("use_keypoints: the keypoints' joint names are needed")
        self.skeleton = skeleton
        self.cameras = list(cameras)
        self.keypoint_names = tuple(keypoint_names or ())
        self.limbs = {s: arm(skeleton, s) for s in SIDES}
        for s, limb in self.limbs.items():
            if limb.translation_dofs.shape[0] != 3 or limb.dofs.shape[0] != 4:
                raise ConfigError(
                    f"skeleton {skeleton.name!r}: the {s} arm needs a 3-DoF shoulder offset "
                    "(azad14 with option adaptive_shoulder), a ball shoulder and a hinge elbow"
                )
        q0 = skeleton.zero_pose()
        names = ["head", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow"]
        names += ["left_wrist", "right_wrist"]
        rest = dict(zip(names, canonical_positions(skeleton, q0, names)))
        self.root_rest = joint_positions(skeleton, q0)[0]
        self.head_off = rest["head"] - self.root_rest
        self.shoulder_off = {s: rest[f"{s}_shoulder"] - rest["head"] for s in SIDES}
        self.lengths = {
            s: (
                float(np.linalg.norm(rest[f"{s}_elbow"] - rest[f"{s}_shoulder"])),
                float(np.linalg.norm(rest[f"{s}_wrist"] - rest[f"{s}_elbow"])),
            )
            for s in SIDES
        }
        self.radii = {
            s: np.concatenate(
                [skeleton.radii_mm[self.limbs[s].root], skeleton.radii_mm[self.limbs[s].middle]]
            )
            for s in SIDES
        }
        rng = np.random.default_rng(cfg.seed)
        #: the arm filters' settings (`ArmFilterConfig.shoulder_box_mm` resolved)
        self.arm_config = cfg.arm
        if cfg.arm.shoulder_box_mm is None and cfg.torso == "keypoints":
            self.arm_config = replace(cfg.arm, shoulder_box_mm=KEYPOINT_TORSO_SHOULDER_BOX_MM)
        self.filters = {s: ArmParticleFilter(s, self.arm_config, rng) for s in SIDES}
        self.yaw = self._facing_yaw(np.zeros(3))
        self.hands = HeadHandTracker(self.cameras, cfg.blobs, yaw_matrix(self.yaw)[:, 0])
        self.shirt: ColourModel | None = None
        self.head_mm: FloatArray | None = None
        self.n_frames = 0
        #: time (s) each measured point (`MEASURED`) was last measured; None: never
        self.last_seen_s: dict[str, float | None] = dict.fromkeys(MEASURED)
        #: the previous frame's time and elbows relative to their shoulders (jump check)
        self._prev_elbows: tuple[float, dict[str, FloatArray]] | None = None
        w, h = self.cameras[0].image_size
        # gradient maps, written in place every frame (no per-frame stacking copies)
        self._gx = np.zeros((len(self.cameras), h, w), np.float32)
        self._gy = np.zeros((len(self.cameras), h, w), np.float32)

    def reset_arms(self) -> None:
        """Forget both arms' filter states (particles back to the initial hanging arm,
        shoulder offsets 0): a wrong start for a subject whose arms are elsewhere, used to
        measure how fast each variant converges (`mocapkit.pipelines.stereo`)."""
        self.filters = {
            s: ArmParticleFilter(s, self.arm_config, self.filters[s].rng) for s in SIDES
        }
        self._prev_elbows = None

    # ------------------------------------------------------------------ helpers
    def _facing_yaw(self, at: FloatArray) -> float:
        centres = np.array([c.center_in_world for c in self.cameras])
        d = centres.mean(axis=0) - at
        d[2] = 0.0
        if np.linalg.norm(d) < 1e-9:
            return 0.0
        return math.atan2(-d[0], d[1])  # forward (-sin, cos) points at the cameras

    def _reach_points(self, head: FloatArray, rb: FloatArray) -> FloatArray:
        pts = [head + rb @ np.array([0.0, 0.0, 150.0])]
        for s in SIDES:
            a, b = self.lengths[s]
            r = a + b + self.config.hand_offset + self.config.reach_pad_mm
            sh = head + rb @ self.shoulder_off[s]
            for corner in np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T:
                pts.append(sh + r * corner)
        return np.array(pts)

    def _rois(self, head: FloatArray | None, rb: FloatArray) -> list[Roi | None]:
        if head is None:
            return [None] * len(self.cameras)
        pts = self._reach_points(head, rb)
        out: list[Roi | None] = []
        for c in self.cameras:
            px = c.project(pts)
            if not np.all(np.isfinite(px)):
                out.append(None)  # a reach corner behind the camera: whole image
            else:
                out.append(roi_around_points(px, c.image_size, 4.0))
        return out

    def _arm_rois(
        self, torso_root: FloatArray, rb: FloatArray, hands: dict[str, FloatArray]
    ) -> list[Roi | None]:
        """Where the arms can be this frame: per arm, the box spanned by the shoulder and
        the measured hand grown by the upper arm's length (the elbow circle lies inside
        it), or the arm's whole reach without a measured hand."""
        pts = []
        corners = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
        for s in SIDES:
            a, b = self.lengths[s]
            pad = float(self.radii[s].max()) + self.config.reach_pad_mm
            sh = torso_root + rb @ (self.shoulder_off[s] + self.head_off)
            h = hands[s]
            if np.all(np.isfinite(h)):
                lo = np.minimum(sh, h) - (a + pad)
                hi = np.maximum(sh, h) + (a + pad)
                pts.append(lo + (corners > 0) * (hi - lo))
            else:
                r = a + b + self.config.hand_offset + pad
                pts.append(sh + r * corners)
        allp = np.concatenate(pts)
        out: list[Roi | None] = []
        for c in self.cameras:
            px = c.project(allp)
            if not np.all(np.isfinite(px)):
                out.append(None)
            else:
                out.append(roi_around_points(px, c.image_size, 4.0))
        return out

    def _fit_shirt(self, images: list[NDArray[np.uint8]], head: FloatArray, rb: FloatArray) -> None:
        chest = head + rb @ np.array([0.0, 0.0, -280.0]) + rb @ np.array([0.0, 60.0, 0.0])
        samples = []
        for c, img in zip(self.cameras, images):
            px = c.project(chest[None])[0]
            if not np.all(np.isfinite(px)) or not c.in_image(px, 10.0):
                continue
            x, y = np.round(px).astype(int)
            samples.append(img[y - 5 : y + 6, x - 5 : x + 6].reshape(-1, 3))
        if samples:
            self.shirt = ColourModel.fit(np.concatenate(samples), radius=3.0, luma_margin=40.0)

    def _torso_from_keypoints(
        self, kps: list[FloatArray]
    ) -> tuple[FloatArray, FloatArray, FloatArray] | None:
        """Torso rotation (x: left to right shoulder, z: pelvis to neck, orthogonalised), the
        neck and the shoulders' midpoint, triangulated from the keypoints; None without
        both shoulders and the neck."""
        names = ("left_shoulder", "right_shoulder", "neck", "pelvis")
        p = keypoint_targets(self.cameras, kps, self.keypoint_names, names)
        if not np.all(np.isfinite(p[:3])):
            return None
        x = p[1] - p[0]
        up = p[2] - p[3] if np.all(np.isfinite(p[3])) else np.array([0.0, 0.0, 1.0])
        x = x / max(float(np.linalg.norm(x)), 1e-9)
        z = up - (up @ x) * x
        nz = float(np.linalg.norm(z))
        if nz < 1e-6:
            return None
        z = z / nz
        rb = np.stack([x, np.cross(z, x), z], axis=1)
        return rb, p[2], 0.5 * (p[0] + p[1])

    def _root_under(self, mid_shoulders: FloatArray, rb: FloatArray) -> FloatArray:
        """The torso root that centres the model's two shoulders on ``mid_shoulders``
        (`StereoConfig.torso_anchor`)."""
        mid_model = 0.5 * (self.shoulder_off["left"] + self.shoulder_off["right"]) + self.head_off
        return np.asarray(mid_shoulders - rb @ mid_model, dtype=float)

    def _figure(
        self, img: NDArray[np.uint8], skin: NDArray[np.uint8], roi: Roi | None
    ) -> NDArray[np.uint8]:
        """Figure mask (shirt or skin, dilated), computed inside ``roi`` only."""
        h, w = skin.shape
        if self.shirt is None:  # no shirt model yet: everything is figure
            return np.full((h, w), 255, np.uint8)
        x0, y0, x1, y1 = (0, 0, w, h) if roi is None else roi
        out = np.zeros((h, w), np.uint8)
        crop = np.ascontiguousarray(img[y0:y1, x0:x1])
        if crop.size:
            out[y0:y1, x0:x1] = figure_mask(shirt_mask(crop, self.shirt), skin[y0:y1, x0:x1])
        return out

    # ------------------------------------------------------------------ update
    def update(self, sample: StereoSample) -> StereoPose:
        """Track one frame (module notes); returns the pose."""
        cfg = self.config
        rb = yaw_matrix(self.yaw)
        torso_root: FloatArray | None = None  # the torso joint (neck), when measured
        images: list[NDArray[np.uint8]] = []
        for c in self.cameras:
            if c.name not in sample.images:
                if cfg.use_keypoints and not sample.images:
                    images = []
                    break
                raise SessionError(
                    f"frame at {sample.time_s:.3f} s has no image of camera {c.name!r}; it has "
                    f"{sorted(sample.images)}"
                )
            images.append(np.asarray(sample.images[c.name]))
        rois = self._rois(self.head_mm, rb)
        # ---------------------------------------------------------- head and hands
        skins: list[NDArray[np.uint8]] = []
        if images and (not cfg.use_keypoints or cfg.figure_ground):
            with self.timer.stage("skin"):
                skins = [skin_mask(img, roi=r) for img, r in zip(images, rois)]
        with self.timer.stage("head_hands"):
            if cfg.use_keypoints:
                kps = []
                for c in self.cameras:
                    kp = sample.keypoints_px.get(c.name)
                    kps.append(
                        np.full((len(self.keypoint_names), 2), np.nan)
                        if kp is None
                        else np.asarray(kp)
                    )
                meas = keypoint_targets(self.cameras, kps, self.keypoint_names)
                head_pt = meas[0]
                if cfg.torso == "keypoints":
                    torso_kp = self._torso_from_keypoints(kps)
                    if torso_kp is not None:
                        rb, torso_root, mid_shoulders = torso_kp
                        if cfg.torso_anchor == "shoulders":
                            torso_root = self._root_under(mid_shoulders, rb)
                        self.yaw = math.atan2(rb[1, 0], rb[0, 0])
            else:
                self.hands.set_right_axis(rb[:, 0])
                meas = (
                    self.hands.update(sample.time_s, skins, rois)
                    if skins
                    else np.full((3, 3), np.nan)
                )
                head_pt = meas[0] - rb @ np.asarray(cfg.face_offset_mm)
            if np.all(np.isfinite(head_pt)):
                if self.head_mm is None and cfg.torso == "shoulders":
                    self.yaw = self._facing_yaw(head_pt)
                    rb = yaw_matrix(self.yaw)
                self.head_mm = head_pt
            head = self.head_mm
            if head is None:
                head = np.array([0.0, 0.0, 1600.0])  # nothing seen yet: a standing adult
            if torso_root is None:
                torso_root = head - rb @ self.head_off
        # ---------------------------------------------------------- gradient maps
        with self.timer.stage("gradients"):
            if images:
                if cfg.figure_ground and self.shirt is None and self.head_mm is not None:
                    self._fit_shirt(images, head, rb)
                hands_now = {"left": meas[1], "right": meas[2]}
                rois = (
                    self._arm_rois(torso_root, rb, hands_now) if self.head_mm is not None else rois
                )
                grads = self._gx
                grads_y = self._gy if cfg.arm.oriented_edges else None
                for i, (img, r) in enumerate(zip(images, rois)):
                    fig = None
                    if cfg.figure_ground and self.shirt is not None:
                        fig = self._figure(img, skins[i], r)
                    if cfg.arm.oriented_edges:
                        gradient_vector_map(
                            img, roi=r, figure=fig, config=cfg.gradient, out=(grads[i], self._gy[i])
                        )
                    else:
                        gradient_map(img, roi=r, figure=fig, config=cfg.gradient, out=grads[i])
            else:
                grads = self._gx
                grads.fill(0.0)
                grads_y = None
                if cfg.arm.oriented_edges:
                    grads_y = self._gy
                    grads_y.fill(0.0)
            views = view_stack(self.cameras, grads, grads_y)
        # ---------------------------------------------------------- arms
        with self.timer.stage("arms"):
            hands = {"left": meas[1], "right": meas[2]}
            ests: dict[str, ArmEstimate] = {}
            sampling = np.array(
                [
                    cfg.arm.step_px,
                    float(cfg.arm.max_samples_per_line),
                    float(cfg.arm.oriented_edges),
                ]
            )
            max_step_mm = math.inf  # the elbow's reach in a frame (jumps held one frame)
            if self._prev_elbows is not None and sample.time_s > self._prev_elbows[0]:
                max_step_mm = cfg.elbow_jump_mm_per_s * (sample.time_s - self._prev_elbows[0])
            for s in SIDES:
                a, b = self.lengths[s]
                model = ArmModel(
                    rb,
                    torso_root + rb @ (self.shoulder_off[s] + self.head_off),
                    np.array([a, b, cfg.hand_offset]),
                    self.radii[s],
                    np.asarray(hands[s], dtype=float),
                    sampling,
                )
                ests[s] = self.filters[s].step(model, views, max_step_mm)
        # ---------------------------------------------------------- torso yaw
        if cfg.yaw_gain > 0 and cfg.torso == "shoulders":
            right = ests["right"].points_mm[0] - ests["left"].points_mm[0]
            if math.hypot(right[0], right[1]) > 1e-6:
                meas_yaw = math.atan2(right[1], right[0])
                self.yaw = _wrap(self.yaw + cfg.yaw_gain * _wrap(meas_yaw - self.yaw))
        self.n_frames += 1
        return self._pose(float(sample.time_s), torso_root, rb, ests, meas)

    def _pose(
        self,
        time_s: float,
        torso_root: FloatArray,
        rb: FloatArray,
        ests: dict[str, ArmEstimate],
        meas: FloatArray,
    ) -> StereoPose:
        sk = self.skeleton
        q = sk.zero_pose()
        q[:3] = torso_root - self.root_rest
        yaw = math.atan2(rb[1, 0], rb[0, 0])
        q[3:6] = rotvec_from_matrix(rb)
        for s in SIDES:
            limb = self.limbs[s]
            q[limb.translation_dofs] = ests[s].state[4:]
            q[limb.dofs] = ests[s].state[:4]
        status = self._status(time_s, meas)
        joints = nan_unobserved(canonical_joints_mm(sk, canonical_positions(sk, q)), status)
        dist = {
            f"{s}_hand": ests[s].dist_mm if np.all(np.isfinite(meas[1 + i])) else math.nan
            for i, s in enumerate(SIDES)
        }
        fit, worst = fit_summary(dist)
        for s in SIDES:
            fit[f"{s}_arm_edge_error"] = float(ests[s].edge_error)
        fit.update(self._elbow_jumps(time_s, ests, joints))
        return StereoPose(
            time_s=time_s,
            q=q,
            joints_mm=joints,
            status=status,
            fit=fit,
            worst=worst,
            measured_mm=meas,
            torso_yaw_rad=yaw,
            arms=ests,
        )

    def _elbow_jumps(
        self, time_s: float, ests: dict[str, ArmEstimate], joints: FloatArray
    ) -> dict[str, float]:
        """Per arm: the elbow's speed relative to its shoulder since the previous frame
        and whether it is a jump (`StereoConfig.elbow_jump_mm_per_s`)."""
        elbows = {s: ests[s].points_mm[1] - ests[s].points_mm[0] for s in SIDES}
        prev, self._prev_elbows = self._prev_elbows, (time_s, elbows)
        out = {}
        for s in SIDES:
            reported = bool(np.all(np.isfinite(joints[CANONICAL_JOINTS.index(f"{s}_elbow")])))
            speed = math.nan
            if prev is not None and reported and time_s > prev[0]:
                speed = float(np.linalg.norm(elbows[s] - prev[1][s])) / (time_s - prev[0])
            out[f"{s}_elbow_speed_mm_per_s"] = speed
            out[f"{s}_elbow_jump"] = float(speed > self.config.elbow_jump_mm_per_s)
        return out

    def _status(self, time_s: float, meas: FloatArray) -> dict[str, str]:
        """Per measured point: seen, bridged, released or missing (never measured yet)."""
        out = {}
        for name, p in zip(MEASURED, meas):
            if np.all(np.isfinite(p)):
                self.last_seen_s[name] = time_s
            last = self.last_seen_s[name]
            unseen_s = math.inf if last is None else time_s - last
            out[name] = observation_status(unseen_s, last is not None, self.config.gap_limit_s)
        return out


def azad_skeleton(
    bone_lengths_mm: Mapping[str, float] | None = None,
    segment_vectors_mm: Mapping[str, Any] | None = None,
) -> Skeleton:
    """The ``azad14`` skeleton with adaptive shoulders, fitted to a subject's measurements.

    Parameters
    ----------
    bone_lengths_mm : mapping, optional
        ``left_upper_arm``, ``left_forearm``, ... (session.json ``subject.bone_lengths_mm``).
    segment_vectors_mm : mapping, optional
        ``head``, ``left_clavicle``, ``right_clavicle`` rest vectors from the neck (mm);
        they place the head point and the shoulders.
    """
    from mocapkit.skeleton.presets import load_preset

    sk = load_preset("azad14", ["adaptive_shoulder"])
    offsets = sk.offsets_mm.copy()
    ends = sk.bone_end_mm.copy()
    canonical = dict(sk.canonical)
    lengths = dict(bone_lengths_mm or {})
    vectors = {k: np.asarray(v, dtype=float) for k, v in (segment_vectors_mm or {}).items()}
    for s in SIDES:
        limb = arm(sk, s)
        up = lengths.get(f"{s}_upper_arm")
        fore = lengths.get(f"{s}_forearm")
        if up is not None:
            if not (up > 0 and math.isfinite(up)):
                raise ShapeError(f"bone_lengths_mm[{s}_upper_arm]: expected > 0, found {up}")
            ends[limb.root] = (0.0, 0.0, -float(up))
            offsets[limb.middle] = (0.0, 0.0, -float(up))
        if fore is not None:
            if not (fore > 0 and math.isfinite(fore)):
                raise ShapeError(f"bone_lengths_mm[{s}_forearm]: expected > 0, found {fore}")
            ends[limb.middle] = (0.0, 0.0, -float(fore))
            offsets[limb.end] = (0.0, 0.0, -float(fore))
        clav = vectors.get(f"{s}_clavicle")
        if clav is not None and clav.shape == (3,):
            offsets[limb.root] = clav
    head_v = vectors.get("head")
    if head_v is not None and head_v.shape == (3,):
        hj, _p = canonical["head"]
        canonical["head"] = (hj, (float(head_v[0]), float(head_v[1]), float(head_v[2])))
    return sk.replace(offsets_mm=offsets, bone_end_mm=ends, canonical=canonical)


__all__ = [
    "MEASURED",
    "SIDES",
    "StereoConfig",
    "StereoPose",
    "StereoSample",
    "StereoTracker",
    "azad_skeleton",
    "yaw_matrix",
]
