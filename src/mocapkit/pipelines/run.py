"""The one runner of every tracker: stream samples through ``update`` and write the result.

`run_tracker` feeds any `mocapkit.tracking.base.Tracker` sample by sample (the same
calls a live feed would make), collects its `FrameResult` objects and writes the result
folder: ``motion.npz``, ``joints.csv``, ``motion.bvh``
(`mocapkit.io.motion_files.write_result_folder`) and
``fit.csv`` (per frame: status of each effector or limb and the fit-quality figures).
The folder is built beside ``--out`` and swapped in whole (`write_run_folder`).
Every tracker's result follows one rule for what was not observed: the joints of a
released or missing effector or limb are NaN (`unobserved_to_nan`) and the pose
(``motion.npz``'s ``q`` and the BVH alike) holds that part at its last observed pose and
blends it back (`motion_with_held_parts`). Method pipelines
(`mocapkit.pipelines.hybrid`) only build the tracker and its sample stream.
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import ShapeError, unknown_name
from mocapkit.eval.plausibility import (
    NAME_COLUMNS,
    MotionCheck,
    SpeedBound,
    check_motion,
)
from mocapkit.io.atomic import (
    atomic_folder,
    atomic_write,
    check_own_folder,
    remove_stale_temporaries,
)
from mocapkit.io.bvh import MAX_ROLL_SPEED_RAD_S
from mocapkit.io.motion import Motion
from mocapkit.io.motion_files import write_result_folder
from mocapkit.io.opensim import write_opensim_folder
from mocapkit.pipelines.result_table import ResultTable
from mocapkit.progress import Progress
from mocapkit.skeleton.limbs import part_dofs
from mocapkit.skeleton.model import CANONICAL_JOINTS, Skeleton
from mocapkit.timing import NULL_TIMER, StageTimer
from mocapkit.tracking.base import (
    INPUT_SPEED_FACTOR,
    REJOIN_BLEND_S,
    UNOBSERVED,
    UNSEEN_SPEED_MM_S,
    DelayedTracker,
    FrameResult,
    Tracker,
    unobserved_joints,
    unobserved_part,
)

#: Name of the per-frame fit and status file in a result folder.
FIT_FILE = "fit.csv"

#: What a pipeline passes the runner so it can hold the result against the inputs: the
#: motion (its canonical joints) -> the speed (mm/s) the inputs show near each joint on
#: each frame, (T, K), NaN without evidence (`mocapkit.eval.plausibility`).
InputSpeeds = Callable[[Motion], NDArray[np.float64]]

#: Fastest a bone may roll about its own axis (deg/s): the BVH writer's limit, so a
#: flagged roll is one the BVH slows down.
ROLL_LIMIT_DEG_S = float(np.rad2deg(MAX_ROLL_SPEED_RAD_S))


def speed_bound() -> SpeedBound:
    """The speed a joint may move at given its input's: the hybrid re-plant's bound,
    `mocapkit.tracking.base.INPUT_SPEED_FACTOR` times the input's speed plus
    `mocapkit.tracking.base.UNSEEN_SPEED_MM_S` for what no input shows, one rule for
    every tracker."""
    return SpeedBound(INPUT_SPEED_FACTOR, UNSEEN_SPEED_MM_S)


def check_run_motion(motion: Motion, input_speeds: InputSpeeds | None = None) -> MotionCheck:
    """`mocapkit.eval.plausibility.check_motion` of a result: its canonical joints (NaN
    where not observed) against ``input_speeds(motion)``, its poses' bone rolls against
    `ROLL_LIMIT_DEG_S`."""
    return check_motion(
        motion.time_s,
        motion.joint_names,
        motion.joints_mm,
        None if input_speeds is None else input_speeds(motion),
        speed_bound(),
        ROLL_LIMIT_DEG_S,
        motion.skeleton,
        motion.q,
    )


#: The result folder's OpenSim export (`mocapkit.io.opensim.write_opensim_folder`).
OPENSIM_FOLDER = "opensim"


@dataclass
class RunResult:
    """What `run_tracker` produced.

    Attributes
    ----------
    motion : Motion
        The tracked motion (the tracker's poses and canonical joints; the folder's poses
        hold the unobserved parts, `motion_with_held_parts`).
    results : list of FrameResult
        One per sample, in order (empty with ``keep_results`` False: see ``table``).
    out_dir : Path or None
        The result folder written, if any.
    table : ResultTable or None
        With ``keep_results`` False, the results' common fields, one row per sample.
    """

    motion: Motion
    results: list[FrameResult]
    out_dir: Path | None
    table: ResultTable | None = None

    @property
    def frames(self) -> Sequence[FrameResult]:
        """The per-sample results however they were kept (``results`` or ``table``)."""
        return self.results if self.table is None else self.table

    @property
    def gaps(self) -> list[Gap]:
        """Where effectors were released or missing (`find_gaps`)."""
        return find_gaps(self.frames)


def run_tracker(
    tracker: Tracker | DelayedTracker,
    samples: Iterable[Any],
    n_samples: int,
    out_dir: str | os.PathLike[str] | None = None,
    label: str = "track",
    source: str = "",
    timer: StageTimer = NULL_TIMER,
    skeleton: Skeleton | None = None,
    joint_names: Sequence[str] | None = None,
    keep_results: bool = True,
    input_speeds: InputSpeeds | None = None,
) -> RunResult:
    """Stream ``samples`` through ``tracker.update`` and write the result folder.

    Parameters
    ----------
    tracker : Tracker or DelayedTracker
        A `DelayedTracker` is fed with ``push`` and drained with ``finish``; its
        results are put in time order.
    samples : iterable
        The tracker's samples, in time order. Drawing one (reading markers, decoding the
        video frame) is timed as stage ``"input"``.
    n_samples : int
        Expected count (for the progress meter only).
    out_dir : path, optional
        Result folder (``motion.npz``, ``joints.csv``, ``motion.bvh``, ``fit.csv``);
        nothing is written when None. Writing is timed as stage ``"write"``.
    label : str
        Progress label and error context.
    source : str
        Stored in the motion (where it came from).
    timer : StageTimer
        Receives ``"input"``, ``"track"`` (the whole ``update``) and ``"write"``; the
        tracker may time its own stages on the same timer.
    skeleton : Skeleton, optional
        Default ``tracker.skeleton``.
    joint_names : sequence of str, optional
        Canonical joints of the motion taken from the results' ``joints_mm`` (trackers
        that estimate joints first and fit ``q`` to them, as the mono tracker); default:
        the skeleton's canonical joints by forward kinematics of ``q``.
    keep_results : bool
        Keep the tracker's result objects (its own fields, as a pipeline reads them);
        False: only their common fields, in a `ResultTable` (about a quarter of the
        memory per frame: what keeps a long recording's run flat).
    input_speeds : callable, optional
        The speed the inputs show near each joint (`InputSpeeds`), for fit.csv's
        plausibility columns (`write_run_folder`).

    Raises
    ------
    ShapeError
        When ``samples`` is empty.
    ConfigError
        ``out_dir`` is not a folder a run may replace (`check_result_folder`), found
        before the work starts.
    """
    if out_dir is not None:
        check_result_folder(out_dir)  # before the work, not after it
    sk = tracker.skeleton if skeleton is None else skeleton
    results: list[FrameResult] | ResultTable = [] if keep_results else ResultTable(n_samples)
    delayed = tracker if isinstance(tracker, DelayedTracker) else None
    streaming = None if isinstance(tracker, DelayedTracker) else tracker
    it = iter(samples)
    stage_in, stage_track = timer.stage("input"), timer.stage("track")
    with Progress(n_samples, label) as prog:
        while True:
            with stage_in:
                sample = next(it, None)
            if sample is None:
                break
            with stage_track:
                if delayed is not None:
                    results.extend(delayed.push(sample))
                elif streaming is not None:
                    results.append(streaming.update(sample))
            prog.update()
    if delayed is not None:
        with stage_track:
            results.extend(delayed.finish())
        if isinstance(results, ResultTable):
            results.sort_by_time()
        else:
            results.sort(key=lambda r: r.time_s)
    if isinstance(results, ResultTable):
        results.trim()
    if not results:
        raise ShapeError(f"{label}: no samples to track")
    motion = results_motion(results, sk, source, joint_names)
    out = None
    if out_dir is not None:
        with timer.stage("write"):
            out = write_run_folder(out_dir, motion, results, input_speeds)
    if isinstance(results, ResultTable):
        return RunResult(motion, [], out, results)
    return RunResult(motion, results, out)


def results_motion(
    results: Sequence[FrameResult],
    skeleton: Skeleton,
    source: str = "",
    joint_names: Sequence[str] | None = None,
) -> Motion:
    """The motion of a run's results (time order), with `unobserved_to_nan` applied:
    joints by forward kinematics of ``q``, or taken from the results' ``joints_mm`` for
    ``joint_names`` (as `run_tracker`'s parameter)."""
    if isinstance(results, ResultTable):
        t, q, all_joints = results.time_s, results.q, results.joints_mm
    else:
        t = np.array([r.time_s for r in results])
        q = np.stack([r.q for r in results])
    if joint_names is None:
        motion = Motion.from_q(skeleton, t, q, source=source)
    else:
        names = tuple(joint_names)
        unknown = [n for n in names if n not in CANONICAL_JOINTS]
        if unknown:
            raise unknown_name("canonical joint", unknown[0], CANONICAL_JOINTS, "joint_names")
        rows = [CANONICAL_JOINTS.index(n) for n in names]
        joints = (
            all_joints[:, rows]
            if isinstance(results, ResultTable)
            else np.stack([r.joints_mm[rows] for r in results])
        )
        motion = Motion(skeleton, t, q, names, joints, source)
    return unobserved_to_nan(motion, results)


def unobserved_to_nan(motion: Motion, results: Sequence[FrameResult]) -> Motion:
    """``motion`` with NaN joints wherever they were not observed: the one rule of every
    tracker's result folder.

    A frame's joints are NaN (1) where its `FrameResult.joints_mm` has NaN, and (2) for
    each effector or limb whose status is ``released`` or ``missing``, the joints that it
    alone places (`mocapkit.tracking.base.unobserved_part`: the head; elbow and wrist
    for a hand or arm; knee and ankle for a foot or leg). So ``joints.csv`` and
    ``motion.npz`` hold no made-up joints, whatever a tracker did with the limb's pose
    (``q`` is left as it is: see `motion_with_held_parts`). Results of another count than the
    motion's frames are not applied.
    """
    if len(results) != motion.n_frames:
        return motion
    joints = np.array(motion.joints_mm, copy=True)
    col = {n: k for k, n in enumerate(motion.joint_names)}
    rows = [CANONICAL_JOINTS.index(n) if n in CANONICAL_JOINTS else -1 for n in motion.joint_names]
    for i, r in enumerate(results):
        rj = np.asarray(r.joints_mm, dtype=float)
        if rj.shape == (len(CANONICAL_JOINTS), 3):
            for k, row in enumerate(rows):
                if row >= 0 and np.isnan(rj[row]).any():
                    joints[i, k] = np.nan
        for joint in unobserved_joints(r.status):
            if joint in col:
                joints[i, col[joint]] = np.nan
    if np.array_equal(joints, motion.joints_mm, equal_nan=True):
        return motion
    return Motion(
        motion.skeleton, motion.time_s, motion.q, motion.joint_names, joints, motion.source
    )


#: Time over which a part held through a gap is blended back to the tracked pose once
#: it is observed again (`motion_with_held_parts`), rather than snapped there: the trackers' own
#: rejoin time (`mocapkit.tracking.base.REJOIN_BLEND_S`): the hybrid's own blend of a
#: rejoining arm (which it declares, `FrameResult.held_dofs`) takes as long.
GAP_BLEND_S = REJOIN_BLEND_S


def _blend_back(
    q: NDArray[np.float64],
    time_s: NDArray[np.float64],
    held: NDArray[np.bool_],
    dofs: NDArray[np.int64],
) -> None:
    """After each held stretch of ``held`` frames, move ``q[:, dofs]`` from the held values
    to the tracked ones linearly over `GAP_BLEND_S` (in place)."""
    ends = np.flatnonzero(held[:-1] & ~held[1:])  # the last held frame of each stretch
    for e in ends:
        start = q[e, dofs].copy()
        for i in range(e + 1, len(q)):
            w = (time_s[i] - time_s[e]) / GAP_BLEND_S
            if held[i] or not w < 1.0 or not np.isfinite(q[i, dofs]).all():
                break
            q[i, dofs] = start + w * (q[i, dofs] - start)


def _hold(
    q: NDArray[np.float64],
    time_s: NDArray[np.float64],
    held: NDArray[np.bool_],
    dofs: NDArray[np.int64],
) -> None:
    """``q[:, dofs]`` on the ``held`` frames set to their values of the last frame not
    held (of the first, before any), then `_blend_back` (in place)."""
    good = ~held & np.isfinite(q[:, dofs]).all(axis=1)
    if not held.any() or not good.any():
        return
    src = np.maximum.accumulate(np.where(good, np.arange(len(q)), -1))
    src[src < 0] = np.flatnonzero(good)[0]
    rows = np.flatnonzero(held)
    q[np.ix_(rows, dofs)] = q[np.ix_(src[rows], dofs)]
    _blend_back(q, time_s, held, dofs)


def motion_with_held_parts(motion: Motion, results: Sequence[FrameResult]) -> Motion:
    """``motion`` with each released or missing part held at its last observed pose: what
    the result folder's poses (``motion.npz``'s ``q`` and the BVH, which cannot hold NaN)
    are written from (`write_run_folder`), the one place a part is held and blended back
    besides the DoFs a tracker declares it holds and blends itself
    (`mocapkit.tracking.base.FrameResult.held_dofs`: the hybrid's released arm), which
    are left as the tracker gave them, so they are blended back once.

    On the frames where an effector or limb is ``released`` or ``missing``, the DoFs that
    pose its part (`mocapkit.skeleton.limbs.part_dofs`: an arm or leg with the joints
    that carry it alone above it, a clavicle, and every joint below it; the head's),
    less the frame's ``held_dofs``, keep their values of the last frame where it was
    ``seen`` or ``bridged`` (of the first such frame, before it was ever seen); the rest
    of the pose is the tracker's.
    When the part is observed again, those DoFs go from the held values to the tracked
    ones linearly over `GAP_BLEND_S`, not in one frame. A part never observed keeps the
    tracker's pose. ``fit.csv`` holds the status that says so. Apply it once, to the
    tracker's motion: a second pass would blend the blended pose again. Frames without
    any pose (NaN ``q``) are left to `mocapkit.io.bvh.write_bvh`, which holds the
    previous pose.
    """
    if len(results) != motion.n_frames:
        return motion
    q = np.array(motion.q, dtype=float, copy=True)
    unobserved: dict[str, NDArray[np.bool_]] = {}
    declared = np.zeros(q.shape, dtype=bool)  # the tracker's own holds, per frame and DoF
    for i, r in enumerate(results):
        declared[i, np.asarray(r.held_dofs, dtype=np.int64)] = True
        for name, st in r.status.items():
            part = unobserved_part(name)
            if part is None:
                continue
            flags = unobserved.setdefault(part[0], np.zeros(motion.n_frames, dtype=bool))
            flags[i] |= st in UNOBSERVED
    for part_name, flags in unobserved.items():
        dofs = part_dofs(motion.skeleton, part_name)
        if dofs.size == 0 or not flags.any():
            continue
        # per DoF, the frames held here; the DoFs held on the same frames go together
        held = flags[:, None] & ~declared[:, dofs]
        columns, group = np.unique(held, axis=1, return_inverse=True)
        group = np.ravel(group)
        for k in range(columns.shape[1]):
            _hold(q, motion.time_s, columns[:, k], dofs[group == k])
    if np.array_equal(q, motion.q, equal_nan=True):
        return motion
    return Motion(
        motion.skeleton, motion.time_s, q, motion.joint_names, motion.joints_mm, motion.source
    )


@dataclass(frozen=True)
class Gap:
    """A stretch of frames where one effector or limb was not observed.

    Attributes
    ----------
    name : str
        The effector or limb (``"left_hand"``, ...).
    status : str
        ``"released"`` or ``"missing"`` (`mocapkit.tracking.base.STATUSES`).
    start_s, end_s : float
        Times of its first and last frame (s).
    n_frames : int
    """

    name: str
    status: str
    start_s: float
    end_s: float
    n_frames: int

    def __str__(self) -> str:
        return (
            f"{self.name} {self.status} {self.start_s:.3f}-{self.end_s:.3f} s "
            f"({self.n_frames} frames)"
        )


def find_gaps(results: Sequence[FrameResult]) -> list[Gap]:
    """The runs of frames whose status is ``released`` or ``missing``, per effector, in
    time order (what a run's summary lists; fit.csv has the per-frame status). A
    `ResultTable` is read by its columns, without building each frame's result."""
    gaps: list[Gap] = []
    if isinstance(results, ResultTable):
        names = list(results.status_names)
        times = results.time_s.tolist()
        column = results.status_column
    else:
        names = _columns(results)[0]
        times = [r.time_s for r in results]

        def column(name: str) -> list[str | None]:
            return [r.status.get(name) for r in results]

    for name in names:
        statuses = column(name)
        start, current = 0, None
        for i in range(len(statuses) + 1):
            st = statuses[i] if i < len(statuses) else None
            if st == current:
                continue
            if current in ("released", "missing"):
                gaps.append(Gap(name, str(current), times[start], times[i - 1], i - start))
            start, current = i, st
    return sorted(gaps, key=lambda g: (g.start_s, g.name))


#: The file whose presence marks an existing folder as a result folder that a run may
#: replace (`check_result_folder`).
RESULT_MARKER_FILE = "motion.npz"


def check_result_folder(out_dir: str | os.PathLike[str]) -> Path:
    """Refuse an ``--out`` that a run must not replace; call it before the work.

    A run replaces its result folder whole (`write_run_folder`), so an existing ``--out``
    must be empty or a previous result folder (one holding ``motion.npz``); any other
    folder with files in it (a session, a home folder) is refused rather than deleted.

    Raises
    ------
    ConfigError
        ``out_dir`` is a file, or a folder with files but no ``motion.npz``.
    """
    return check_own_folder(out_dir, (RESULT_MARKER_FILE,), "result folder", "a run")


def write_run_folder(
    out_dir: str | os.PathLike[str],
    motion: Motion,
    results: Sequence[FrameResult],
    input_speeds: InputSpeeds | None = None,
) -> Path:
    """Write a result folder whole: ``motion.npz``, ``joints.csv``, ``motion.bvh``
    (`mocapkit.io.motion_files.write_result_folder`), ``fit.csv`` (`write_fit_csv`) and
    ``opensim/`` (TRC, model and IK setup: `mocapkit.io.opensim.write_opensim_folder`).
    ``motion`` is the tracker's: the poses of ``motion.npz`` and the BVH hold its
    unobserved parts (`unobserved_to_nan`, then `motion_with_held_parts`); the TRC's markers
    are the tracker's observed joints (`unobserved_to_nan` only).

    The folder is built under a temporary name beside ``out_dir`` and swapped in when
    complete (`mocapkit.io.atomic.atomic_folder`): a kill or an error mid-write leaves
    the previous folder as it was, never a mix of old and new files. An existing result
    folder is replaced whole, so what else it held (the ``report/`` of ``mocapkit
    view``, which described the old result) is gone; a folder that is not a result
    folder is refused (`check_result_folder`). What a killed earlier run left beside it
    (``.NAME.new-*``, ``.NAME.old-*``) is cleared first
    (`mocapkit.io.atomic.remove_stale_temporaries`). Shared by `run_tracker` and the
    trackers that need the whole sequence before their motion exists; returns the folder.

    fit.csv gets the plausibility columns (`mocapkit.eval.plausibility.FRAME_COLUMNS`)
    of the written motion (`check_run_motion`: its joints against ``input_speeds``, its
    poses' rolls), computed after the tracking.
    """
    out = check_result_folder(out_dir)
    motion = unobserved_to_nan(motion, results)
    remove_stale_temporaries(out.parent, out.name)
    posed = motion_with_held_parts(motion, results)
    check = check_run_motion(posed, input_speeds)
    with atomic_folder(out) as tmp:
        write_result_folder(tmp, posed)
        write_fit_csv(tmp / FIT_FILE, results, check.columns())
        write_opensim_folder(tmp / OPENSIM_FOLDER, motion)
    return out


def _columns(results: Sequence[FrameResult]) -> tuple[list[str], list[str]]:
    status: dict[str, None] = {}
    fit: dict[str, None] = {}
    for r in results:
        status.update(dict.fromkeys(r.status))
        fit.update(dict.fromkeys(r.fit))
    return list(status), list(fit)


def write_fit_csv(
    path: str | os.PathLike[str],
    results: Sequence[FrameResult],
    extra: Mapping[str, Sequence[Any] | NDArray[Any]] | None = None,
) -> None:
    """Write per-frame statuses and fit figures as CSV, atomically.

    Columns: ``time_s``, ``<name>_status`` per effector or limb (``seen``, ``bridged``,
    ``released``, ``missing``; empty where a frame did not report it), then the fit
    figures by name (``nan`` where missing), ``worst``, then the ``extra`` columns (one
    value per result: numbers, or names as strings; the plausibility columns of
    `write_run_folder`), left out when their length is not the results'.
    """
    status_cols, fit_cols = _columns(results)
    more = {k: v for k, v in (extra or {}).items() if len(v) == len(results)}

    def cell(v: Any) -> str:
        return v if isinstance(v, str) else f"{float(v):.6f}"

    with atomic_write(path, "w", newline="") as fh:  # rows go to the file as formatted
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["time_s", *(f"{n}_status" for n in status_cols), *fit_cols, "worst", *more])
        for i, r in enumerate(results):
            w.writerow(
                [
                    f"{r.time_s:.9f}",
                    *(r.status.get(n, "") for n in status_cols),
                    *(f"{r.fit.get(n, math.nan):.6f}" for n in fit_cols),
                    r.worst,
                    *(cell(v[i]) for v in more.values()),
                ]
            )


def read_fit_csv(path: str | os.PathLike[str]) -> tuple[list[dict[str, str]], dict[str, Any]]:
    """Read ``fit.csv`` back: per-frame rows as dicts of strings, and the fit columns as
    float arrays (``{"time_s": (T,), "<figure>": (T,), ...}``; the name columns, as
    ``worst`` and `mocapkit.eval.plausibility.NAME_COLUMNS`, only in the rows)."""
    from mocapkit.errors import FormatError

    p = Path(path)
    try:
        with p.open(newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
    except OSError as exc:
        raise FormatError(f"{p}: cannot read ({exc})") from None
    if not rows or "time_s" not in rows[0] or "worst" not in rows[0]:
        raise FormatError(f"{p}: expected a fit.csv with time_s and worst columns")
    numeric: dict[str, Any] = {}
    for name in rows[0]:
        if name == "worst" or name.endswith("_status") or name in NAME_COLUMNS:
            continue
        try:
            numeric[name] = np.array([float(r[name]) for r in rows])
        except ValueError:
            raise FormatError(f"{p}: column {name!r}: expected numbers") from None
    return rows, numeric


__all__ = [
    "FIT_FILE",
    "GAP_BLEND_S",
    "OPENSIM_FOLDER",
    "RESULT_MARKER_FILE",
    "ROLL_LIMIT_DEG_S",
    "Gap",
    "InputSpeeds",
    "RunResult",
    "check_result_folder",
    "check_run_motion",
    "find_gaps",
    "motion_with_held_parts",
    "read_fit_csv",
    "results_motion",
    "run_tracker",
    "speed_bound",
    "unobserved_joints",
    "unobserved_to_nan",
    "write_fit_csv",
    "write_run_folder",
]
