"""Accuracy of a tracker on synthetic sessions rendered from real motion clips.

For each clip an excerpt is rendered with the default realism (`mocapkit synth`), tracked
with and without the video refinement, and evaluated on the upper body against the
session's truth (`mocapkit eval`). The figures the hybrid issue asks for are the means of
the per-clip elbow and upper-body MPJPE errors and the share by which the video cuts the
IK-only elbow error.

The tracker's figures are chaotic in round-off (docs/design-notes/hybrid.md): moving every
marker by 1e-9 mm moves a clip's mean elbow error by up to a few millimetres. So a
comparison to 1 mm can average over jittered repeats (`hybrid_accuracy_repeats`): each
repeat tracks a copy of every session whose marker positions are moved by a seeded
amount far below the marker noise (`jitter_session`, 1e-6 mm by default), and
`repeat_summary` reports the mean over repeats and their spread.
"""

from __future__ import annotations

import json
import math
import os
import shutil
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from mocapkit.errors import ConfigError, SessionError
from mocapkit.eval.metrics import evaluate_result
from mocapkit.io.marker_csv import write_markers_csv
from mocapkit.io.session import MARKER_FILES, load_session
from mocapkit.pipelines.harness import JITTER_MM
from mocapkit.pipelines.hybrid import track_hybrid_session
from mocapkit.skeleton.model import UPPER_BODY_JOINTS
from mocapkit.synth.session_writer import SynthOptions, synthesize_session

#: Upper-body-rich CMU clips of ``shared/data/mocap`` and the excerpt (start s, length s)
#: rendered from each. The hybrid method assumes a subject standing on the spot (feet
#: planted, §3 of the paper); each start is, among the 6 s windows on a 0.5 s grid where
#: the subject stands upright on the floor (head above the lower ankle by more than 74 %
#: of the stature 95 % of the time and by less than 105 %), the one with the least foot
#: travel (mm) plus twice the trunk turn (deg); a clip shorter than 6 s is taken whole. None of
#: these clips holds still: the feet still travel 0.5-1.5 m in the chosen windows.
HYBRID_CLIPS: dict[str, tuple[float, float]] = {
    "13_26.bvh": (11.5, 6.0),
    "01_09.amc": (27.0, 6.0),
    "lambada.amc": (11.0, 6.0),
    "charleston1.amc": (0.0, 4.0),
    "zombie.amc": (0.0, 6.0),
}


@dataclass(frozen=True)
class ClipAccuracy:
    """Upper-body figures of one clip (mm)."""

    clip: str
    start_s: float
    seconds: float
    elbow_ik_mm: float
    elbow_video_mm: float
    mpjpe_ik_mm: float
    mpjpe_video_mm: float
    pa_mpjpe_video_mm: float
    coverage: float


def hybrid_accuracy(
    mocap_dir: str | os.PathLike[str],
    work_dir: str | os.PathLike[str],
    clips: Sequence[str] | None = None,
    seed: int = 0,
    say: Callable[[str], None] = lambda _line: None,
    oriented_sets: Sequence[str] | None = None,
) -> list[ClipAccuracy]:
    """Render, track (IK only and with video) and evaluate each clip.

    Parameters
    ----------
    mocap_dir : path-like
        Folder of the motion clips (``shared/data/mocap``).
    work_dir : path-like
        Where sessions and results are written (one sub-folder per clip).
    clips : sequence of str, optional
        Clip file names, default the keys of `HYBRID_CLIPS` (unknown ones: 0-8 s).
    seed : int
        Rendering seed.
    oriented_sets : sequence of str, optional
        Marker sets whose orientation the tracker sees (default: all, its default);
        ``()`` uses their positions only, as the paper does.
    """
    runs = hybrid_accuracy_repeats(mocap_dir, work_dir, clips, seed, say, oriented_sets, 0)
    return runs[0]


def hybrid_accuracy_repeats(
    mocap_dir: str | os.PathLike[str],
    work_dir: str | os.PathLike[str],
    clips: Sequence[str] | None = None,
    seed: int = 0,
    say: Callable[[str], None] = lambda _line: None,
    oriented_sets: Sequence[str] | None = None,
    repeats: int = 3,
    jitter_mm: float = JITTER_MM,
) -> list[list[ClipAccuracy]]:
    """`hybrid_accuracy` over ``repeats`` copies of each session with jittered markers.

    Each clip is rendered once; repeat ``r`` tracks (IK only and with video) a copy of
    the session whose every marker coordinate is moved by an amount uniform in
    ``[-jitter_mm, jitter_mm]`` drawn from ``np.random.default_rng([seed, r, clip
    number])`` (`jitter_session`). ``repeats=0`` is the plain study: one run on the
    session as rendered.

    Returns
    -------
    list of list of ClipAccuracy
        One list of per-clip rows per repeat (one list when ``repeats=0``).

    Raises
    ------
    ConfigError
        For ``repeats < 0`` or a jitter that is not positive and finite.
    """
    if repeats < 0:
        raise ConfigError(f"repeats: expected a count >= 0, found {repeats}")
    if not (math.isfinite(jitter_mm) and jitter_mm > 0):
        raise ConfigError(f"jitter_mm: expected a positive length, found {jitter_mm}")
    runs: list[list[ClipAccuracy]] = [[] for _ in range(max(repeats, 1))]
    for number, clip in enumerate(clips or tuple(HYBRID_CLIPS)):
        start, seconds = HYBRID_CLIPS.get(clip, (0.0, 8.0))
        base = Path(work_dir) / Path(clip).stem
        session = base / "session"
        synthesize_session(
            str(Path(mocap_dir) / clip),
            session,
            SynthOptions(rig="mono", start_s=start, seconds=seconds, seed=seed, overwrite=True),
        )
        for r, rows in enumerate(runs):
            if repeats == 0:
                tracked, out = session, base
            else:
                out = base / f"jitter{r}"
                tracked = jitter_session(
                    session,
                    out / "session",
                    jitter_mm,
                    np.random.default_rng([seed, r, number]),
                )
            row = _track_and_evaluate(clip, start, seconds, tracked, session, out, oriented_sets)
            prefix = "" if repeats == 0 else f"[{r}] "
            say(prefix + format_rows([row]).splitlines()[-1])
            rows.append(row)
    return runs


def _track_and_evaluate(
    clip: str,
    start: float,
    seconds: float,
    tracked: Path,
    session: Path,
    out: Path,
    oriented_sets: Sequence[str] | None,
) -> ClipAccuracy:
    """Track ``tracked`` IK only and with video into ``out``; evaluate on ``session``'s truth."""
    reports = {}
    for label, video in (("ik", False), ("video", True)):
        track_hybrid_session(tracked, out / label, use_video=video, oriented_sets=oriented_sets)
        reports[label] = evaluate_result(out / label, session, joints=UPPER_BODY_JOINTS)
    return ClipAccuracy(
        clip,
        start,
        seconds,
        reports["ik"].elbow_mm,
        reports["video"].elbow_mm,
        reports["ik"].mpjpe_mm,
        reports["video"].mpjpe_mm,
        reports["video"].pa_mpjpe_mm,
        reports["video"].coverage,
    )


def jitter_session(
    session_dir: str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    jitter_mm: float,
    rng: np.random.Generator,
) -> Path:
    """A copy of a session whose marker positions are moved by tiny seeded amounts.

    Every finite marker coordinate gets an independent offset uniform in
    ``[-jitter_mm, jitter_mm]`` (mm); the markers are written as ``markers.csv`` (exact
    round trip). The session's other files are linked, not copied (videos are large).
    An old ``out_dir`` is replaced.

    Parameters
    ----------
    session_dir : path-like
        A session folder with a marker file.
    out_dir : path-like
        Folder of the copy.
    jitter_mm : float
        Half-width of the offsets (mm).
    rng : numpy.random.Generator
        Draws the offsets.

    Returns
    -------
    Path
        ``out_dir``.
    """
    src = Path(session_dir).resolve()
    markers = load_session(src).markers
    if markers is None:
        raise SessionError(
            f"{src}: expected a marker file ({' or '.join(MARKER_FILES)}), found none"
        )
    out = Path(out_dir)
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    for entry in sorted(src.iterdir()):
        if entry.name not in MARKER_FILES:
            (out / entry.name).symlink_to(entry)
    pos = np.array(markers.positions_mm, dtype=float)
    pos = pos + rng.uniform(-jitter_mm, jitter_mm, size=pos.shape)
    write_markers_csv(out / "markers.csv", markers.time_s, markers.names, pos)
    return out


def summary(rows: Sequence[ClipAccuracy]) -> dict[str, float]:
    """Means over clips and the share by which the video cuts the IK-only elbow error."""
    ik = float(np.mean([r.elbow_ik_mm for r in rows]))
    vid = float(np.mean([r.elbow_video_mm for r in rows]))
    return {
        "elbow_ik_mm": ik,
        "elbow_video_mm": vid,
        "elbow_reduction": 1.0 - vid / ik,
        "mpjpe_ik_mm": float(np.mean([r.mpjpe_ik_mm for r in rows])),
        "mpjpe_video_mm": float(np.mean([r.mpjpe_video_mm for r in rows])),
        "pa_mpjpe_video_mm": float(np.mean([r.pa_mpjpe_video_mm for r in rows])),
    }


def repeat_summary(runs: Sequence[Sequence[ClipAccuracy]]) -> dict[str, dict[str, float]]:
    """Mean and spread over repeats of `summary`'s figures.

    Parameters
    ----------
    runs : sequence of sequence of ClipAccuracy
        One run (per-clip rows) per repeat, as `hybrid_accuracy_repeats` returns.

    Returns
    -------
    dict
        For each figure of `summary` (``elbow_ik_mm``, ...): ``mean``, ``min`` and ``max``
        over the repeats' five-clip means, ``std`` (ddof 1; 0 for one repeat) and
        ``sem`` (``std / sqrt(repeats)``, the standard error of the mean).
    """
    if not runs:
        raise ConfigError("repeat_summary: expected at least one run, found none")
    sums = [summary(rows) for rows in runs]
    out: dict[str, dict[str, float]] = {}
    for key in sums[0]:
        v = np.array([s[key] for s in sums])
        std = float(v.std(ddof=1)) if v.size > 1 else 0.0
        out[key] = {
            "mean": float(v.mean()),
            "min": float(v.min()),
            "max": float(v.max()),
            "std": std,
            "sem": std / math.sqrt(v.size),
        }
    return out


def format_rows(rows: Sequence[ClipAccuracy]) -> str:
    """A plain-text table of per-clip figures."""
    head = (
        f"{'clip':<18}{'excerpt s':>11}{'elbow IK':>10}{'elbow vid':>11}"
        f"{'MPJPE IK':>10}{'MPJPE vid':>11}{'PA vid':>8}"
    )
    lines = [head]
    for r in rows:
        lines.append(
            f"{r.clip:<18}{f'{r.start_s:g}+{r.seconds:g}':>11}{r.elbow_ik_mm:>10.1f}"
            f"{r.elbow_video_mm:>11.1f}{r.mpjpe_ik_mm:>10.1f}{r.mpjpe_video_mm:>11.1f}"
            f"{r.pa_mpjpe_video_mm:>8.1f}"
        )
    return "\n".join(lines)


def to_json(rows: Sequence[ClipAccuracy]) -> str:
    """Per-clip rows and the summary as JSON."""
    return json.dumps({"clips": [asdict(r) for r in rows], "summary": summary(rows)}, indent=2)


def repeats_to_json(runs: Sequence[Sequence[ClipAccuracy]]) -> str:
    """Per-repeat rows and summaries, and `repeat_summary`, as JSON."""
    return json.dumps(
        {
            "repeats": [
                {"clips": [asdict(r) for r in rows], "summary": summary(rows)} for rows in runs
            ],
            "summary": repeat_summary(runs),
        },
        indent=2,
    )
