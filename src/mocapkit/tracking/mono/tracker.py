"""The monocular tracker: smoothed 2-D joints -> flips -> pruning -> Viterbi (Mamania 2004).

Per frame (streaming, `MonoTracker.push`):

1. the stick's joints are smoothed by the fixed-lag smoother (§3.3, errata M6;
   `mocapkit.tracking.mono.smoother`), final ``smooth_lag`` frames later;
2. the subject's depth is estimated from the known link lengths (camera models below);
3. every flip configuration is enumerated, pruned by joint limits and collisions during
   the search (§4.2; `mocapkit.tracking.mono.flips`); a link whose child's ray lies
   within ``reach_tolerance`` of its length keeps both flips (errata M5 with a length
   band, beyond the paper: video lengths are a few per cent short);
4. the survivors become a layer of the pose graph (`mocapkit.tracking.mono.graph`);
   edges are weighted by the corrected angular acceleration of eq. 3 over pair states
   (errata M1-M3, ``cost="acceleration"``), by joint accelerations (eq. 4-5 with errata
   M4, ``"joint_acceleration"``), or by the first-order rotation (``"rotation"``).
   Beyond the paper, each pose carries soft costs (`mocapkit.tracking.mono.priors`):
   by default the clavicle prior (``clavicle_weight``) and the data-driven arm prior
   (``arm_prior_weight``, `mocapkit.tracking.mono.arm_prior`), and where the neck is
   rebuilt (a detector's, ``rebuilt_joints``) the rigid girdle's clavicle angle
   (``girdle_weight``) with a wider reach band on the clavicles;
5. Viterbi picks the path (§4.3; `mocapkit.tracking.mono.viterbi.Decoder`): offline
   (``lag=None``) exactly, each frame fixed as soon as every path agrees on it (or
   ``window`` frames later); online with a fixed lag. The online latency is
   ``smooth_lag + lag`` frames.

With legs (``legs``) the graph is decoded one chain at a time: the upper body (trunk,
clavicles, head, arms: at most 2^8 poses a frame) first, then the legs (at most 2^6)
enumerated below each decided upper-body pose, in a second graph. Enumerating all 14
links together gives up to 2^14 poses a frame and 2^28 edges between two frames (the
cause of gigabytes per clip and MemoryError); the two-chain search keeps both bounded,
at the cost that the legs do not vote on the trunk's flip, and online a latency of
``smooth_lag + 2 lag`` frames for the legs. Memory stays flat with the recording's
length: only open frames are kept. The legs' only soft cost is the floor's: with a
calibrated camera and the floor known (``ankle_floor_mm``), in frames where both feet stand
still each ankle lies where its ray meets the floor, and the difference of the two depths
(free of the error of the subject's own depth) costs the legs' poses that put the other
foot in front (``floor_leg_weight``, `mocapkit.tracking.mono.priors.planted_feet_cost`).

Camera models (the paper assumes orthography, the camera 10 m away, §4):

- ``"orthographic"``: pixels as they are; lengths in px; no calibration needed. 3-D is
  returned in mm through the image scale (px per mm, from the stature) in a camera-like
  frame.
- ``"weak"``: weak perspective with a calibrated camera: undistorted normalised image
  coordinates are scaled by the subject's depth Z_t, the flips are those of the
  orthographic case, and the subject is placed at Z_t in the camera's world frame.
- ``"perspective"`` (default with a camera): the neck lies at depth Z_t on its ray and each
  child joint on its own ray at the link's length from its parent (two points).

Depth Z_t of the neck: a link of length L hanging from the neck at depth Z can reach the
child's viewing ray only if ``Z sin(angle between the two rays) <= L``, with equality when
the link is parallel to the image (§4.1's observation). So each frame bounds the depth
from above: ``Z_raw = min_l L_l / sin(angle_l - margin)`` over the links from the neck
(trunk, clavicles, head; the other links' parents have unknown depth), the angle reduced
by ``depth_margin_px`` of image noise. Z_t is a low percentile (10 %) of Z_raw over the
last ``depth_window`` frames (causal), so a frame where such a link is near parallel sets
the depth of its neighbours. On two synthetic clips (true 2-D + 2 px noise, smoothed) this
was within -37..+22 mm of the truth in the median, 134-185 mm at the 90th percentile; the
percentile, window and margin were picked on those two clips. The paper has no such step
(its camera is orthographic).

The trunk's lean (beyond the paper): the neck's depth is a bound at which the trunk just
reaches the pelvis's ray, and the trunk's length comes from the video, where a detector's
rebuilt pelvis and a trunk that leans throughout make it short; so a leaning trunk is
drawn in the image plane with one candidate. Each frame therefore also offers the poses
with the pelvis on its ray at the trunk sines ``trunk_lean_sines`` either way (the neck
where the depth estimate puts it, the trunk longer than its estimate), and the path chooses
the lean over time by the motion cost, the soft costs and, from a detector with its own
3-D, its depth order. A frame then has up to 2^8 + 2 x 2^7 poses before pruning.

Known initial pose (the paper's third assumption, §4: "The initial pose of the subject
is also known"; optional, ``initial_pose``): the first frame with a pose keeps only the
surviving candidate nearest to it (mean distance of the joints relative to the neck), so
the path starts in that pose's flips. Without it the offline path chooses its start
freely: a link and its mirror through the image plane cost nearly the same in eq. 3
(a reflection keeps every |alpha|; only perspective breaks the tie), so where the limits
and priors allow both, the start decides which of the two the path follows
(docs/design-notes/mono.md).

A frame whose poses are all pruned keeps its unpruned set (recipe M). Pair-state
decoding is O(N^3) per frame; where a frame has more than ``max_pair_states`` survivors,
the ones with the lowest first-order forward cost are kept (a beam; exact below the cap).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.camera.pinhole import Camera
from mocapkit.errors import ConfigError, ShapeError, unknown_name
from mocapkit.tracking.mono.arm_prior import ArmPrior, default_arm_prior
from mocapkit.tracking.mono.flips import enumerate_poses
from mocapkit.tracking.mono.graph import Layer, PoseGraph
from mocapkit.tracking.mono.placement import ANKLE_JOINTS, floor_points
from mocapkit.tracking.mono.priors import (
    clavicle_forward_cost,
    depth_order_cost,
    girdle_angle_cost,
    planted_feet_cost,
)
from mocapkit.tracking.mono.smoother import KeypointSmoother
from mocapkit.tracking.mono.stick import UPPER_LINKS, LimitConfig, StickModel, stick_model

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

CAMERA_MODELS = ("orthographic", "weak", "perspective")
COSTS = ("acceleration", "joint_acceleration", "rotation")


@dataclass(frozen=True)
class MonoConfig:
    """Settings of the monocular tracker (see the module docstring).

    Attributes
    ----------
    legs : bool
        Track the legs too (the paper: upper body).
    camera_model : {"orthographic", "weak", "perspective"}
    cost : {"acceleration", "joint_acceleration", "rotation"}
    lag : int or None
        Viterbi lag in frames (online); None: offline, exact.
    smooth_lag : int
        Fixed-lag smoother lag (frames; recipe M: 5).
    noise_px : float
        2-D measurement noise of the smoother (recipe M: 3 px).
    accel_px_s2 : float
        Smoother's white-noise acceleration (px/s^2).
    max_gap : int
        Frames a joint may be unseen before it counts as missing.
    depth_window : int
        Frames of the causal depth estimate.
    depth_margin_px : float
        Image noise allowed for in the depth bound (px).
    max_pair_states : int
        Beam cap of pair-state decoding.
    window : int
        Offline: most frames a frame waits for every path to agree on it before it is
        fixed from the best current path (`mocapkit.tracking.mono.viterbi.Decoder`);
        bounds the memory. Default 300 (10 s at 30 fps).
    limits : LimitConfig
    clavicle_weight : float
        Unary cost per unit of `mocapkit.tracking.mono.priors.clavicle_forward_cost`
        (eq. 3 costs ~450 rad/s^2 per frame on a tuning clip); 0: the paper's. Default 300,
        chosen on the five accuracy clips and checked on four held-out clips
        (docs/design-notes/mono.md).
    arm_prior_weight : float
        Unary cost per nat of the arm prior
        (`mocapkit.tracking.mono.arm_prior.ArmPrior.cost`, both arms); 0: off. Default
        30: weights 10-100 all lowered the mean error of the five accuracy clips and of
        four held-out clips (each tracked with a prior fitted without it; design notes).
    short_link_weight : float
        With video lengths and the perspective model: after each length pass, links
        shorter than the body's proportions at the video's stature are moved this share
        of the way up (`mocapkit.tracking.mono.lengths.raise_short_links`); 0: off.
        Default 0.5 (docs/design-notes/mono.md).
    reach_tolerance : float
        Length band of errata M5 (`mocapkit.tracking.mono.flips`, ``reach_tolerance``):
        a link whose parent lies within ``L (1 +- reach_tolerance)`` of its child's ray
        keeps both flips, the child on its ray at a length rising from L to
        ``L (1 + reach_tolerance)`` across the band; 0: M5 exactly. Default 0.02 (in
        `mocapkit.pipelines.mono.track_mono` the last pass only): 0.015-0.025 lowered
        the error and raised the flips of the five accuracy clips and of four held-out
        clips, over three noise seeds (docs/design-notes/mono.md).
    rebuilt_joints : tuple of str
        Joints of the 2-D input that were not observed but rebuilt from others (a
        detector's neck and pelvis, placed on the hip-to-shoulder midpoint line by
        `mocapkit.io.openpose`; `mocapkit.pipelines.mono.detector_config`). Default none
        (the keypoints' own neck and pelvis).
    rebuilt_reach_tolerance : float
        The reach band of the ``rebuilt_reach_links`` with an end in ``rebuilt_joints``
        (at least ``reach_tolerance``): a few px of a rebuilt neck's error change a 40 px
        clavicle's projected length by up to 10 %, so a clavicle 15-20 deg out of the
        plane can look longer than its link and lose both flips to the in-plane one.
        Default 0.1 (0.08-0.1 with the girdle cost kept both sets' figures; 0.15 and
        0.06 did not, `git log -p docs/design-notes/mono.md`).
    rebuilt_reach_links : tuple of str
        Links the wider band applies to: the clavicles (also the trunk and head: worse).
    girdle_weight : float
        Unary cost per unit of `mocapkit.tracking.mono.priors.girdle_angle_cost` where
        the clavicles' common parent (the neck) is in ``rebuilt_joints`` and
        ``girdle_cosine`` is finite; 0: off. Default 100: offline 300 gained 0.3-0.5 mm
        and about a point of flips on the tuning clips, but online (``lag`` 10) it
        mirrored an arm; 1000 mirrors it offline too (`git log -p docs/design-notes/mono.md`).
    girdle_cosine : float
        Cosine of the angle between the two clavicles of the subject's rigid girdle;
        NaN (default): no girdle cost.
    depth_order_weight : float
        Unary cost per unit of `mocapkit.tracking.mono.priors.depth_order_cost` where
        the frame comes with a detector's depth order of its links (``link_sines`` of
        `MonoTracker.push`, from MediaPipe's world landmarks); 0: off. Default 1000
        (eq. 3 costs ~450 per frame): of 10-3000 the best on the five tuning clips from
        MediaPipe on the rendered video (62.8 -> 59.4 mm PA); report clips 55.8 -> 54.5
        (docs/design-notes/mono.md).
    depth_fusion_weight : float
        Perspective model, where the frame comes with a detector's ``link_sines``: the
        share of the detector's depth offset in each link's, the chosen pose's joints
        moved along their rays (`mocapkit.tracking.mono.depth_fusion.fuse_link_depths`,
        applied by `mocapkit.tracking.mono.stream.MonoStream` after the placement); 0: off.
        Default 0.4: of 0.3-0.6 the best on the five tuning clips from MediaPipe on the
        rendered video (53.5 -> 51.1 mm PA, a flat 51.1-51.2 over 0.3-0.5); report clips
        48.3 -> 43.7 (docs/design-notes/mono.md).
    floor_leg_weight : float
        With legs, a calibrated perspective camera and the floor known (`MonoTracker`'s
        ``ankle_floor_mm``): unary cost per leg length of
        `mocapkit.tracking.mono.priors.planted_feet_cost` in frames where both feet stand
        on the floor; 0: off. Default 1000: of 300 / 1000 / 3000 the best on the five
        tuning clips from MediaPipe (whole-body PA 72.1 -> 68.9 / 68.4 / 68.9 mm;
        docs/design-notes/mono.md).
    planted_speed_mm_s : float
        A foot counts as standing on the floor where its ankle's floor point (its ray
        met with the floor's plane) moves slower than this. Default 300 (150 / 600 gave
        69.0 / 68.9 mm on the tuning clips at weight 1000).
    trunk_lean_sines : tuple of float
        Perspective model: besides the search's poses, those with the pelvis on its ray
        where the trunk leaves the plane normal to that ray by each of these sines, towards
        and away from the camera, where the trunk's length does not already reach that far
        (the trunk then longer than its estimate): the trunk's lean as states of the graph
        (module docstring). Empty: the search's poses only. Default (0.25,): of single
        sines 0.15-0.4 the best on the five tuning clips from MediaPipe on the rendered
        video (59.4 -> 58.4 mm PA; a flat 58.4-58.9 over 0.15-0.35; two sines or a cost
        towards the detector's own lean did no better; docs/design-notes/mono.md).
    arm_prior : ArmPrior or None
        The mixture the arm prior uses; None: the shipped table
        (`mocapkit.tracking.mono.arm_prior.default_arm_prior`).
    """

    legs: bool = False
    camera_model: str = "perspective"
    cost: str = "acceleration"
    lag: int | None = None
    smooth_lag: int = 5
    noise_px: float = 3.0
    accel_px_s2: float = 3000.0
    max_gap: int = 5
    depth_window: int = 31
    depth_margin_px: float = 1.5
    max_pair_states: int = 96
    window: int = 300
    limits: LimitConfig = field(default_factory=LimitConfig)
    clavicle_weight: float = 300.0
    arm_prior_weight: float = 30.0
    short_link_weight: float = 0.5
    reach_tolerance: float = 0.02
    rebuilt_joints: tuple[str, ...] = ()
    rebuilt_reach_tolerance: float = 0.1
    rebuilt_reach_links: tuple[str, ...] = ("left_clavicle", "right_clavicle")
    girdle_weight: float = 100.0
    girdle_cosine: float = float("nan")
    depth_order_weight: float = 1000.0
    depth_fusion_weight: float = 0.4
    trunk_lean_sines: tuple[float, ...] = (0.25,)
    floor_leg_weight: float = 1000.0
    planted_speed_mm_s: float = 300.0
    arm_prior: ArmPrior | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        if self.camera_model not in CAMERA_MODELS:
            raise ConfigError(
                f"MonoConfig.camera_model: expected one of {CAMERA_MODELS}, found "
                f"{self.camera_model!r}"
            )
        if self.cost not in COSTS:
            raise ConfigError(f"MonoConfig.cost: expected one of {COSTS}, found {self.cost!r}")
        if self.lag is not None and self.lag < 1:
            raise ConfigError(f"MonoConfig.lag: expected >= 1 frame or None, found {self.lag}")
        if not 0.0 <= self.short_link_weight <= 1.0:
            raise ConfigError(
                f"MonoConfig.short_link_weight: expected [0, 1], found {self.short_link_weight}"
            )
        if not 0.0 <= self.reach_tolerance < 1.0:
            raise ConfigError(
                f"MonoConfig.reach_tolerance: expected [0, 1), found {self.reach_tolerance}"
            )
        if not 0.0 <= self.rebuilt_reach_tolerance < 1.0:
            raise ConfigError(
                "MonoConfig.rebuilt_reach_tolerance: expected [0, 1), found "
                f"{self.rebuilt_reach_tolerance}"
            )
        for name in (
            "clavicle_weight",
            "arm_prior_weight",
            "girdle_weight",
            "depth_order_weight",
            "floor_leg_weight",
        ):
            # a negative weight rewards what the cost penalises; NaN poisons every path
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ConfigError(
                    f"MonoConfig.{name}: expected a finite weight >= 0 (0: off), found {value}"
                )
        if not 0.0 <= self.depth_fusion_weight <= 1.0:
            raise ConfigError(
                "MonoConfig.depth_fusion_weight: expected [0, 1] (0: off), found "
                f"{self.depth_fusion_weight}"
            )
        if not (math.isfinite(self.planted_speed_mm_s) and self.planted_speed_mm_s > 0.0):
            raise ConfigError(
                "MonoConfig.planted_speed_mm_s: expected a finite speed > 0 (mm/s), found "
                f"{self.planted_speed_mm_s}"
            )
        if not all(0.0 < x < 1.0 for x in self.trunk_lean_sines):
            raise ConfigError(
                "MonoConfig.trunk_lean_sines: expected sines in (0, 1), found "
                f"{self.trunk_lean_sines}"
            )
        if (
            self.depth_window < 1
            or self.max_pair_states < 1
            or self.window < 1
            or self.smooth_lag < 0
        ):
            raise ConfigError(
                "MonoConfig: depth_window, max_pair_states and window must be >= 1, "
                f"smooth_lag >= 0; found {self.depth_window}, {self.max_pair_states}, "
                f"{self.window}, {self.smooth_lag}"
            )


@dataclass
class MonoFrame:
    """The tracker's answer for one frame.

    Attributes
    ----------
    index : int
    time_s : float
    joints_in_camera : (K, 3) float
        Stick joints in the camera frame (mm); NaN where unseen or no pose.
    code : int
        Chosen flips (bit l: link l away from the camera); -1 without a pose.
    n_candidates : int
        Distinct poses before pruning.
    n_survivors : int
        Poses left after pruning (the layer's size).
    pruned_all : bool
        Every pose was pruned; the unpruned set was kept.
    residual_px : float
        Mean image distance between the chosen pose's projection and the input points.
    depth_mm : float
        Depth of the neck (mm; NaN for the orthographic model).
    """

    index: int
    time_s: float
    joints_in_camera: FloatArray
    code: int
    n_candidates: int
    n_survivors: int
    pruned_all: bool
    residual_px: float
    depth_mm: float


@dataclass
class _FrameInfo:
    """What a frame carries through the graphs besides its poses."""

    raw_px: FloatArray
    obs: FloatArray
    root: FloatArray
    depth: float
    n_candidates: int
    n_survivors: int
    pruned_all: bool
    floor_depth: FloatArray | None = None  # per ankle, where its foot is planted


class MonoTracker:
    """Streaming monocular tracker over a stick figure (see the module docstring).

    A `mocapkit.tracking.base.DelayedTracker`-like core: `push` takes one frame's 2-D
    joints and returns the frames it makes final; `finish` the rest.

    Parameters
    ----------
    lengths : (L,) float
        Link lengths of ``model`` (mm; px for the orthographic model).
    camera : Camera or None
        Calibrated camera (needed for the weak and perspective models).
    dt_s : float
        Nominal frame interval (the smoother's step).
    config : MonoConfig
    model : StickModel, optional
        Default: `stick_model` with ``config.legs`` and ``config.limits``.
    initial_pose : (K, 3) float, optional
        The known pose of the first posed frame (the paper's assumption 3): the stick's
        joints in the camera frame, in the tracker's units (mm; px for the orthographic
        model, whose depth is in px too), NaN where unknown; only positions relative to
        the neck are used, so its depth need not match the tracker's. That frame keeps
        only its surviving candidate nearest to it.
    ankle_floor_mm : float, optional
        With legs and the perspective model: the height above the world's floor (z = 0,
        z up) of the ankles' image points when the foot stands on it (the placement's,
        `mocapkit.tracking.mono.placement.FloorDepth`). Where both feet are planted (their
        ankles' floor points moving slower than ``planted_speed_mm_s`` across the floor),
        the legs' poses whose ankles' depth difference departs from the floor points'
        are costed (``floor_leg_weight``, `mocapkit.tracking.mono.priors.planted_feet_cost`).
        None: no such cost.
    """

    def __init__(
        self,
        lengths: ArrayLike,
        camera: Camera | None,
        dt_s: float,
        config: MonoConfig | None = None,
        model: StickModel | None = None,
        initial_pose: ArrayLike | None = None,
        ankle_floor_mm: float | None = None,
    ) -> None:
        self.config = cfg = config or MonoConfig()
        self.model = model or stick_model(cfg.legs, cfg.limits)
        self.lengths = np.asarray(lengths, dtype=float)
        self.model.arrays(self.lengths)  # validates
        # the upper body's chain: the model itself, or its first links where it has legs
        n_upper = len(UPPER_LINKS)
        self._legs = self.model.n_links > n_upper
        self.upper = stick_model(False, self.model.limits) if self._legs else self.model
        if self.upper.joint_names != self.model.joint_names[: self.upper.n_joints]:
            raise ConfigError(
                "MonoTracker: expected a stick whose first links are the upper body's "
                f"{self.upper.segments}, found {self.model.segments}"
            )
        self._n_up = self.upper.n_joints
        self._ankles = (
            (
                self.model.joint_names.index(ANKLE_JOINTS[0]),
                self.model.joint_names.index(ANKLE_JOINTS[1]),
            )
            if self._legs
            else (0, 0)
        )
        self._ankle_floor_mm = (
            ankle_floor_mm
            if self._legs
            and cfg.floor_leg_weight > 0
            and cfg.camera_model == "perspective"
            and camera is not None
            else None
        )
        legs = [("left_thigh", "left_shank"), ("right_thigh", "right_shank")] if self._legs else []
        self._leg_mm = float(
            np.mean([sum(self.lengths[self.model.link_index(s)] for s in leg) for leg in legs])
            if legs
            else float("nan")
        )
        self._last_feet: tuple[float, FloatArray] | None = None  # time, floor points (A, 3)
        self._reach = self._link_reach()
        self._trunk = self.model.link_index("trunk")
        # the girdle cost where the neck is rebuilt (its clavicles mirror images in 2-D)
        self._girdle = (
            cfg.girdle_weight > 0
            and np.isfinite(cfg.girdle_cosine)
            and self.model.joint_names[self.model.parent[self.model.link_index("left_clavicle")]]
            in cfg.rebuilt_joints
        )
        if cfg.camera_model != "orthographic" and camera is None:
            raise ConfigError(
                f"MonoTracker: camera model {cfg.camera_model!r} needs a calibrated camera"
            )
        self.camera = camera
        self.dt_s = float(dt_s)
        self._smoother = KeypointSmoother(
            self.model.n_joints, dt_s, cfg.smooth_lag, cfg.noise_px, cfg.accel_px_s2, cfg.max_gap
        )

        def graph(model: StickModel) -> PoseGraph:
            return PoseGraph(model, cfg.cost, dt_s, cfg.lag, cfg.window, cfg.max_pair_states)

        self._graph = graph(self.upper)
        self._leg_graph = graph(self.model) if self._legs else None
        # (time, raw, the detector's link sines or None) of the frames to smooth
        self._pending: deque[tuple[float, FloatArray, FloatArray | None]] = deque()
        self._pushed = 0
        self._processed = 0
        self._depths: deque[float] = deque(maxlen=cfg.depth_window)
        self._arm_prior: ArmPrior | None = None
        if cfg.arm_prior_weight > 0:
            self._arm_prior = cfg.arm_prior or default_arm_prior()
        self._initial: FloatArray | None = None
        self._initial_legs: FloatArray | None = None
        if initial_pose is not None:
            q = np.asarray(initial_pose, dtype=float)
            if q.shape != (self.model.n_joints, 3):
                raise ShapeError(
                    f"MonoTracker: expected an initial pose of shape ({self.model.n_joints}, 3) "
                    f"for {self.model.joint_names}, found {q.shape}"
                )
            known = np.isfinite(q).all(axis=1)
            if not known[0] or not known[1:].any():
                found = [n for n, ok in zip(self.model.joint_names, known) if ok]
                raise ConfigError(
                    "MonoTracker: expected an initial pose with the neck and at least one "
                    f"other joint finite (it needs the neck), found finite joints {found}"
                )
            self._initial = q[: self._n_up] - q[0]
            if self._legs:
                self._initial_legs = q - q[0]

    # ------------------------------------------------------------ streaming

    def push(
        self, time_s: float, points_px: ArrayLike, link_sines: ArrayLike | None = None
    ) -> list[MonoFrame]:
        """Add one frame of the stick's joints (K, 2) px (NaN where unseen), and where a
        detector gives its own 3-D, its ``dz / L`` per link (L,) (NaN where unknown; the
        ``depth_order_weight`` cost).

        Returns the frames this makes final, in order.
        """
        p = np.asarray(points_px, dtype=float)
        if p.shape != (self.model.n_joints, 2):
            raise ShapeError(
                f"MonoTracker.push: expected ({self.model.n_joints}, 2) points of "
                f"{self.model.joint_names}, found {p.shape}"
            )
        sines = None if link_sines is None else np.asarray(link_sines, dtype=float)
        self._pending.append((float(time_s), p, sines))
        self._pushed += 1
        self._smoother.push(p)
        out: list[MonoFrame] = []
        ready = self._pushed - 1 - self.config.smooth_lag
        while self._processed <= ready:
            out += self._process()
        return out

    def finish(self) -> list[MonoFrame]:
        """Process the frames still waiting and return every frame not yet returned."""
        out: list[MonoFrame] = []
        while self._processed < self._pushed:
            out += self._process()
        out += self._legs_of(self._graph.finish())
        if self._leg_graph is not None:
            out += [self._frame(layer, s) for layer, s in self._leg_graph.finish()]
        return out

    # ------------------------------------------------------------ one frame

    def _observation(self, pts: FloatArray) -> tuple[FloatArray, FloatArray, float]:
        """Observed input of the search, the root, and the depth (NaN if orthographic)."""
        model = self.config.camera_model
        if model == "orthographic" or self.camera is None:
            root = np.array([pts[0, 0], pts[0, 1], 0.0])
            return pts, root, float("nan")
        n = np.full_like(pts, np.nan)
        ok = np.isfinite(pts).all(axis=1)
        if ok.any():
            n[ok] = self.camera.undistort_pixels(pts[ok])
        z_raw = self._depth_bound(n)
        if np.isfinite(z_raw):
            self._depths.append(float(z_raw))
        depth = float(np.percentile(self._depths, 10.0)) if self._depths else float("nan")
        if not np.isfinite(depth) or not np.isfinite(n[0]).all():
            return n, np.full(3, np.nan), depth
        if model == "weak":
            obs = n * depth
            return obs, np.array([obs[0, 0], obs[0, 1], depth]), depth
        return n, depth * np.array([n[0, 0], n[0, 1], 1.0]), depth

    def _depth_bound(self, n: FloatArray) -> float:
        """Upper bound on the neck's depth from the links that hang from it (mm).

        The neck at depth Z is ``Z r`` with r = (x_n, y_n, 1); its distance to a child's
        viewing ray (unit c) is ``Z |r x c|``, at most the link's length.
        """
        assert self.camera is not None
        r = np.array([n[0, 0], n[0, 1], 1.0])
        from_root = self.model.parent == 0
        kids = n[self.model.child[from_root]]
        c = np.concatenate([kids, np.ones((kids.shape[0], 1))], axis=1)
        c /= np.linalg.norm(c, axis=1, keepdims=True)
        # the noise margin shrinks each ray's angle to the neck's ray by margin_px / f
        sin_a = np.linalg.norm(np.cross(r / np.linalg.norm(r), c), axis=1)
        margin = self.config.depth_margin_px / float(self.camera.K[0, 0])
        ang = np.arcsin(np.clip(sin_a, 0.0, 1.0)) - margin
        with np.errstate(invalid="ignore", divide="ignore"):
            z = self.lengths[from_root] / (np.linalg.norm(r) * np.sin(np.maximum(ang, 1e-9)))
        return float(np.nanmin(z)) if np.isfinite(z).any() else float("nan")

    def _link_reach(self) -> FloatArray:
        """Reach band per link (L,): ``reach_tolerance``, widened to
        ``rebuilt_reach_tolerance`` on the ``rebuilt_reach_links`` with an end in
        ``rebuilt_joints``."""
        cfg = self.config
        names = self.model.joint_names
        for j in cfg.rebuilt_joints:
            if j not in names:
                raise unknown_name("MonoConfig.rebuilt_joints joint", j, names)
        rebuilt = [names.index(j) for j in cfg.rebuilt_joints]
        tol = np.full(self.model.n_links, cfg.reach_tolerance)
        for s in cfg.rebuilt_reach_links:
            li = self.model.link_index(s)  # raises on an unknown link
            if self.model.parent[li] in rebuilt or self.model.child[li] in rebuilt:
                tol[li] = max(tol[li], cfg.rebuilt_reach_tolerance)
        return tol

    def _enumerate(
        self, model: StickModel, obs: FloatArray, root: FloatArray, fixed: FloatArray | None
    ) -> tuple[IntArray, FloatArray, int, bool]:
        """Candidate poses of ``model`` (one empty pose without a root: it keeps the graph
        connected)."""
        if not np.isfinite(root).all():
            return np.zeros(1, dtype=np.int64), np.full((1, model.n_joints, 3), np.nan), 0, False
        persp = self.config.camera_model == "perspective" and self.camera is not None
        fp = enumerate_poses(
            model,
            self.lengths[: model.n_links],
            obs[: model.n_joints],
            root,
            perspective=persp,
            reach_tolerance=self._reach[: model.n_links],
            fixed=fixed,
        )
        return fp.codes, fp.positions, fp.n_candidates, fp.pruned_all

    def _lean_pelvises(self, obs: FloatArray, root: FloatArray) -> list[FloatArray]:
        """The pelvis on its ray where the trunk from the neck at ``root`` leaves the image
        plane by each of ``trunk_lean_sines``, towards and away from the camera, where that
        leans more than the trunk's length lets it (the trunk then longer than its
        estimate)."""
        cfg = self.config
        if (
            not cfg.trunk_lean_sines
            or cfg.camera_model != "perspective"
            or self.camera is None
            or not np.isfinite(root).all()
        ):
            return []
        pelvis = obs[self.model.child[self._trunk]]
        if not np.isfinite(pelvis[:2]).all():
            return []
        c = np.array([pelvis[0], pelvis[1], 1.0])
        c /= np.linalg.norm(c)
        t0 = float(root @ c)
        d = float(np.linalg.norm(root - t0 * c))
        length = self.lengths[self._trunk] * (1.0 + self._reach[self._trunk])
        base = math.sqrt(max(0.0, 1.0 - (d / length) ** 2))
        out = []
        for s in cfg.trunk_lean_sines:
            if s <= base:
                continue
            dt = d * s / math.sqrt(1.0 - s * s)
            out += [(t0 - dt) * c, (t0 + dt) * c]
        return out

    def _enumerate_leans(
        self, obs: FloatArray, root: FloatArray
    ) -> tuple[IntArray, FloatArray, int, bool]:
        """Candidate upper-body poses: the search's, then those with the pelvis at each of
        `_lean_pelvises`, in one set.

        Poses that break a constraint are dropped in every set; only where all of them
        do is the search's unpruned set kept (recipe M)."""
        base = self._enumerate(self.upper, obs, root, None)
        pelvises = self._lean_pelvises(obs, root)
        if not pelvises:
            return base
        sets = [base] if not base[3] else []
        n_cand = base[2]
        pelvis = self.upper.child[self._trunk]
        for p in pelvises:
            fixed = np.full((self.upper.n_joints, 3), np.nan)
            fixed[pelvis] = p
            codes, positions, n, pruned = self._enumerate(self.upper, obs, root, fixed)
            n_cand += n
            if not pruned:
                far = np.int64(1 << self._trunk) if p[2] > root[2] else np.int64(0)
                sets.append((codes | far, positions, n, pruned))
        if not sets:
            return base[0], base[1], n_cand, True
        codes = np.concatenate([x[0] for x in sets])
        positions = np.concatenate([x[1] for x in sets])
        return codes, positions, n_cand, False

    def _process(self) -> list[MonoFrame]:
        k = self._processed
        self._processed += 1
        time_s, raw, sines = self._pending.popleft()
        pts = self._smoother.smoothed(k)
        obs, root, depth = self._observation(pts)
        codes, positions, n_cand, pruned_all = self._enumerate_leans(obs, root)
        unary = self._unary(positions)
        if sines is not None and self.config.depth_order_weight > 0:
            cost = depth_order_cost(self.upper, positions, sines[: self.upper.n_links])
            unary = unary + self.config.depth_order_weight * cost
        only = None
        if self._initial is not None and np.isfinite(positions).any():
            only = _nearest(positions, self._initial)
            self._initial = None  # only the first posed frame
        info = _FrameInfo(raw, obs, root, depth, n_cand, codes.shape[0], pruned_all)
        info.floor_depth = self._planted(time_s, obs)
        decided = self._graph.add(time_s, codes, positions, unary, info, only)
        return self._legs_of(decided)

    def _planted(self, time_s: float, obs: FloatArray) -> FloatArray | None:
        """Per ankle, the depth of its ray's floor point where both feet are planted (both
        floor points moving slower than ``planted_speed_mm_s`` across the floor since
        the previous frame), else NaN; None without the floor (``ankle_floor_mm``)."""
        if self._ankle_floor_mm is None or self.camera is None:
            return None
        depth, feet = floor_points(self.camera, obs[list(self._ankles)], self._ankle_floor_mm)
        last, self._last_feet = self._last_feet, (time_s, feet)
        out = np.full(depth.shape, np.nan)
        if last is None or time_s <= last[0]:
            return out
        speed = np.linalg.norm((feet - last[1])[:, :2], axis=1) / (time_s - last[0])
        if (speed < self.config.planted_speed_mm_s).all():
            out[:] = depth
        return out

    def _legs_of(self, decided: list[tuple[Layer, int]]) -> list[MonoFrame]:
        """The frames whose upper body is decided: final without legs; with legs, their
        legs enumerated below it and added to the legs' graph."""
        if self._leg_graph is None:
            return [self._frame(layer, s) for layer, s in decided]
        out: list[MonoFrame] = []
        for layer, s in decided:
            info: _FrameInfo = layer.info
            fixed = np.full((self.model.n_joints, 3), np.nan)
            fixed[: self._n_up] = layer.positions[s]
            posed = np.isfinite(fixed[0]).all()
            codes, positions, n_cand, pruned = self._enumerate(
                self.model, info.obs, info.root, fixed if posed else None
            )
            codes = codes | layer.codes[s]
            only = None
            if self._initial_legs is not None and np.isfinite(positions).any():
                only = _nearest(positions, self._initial_legs)
                self._initial_legs = None
            whole = _FrameInfo(
                info.raw_px,
                info.obs,
                info.root,
                info.depth,
                info.n_candidates * max(n_cand, 1),
                info.n_survivors * codes.shape[0],
                info.pruned_all or pruned,
            )
            unary = np.zeros(codes.shape[0])  # the upper body's soft costs are decided
            if info.floor_depth is not None:
                unary += self.config.floor_leg_weight * planted_feet_cost(
                    self.model, positions, self._ankles, info.floor_depth, self._leg_mm
                )
            done = self._leg_graph.add(layer.time_s, codes, positions, unary, whole, only)
            out += [self._frame(g, c) for g, c in done]
        return out

    def _unary(self, positions: FloatArray) -> FloatArray:
        """Soft costs of each upper-body pose (zeros with the paper's settings)."""
        cfg = self.config
        u = np.zeros(positions.shape[0])
        if cfg.clavicle_weight > 0:
            u += cfg.clavicle_weight * clavicle_forward_cost(self.upper, positions)
        if self._girdle:
            u += cfg.girdle_weight * girdle_angle_cost(self.upper, positions, cfg.girdle_cosine)
        if self._arm_prior is not None:
            u += cfg.arm_prior_weight * self._arm_prior.cost(self.upper, positions)
        return u

    def _frame(self, layer: Layer, s: int) -> MonoFrame:
        info: _FrameInfo = layer.info
        pos = np.full((self.model.n_joints, 3), np.nan)
        pos[: layer.positions.shape[1]] = layer.positions[s]
        code = int(layer.codes[s]) if np.isfinite(pos).any() else -1
        return MonoFrame(
            index=layer.index,
            time_s=layer.time_s,
            joints_in_camera=pos,
            code=code,
            n_candidates=info.n_candidates,
            n_survivors=info.n_survivors if code >= 0 else 0,
            pruned_all=info.pruned_all,
            residual_px=self._residual(pos, info.raw_px),
            depth_mm=info.depth,
        )

    def _residual(self, pos: FloatArray, raw: FloatArray) -> float:
        if self.config.camera_model == "orthographic" or self.camera is None:
            proj = pos[:, :2]
        else:
            proj = self.camera.project_camera_points(pos)
        d = np.linalg.norm(proj - raw, axis=1)
        return float(np.nanmean(d)) if np.isfinite(d).any() else float("nan")


def _nearest(positions: FloatArray, initial: FloatArray) -> int:
    """Index of the candidate (N, K, 3) nearest to the neck-relative ``initial`` pose
    (mean distance over the joints finite in both)."""
    rel = positions - positions[:, :1]
    d = np.linalg.norm(rel - initial, axis=-1)  # (N, K)
    ok = np.isfinite(d)
    n = ok.sum(axis=1)
    mean = np.where(n > 0, np.where(ok, d, 0.0).sum(axis=1) / np.maximum(n, 1), np.inf)
    return int(np.argmin(mean))
