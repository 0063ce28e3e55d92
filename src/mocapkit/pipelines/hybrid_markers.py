"""The hybrid tracker on raw marker files (C3D, TRC, CSV) without a session.

A lab's file is turned into the library's Z-up world (its up axis and floor found or
given), the subject's stature and posture chosen, the marker sets' member offsets
calibrated (on a still interval or on the motion), then the same `HybridTracker` runs
through the one runner as for a session (`mocapkit.pipelines.hybrid`).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ConfigError, ShapeError, unknown_name
from mocapkit.io.lab_frame import LabFrame, detect_lab_frame, to_world
from mocapkit.io.marker_sets import MarkerSet
from mocapkit.io.markers import MarkerData
from mocapkit.io.motion import Motion
from mocapkit.pipelines.hybrid import (
    hybrid_skeleton,
    require_observed_sets,
    seated_skeleton,
)
from mocapkit.pipelines.input_speeds import marker_input_speeds
from mocapkit.pipelines.run import (
    check_result_folder,
    run_tracker,
    unobserved_to_nan,
    write_run_folder,
)
from mocapkit.skeleton.model import Skeleton
from mocapkit.skeleton.scaling import (
    standing_height_mm,
)
from mocapkit.timing import NULL_TIMER, StageTimer
from mocapkit.tracking.base import FrameResult
from mocapkit.tracking.hybrid.dynamic_calibration import (
    DynamicCalibration,
    calibrate_members_on_motion,
)
from mocapkit.tracking.hybrid.posture import (
    UPRIGHT_PERCENTILE,
    PostureChoice,
    check_posture,
    choose_posture,
    stature_from_reach_mm,
)
from mocapkit.tracking.hybrid.static_calibration import (
    MAX_STATIC_RMS_MM,
    STATIC_SEARCH_S,
    STATIC_WINDOW_S,
    MemberCalibration,
    calibrate_member_offsets,
    find_static_interval,
)
from mocapkit.tracking.hybrid.tracker import (
    MARKER_SETS,
    OPTIONAL_SETS,
    SEGMENT_SETS,
    HybridConfig,
    HybridPose,
    HybridSample,
    HybridTracker,
    default_marker_effectors,
    marker_set_effectors,
)

if TYPE_CHECKING:
    pass

FloatArray = NDArray[np.float64]

#: How `track_hybrid_marker_file` calibrates the member offsets of a raw file's marker
#: sets: ``auto`` (static where a still window is found, else on the motion where a hand
#: set has two or more members), ``static``, ``dynamic`` (on the motion) or ``none`` (set
#: positions only).
CALIBRATIONS: tuple[str, ...] = ("auto", "static", "dynamic", "none")
#: The hand sets, whose orientation (a wrist bar's) fixes the elbow's swivel.
HAND_SETS: tuple[str, ...] = ("left_hand", "right_hand")


#: Share of frames on which a hand set's marker is the lowest of a file beyond which its
#: floor, found from the lowest markers, is taken to lie at hand height.
HANDS_LOWEST_SHARE = 0.5


def _floor_from_hands(markers: MarkerData, sets: Sequence[MarkerSet], frame: LabFrame) -> str:
    """Why the floor found from the lowest markers is likely wrong, or "": the lowest
    marker is a hand set's on most frames (a file with head and hand markers only), so
    the floor was put at hand height, the subject about 0.8 m shorter than they are."""
    hand_members = {m for s in sets if s.name in HAND_SETS for m in s.all_members}
    if not hand_members:
        return ""
    a, sign = "xyz".index(frame.up[-1]), (-1.0 if frame.up.startswith("-") else 1.0)
    h = sign * markers.positions_mm[:, :, a]
    seen = ~np.all(np.isnan(h), axis=1)
    if not seen.any():
        return ""
    lowest = np.nanargmin(np.where(np.isnan(h[seen]), np.inf, h[seen]), axis=1)
    is_hand = np.array([n in hand_members for n in markers.names])
    share = float(is_hand[lowest].mean())
    if share <= HANDS_LOWEST_SHARE:
        return ""
    return (
        f"the floor ({frame.floor_mm:.0f} mm along {frame.up}) was found from the lowest "
        f"markers, but the lowest is a hand set's on {100 * share:.0f} % of the frames (no "
        "marker near the floor, only head and hands?), so it lies at hand height; give the "
        "floor's coordinate along the up axis with --floor-mm (and --up if the axis is wrong)"
    )


#: Arm re-seed trigger (mm) for raw marker files (`HybridConfig.reseed_arm_mm`). The
#: tennis serve's racket arm ran into its shoulder limits at each racket drop and stayed
#: folded there, its hand set 130 mm off on average; re-seeded beyond 30, 50 or 100 mm the
#: elbow errors were 77 / 136, 74 / 134 and 75 / 135 mm (left / right, mean) against 80 /
#: 210 without. The basket sprint's single hand marker was lost likewise (245 -> 140 mm).
RAW_MARKERS_RESEED_MM = 50.0


def raw_marker_skeleton(
    height_mm: float, oriented: Iterable[str] = (), proportions: str = "anthropometric"
) -> Skeleton:
    """The model `track_hybrid_marker_file` tracks a raw file with (`hybrid_skeleton`).

    Which DoFs beyond Table 1's it gets depends on the marker sets whose orientation
    drives the IK (``oriented``: sets with member offsets, given or calibrated on a
    static interval):

    * a hand set (a wrist cluster): the forearm's turn (``forearm_rotation``), so that a
      turning wrist bar turns the forearm rather than the whole arm, and the clavicles
      (``clavicle``), so that the shoulder rises and moves forward when the arm reaches
      (a serve's racket arm) where the oriented forearm puts the elbow;
    * the head set and a hand set: the spine's and neck's twists (``spine_rotation``,
      ``neck_rotation``), so that the head turns apart from the shoulders (a server looks
      up at the ball while the trunk coils), the trunk's turn left to the hands;
    * a thorax set: the trunk's sideways bend (``spine_lateral``), which it sees (tennis
      serve with pelvis and thorax sets: largest joint speed 12.2 m/s with the bend, 19.0
      without; the pelvis set 13 against 23 mm off, median).

    With positions only (no set oriented) the model has Table 1's DoFs: those extra DoFs
    would be left to the relaxed-pose task (tennis serve, positions only: elbows 115 /
    127 mm mean without the clavicles, 110 / 183 with them).
    """
    names = set(oriented)
    hands = bool(names & {"left_hand", "right_hand"})
    return hybrid_skeleton(
        height_mm,
        proportions=proportions,
        forearm_rotation=hands,
        clavicle=hands,
        twist=hands and "head" in names,
        spine_lateral="thorax" in names,
    )


#: Stature (mm) of the model that measures scale-free ratios before the subject's is known.
NOMINAL_HEIGHT_MM = 1750.0


#: Re-plant trigger (mm) for raw marker files. Their sets are centres of skin markers
#: whose offsets from the joints are not declared, so the IK leaves residuals of several
#: mm on frames where nothing moved: at the tracker's default (8 mm, tuned on sessions
#: with declared offsets) the feet of the tennis serve were re-planted on most frames
#: (mean elbow error 214/224 mm left/right against 163/226 mm at 15 mm).
RAW_MARKERS_REPLANT_MM = 15.0


def track_hybrid_marker_arrays(
    time_s: ArrayLike,
    sets_mm: Mapping[str, ArrayLike],
    height_mm: float,
    config: HybridConfig | None = None,
    label: str = "track hybrid",
    out_dir: str | os.PathLike[str] | None = None,
    source: str = "",
    timer: StageTimer = NULL_TIMER,
    skeleton: Skeleton | None = None,
    members_mm: Mapping[str, ArrayLike] | None = None,
) -> tuple[Skeleton, FloatArray, list[HybridPose]]:
    """Run the hybrid tracker (IK only) on marker-set trajectories.

    Parameters
    ----------
    time_s : array_like, shape (T,)
    sets_mm : mapping of str to array_like (T, 3)
        ``head``, ``left_hand``, ``right_hand`` positions (NaN when occluded); one hand
        set may be absent (a subject instrumented on one side): that arm is left out
        (`drop_unobserved_arms`).
    height_mm : float
        Subject stature (scales ``zhang21``).
    config : HybridConfig, optional
        Default: ``HybridConfig(use_video=False, start_upright=False,
        replant_mm=RAW_MARKERS_REPLANT_MM)``: a lab's marker frame has its floor at
        z = 0, and where a raw head set sits on the head is not known, so the model
        stands on that floor rather than hanging from the set.
    out_dir : path, optional
        Result folder written by the runner (`mocapkit.pipelines.run.run_tracker`).
    source : str
        Stored in the written motion.
    timer : StageTimer, optional
    skeleton : Skeleton, optional
        The model to use instead of `hybrid_skeleton` at ``height_mm`` (e.g. one sat on
        a seat, `mocapkit.tracking.hybrid.posture.seat_skeleton`).
    members_mm : mapping of str to array_like (T, 3), optional
        Member markers' trajectories by the names ``config.member_offsets_mm`` gives them
        (their sets' orientation then drives the IK too).

    Returns
    -------
    skeleton, q (T, D), poses
    """
    if out_dir is not None:
        check_result_folder(out_dir)  # before the work, not after it
    t = np.asarray(time_s, dtype=float)
    if t.ndim != 1 or t.size == 0:
        raise ShapeError(f"time_s: expected a non-empty 1-D array of times (s), found {t.shape}")
    arrays = {}
    for name in partial_marker_sets(sets_mm, "sets_mm"):
        a = np.asarray(sets_mm[name], dtype=float)
        if a.shape != (t.size, 3):
            raise ShapeError(f"sets_mm[{name!r}]: expected shape ({t.size}, 3), found {a.shape}")
        arrays[name] = a
    cfg = config or HybridConfig(
        use_video=False, start_upright=False, replant_mm=RAW_MARKERS_REPLANT_MM
    )
    sk = hybrid_skeleton(height_mm) if skeleton is None else skeleton
    effectors = marker_set_effectors(sk)
    tracker = HybridTracker(
        sk, None, cfg, timer=timer, marker_effectors={n: effectors[n] for n in arrays}
    )
    members = {k: np.asarray(v, dtype=float) for k, v in (members_mm or {}).items()}
    for k, v in members.items():
        if v.shape != (t.size, 3):
            raise ShapeError(f"members_mm[{k!r}]: expected shape ({t.size}, 3), found {v.shape}")
    samples = (
        HybridSample(
            float(t[i]),
            {k: v[i] for k, v in arrays.items()},
            members_mm={k: v[i] for k, v in members.items()},
        )
        for i in range(t.size)
    )
    run = run_tracker(tracker, samples, t.size, None, label, source=source, timer=timer)
    poses = [p for p in run.results if isinstance(p, HybridPose)]
    if out_dir is not None:
        # the inputs: the sets' positions and the members given
        used = np.stack([*arrays.values(), *members.values()], axis=1)
        set_of = {m: n for n, ms in cfg.member_offsets_mm.items() for m in ms}
        of_set = [*arrays, *(set_of.get(m, m) for m in members)]
        with timer.stage("write"):
            write_run_folder(
                out_dir,
                drop_unobserved_arms(run.motion, arrays, run.results),
                run.results,
                marker_input_speeds(t, used, of_set),
            )
    return sk, np.asarray(run.motion.q), poses


def partial_marker_sets(sets: Iterable[str], where: str) -> tuple[str, ...]:
    """The hybrid marker sets present among ``sets``, in `MARKER_SETS` order, then the
    `OPTIONAL_SETS` present.

    A subject instrumented on one side has one hand set: the head set and at least one
    hand set are needed; an arm without its hand set is left out (its elbow and wrist are
    NaN in the results, see `drop_unobserved_arms`), never invented.
    """
    given = set(sets)
    present = tuple(n for n in MARKER_SETS if n in given)
    optional = tuple(n for n in OPTIONAL_SETS if n in given)
    if "head" not in given or len(present) < 2:
        raise ShapeError(
            f"{where}: the hybrid tracker needs marker set 'head' and at least one of "
            f"'left_hand', 'right_hand'; missing marker set "
            f"{'head' if 'head' not in given else 'left_hand/right_hand'!r}; found {sorted(given)}"
        )
    return present + optional


def drop_unobserved_arms(
    motion: Motion, sets: Iterable[str], results: Sequence[FrameResult] = ()
) -> Motion:
    """``motion`` with the elbow and wrist of an arm that no hand set sees set to NaN.

    An arm is left out on every frame when ``sets`` has no hand set for its side, and on
    the frames where ``results`` report its hand set ``released`` or ``missing`` (past
    the gap the tracker bridges). The tracker leaves such an arm in the secondary task's
    relaxed pose, which no marker saw, so its joints are not reported (``q`` keeps the
    pose, so the BVH still plays).
    """
    given = set(sets)
    joints = motion.joints_mm.copy()
    changed = False
    for side in ("left", "right"):
        hand = f"{side}_hand"
        cols = [
            motion.joint_names.index(f"{side}_{j}")
            for j in ("elbow", "wrist")
            if f"{side}_{j}" in motion.joint_names
        ]
        if hand not in given:
            rows = np.ones(motion.n_frames, dtype=bool)
        else:
            rows = np.array(
                [r.status.get(hand) in ("released", "missing") for r in results], dtype=bool
            )
            if rows.size != motion.n_frames:
                rows = np.zeros(motion.n_frames, dtype=bool)
        if cols and rows.any():
            joints[np.ix_(rows, np.asarray(cols, dtype=np.intp))] = np.nan
            changed = True
    if not changed:
        return motion
    return Motion(
        motion.skeleton, motion.time_s, motion.q, motion.joint_names, joints, motion.source
    )


@dataclass
class MarkerFileRun:
    """What `track_hybrid_marker_file` produced.

    Attributes
    ----------
    motion : Motion
        The tracked motion; its ``joints_mm`` are in the input file's frame unless
        ``world_output`` was asked (``q`` and the BVH are always the Z-up world's, so a
        BVH lands upright in Blender).
    frame : LabFrame
        The file's up axis and floor used.
    results : list of FrameResult
        The tracker's per-frame results (fit figures in ``fit``).
    posture : PostureChoice
        The posture used and why, the stature and (seated) the seat's height.
    calibration : MemberCalibration or DynamicCalibration or None
        The member offsets calibrated on a static interval or on the motion, when either
        ran.
    calibration_note : str
        Which calibration was used and what it did, or why none ran.
    floor_warning : str
        Why the floor found from the markers is likely wrong (`_floor_from_hands`), or
        empty.
    """

    motion: Motion
    frame: LabFrame
    results: list[FrameResult]
    posture: PostureChoice | None = None
    calibration: MemberCalibration | DynamicCalibration | None = None
    calibration_note: str = ""
    floor_warning: str = ""


def track_hybrid_markers(
    markers_path: str | os.PathLike[str],
    marker_sets: Sequence[str],
    height_mm: float | None = None,
    out_dir: str | os.PathLike[str] | None = None,
    config: HybridConfig | None = None,
    plant_feet: bool = True,
    timer: StageTimer = NULL_TIMER,
    up: str | None = None,
) -> Motion:
    """`track_hybrid_marker_file` on a file path, returning the motion only."""
    from mocapkit.io.marker_files import read_markers

    with timer.stage("load"):
        markers = read_markers(markers_path)
    return track_hybrid_marker_file(
        markers, marker_sets, height_mm, out_dir, config, plant_feet, timer, up
    ).motion


def track_hybrid_marker_file(
    markers: MarkerData,
    marker_sets: Sequence[str],
    height_mm: float | None = None,
    out_dir: str | os.PathLike[str] | None = None,
    config: HybridConfig | None = None,
    plant_feet: bool = True,
    timer: StageTimer = NULL_TIMER,
    up: str | None = None,
    world_output: bool = False,
    posture: str = "standing",
    calibration: str = "auto",
    static: MarkerData | None = None,
    proportions: str = "anthropometric",
    floor_mm: float | None = None,
) -> MarkerFileRun:
    """Run the hybrid tracker's IK on raw marker data (C3D, TRC, CSV) without a session.

    Parameters
    ----------
    markers : MarkerData
        In the file's own lab frame.
    marker_sets : sequence of str
        Specs ``"name=M1+M2+..."`` for ``head``, ``left_hand`` and ``right_hand``
        (e.g. ``head=LFHD+RFHD+LBHD+RBHD``); a set's position is the mean of its members.
        One hand set may be left out (one-sided marker sets): that arm's elbow and
        wrist are NaN and it has no fit figures.
    height_mm : float, optional
        Subject stature; estimated from the head markers when omitted
        (`mocapkit.io.marker_sets.estimate_height_mm`: head-set height over standing
        frames plus a head-top offset).
    out_dir : path, optional
        Result folder (joints.csv in the file's frame unless ``world_output``).
    config : HybridConfig, optional
        Default: IK only (``use_video=False``).
    plant_feet : bool
        Hold the feet where the first frame puts them (the paper); False for takes
        where the subject walks (ignored when ``config`` is given).
    timer : StageTimer, optional
        Stage times (the runner's and tracker's).
    up : str, optional
        The file's up axis (`mocapkit.io.lab_frame.UP_AXES`); found from the head
        markers when omitted (`mocapkit.io.lab_frame.detect_lab_frame`).
    world_output : bool
        Give joints in the library's Z-up world (floor at z = 0) instead of the file's frame.
    posture : str
        ``standing`` (default), ``seated`` or ``auto`` (`mocapkit.tracking.hybrid.posture`).
        Seated: the pelvis sits at the seat's height estimated from the head set, the
        legs are held bent, out of the IK and NaN in the joints, no feet are planted and
        no balance step runs; without ``height_mm`` the stature comes from the
        head-to-hand reach (`mocapkit.tracking.hybrid.posture.stature_from_reach_mm`), which
        does not assume standing. ``auto`` compares the head set's upright height with
        the stature (given, or from the reach) and takes standing or seated
        (`mocapkit.tracking.hybrid.posture.choose_posture`); a standing subject's stature is
        then estimated as before (from the head over standing frames).
    calibration : str
        How the member offsets of the sets with two or more members are calibrated, so
        their orientation drives the IK too (the glasses' turn, the wrist bar's
        direction); one of `CALIBRATIONS`. ``static``: on a still interval
        (`mocapkit.tracking.hybrid.static_calibration`; positions only where none is found);
        ``dynamic``: on the motion, the take tracked from the set centres first and each
        member's offset the median over the frames that agree on the set's layout
        (`mocapkit.tracking.hybrid.dynamic_calibration`); ``auto`` (default): static where a
        still window is found, else dynamic where a hand set has two or more members
        (a head set's orientation alone turns the trunk with the head: the basket
        sprint's elbow error 140 -> 242 mm), else none; ``none``: set positions only. Not
        done when ``config`` already gives ``member_offsets_mm``. ``calibration_note``
        says which ran.
    static : MarkerData, optional
        A separate static trial (same lab and marker names) to calibrate on; its stillest
        window anywhere is used. Default: the stillest window in the take's first
        `mocapkit.tracking.hybrid.static_calibration.STATIC_SEARCH_S` seconds.
    proportions : str
        The model's proportions (`PROPORTIONS`): ``"anthropometric"`` (default: a raw
        file gives no segment lengths, and Table 1's forearm is 0.207 of the stature
        against a population's 0.146; `mocapkit.skeleton.scaling.fit_anthropometric`)
        or ``"preset"`` (Table 1's, scaled by the stature).
    floor_mm : float, optional
        The floor's coordinate along the file's up axis (mm); default: found from the
        lowest markers (`mocapkit.io.lab_frame.detect_lab_frame`), which a file with
        head and hand markers only does not allow (``floor_warning`` then says so).

    Notes
    -----
    The markers are turned into the Z-up world with the floor at z = 0, where the root
    starts under the head marker, facing so the body's right points from the
    left-hand to the right-hand set (`HybridTracker.initial_pose`); feet are planted
    where that first pose puts them, on the floor.
    """
    from mocapkit.io.marker_sets import evaluate_marker_sets

    if out_dir is not None:
        check_result_folder(out_dir)  # before the work, not after it
    sets = _checked_request(markers, marker_sets, calibration, static)
    names = [s.name for s in sets]
    head = sets[names.index("head")]
    frame = detect_lab_frame(markers, evaluate_marker_sets(markers, head)[:, 0], up, floor_mm)
    floor_warning = "" if frame.floor_given else _floor_from_hands(markers, sets, frame)
    world = to_world(markers, frame)
    pos = evaluate_marker_sets(world, sets)
    require_observed_sets({n: pos[:, i] for i, n in enumerate(names)}, markers.source, ConfigError)
    check_posture(posture)
    take = _RawTake(world, sets, pos, frame, floor_warning, str(markers.source))
    # the sets whose orientation will drive the IK (members given, or calibrated)
    given_members = frozenset(config.member_offsets_mm) if config is not None else frozenset()
    oriented = given_members or (
        frozenset(s.name for s in sets if s.orientable) if calibration != "none" else frozenset()
    )

    def model(stature_mm: float, oriented: frozenset[str]) -> Skeleton:
        return raw_marker_skeleton(stature_mm, oriented, proportions)

    height_mm, choice, skeleton = _stature_and_posture(take, model, posture, height_mm, oriented)
    cfg = config or HybridConfig(
        use_video=False,
        plant_feet=plant_feet,
        start_upright=False,
        replant_mm=RAW_MARKERS_REPLANT_MM,
        reseed_arm_mm=RAW_MARKERS_RESEED_MM,
        marker_offsets_mm=(
            {"head": head_band_offset_mm(skeleton)} if choice.posture == "standing" else {}
        ),
    )
    if cfg.posture != choice.posture:
        cfg = replace(cfg, posture=choice.posture)
    cfg, calib, note, skeleton = _calibrated_config(
        take, model, skeleton, cfg, calibration, height_mm, choice, static, oriented, timer
    )
    members: dict[str, FloatArray] = {}
    for set_members in cfg.member_offsets_mm.values():
        for m in set_members:
            members[m] = world.trajectory(m)
    where = "the Z-up world" if world_output else "the file's frame"
    source = (
        f"hybrid tracker IK on {Path(markers.source).name} (file up = {frame.up}, floor "
        f"{frame.floor_mm:.0f} mm; joints in {where})"
    )
    sk, q, poses = track_hybrid_marker_arrays(
        world.time_s,
        {n: pos[:, i] for i, n in enumerate(names)},
        height_mm,
        cfg,
        source=source,
        timer=timer,
        skeleton=skeleton,
        members_mm=members,
    )
    motion = drop_unobserved_arms(Motion.from_q(sk, world.time_s, q, source=source), names, poses)
    # the runner's rule: NaN where the tracker reported none (a seated subject's legs)
    motion = unobserved_to_nan(motion, poses)
    if not world_output:
        motion = Motion(
            sk,
            motion.time_s,
            motion.q,
            motion.joint_names,
            frame.lab_from_world_points(motion.joints_mm),
            source,
        )
    if out_dir is not None:
        # the markers the sets are made of, in the frame of the motion's joints
        used = np.stack([world.trajectory(m) for s in sets for m in s.all_members], axis=1)
        if not world_output:
            used = frame.lab_from_world_points(used)
        of_set = [s.name for s in sets for _ in s.all_members]
        with timer.stage("write"):
            write_run_folder(
                out_dir, motion, poses, marker_input_speeds(world.time_s, used, of_set)
            )
    return MarkerFileRun(motion, frame, list(poses), choice, calib, note, floor_warning)


def _checked_request(
    markers: MarkerData,
    marker_sets: Sequence[str],
    calibration: str,
    static: MarkerData | None,
) -> tuple[MarkerSet, ...]:
    """The parsed marker sets of `track_hybrid_marker_file`, after checking its request."""
    from mocapkit.io.marker_sets import parse_marker_sets
    from mocapkit.io.markers import check_plausible_markers

    check_plausible_markers(markers)
    if calibration not in CALIBRATIONS:
        raise unknown_name("calibration", calibration, CALIBRATIONS)
    if static is not None and calibration in ("dynamic", "none"):
        raise ConfigError(
            f"calibration: a static trial is for calibration 'static' or 'auto', found "
            f"{calibration!r} with one"
        )
    sets = parse_marker_sets(list(marker_sets))
    names = [s.name for s in sets]
    extra = [n for n in names if n not in MARKER_SETS + OPTIONAL_SETS]
    if extra:
        raise ConfigError(
            f"marker_sets: the hybrid tracker uses only sets {list(MARKER_SETS + OPTIONAL_SETS)}; "
            f"found {extra} as well, which it would ignore"
        )
    try:
        partial_marker_sets(names, "marker_sets")
    except ShapeError as exc:
        raise ConfigError(str(exc)) from None
    return sets


@dataclass(frozen=True)
class _RawTake:
    """A raw file's markers in the Z-up world and what `track_hybrid_marker_file` found."""

    world: MarkerData
    sets: tuple[MarkerSet, ...]
    #: Set positions (T, S, 3) in the world, in the order of ``sets``.
    pos: FloatArray
    frame: LabFrame
    floor_warning: str
    source: str

    @property
    def head_pos(self) -> FloatArray:
        """The head set's positions (T, 3)."""
        return self.pos[:, [s.name for s in self.sets].index("head")]


def _stature_and_posture(
    take: _RawTake,
    model: Callable[[float, frozenset[str]], Skeleton],
    posture: str,
    height_mm: float | None,
    oriented: frozenset[str],
) -> tuple[float, PostureChoice, Skeleton]:
    """The stature, the posture chosen and the model of `track_hybrid_marker_file`."""
    from mocapkit.io.marker_sets import estimate_height_mm

    world, head_pos, floor_warning = take.world, take.head_pos, take.floor_warning
    head = take.sets[[s.name for s in take.sets].index("head")]
    names = [s.name for s in take.sets]
    skeleton: Skeleton | None = None

    if posture == "standing":
        given = height_mm is not None
        if height_mm is None:
            height_mm = float(estimate_height_mm(world, head=head))
        choice = PostureChoice(
            "standing",
            f"as asked; stature {height_mm:.0f} mm "
            f"({'given' if given else 'from the head set over standing frames'})",
            height_mm,
        )
    else:
        # the reach ratio is scale-free: any stature serves until the subject's is known
        probe = model(NOMINAL_HEIGHT_MM if height_mm is None else height_mm, oriented)
        head_point = default_marker_effectors(probe)["head"].point_mm
        if height_mm is None:
            stature = stature_from_reach_mm(
                probe,
                head_point,
                head_pos,
                [take.pos[:, i] for i, n in enumerate(names) if n in HAND_SETS],
                take.source,
            )
            how = "from the head-to-hand reach"
        else:
            stature, how = float(height_mm), "given"
        upright = float(np.nanpercentile(head_pos[:, 2], UPRIGHT_PERCENTILE))
        choice = choose_posture(posture, upright, stature, how)
        if choice.posture == "standing" and height_mm is None:
            height_mm = float(estimate_height_mm(world, head=head))
            choice = replace(
                choice,
                height_mm=height_mm,
                reason=f"{choice.reason}; stature for standing {height_mm:.0f} mm "
                "(from the head set over standing frames)",
            )
        elif choice.posture == "seated":
            height_mm = stature
            skeleton, choice = seated_skeleton(
                model(height_mm, oriented), head_pos[:, 2], choice, floor_warning
            )
    assert height_mm is not None
    if skeleton is None:
        skeleton = model(height_mm, oriented)
    return height_mm, choice, skeleton


def _calibrated_config(
    take: _RawTake,
    model: Callable[[float, frozenset[str]], Skeleton],
    skeleton: Skeleton,
    cfg: HybridConfig,
    calibration: str,
    height_mm: float,
    choice: PostureChoice,
    static: MarkerData | None,
    oriented: frozenset[str],
    timer: StageTimer,
) -> tuple[HybridConfig, MemberCalibration | DynamicCalibration | None, str, Skeleton]:
    """The member offsets of `track_hybrid_marker_file`'s sets calibrated as asked.

    Returns the config with the offsets, the calibration, a note on what ran and the
    model to track with (the plain model where offsets were wanted but none came).
    """
    sets, world, frame = take.sets, take.world, take.frame
    head_pos, floor_warning = take.head_pos, take.floor_warning
    calib: MemberCalibration | DynamicCalibration | None = None
    note = "none (positions only)"
    if calibration != "none" and not cfg.member_offsets_mm:
        # the model without the DoFs the sets' orientation would drive (the same rest
        # geometry and joint frames at those DoFs' zero, so the seat, the head-set offset
        # and offsets calibrated on it stand)
        plain = model(height_mm, frozenset())
        if choice.posture == "seated":
            plain = seated_skeleton(plain, head_pos[:, 2], choice, floor_warning)[0]
        if calibration in ("auto", "static"):
            calib, note = _calibrate_static(skeleton, cfg, sets, world, static, frame)
            note = f"static: {note}"
        if calib is None and calibration == "auto" and not oriented & set(HAND_SETS):
            # a head set's orientation without a hand set's turns the trunk with the head
            # (the model has the spine's and neck's twists only with both): calibrated on
            # the motion, the basket sprint's elbow went 140 -> 242 mm
            note = f"{note}; no hand set with two or more members to calibrate on the motion"
        elif calib is None and calibration in ("auto", "dynamic") and oriented:
            failed = f"{note}; " if calibration == "auto" else ""
            calib, how = _calibrate_dynamic(plain, cfg, sets, world, height_mm, timer)
            note = f"{failed}dynamic: {how}"
        if calib is not None:
            members, centres = _optional_set_offsets(sets, calib.offsets_mm)
            cfg = replace(
                cfg,
                member_offsets_mm=members,
                marker_offsets_mm={**cfg.marker_offsets_mm, **centres},
            )
        else:
            note = f"{note}; member offsets not calibrated (positions only)"
            if oriented:
                skeleton = plain
    elif cfg.member_offsets_mm:
        note = "member offsets given"
    note += _blind_turn_note(sets, frozenset(cfg.member_offsets_mm))
    return cfg, calib, note, skeleton


def _optional_set_offsets(
    sets: Sequence[MarkerSet], offsets_mm: Mapping[str, Mapping[str, Sequence[float]]]
) -> tuple[dict[str, dict[str, Sequence[float]]], dict[str, tuple[float, float, float]]]:
    """The calibrated member offsets with the optional sets' (`OPTIONAL_SETS`) made
    consistent with where their centres sit, and those centres (offsets in the joint's
    frame).

    The calibration's pose comes from head and hands alone. It places the trunk under the
    head as a standing subject's is, so a segment set's centre (`SEGMENT_SETS`: a pelvis
    set's well above the hips, a thorax set's in front of or behind the chest joint) is
    where its members' mean says. It does not know where the feet stand,
    so a foot set keeps only its layout (members about their mean) and its centre is
    taken at the ankle (the markers' own offset from the joint, a few cm, against a
    stance that may differ by a foot's length).
    """
    members = {k: dict(v) for k, v in offsets_mm.items()}
    centres = {}
    for s in sets:
        got = offsets_mm.get(s.name, {})
        if s.name not in OPTIONAL_SETS or not all(m in got for m in s.members):
            continue
        c = np.mean([np.asarray(got[m], dtype=float) for m in s.members], axis=0)
        if s.name in SEGMENT_SETS:
            centres[s.name] = (float(c[0]), float(c[1]), float(c[2]))
        else:
            members[s.name] = {
                m: [float(x) for x in np.asarray(o, dtype=float) - c] for m, o in got.items()
            }
    return members, centres


def _blind_turn_note(sets: Sequence[MarkerSet], oriented: frozenset[str]) -> str:
    """A note for the oriented hand sets of two members and no turning marker: both
    members and the set's centre lie on one line (a wrist bar), so the forearm may turn
    about that line unseen, and a serve's elbow flips round to the other side there
    (docs/design-notes/hybrid.md). Empty where none."""
    blind = [
        s.name
        for s in sets
        if s.name in HAND_SETS and s.name in oriented and len(s.all_members) == 2
    ]
    if not blind:
        return ""
    return (
        f"; {', '.join(blind)}: two members on one line with the set's centre, so the "
        "forearm's turn about it is not seen (add a forearm marker after '/', e.g. "
        "left_hand=LWRA+LWRB/LFRM)"
    )


def _member_trajectories(
    data: MarkerData, sets: Sequence[MarkerSet]
) -> dict[str, dict[str, FloatArray]]:
    """Per set, per marker whose offset is calibrated (``all_members``): its (T, 3) mm."""
    return {s.name: {m: data.trajectory(m) for m in s.all_members} for s in sets}


def head_band_offset_mm(skeleton: Skeleton) -> tuple[float, float, float]:
    """Offset (mm, head joint frame) of a raw head set's centre from the model's head point.

    The stature of a raw file is estimated with the head set `HEAD_TOP_OFFSET_MM` below
    the top of the head (`mocapkit.io.marker_sets.estimate_height_mm`), but ``zhang21``'s
    head point sits at 0.97 of the stature, about 50 mm higher at 1731 mm: without this
    offset a model standing on the floor reaches down to the head set by flexing its neck
    to the 45 deg limit and bending the trunk (the tennis serve's static start: neck
    flexion 45 deg with the offset 0, 6-9 deg with it). The offset lowers the head point
    to where the head set sits on a standing model (straight down, at q = 0).
    """
    from mocapkit.io.marker_sets import HEAD_TOP_OFFSET_MM
    from mocapkit.skeleton.kinematics import forward_kinematics

    eff = default_marker_effectors(skeleton)["head"]
    q0 = np.clip(skeleton.zero_pose(), skeleton.lower, skeleton.upper)
    head = forward_kinematics(skeleton, q0)[skeleton.joint_index(eff.joint)]
    point = head[:3, :3] @ np.asarray(eff.point_mm, dtype=float) + head[:3, 3]
    # at q = 0 the model stands on z = 0, so heights are above the floor
    lower_by = np.array([0.0, 0.0, standing_height_mm(skeleton) - HEAD_TOP_OFFSET_MM - point[2]])
    local = head[:3, :3].T @ lower_by
    return (float(local[0]), float(local[1]), float(local[2]))


def _calibrate_static(
    sk: Skeleton,
    cfg: HybridConfig,
    sets: Sequence[MarkerSet],
    world: MarkerData,
    static: MarkerData | None,
    frame: LabFrame,
) -> tuple[MemberCalibration | None, str]:
    """Member offsets of the sets with two or more members, from the stillest window of
    ``static`` (whole trial) or of ``world``'s first seconds; None and why when none."""
    from mocapkit.io.marker_sets import evaluate_marker_sets

    multi = [s for s in sets if s.orientable]
    if not multi:
        return None, "no marker set has two or more members"
    source = world if static is None else to_world(static, frame)
    where = "the take" if static is None else f"static trial {Path(static.source).name}"
    pos = evaluate_marker_sets(source, sets)
    span = STATIC_SEARCH_S if static is None else float(source.time_s[-1] - source.time_s[0]) + 1.0
    interval = find_static_interval(source.time_s, pos, search_s=span)
    if interval is None:
        first = f" (first {STATIC_SEARCH_S:g} s)" if static is None else ""
        return None, (
            f"no window of {STATIC_WINDOW_S:g} s in {where}{first} sees every marker set "
            f"and moves less than {MAX_STATIC_RMS_MM:g} mm RMS"
        )
    members = _member_trajectories(source, multi)
    calib = calibrate_member_offsets(
        sk,
        cfg,
        source.time_s,
        {s.name: pos[:, i] for i, s in enumerate(sets)},
        members,
        interval,
    )
    spread = ", ".join(f"{n} {v:.1f} mm" for n, v in calib.spread_mm.items())
    return calib, (
        f"member offsets of {', '.join(calib.offsets_mm)} calibrated on {where} over "
        f"{interval.summary()}; spread {spread}"
    )


def _calibrate_dynamic(
    sk: Skeleton,
    cfg: HybridConfig,
    sets: Sequence[MarkerSet],
    world: MarkerData,
    height_mm: float,
    timer: StageTimer,
) -> tuple[DynamicCalibration | None, str]:
    """Member offsets of the sets with two or more members calibrated on the motion:
    ``world`` tracked from the set centres with ``sk`` (the model without the sets'
    orientation DoFs), then `calibrate_members_on_motion`; None and why when no set
    fits on enough frames."""
    from mocapkit.io.marker_sets import evaluate_marker_sets

    multi = [s for s in sets if s.orientable]
    if not multi:
        return None, "no marker set has two or more members"
    pos = evaluate_marker_sets(world, sets)
    _sk, q, poses = track_hybrid_marker_arrays(
        world.time_s,
        {s.name: pos[:, i] for i, s in enumerate(sets)},
        height_mm,
        replace(cfg, member_offsets_mm={}),
        label="calibration pass (positions only)",
        timer=timer,
        skeleton=sk,
    )
    fit = {s.name: np.array([p.fit.get(f"{s.name}_mm", np.nan) for p in poses]) for s in multi}
    members = _member_trajectories(world, multi)
    try:
        calib = calibrate_members_on_motion(sk, q, world.time_s, fit, members)
    except ConfigError as exc:
        return None, str(exc)
    return calib, calib.summary()
