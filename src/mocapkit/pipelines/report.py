"""The visual report of a result folder: one offline HTML page (``mocapkit view``).

`build_report` reads any tracker's result folder (``motion.npz`` or ``joints.csv``, and
``fit.csv`` when the tracker wrote one), optionally the session it came from (videos,
cameras, markers) and a session's ``truth.npz``, and writes a folder holding
``index.html``, ``plotly.min.js``, one overlay video per camera with a video and a TRC
of the canonical joints. It lives in `pipelines` because it joins `eval` (the accuracy)
and `viz` (the figures and the page), which side packages may not import from each
other.
"""

from __future__ import annotations

import contextlib
import csv
import math
import os
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import ConfigError, FormatError, SessionError
from mocapkit.eval.metrics import EvalReport, evaluate_joints, match_by_time
from mocapkit.io.atomic import atomic_folder, check_own_folder, remove_stale_temporaries
from mocapkit.io.joints_csv import read_joints_csv
from mocapkit.io.marker_files import read_markers
from mocapkit.io.markers import MarkerData
from mocapkit.io.motion_npz import load_motion_npz
from mocapkit.io.session import Session, load_session
from mocapkit.io.trc import write_trc
from mocapkit.io.truth import Truth, load_truth
from mocapkit.pipelines.fit_report import implausible_spans_in_folder, implausible_warnings
from mocapkit.skeleton.model import UPPER_BODY_JOINTS, Skeleton
from mocapkit.viz.overlay_video import OverlayLayer, write_overlay_video
from mocapkit.viz.report.figures import (
    CAPTURED_COLOUR,
    MARKER_COLOUR,
    TRUTH_COLOUR,
    PointLayer,
    animation_options,
    error_figure,
    fit_figures,
    skeleton_animation,
)
from mocapkit.viz.report.page import PAGE_NAME, ReportPage, Section, Table, write_report_page
from mocapkit.viz.web_video import JPEG_SEQUENCE, WebVideo

FloatArray = NDArray[np.float64]

#: Default report folder inside the result folder.
REPORT_FOLDER = "report"
#: Per-frame fit file a tracker may write into its result folder (columns not fixed).
FIT_FILE = "fit.csv"
#: Most frames the 3-D animation holds (longer clips show every k-th frame).
MAX_ANIMATION_FRAMES = 300
#: Result files the page links to, by suffix.
LINKED_SUFFIXES = (".bvh", ".trc", ".csv", ".npz", ".c3d", ".json")

_CAPTURED_BGR = (26, 140, 255)
_TRUTH_BGR = (60, 210, 60)
_KEYPOINTS_BGR = (255, 80, 255)


@dataclass(frozen=True)
class ResultData:
    """What the report reads from a result folder.

    Attributes
    ----------
    folder : Path
    time_s : ndarray, shape (T,)
    joint_names : tuple of str, length K
    joints_mm : ndarray, shape (T, K, 3)
    skeleton : Skeleton or None
        With ``q``, from ``motion.npz``; None for a ``joints.csv``-only result.
    q : ndarray, shape (T, D), or None
    source : str
    """

    folder: Path
    time_s: FloatArray
    joint_names: tuple[str, ...]
    joints_mm: FloatArray
    skeleton: Skeleton | None
    q: FloatArray | None
    source: str


@dataclass(frozen=True)
class FitTable:
    """A per-frame table read from ``fit.csv``: numeric columns and text (status) columns."""

    time_s: FloatArray
    numeric: dict[str, FloatArray]
    text: dict[str, list[str]]


def load_result(folder: str | os.PathLike[str]) -> ResultData:
    """Read a result folder (``motion.npz`` preferred, else ``joints.csv``).

    Raises
    ------
    SessionError
        When ``folder`` is missing, not a folder, or holds neither file.
    """
    p = Path(folder)
    if not p.exists():
        raise SessionError(f"{p}: result folder not found")
    if not p.is_dir():
        raise SessionError(
            f"{p}: expected a result folder (with motion.npz or joints.csv), found a file"
        )
    if (p / "motion.npz").is_file():
        m = load_motion_npz(p / "motion.npz")
        return ResultData(
            p,
            np.asarray(m.time_s),
            m.joint_names,
            np.asarray(m.joints_mm),
            m.skeleton,
            np.asarray(m.q),
            m.source,
        )
    if (p / "joints.csv").is_file():
        t, names, joints = read_joints_csv(p / "joints.csv")
        return ResultData(p, t, names, joints, None, None, str(p / "joints.csv"))
    found = sorted(e.name for e in p.iterdir())
    hint = (
        "; this is a session folder: give the result folder, and the session with --truth "
        "or --session"
        if (p / "session.json").is_file()
        else ""
    )
    raise SessionError(
        f"{p}: not a result folder: expected motion.npz or joints.csv (written by "
        f"mocapkit track), found {found[:8] or 'an empty folder'}{hint}"
    )


def mixed_runs(result: ResultData) -> list[str]:
    """Warnings for a result folder whose files do not come from one run.

    A tracker writes ``motion.npz``, ``joints.csv`` and ``fit.csv`` together, over the
    same frames; a folder where they disagree (a file copied in from another run, or
    left from one) is reported as it is, with these lines saying which files disagree
    and how.
    """
    lines: list[str] = []
    folder = result.folder
    times = {"motion.npz": result.time_s} if (folder / "motion.npz").is_file() else {}
    joints_csv = folder / "joints.csv"
    if times and joints_csv.is_file():
        t, names, joints = read_joints_csv(joints_csv)
        same = t.shape == result.time_s.shape and np.allclose(t, result.time_s, atol=1e-6)
        if same and tuple(names) == tuple(result.joint_names):
            d = np.abs(joints - result.joints_mm)
            finite = np.isfinite(joints) == np.isfinite(result.joints_mm)
            same = bool(np.all(finite) and np.all(d[np.isfinite(d)] < 0.01))
        if not same:
            lines.append(
                f"{folder}: joints.csv and motion.npz are not from the same run "
                f"({t.shape[0]} vs {result.time_s.shape[0]} frames, or different joints); "
                "the report shows motion.npz"
            )
    fit_path = folder / FIT_FILE
    if fit_path.is_file():
        with contextlib.suppress(FormatError):
            ft = read_fit_table(fit_path).time_s
            n = result.time_s.shape[0]
            if ft.shape[0] != n or not np.allclose(ft, result.time_s, atol=1e-6):
                span = f"{ft[0]:.3f}-{ft[-1]:.3f} s" if ft.size else "none"
                lines.append(
                    f"{fit_path}: not from the same run as the result ({ft.shape[0]} frames, "
                    f"{span}, vs {n} frames, {result.time_s[0]:.3f}-{result.time_s[-1]:.3f} s"
                    "); its fit plots describe another run"
                    if n
                    else f"{fit_path}: not from the same run as the (empty) result"
                )
    return lines


def read_fit_table(path: str | os.PathLike[str]) -> FitTable:
    """Read a per-frame fit file: a ``time_s`` column, then any columns.

    A column whose non-empty cells all parse as numbers is numeric (empty cells become
    NaN); any other column is kept as text (e.g. ``seen``/``bridged``/``missing``).
    """
    p = Path(path)
    try:
        with p.open(newline="", encoding="utf-8") as fh:
            rows = [r for r in csv.reader(fh) if r]
    except (OSError, UnicodeDecodeError) as exc:
        raise FormatError(f"{p}: cannot read ({exc})") from None
    if not rows or "time_s" not in rows[0]:
        raise FormatError(
            f"{p}: line 1: expected a header with a 'time_s' column, found "
            f"{rows[0][:5] if rows else 'an empty file'}"
        )
    header = [h.strip() for h in rows[0]]
    for i, row in enumerate(rows[1:]):
        if len(row) != len(header):
            raise FormatError(f"{p}: line {i + 2}: expected {len(header)} fields, found {len(row)}")
    columns = {h: [r[k].strip() for r in rows[1:]] for k, h in enumerate(header)}
    numeric: dict[str, FloatArray] = {}
    text: dict[str, list[str]] = {}
    for name, cells in columns.items():
        try:
            numeric[name] = np.array([float(c) if c else math.nan for c in cells])
        except ValueError:
            text[name] = cells
    if "time_s" not in numeric or not np.all(np.isfinite(numeric["time_s"])):
        raise FormatError(f"{p}: column 'time_s': expected a number (s) in every row")
    t = numeric.pop("time_s")
    return FitTable(t, numeric, text)


def _aligned(frame_time_s: FloatArray, sample_time_s: FloatArray, values: FloatArray) -> FloatArray:
    """``values`` (S, ...) at the sample nearest each frame time (within half a frame)."""
    idx = match_by_time(frame_time_s, sample_time_s)
    out = np.full((frame_time_s.shape[0], *values.shape[1:]), np.nan)
    ok = idx >= 0
    out[ok] = values[idx[ok]]
    return out


def _markers_at(frame_time_s: FloatArray, markers: MarkerData) -> FloatArray:
    """Markers (T, M, 3) at each frame: the newest sample at or before it (as a tracker
    sees them, Zhang et al. 2011 §3); NaN before the first sample."""
    i = np.searchsorted(markers.time_s, frame_time_s, side="right") - 1
    out = np.full((frame_time_s.shape[0], len(markers.names), 3), np.nan)
    ok = i >= 0
    out[ok] = markers.positions_mm[i[ok]]
    return out


def _error_over_time(result: ResultData, truth: Truth) -> tuple[tuple[str, ...], FloatArray]:
    """Per-joint error (T_truth, K) at the truth frames, for the joints both sides have."""
    common = tuple(n for n in truth.joint_names if n in result.joint_names)
    ti = [truth.joint_names.index(n) for n in common]
    ri = [result.joint_names.index(n) for n in common]
    est = _aligned(truth.time_s, result.time_s, result.joints_mm[:, ri])
    return common, np.linalg.norm(est - truth.joints_mm[:, ti], axis=-1)


#: A joint whose mean error is below this equals the truth: the tracker placed it on an
#: input (on a synthetic session, a noise-free keypoint), so it is not an estimate.
PLACED_ON_INPUT_MM = 0.05


def _accuracy_tables(reports: Sequence[tuple[str, EvalReport]]) -> list[Table]:
    """The summary (one column per joint set) and the error per joint of the widest set."""

    def f(v: float) -> str:
        return "n/a" if not np.isfinite(v) else f"{v:.1f}"

    def jitter(r: EvalReport) -> str:
        return f"{f(r.jitter_mm_s2)} (truth {f(r.truth_jitter_mm_s2)})"

    rows = [
        ("joints", lambda r: f"{len(r.joints)}"),
        ("MPJPE (mm)", lambda r: f(r.mpjpe_mm)),
        ("PA-MPJPE (mm)", lambda r: f(r.pa_mpjpe_mm)),
        ("elbow error (mm)", lambda r: f(r.elbow_mm)),
        ("jitter (mm/s²)", jitter),
        (
            "coverage",
            lambda r: (
                f"{r.coverage:.3f} of the joints estimated ({r.n_matched_frames}/"
                f"{r.n_truth_frames} truth frames with a pose)"
            ),
        ),
    ]
    summary = Table(
        "Summary",
        ("measure", *(name for name, _ in reports)),
        tuple((label, *(cell(r) for _, r in reports)) for label, cell in rows),
    )
    widest = reports[-1][1]
    per_joint = Table(
        f"Error per joint ({reports[-1][0]})",
        ("joint", "mean error (mm)"),
        tuple(
            (n, f(v) + (" (placed on its input, not estimated)" if v < PLACED_ON_INPUT_MM else ""))
            for n, v in widest.per_joint_mm.items()
        ),
    )
    return [summary, per_joint]


def _accuracy_notes(reports: Sequence[tuple[str, EvalReport]]) -> list[str]:
    notes = [
        "Joints matched to the truth by time stamp (mocapkit eval). Upper body: "
        + ", ".join(UPPER_BODY_JOINTS)
        + " (the joint set of mocapkit demo's table and mocapkit accuracy)."
    ]
    for name, r in reports:
        if np.isfinite(r.pa_mpjpe_mm) and r.pa_mpjpe_mm > r.mpjpe_mm:
            worst = max(r.per_joint_mm, key=lambda n: r.per_joint_mm[n])
            notes.append(
                f"PA-MPJPE ({name}) is above MPJPE: each frame is aligned to the truth by "
                "the least-squares rotation, translation and scale, which spreads one "
                f"joint's large error (here {worst}, {r.per_joint_mm[worst]:.1f} mm) over "
                "the others; it lowers the RMS error, not always the mean."
            )
    placed = [n for n, v in reports[-1][1].per_joint_mm.items() if v < PLACED_ON_INPUT_MM]
    if placed:
        notes.append(
            f"{', '.join(placed)}: equal to the truth (mean error under "
            f"{PLACED_ON_INPUT_MM} mm): the tracker placed {'it' if len(placed) == 1 else 'them'}"
            " on its input (a keypoint), so the figure measures the input, not the tracker."
        )
    return notes


def _cameras_used(source: str) -> tuple[str, ...] | None:
    """The cameras a result's source names (``camera A`` or ``cameras A,B``); None if none."""
    m = re.search(r"\bcameras? ([\w.-]+(?:,[\w.-]+)*)", source)
    return None if m is None else tuple(m.group(1).split(","))


def _check_out_dir(out: Path, protected: Sequence[Path]) -> None:
    """Refuse a report folder that would replace the result or the session (or hold them)."""
    o = out.resolve()
    for p in protected:
        r = p.resolve()
        if o == r or o in r.parents:
            raise ConfigError(
                f"report folder {out}: would replace {p} (the report folder is swapped in "
                f"whole); choose another --out"
            )


def _video_section(
    folder: Path,
    session: Session,
    result: ResultData,
    truth: Truth | None,
    used: tuple[str, ...] | None,
) -> Section:
    videos: list[tuple[str, WebVideo]] = []
    notes: list[str] = []
    for cam in session.video_cameras:
        source = session.video(cam)
        camera = session.camera(cam)
        captured = _aligned(source.time_s, result.time_s, result.joints_mm)
        if not np.any(np.isfinite(captured)):
            notes.append(
                f"Camera {cam}: no result frame falls on this video's frame times "
                f"({source.time_s[0]:.3f}-{source.time_s[-1]:.3f} s vs "
                f"{result.time_s[0]:.3f}-{result.time_s[-1]:.3f} s): is this the session "
                "the result was tracked from?"
            )
        layers = []
        if truth is not None:
            layers.append(
                OverlayLayer(
                    "truth",
                    truth.joint_names,
                    _aligned(source.time_s, truth.time_s, truth.joints_mm),
                    _TRUTH_BGR,
                )
            )
        kp = session.keypoints.get(cam)
        if kp is not None:  # the 2-D input beside the result: did the detector or the tracker fail?
            pixels = _aligned(source.time_s, kp.time_s, kp.pixels)
            layers.append(OverlayLayer("2-D keypoints", kp.joint_names, pixels, _KEYPOINTS_BGR, 1))
        layers.append(OverlayLayer("captured", result.joint_names, captured, _CAPTURED_BGR, 3))
        body = None
        if result.skeleton is not None and result.q is not None:
            body = (result.skeleton, _aligned(source.time_s, result.time_s, result.q))
        video = write_overlay_video(folder, f"overlay_{cam}", source, camera, layers, body)
        if video.codec == JPEG_SEQUENCE:
            notes.append(
                "No web video codec (VP8, VP9) works in this OpenCV: the overlays are JPEG "
                "frames flipped by the page."
            )
        if used is None:
            videos.append((f"camera {cam}", video))
        elif cam in used:
            videos.append((f"camera {cam} (used by the tracker)", video))
        else:
            videos.append((f"camera {cam} (not used by the tracker: its result projected)", video))
    notes.insert(
        0,
        "The camera images with the captured canonical joints (orange sticks over the body "
        "model's limbs)" + (" and the truth (green)" if truth is not None else "") + "; thin "
        "magenta sticks: the session's 2-D keypoints (the detector's, `mocapkit detect`), "
        "where it has them.",
    )
    if used is not None and any(c not in used for c in session.video_cameras):
        notes.insert(
            1,
            f"The tracker used camera(s) {', '.join(used)}; in the other cameras the overlay "
            "shows its result projected, where a one-camera result's depth errors show.",
        )
    return Section("Overlay video", videos=videos, notes=notes)


def _skeleton_section(
    result: ResultData, truth: Truth | None, markers: MarkerData | None
) -> Section:
    n = result.time_s.shape[0]
    stride = max(1, math.ceil(n / MAX_ANIMATION_FRAMES))
    frames = np.arange(0, n, stride)
    t = result.time_s[frames]
    layers = [PointLayer("captured", result.joint_names, result.joints_mm[frames], CAPTURED_COLOUR)]
    if truth is not None:
        layers.append(
            PointLayer(
                "truth",
                truth.joint_names,
                _aligned(t, truth.time_s, truth.joints_mm),
                TRUTH_COLOUR,
            )
        )
    if markers is not None:
        layers.append(
            PointLayer("markers", markers.names, _markers_at(t, markers), MARKER_COLOUR, False)
        )
    notes = ["Drag to turn the view, scroll to zoom; Play, Pause and the slider move in time."]
    if stride > 1:
        notes.append(f"Every {stride}th of the {n} frames is shown.")
    return Section(
        "3D view",
        figures=[
            skeleton_animation(
                t, layers, "Captured skeleton" + (" and truth" if truth is not None else "")
            )
        ],
        notes=notes,
        animation_opts=animation_options(t),
    )


def build_report(
    result_dir: str | os.PathLike[str],
    truth_session: str | os.PathLike[str] | None = None,
    out_dir: str | os.PathLike[str] | None = None,
    *,
    session: str | os.PathLike[str] | None = None,
    markers: str | os.PathLike[str] | None = None,
    say: Callable[[str], None] = lambda line: None,
) -> Path:
    """Write the report of a result folder; returns the path of its ``index.html``.

    Parameters
    ----------
    result_dir : path-like
        A tracker's result folder (``motion.npz`` or ``joints.csv``; ``fit.csv`` when
        present is plotted column by column).
    truth_session : path-like, optional
        A session folder with ``truth.npz`` (or the ``truth.npz`` itself): adds the truth
        to the 3-D view and the overlays, the error plots and the accuracy table
        (`mocapkit.eval.metrics.evaluate_joints`). A session folder given here is also
        the session of the videos and markers unless ``session`` is given.
    out_dir : path-like, optional
        The report folder (default ``<result_dir>/report``); replaced whole, atomically.
    session : path-like, optional
        The session the result was tracked from (videos, cameras, markers), when it is
        not ``truth_session`` (e.g. a real recording without truth).
    markers : path-like, optional
        A marker file (.c3d, .trc, .csv) to show as points, for a result tracked from raw
        markers without a session (default: the session's markers).
    say : callable, optional
        Receives one-line warnings (a result folder whose files come from different
        runs, `mixed_runs`); they are also shown on the page.

    Raises
    ------
    SessionError
        ``result_dir`` is not a result folder; a session lacks ``truth.npz``.
    ConfigError
        ``out_dir`` would replace the result or the session, or is a folder that is not
        a report folder (`mocapkit.io.atomic.check_own_folder`: no ``index.html``).
    """
    result = load_result(result_dir)
    truth: Truth | None = None
    sess: Session | None = None
    if truth_session is not None:
        tp = Path(truth_session)
        if tp.is_file():
            truth = load_truth(tp)
        else:
            sess = load_session(tp)
            sess.require(truth=True)
            truth = sess.truth
    if session is not None:
        sess = load_session(session)
    marker_data = (
        read_markers(markers)
        if markers is not None
        else (sess.markers if sess is not None else None)
    )
    out = Path(out_dir) if out_dir is not None else result.folder / REPORT_FOLDER
    _check_out_dir(out, [result.folder] + ([sess.path] if sess is not None else []))
    check_own_folder(out, (PAGE_NAME,), "report folder", "mocapkit view")
    mixed = mixed_runs(result)
    for line in mixed:
        say(line)

    n = result.time_s.shape[0]
    facts = [
        ("result", str(result.folder.resolve())),
        ("source", result.source or "n/a"),
        ("frames", f"{n} over {result.time_s[-1] - result.time_s[0]:.2f} s" if n else "0"),
        ("joints", ", ".join(result.joint_names)),
    ]
    used = _cameras_used(result.source)
    facts.append(("cameras used", ", ".join(used) if used else "not named by the result"))
    if sess is not None:
        facts.append(("session", str(sess.path.resolve())))
    if truth is not None:
        facts.append(("truth", str(Path(truth_session or "").resolve())))

    if mixed:
        facts.append(("warning", " ".join(mixed)))

    remove_stale_temporaries(out.parent, out.name)  # what a killed earlier view left
    with atomic_folder(out) as tmp:
        sections: list[Section] = []
        if sess is not None and sess.video_cameras:
            sections.append(_video_section(tmp, sess, result, truth, used))
        if n:
            sections.append(_skeleton_section(result, truth, marker_data))
        if truth is not None:
            names, err = _error_over_time(result, truth)
            args = (
                result.time_s,
                result.joint_names,
                result.joints_mm,
                truth.time_s,
                truth.joint_names,
                truth.joints_mm,
            )
            every = evaluate_joints(*args)
            n_all = len(every.joints)
            upper_only = set(every.joints) == set(UPPER_BODY_JOINTS)
            label = f"upper body ({n_all} joints)" if upper_only else f"all {n_all} joints"
            reports = [(label, every)]
            if set(UPPER_BODY_JOINTS) & set(every.joints) != set(every.joints):
                upper = evaluate_joints(*args, joints=UPPER_BODY_JOINTS)
                reports.insert(0, (f"upper body ({len(upper.joints)} joints)", upper))
            title = f"Error per joint over time (all {len(names)} joints)"
            sections.append(
                Section(
                    "Accuracy against the truth",
                    figures=[error_figure(truth.time_s, names, err, title)],
                    tables=_accuracy_tables(reports),
                    notes=_accuracy_notes(reports),
                )
            )
        fit_path = result.folder / FIT_FILE
        if fit_path.is_file():
            fit = read_fit_table(fit_path)
            # the spans of motion faster than the inputs show, as the run warned
            pops = (
                implausible_warnings(implausible_spans_in_folder(result.folder))
                if "implausible_joints" in fit.numeric
                else []
            )
            sections.append(
                Section(
                    "Fit quality",
                    figures=fit_figures(fit.time_s, fit.numeric, fit.text),
                    notes=[f"Every column of {FIT_FILE} against time.", *pops],
                )
            )
        trc_name = "joints.trc"
        if n:
            write_trc(tmp / trc_name, result.time_s, list(result.joint_names), result.joints_mm)
        links = [
            (f.name, os.path.relpath(f, out).replace(os.sep, "/"))
            for f in sorted(result.folder.iterdir())
            if f.is_file() and f.suffix.lower() in LINKED_SUFFIXES
        ]
        if n:
            links.append((f"{trc_name} (canonical joints as TRC markers, mm)", trc_name))
        write_report_page(
            tmp,
            ReportPage(f"mocapkit report: {result.folder.resolve().name}", facts, sections, links),
        )
    return out / PAGE_NAME


__all__ = [
    "FIT_FILE",
    "MAX_ANIMATION_FRAMES",
    "REPORT_FOLDER",
    "FitTable",
    "ResultData",
    "build_report",
    "load_result",
    "mixed_runs",
    "read_fit_table",
]
