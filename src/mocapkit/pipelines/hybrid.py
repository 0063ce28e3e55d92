"""The hybrid tracker on files (sessions, raw marker files) and its IK micro-benchmark.

Both build a `mocapkit.tracking.hybrid.HybridTracker` and its sample stream and hand them
to the one runner, `mocapkit.pipelines.run.run_tracker`, which calls ``update`` sample by
sample (the same code a live feed would call) and writes the result folder.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ConfigError, SessionError, unknown_name
from mocapkit.io.motion import Motion
from mocapkit.pipelines.camera_check import check_session_cameras
from mocapkit.pipelines.input_speeds import marker_input_speeds
from mocapkit.pipelines.run import (
    RunResult,
    run_tracker,
)
from mocapkit.skeleton.model import Skeleton
from mocapkit.skeleton.presets import load_preset
from mocapkit.skeleton.scaling import (
    fit_anthropometric,
    fit_segments,
    scale_skeleton,
    standing_height_mm,
)
from mocapkit.timing import NULL_TIMER, StageTimer
from mocapkit.tracking.hybrid.arm_refinement import RefineConfig
from mocapkit.tracking.hybrid.posture import (
    UPRIGHT_PERCENTILE,
    PostureChoice,
    check_posture,
    choose_posture,
    estimate_seat_height_mm,
    seat_skeleton,
)
from mocapkit.tracking.hybrid.tracker import (
    MARKER_SETS,
    HybridConfig,
    HybridSample,
    HybridTracker,
    default_marker_effectors,
)

if TYPE_CHECKING:
    from mocapkit.io.session import Session, SessionSample

FloatArray = NDArray[np.float64]


#: Body proportions `hybrid_skeleton` gives its model: Table 1's scaled by stature, or a
#: population's (`mocapkit.skeleton.scaling.fit_anthropometric`).
PROPORTIONS: tuple[str, ...] = ("preset", "anthropometric")


def hybrid_skeleton(
    height_mm: float | None = None,
    bone_lengths_mm: Mapping[str, float] | None = None,
    root_rotation: bool = True,
    segment_vectors_mm: Mapping[str, ArrayLike] | None = None,
    clavicle: bool = False,
    twist: bool = False,
    proportions: str = "preset",
    forearm_rotation: bool = False,
    spine_lateral: bool = False,
) -> Skeleton:
    """``zhang21`` scaled to a subject, for the hybrid tracker.

    With ``root_rotation`` the root gets a free yaw (limits removed, so a subject may
    turn round) while root pitch and roll are held at 0: with feet planted and only
    head and hands observed, whole-body tilt is not determined by the markers.
    The model is scaled to the stature, then its canonical segments are fitted to the
    measured ``bone_lengths_mm`` and, for the trunk, ``segment_vectors_mm`` (where the
    shoulders and hips sit relative to the neck base and the pelvis; names of
    `CANONICAL_SEGMENTS`).

    ``clavicle`` adds the 2-DoF clavicles and ``twist`` the axial rotations of the spine
    (at spine3) and the neck (options ``spine_rotation`` and ``neck_rotation`` of
    ``zhang21``), none of which Table 1 has. Without the twists the head turns only
    with the whole body, so glasses that see the head's turn turn the shoulders with it,
    though subjects turn their heads by 16-34 deg (standard deviation) against their
    shoulders in the accuracy clips; with them, the trunk's turn is left to the hands'
    markers (and the video).

    ``forearm_rotation`` turns each forearm about its long axis (pronation, option
    ``forearm_rotation`` of ``zhang21``): without it a wrist cluster's orientation (two
    or more members on the hand set) can be followed only by turning the whole arm.

    ``spine_lateral`` bends the trunk sideways at spine2 (option ``spine_lateral`` of
    ``zhang21``), for a thorax marker set that sees the bend.

    ``proportions``: ``"preset"`` scales Table 1's model by the stature alone;
    ``"anthropometric"`` (for subjects known by their stature only: raw marker files)
    also gives it a population's proportions
    (`mocapkit.skeleton.scaling.fit_anthropometric`), before any measured segments.
    """
    if proportions not in PROPORTIONS:
        raise ConfigError(
            f"proportions: expected one of {', '.join(PROPORTIONS)}, found {proportions!r}"
        )
    if proportions == "anthropometric" and height_mm is None:
        raise ConfigError(
            "proportions 'anthropometric': expected a stature (height_mm), found None"
        )
    options = (
        (("root_rotation",) if root_rotation else ())
        + (("clavicle",) if clavicle else ())
        + (("spine_rotation", "neck_rotation") if twist else ())
        + (("forearm_rotation",) if forearm_rotation else ())
        + (("spine_lateral",) if spine_lateral else ())
    )
    sk = load_preset("zhang21", options)
    if proportions == "anthropometric":
        assert height_mm is not None
        sk = fit_anthropometric(sk, height_mm)
    else:
        sk = scale_skeleton(sk, height_mm=height_mm)
    if bone_lengths_mm or segment_vectors_mm:
        sk = fit_segments(sk, bone_lengths_mm, segment_vectors_mm)
    if root_rotation:
        lower, upper = sk.lower.copy(), sk.upper.copy()
        lower[sk.dof_index("root_yaw")], upper[sk.dof_index("root_yaw")] = -np.inf, np.inf
        for name in ("root_pitch", "root_roll"):
            lower[sk.dof_index(name)] = upper[sk.dof_index(name)] = 0.0
        sk = sk.replace(lower=lower, upper=upper)
    return sk


#: The canonical joint each hybrid effector sits on (its default point, see
#: `mocapkit.tracking.hybrid.default_marker_effectors`).
EFFECTOR_SEGMENTS = {"head": "head", "left_hand": "left_wrist", "right_hand": "right_wrist"}


def effector_offsets(
    declared: Mapping[str, tuple[str, FloatArray]], where: str | os.PathLike[str] = "session"
) -> dict[str, tuple[float, float, float]]:
    """Marker offsets declared in a session, as offsets from the hybrid effector points.

    ``zhang21`` joint frames are parallel to the anatomical frames at q = 0 (arms hang,
    palms forward), so a declared anatomical offset is the offset in the effector's joint
    frame. An offset declared on another body part than the effector's is refused.
    """
    out: dict[str, tuple[float, float, float]] = {}
    for name, (segment, offset) in declared.items():
        if name not in EFFECTOR_SEGMENTS:
            continue
        if segment != EFFECTOR_SEGMENTS[name]:
            raise SessionError(
                f"{where}: marker_offsets_mm.{name}.segment: the hybrid tracker expects "
                f"{EFFECTOR_SEGMENTS[name]!r}, found {segment!r}"
            )
        out[name] = (float(offset[0]), float(offset[1]), float(offset[2]))
    return out


#: Marker sets whose members the tracker uses (when the session declares their offsets)
#: to see the set's orientation; see ``HybridConfig.member_offsets_mm``.
ORIENTED_SETS: tuple[str, ...] = ("head", "left_hand", "right_hand")


def parse_oriented_sets(text: str) -> tuple[str, ...]:
    """Parse a ``--oriented-sets`` value: comma-separated names of `ORIENTED_SETS`, or
    ``none`` (positions only, as the paper)."""
    if text.strip().lower() == "none":
        return ()
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    for n in names:
        if n not in ORIENTED_SETS:
            raise unknown_name("marker set", n, ORIENTED_SETS, "--oriented-sets")
    if not names:
        raise ConfigError(
            "--oriented-sets: expected 'none' or comma-separated marker sets "
            f"({', '.join(ORIENTED_SETS)}), found {text!r}"
        )
    return names


def member_offsets(
    declared: Mapping[str, Mapping[str, FloatArray]],
    set_offsets: Mapping[str, tuple[str, FloatArray]],
    sets: Sequence[str],
    where: str | os.PathLike[str] = "session",
) -> dict[str, dict[str, tuple[float, float, float]]]:
    """Member-marker offsets declared in a session for the chosen ``sets``, as offsets
    from the hybrid effector points (the frame convention of `effector_offsets`)."""
    out: dict[str, dict[str, tuple[float, float, float]]] = {}
    for name in sets:
        if name not in declared or name not in EFFECTOR_SEGMENTS:
            continue
        effector_offsets({name: set_offsets[name]}, where)  # checks the segment
        out[name] = {m: (float(o[0]), float(o[1]), float(o[2])) for m, o in declared[name].items()}
    return out


def session_config(
    session: Session, config: HybridConfig, oriented_sets: Sequence[str] = ORIENTED_SETS
) -> HybridConfig:
    """The configuration of a run on ``session``: ``config`` over the session's settings.

    The session's marker offsets (``marker_offsets_mm``) and the member-marker offsets of
    the ``oriented_sets`` fill the fields ``config`` leaves empty; a config that gives
    its own keeps them.
    """
    fill: dict[str, Any] = {}
    if not config.marker_offsets_mm:
        fill["marker_offsets_mm"] = effector_offsets(session.marker_offsets, session.path)
    if not config.member_offsets_mm:
        fill["member_offsets_mm"] = member_offsets(
            session.marker_member_offsets, session.marker_offsets, oriented_sets, session.path
        )
    return replace(config, **fill) if fill else config


def require_observed_sets(
    sets_mm: Mapping[str, ArrayLike], where: str | os.PathLike[str], error: type[Exception]
) -> None:
    """Refuse marker sets the hybrid tracker needs (`MARKER_SETS`) that are never seen.

    A set with no finite sample in the whole recording (a hand whose markers were never
    labelled) would leave its limb wholly made up by the relaxed pose; the tracker needs
    each one at least once.

    Parameters
    ----------
    sets_mm : mapping of str to array_like (T, 3)
        Set positions over the recording (NaN where unseen).
    where : path or str
        The file or session, for the message.
    error : exception type
        `SessionError` for a session, `ConfigError` for ``--marker-set`` specs.
    """
    never = [
        n
        for n in MARKER_SETS
        if n in sets_mm and not np.any(np.all(np.isfinite(np.asarray(sets_mm[n])), axis=-1))
    ]
    if never:
        raise error(
            f"{where}: marker set(s) {never} have no sample in the whole recording; the "
            f"hybrid tracker needs {list(MARKER_SETS)} seen at least once"
        )


def hybrid_setup(
    session: Session,
    paper: bool = False,
    use_video: bool = True,
    config: HybridConfig | None = None,
    oriented_sets: Sequence[str] | None = None,
    clavicle: bool | None = None,
    twist: bool | None = None,
    refine_config: RefineConfig | None = None,
) -> tuple[HybridConfig, Skeleton]:
    """The tracker's configuration and model from a session's ``session.json`` (marker
    offsets, members, subject): what `track_hybrid_session_run` and the live tracker
    (`mocapkit.pipelines.live`) build the `HybridTracker` from. Arguments as
    `track_hybrid_session`."""
    if oriented_sets is None:
        oriented_sets = () if paper else ORIENTED_SETS
    cfg = session_config(
        session,
        config or HybridConfig(paper=paper, use_video=use_video, refine_config=refine_config),
        oriented_sets,
    )
    sk = hybrid_skeleton(
        session.height_mm,
        session.bone_lengths_mm,
        segment_vectors_mm=session.segment_vectors_mm,
        clavicle=not cfg.paper if clavicle is None else clavicle,
        twist=(not cfg.paper and "head" in cfg.member_offsets_mm) if twist is None else twist,
    )
    return cfg, sk


def member_markers(config: HybridConfig) -> frozenset[str]:
    """The member markers whose positions a `HybridSample` carries (the oriented sets')."""
    return frozenset(m for members in config.member_offsets_mm.values() for m in members)


def hybrid_sample(
    s: SessionSample, camera: str, members: frozenset[str], use_video: bool
) -> HybridSample:
    """A session sample (a video frame and the newest marker sample before it) as the
    hybrid tracker's sample: the marker sets' centres, the ``members`` markers and the
    frame of ``camera``, decoded only if the tracker refines an arm on it."""
    markers = {k: v for k, v in s.marker_sets_mm.items() if k in MARKER_SETS}
    chosen = (
        {}
        if s.markers_mm is None
        else {m: p for m, p in zip(s.marker_names, s.markers_mm) if m in members}
    )
    return HybridSample(
        s.time_s,
        markers,
        None if np.isnan(s.marker_time_s) else s.marker_time_s,
        s.frames[camera].load if use_video else None,
        chosen,
    )


def track_hybrid_session(
    session_dir: str | os.PathLike[str],
    out_dir: str | os.PathLike[str] | None,
    use_video: bool = True,
    paper: bool = False,
    config: HybridConfig | None = None,
    oriented_sets: Sequence[str] | None = None,
    clavicle: bool | None = None,
    twist: bool | None = None,
    max_elbow_speed_mm_per_s: float | None = None,
    timer: StageTimer = NULL_TIMER,
) -> Motion:
    """Track a recording session with head and hand marker sets plus one camera.

    Uses the marker sets ``head``, ``left_hand``, ``right_hand`` of the session (any other
    set, such as elbow reference markers, is ignored), the first camera with a video
    for the refinement, the subject's height and bone lengths from ``session.json``.

    Parameters
    ----------
    session_dir : path
    out_dir : path or None
        Result folder (``motion.npz``, ``joints.csv``, ``motion.bvh``); nothing written if None.
    use_video : bool
        Run the video refinement of the arms.
    paper : bool
        Follow the paper literally (no smoothing, proportional balance).
    config : HybridConfig, optional
        Overrides ``paper`` and ``use_video`` when given; the session's marker offsets
        fill the offsets it leaves empty (`session_config`).
    oriented_sets : sequence of str, optional
        Marker sets whose member markers drive the IK too, so that their orientation
        is seen (where ``session.json`` declares their ``members_mm``); default
        `ORIENTED_SETS`, none in paper mode (the paper uses set positions only).
    clavicle : bool, optional
        Give the model its 2-DoF clavicles (`hybrid_skeleton`); default on, off in paper
        mode (Table 1 has none). Measured on the accuracy clips with oriented marker
        sets: mean elbow error 68 mm without, 49 mm with.
    twist : bool, optional
        Give the model axial rotations of the spine and neck (`hybrid_skeleton`);
        default on when the head set's orientation is seen (its members drive the IK),
        since only then is the head's turn known apart from the trunk's; off in paper
        mode.
    max_elbow_speed_mm_per_s : float, optional
        Elbow speed the video refinement's elbow-jump penalty leaves free
        (`RefineConfig.elbow_speed_mm_per_s`, default 3000 mm/s); 0 turns the penalty
        off. Raise it for sports with fast arms. Not with ``paper`` (no penalty there).
    timer : StageTimer, optional
        Receives the stage times: ``"load"`` (session), the runner's ``"input"`` (marker
        samples and video decoding), ``"track"`` and ``"write"``, and the tracker's own.
    """
    return track_hybrid_session_run(
        session_dir,
        out_dir,
        use_video,
        paper,
        config,
        oriented_sets,
        clavicle,
        twist,
        max_elbow_speed_mm_per_s,
        timer,
    ).motion


def track_hybrid_session_run(
    session_dir: str | os.PathLike[str],
    out_dir: str | os.PathLike[str] | None,
    use_video: bool = True,
    paper: bool = False,
    config: HybridConfig | None = None,
    oriented_sets: Sequence[str] | None = None,
    clavicle: bool | None = None,
    twist: bool | None = None,
    max_elbow_speed_mm_per_s: float | None = None,
    timer: StageTimer = NULL_TIMER,
    posture: str = "standing",
    on_posture: Callable[[PostureChoice], None] | None = None,
) -> RunResult:
    """`track_hybrid_session`, returning the runner's whole result (motion and the
    per-frame `HybridPose` results).

    ``posture`` (`mocapkit.tracking.hybrid.posture.POSTURES`): ``seated`` sits the model on a
    seat whose height is estimated from the head set
    (`mocapkit.tracking.hybrid.posture.estimate_seat_height_mm`, with the stature of
    ``session.json``); ``auto`` chooses from the head set's height against that stature
    (`mocapkit.tracking.hybrid.posture.choose_posture`). The choice is in the motion's source
    and, when given, passed to ``on_posture`` before the run.
    """
    from mocapkit.io.session import load_session

    with timer.stage("load"):
        session = load_session(session_dir)
    missing = [n for n in MARKER_SETS if n not in session.marker_sets]
    if missing or session.markers is None:
        raise SessionError(
            f"{session.path}: the hybrid tracker needs marker sets {list(MARKER_SETS)} in "
            f"session.json; missing {missing or 'the marker file'}"
        )
    positions = session.marker_set_positions(MARKER_SETS)
    require_observed_sets(
        {n: positions[:, i] for i, n in enumerate(MARKER_SETS)}, session.path, SessionError
    )
    refine_config = None
    if max_elbow_speed_mm_per_s is not None:
        if paper:
            raise ConfigError(
                "max_elbow_speed_mm_per_s: the paper mode has no elbow-jump penalty; "
                "give one or the other"
            )
        if not max_elbow_speed_mm_per_s >= 0:
            raise ConfigError(
                "max_elbow_speed_mm_per_s: expected a speed >= 0 mm/s (0: no penalty), "
                f"found {max_elbow_speed_mm_per_s}"
            )
        refine_config = (
            RefineConfig(elbow_jump_weight_per_mm=0.0)
            if max_elbow_speed_mm_per_s == 0
            else RefineConfig(elbow_speed_mm_per_s=float(max_elbow_speed_mm_per_s))
        )
    cfg, sk = hybrid_setup(
        session, paper, use_video, config, oriented_sets, clavicle, twist, refine_config
    )
    wanted = member_markers(cfg)
    # the markers the sets are made of: the inputs whose motion the result is held to
    used = [(n, m) for n in MARKER_SETS for m in session.marker_sets[n]]
    check_posture(posture)
    if posture != "standing":
        head_z = positions[:, MARKER_SETS.index("head"), 2]
        choice = choose_posture(
            posture,
            float(np.nanpercentile(head_z, UPRIGHT_PERCENTILE)),
            standing_height_mm(sk),
            "session.json",
        )
        if choice.posture == "seated":
            sk, choice = seated_skeleton(sk, head_z, choice)
            cfg = replace(cfg, posture="seated")
    else:
        choice = PostureChoice("standing", "as asked", standing_height_mm(sk))
    if on_posture is not None:
        on_posture(choice)
    cams = session.video_cameras
    if not cams:
        raise SessionError(
            f"{session.path}: no camera with a video; the hybrid tracker's time line is the video's"
        )
    camera = session.camera(cams[0])
    if cfg.use_video:  # the one camera check of every tracker, on the marker sets
        check_session_cameras(
            session, [cams[0]], subject_points=(session.markers.time_s, positions)
        )
    # the camera also sets the initial facing, so it is passed even without video
    tracker = HybridTracker(sk, camera, cfg, timer=timer)
    n = session.video(cams[0]).n_frames

    def stream() -> Iterator[HybridSample]:
        for s in session.samples(cams[0]):
            yield hybrid_sample(s, cams[0], wanted, cfg.use_video)

    mode = "paper" if cfg.paper else "default"
    seated = (
        "" if choice.posture != "seated" else f", seated: pelvis at {choice.seat_height_mm:.0f} mm"
    )
    return run_tracker(
        tracker,
        stream(),
        n,
        out_dir,
        "track hybrid",
        source=f"hybrid tracker ({mode}, video="
        f"{'on' if cfg.use_video else 'off'}{seated}, camera {cams[0]}) on {session.path}",
        timer=timer,
        input_speeds=marker_input_speeds(
            session.markers.time_s,
            session.markers.select([m for _, m in used]).positions_mm,
            [n for n, _ in used],
        ),
    )


def seated_skeleton(
    sk: Skeleton, head_z_mm: ArrayLike, choice: PostureChoice, floor_warning: str = ""
) -> tuple[Skeleton, PostureChoice]:
    """``sk`` sat on the seat estimated from the head set's heights, and the choice
    with that seat's height; ``floor_warning`` (`_floor_from_hands`) names the likelier
    cause when the seat lands below the floor."""
    head_point = default_marker_effectors(sk)["head"].point_mm
    seat_mm = estimate_seat_height_mm(sk, head_point, head_z_mm)
    if not seat_mm > 0:
        cause = (
            f"the likely cause: {floor_warning}"
            if floor_warning
            else "check the floor (--floor-mm), the up axis (--up) and --height-mm"
        )
        raise ConfigError(
            f"seated posture: the seat estimated from the head set lies {seat_mm:.0f} mm "
            f"above the floor at a stature of {choice.height_mm:.0f} mm; expected above the "
            f"floor; {cause}"
        )
    return seat_skeleton(sk, seat_mm), replace(choice, seat_height_mm=seat_mm)
