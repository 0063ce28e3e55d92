"""Settings of the model-based multi-view fit (`mocapkit.tracking.multiview.tracker`) and
of its runs (`mocapkit.pipelines.multiview`), apart from the compiled code so that the
command line reads their defaults without loading it."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from mocapkit.errors import ConfigError, unknown_name

#: ``method`` choices of `mocapkit.pipelines.multiview.track_stereo_auto`: the fit when
#: the session has keypoints, else skin colour; the fit; the paper's particle filter on
#: keypoints; skin colour.
STEREO_METHODS: tuple[str, ...] = ("auto", "fit", "filter", "skin")


#: Smoothing of the fitted poses, and its lag: ``none``; ``one-euro``, online (a few
#: frames of lag on fast motion, none when still); ``butterworth``, offline zero-lag
#: (forward and backward 4th-order low-pass, as Pose2Sim filters; needs the whole take).
SMOOTHING: tuple[str, ...] = ("none", "one-euro", "butterworth")


@dataclass(frozen=True)
class MultiviewConfig:
    """Settings of `MultiviewTracker`.

    Parameters
    ----------
    delta_mm : float
        Huber threshold of a detection's residual (mm across the ray at the subject).
    reject_mm : float
        A detection further than this from the fit is dropped for the frame.
    swap_ratio, swap_margin_mm : float
        A view's exchanged left/right labels are taken when their cost is below
        ``swap_ratio`` of the labels as given and lower by ``swap_margin_mm`` per pair.
    prior_mm_per_rad : float
        Temporal prior: residual (mm) per radian a joint angle moves from the previous
        frame.
    prior_root : float
        Temporal prior of the root translation (mm of residual per mm).
    point_prior : float
        Temporal prior of each fitted point's place in 3-D (mm of residual per mm), for
        a joint seen by views nearly in line (two facing cameras, a narrow pair) whose
        detections leave its depth free; scaled down to 0 as the joint's views spread
        to 90 degrees (`MultiviewTracker._point_weights`).
    max_iter, first_iter : int
        Levenberg-Marquardt steps per fit, and on the frame that starts a track.
    gap_limit_s : float
        Longest gap (s) in a part's detections called ``bridged``; longer gaps are
        ``released``.
    warn_px : float
        A joint further than this from its detections in most views that see it counts
        as far on that frame (``far_joints``; warned about over time spans).
    restart_mm : float
        A limb any of whose joints stays further than this from its kept
        detections (median over the views) after the fit is started again from
        `restart_seeds` random poses within its joint limits (a local minimum, often
        at a limit, that the warm start cannot leave); the best fit is kept.
    restart_seeds : int
    rebuilt_weight : float
        Weight of the detections a reader placed from others rather than detected (a
        detector's neck and pelvis, midpoints of the shoulders and hips,
        `mocapkit.io.session_csv.Keypoints.rebuilt_joints`); 1 for the others.
    jump_mm : float
        A joint detected in two views has no majority to outvote a wild detection: a
        detection further than this from the joint's place in the previous frame is
        dropped when the other view's is within ``reject_mm`` of it (a per-frame jump;
        `mocapkit.tracking.multiview.frame.fit_rejecting_nb`). The same rule settles a
        joint seen by more views whose kept views all stay further than ``reject_mm``
        from the fit, when two views confirmed its place in the previous frame.
    """

    delta_mm: float = 25.0
    reject_mm: float = 150.0
    swap_ratio: float = 0.6
    swap_margin_mm: float = 40.0
    prior_mm_per_rad: float = 60.0
    prior_root: float = 0.02
    point_prior: float = 0.5
    max_iter: int = 12
    first_iter: int = 80
    gap_limit_s: float = 0.25  # mocapkit.tracking.base.BRIDGE_S (a test holds them equal)
    warn_px: float = 40.0
    restart_mm: float = 60.0
    restart_seeds: int = 24
    rebuilt_weight: float = 0.0
    jump_mm: float = 400.0

    def __post_init__(self) -> None:
        for name in (
            "delta_mm",
            "reject_mm",
            "prior_mm_per_rad",
            "prior_root",
            "warn_px",
            "jump_mm",
        ):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"MultiviewConfig.{name}: expected a positive number, found {v}")
        if not 0.0 < self.swap_ratio <= 1.0:
            raise ConfigError(
                f"MultiviewConfig.swap_ratio: expected a share in (0, 1], found {self.swap_ratio}"
            )
        if self.max_iter < 1 or self.first_iter < 1:
            raise ConfigError(
                "MultiviewConfig: expected max_iter and first_iter of at least 1, found "
                f"{self.max_iter} and {self.first_iter}"
            )


@dataclass(frozen=True)
class MultiviewRunConfig:
    """What `track_multiview_session` does besides the per-frame fit.

    Parameters
    ----------
    fit : MultiviewConfig
    smoothing : {"none", "one-euro", "butterworth"}
        `SMOOTHING`.
    cutoff_hz : float
        Butterworth cut-off (Pose2Sim's default 6 Hz), or the one-euro filter's cut-off
        when still.
    one_euro_beta : float
        One-euro speed coefficient (per rad/s of a joint angle).
    reject_mm, good_mm : float
        Segment lengths: views further than ``reject_mm`` (across the ray at the point)
        from a point's triangulation are dropped; a point counts when its kept views are
        within ``good_mm``.
    """

    fit: MultiviewConfig = field(default_factory=MultiviewConfig)
    smoothing: str = "butterworth"
    cutoff_hz: float = 6.0
    one_euro_beta: float = 0.5
    reject_mm: float = 200.0
    good_mm: float = 100.0

    def __post_init__(self) -> None:
        if self.smoothing not in SMOOTHING:
            raise unknown_name("smoothing", self.smoothing, SMOOTHING, "--smooth")
        if not (math.isfinite(self.cutoff_hz) and self.cutoff_hz > 0):
            raise ConfigError(f"--cutoff-hz: expected a positive frequency, found {self.cutoff_hz}")


__all__ = ["SMOOTHING", "STEREO_METHODS", "MultiviewConfig", "MultiviewRunConfig"]
