"""The built-in demonstration: render a session, track it with every method, compare and report.

`run_demo` needs no data files: it renders the built-in table-tennis rally as a
synthetic session seen by a rig that serves all three trackers (``all``: the camera
``mono`` in front of the subject plus the stereo pair ``stereo_left``/``stereo_right``;
video, head and hand markers with realistic noise, 2-D keypoints) and tracks it with

- **hybrid** (Zhang 2011): head and hand markers plus the ``mono`` video;
- **stereo** (Azad 2008): the stereo pair's video with head, hands and torso from the
  pair's 2-D keypoints and fixed shoulders, the most accurate mode measured in
  ``docs/stereo.md`` (``--keypoints --torso keypoints --fixed-shoulders``);
- **mono** (Mamania 2004): the ``mono`` camera's 2-D keypoints.

The session's keypoints are the truth's joints projected into each camera (no detector
noise), so the stereo and mono rows show the trackers given perfect 2-D joints, not a
detector. Each result is evaluated against the session's truth (upper body) and timed,
one table compares them, and an offline HTML report (`build_report`) is written per
tracker with an index page linking them. The hybrid tracker is also run without its
video refinement and with the marker sets' positions only (the paper's input), where
the video has the elbow swivel to resolve. When the real CMU clips in ``../shared/data``
are present it also reads one and prints a few of its joints, to show the motion
readers on data nobody on the team made.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mocapkit.eval.metrics import EvalReport, evaluate_result
from mocapkit.io.motion import Motion
from mocapkit.pipelines.fit_report import implausible_spans_in_folder, implausible_warnings
from mocapkit.pipelines.hybrid import track_hybrid_session
from mocapkit.pipelines.mono import track_mono
from mocapkit.pipelines.report import build_report
from mocapkit.pipelines.stereo import (
    ACCURACY_MODES,
    elbow_jump_warnings,
    elbow_jumps_in_folder,
    track_stereo_session,
)
from mocapkit.progress import silenced
from mocapkit.skeleton import UPPER_BODY_JOINTS, load_preset, standing_height_mm
from mocapkit.synth.session_writer import SynthOptions, synthesize_session
from mocapkit.viz.report.page import ReportPage, Section, Table, write_report_page

#: The stereo tracker's mode in the demo: the most accurate one in docs/stereo.md.
STEREO_MODE = "keypoints+torso+static"
#: The stereo tracker's cameras: the pair of the ``all`` rig.
STEREO_CAMERAS = "stereo_left,stereo_right"
#: Why mono's MPJPE is large, said under the table.
MONO_NOTE = (
    "mono: one camera leaves the body's distance and size open, so its MPJPE is large; "
    "PA-MPJPE (after the best rotation, translation and scale) shows its pose."
)
#: Order of the trackers in the table and the report.
TRACKER_NAMES = ("hybrid", "stereo", "mono")


@dataclass(frozen=True)
class TrackerRow:
    """One tracker's run in the demo: what it used, how well and how fast.

    Attributes
    ----------
    name : str
        ``hybrid``, ``stereo`` or ``mono``.
    inputs : str
        The inputs it was given, in words.
    result_dir : Path
        Its result folder.
    report : EvalReport
        Upper-body accuracy against the session's truth.
    n_frames : int
        Frames tracked.
    wall_s, cpu_s : float
        Wall-clock and CPU time of the tracking call (s), loading the session included.
    report_page : Path
        Its HTML report.
    """

    name: str
    inputs: str
    result_dir: Path
    report: EvalReport
    n_frames: int
    wall_s: float
    cpu_s: float
    report_page: Path

    @property
    def frames_per_s(self) -> float:
        """Frames tracked per second of wall-clock time."""
        return self.n_frames / self.wall_s if self.wall_s > 0 else float("nan")


@dataclass(frozen=True)
class DemoResult:
    """What the demo wrote and measured.

    Attributes
    ----------
    out_dir, session_dir : Path
    rows : dict of str to TrackerRow
        One per tracker (`TRACKER_NAMES`).
    hybrid_variants : dict of str to EvalReport
        The hybrid tracker's ``ik_only``, ``with_video`` (its row),
        ``positions_only_ik`` and ``positions_only_video`` runs.
    report_page : Path
        The index page linking the trackers' reports.
    """

    out_dir: Path
    session_dir: Path
    rows: dict[str, TrackerRow]
    hybrid_variants: dict[str, EvalReport]
    report_page: Path


def find_shared_data(start: Path | None = None) -> Path | None:
    """The ``shared/data`` folder of real recordings beside a checkout, if any.

    Looks at ``$MOCAPKIT_SHARED_DATA`` first, then for ``shared/data`` or
    ``../shared/data`` above the working directory.
    """
    env = os.environ.get("MOCAPKIT_SHARED_DATA")
    if env:
        return Path(env) if Path(env).is_dir() else None
    here = (start or Path.cwd()).resolve()
    for parent in (here, *here.parents):
        for candidate in (parent / "shared" / "data", parent.parent / "shared" / "data"):
            if candidate.is_dir():
                return candidate
    return None


def _describe_real_clip(say: Callable[[str], None]) -> None:
    from mocapkit.io.motion_files import read_motion

    data = find_shared_data()
    clip = data / "mocap" / "13_26.bvh" if data else None
    if clip is None or not clip.is_file():
        say("real CMU clips: ../shared/data not found, skipping the real-motion readout")
        return
    motion = read_motion(clip)
    say(
        f"real motion {clip.name}: {motion.n_frames} frames over {motion.time_s[-1]:.1f} s, "
        f"{motion.skeleton.n_joints} joints, {motion.skeleton.n_dofs} DoFs"
    )
    frame = motion.n_frames // 2
    for name in ("head", "left_wrist", "right_wrist"):
        p = motion.joints_mm[frame, motion.joint_names.index(name)]
        xyz = f"({p[0]:7.0f}, {p[1]:7.0f}, {p[2]:7.0f}) mm"
        say(f"  t={motion.time_s[frame]:6.2f} s  {name:<12} {xyz}")


@contextmanager
def _timed() -> Iterator[list[float]]:
    """Yields a list that holds ``[wall_s, cpu_s]`` of the block once it ends."""
    times: list[float] = []
    wall0, cpu0 = time.perf_counter(), time.process_time()
    try:
        yield times
    finally:
        times += [time.perf_counter() - wall0, time.process_time() - cpu0]


def format_table(rows: dict[str, TrackerRow]) -> list[str]:
    """The demo's comparison table, one line per tracker (upper body, mm; frames/s)."""
    lines = [
        f"{'tracker':<8}{'MPJPE':>8}{'PA-MPJPE':>10}{'elbow':>8}{'frames/s':>10}  inputs",
        f"{'':<8}{'mm':>8}{'mm':>10}{'mm':>8}",
    ]
    for row in rows.values():
        r = row.report
        lines.append(
            f"{row.name:<8}{r.mpjpe_mm:>8.1f}{r.pa_mpjpe_mm:>10.1f}{r.elbow_mm:>8.1f}"
            f"{row.frames_per_s:>10.1f}  {row.inputs}"
        )
    return lines


def _index_page(
    folder: Path, session: Path, rows: dict[str, TrackerRow], hybrid_line: str, rendered: str
) -> Path:
    table = Table(
        "Upper body against the truth",
        ("tracker", "MPJPE (mm)", "PA-MPJPE (mm)", "elbow (mm)", "frames/s", "inputs"),
        tuple(
            (
                row.name,
                f"{row.report.mpjpe_mm:.1f}",
                f"{row.report.pa_mpjpe_mm:.1f}",
                f"{row.report.elbow_mm:.1f}",
                f"{row.frames_per_s:.1f}",
                row.inputs,
            )
            for row in rows.values()
        ),
    )
    notes = [
        rendered,
        "The keypoints are the truth's joints projected into each camera (no detector "
        "noise). frames/s: wall clock of one run on this machine, loading the session "
        "included, after an untimed warm-up that compiles the Numba kernels.",
        MONO_NOTE,
        hybrid_line,
    ]
    links = [
        (f"{row.name} report", os.path.relpath(row.report_page, folder).replace(os.sep, "/"))
        for row in rows.values()
    ]
    page = ReportPage(
        "mocapkit demo: three trackers on builtin:table-tennis",
        facts=[("session", str(session.resolve()))],
        sections=[Section("Comparison", tables=[table], notes=notes)],
        links=links,
    )
    return write_report_page(folder, page)


def run_demo(
    out_dir: str | os.PathLike[str] = "demo-output",
    seconds: float = 4.0,
    say: Callable[[str], None] = print,
    quiet: bool = False,
) -> DemoResult:
    """Render the built-in table-tennis rally, track it with hybrid, stereo and mono,
    compare them and write their reports.

    Parameters
    ----------
    out_dir : path-like
        Folder for ``session/``, the result folders ``result_hybrid``, ``result_stereo``,
        ``result_mono``, the hybrid variants ``result_hybrid_ik_only``,
        ``result_hybrid_positions_only_ik``, ``result_hybrid_positions_only_video``, and
        ``report/`` (``index.html`` linking ``report/<tracker>/index.html``); created,
        replaced pieces are written atomically.
    seconds : float
        Length of the rendered excerpt (s). 4 s (120 frames at 640x480, three cameras)
        keeps ``make demo`` well under 5 minutes on one core.
    say : callable
        Where the lines go (``print`` by default).
    quiet : bool
        Print only the table and the report's path; no progress meters.
    """
    out = Path(out_dir)
    tell: Callable[[str], None] = (lambda _line: None) if quiet else say
    with _timed() as times, silenced() if quiet else nullcontext():
        result = _run(out, seconds, say, tell)
    tell(f"the demo took {times[0]:.0f} s ({times[1]:.0f} s of CPU time)")
    return result


def _run(
    out: Path, seconds: float, say: Callable[[str], None], tell: Callable[[str], None]
) -> DemoResult:
    model = load_preset("zhang21")
    tell(
        f"body model zhang21: {model.n_joints} joints, {model.n_dofs} DoFs "
        f"(21 rotational + 3 root), {model.total_mass_kg:.2f} kg, "
        f"{standing_height_mm(model):.0f} mm tall"
    )
    _describe_real_clip(tell)

    session = out / "session"
    summary = synthesize_session(
        "builtin:table-tennis", session, SynthOptions(rig="all", seconds=seconds, overwrite=True)
    )
    tell(summary.text())

    # The hybrid variants first: they also compile the Numba kernels that the timed
    # default run then finds cached.
    variants: dict[str, EvalReport] = {}
    for label, use_video, oriented_sets in (
        ("positions_only_ik", False, ()),
        ("positions_only_video", True, ()),
        ("ik_only", False, None),
    ):
        result_dir = out / f"result_hybrid_{label}"
        track_hybrid_session(session, result_dir, use_video=use_video, oriented_sets=oriented_sets)
        variants[label] = evaluate_result(result_dir, session, joints=UPPER_BODY_JOINTS)
        tell(f"tracked hybrid ({label.replace('_', ' ')}) -> {result_dir}")

    stereo_config = ACCURACY_MODES[STEREO_MODE]
    # (inputs, the timed run writing a result folder, an untimed warm-up compiling the
    # tracker's Numba kernels so that frames/s is the steady rate; the hybrid kernels
    # are warm from its variants above)
    runs: dict[str, tuple[str, Callable[[Path], Motion], Callable[[], object]]] = {
        "hybrid": (
            "head+hand markers, mono video",
            lambda d: track_hybrid_session(session, d),
            lambda: None,
        ),
        "stereo": (
            "stereo pair video + its 2-D keypoints (head, hands, torso)",
            lambda d: (
                (
                    track_stereo_session(session, d, cameras=STEREO_CAMERAS, config=stereo_config)
                ).motion
            ),
            lambda: track_stereo_session(
                session, None, cameras=STEREO_CAMERAS, config=stereo_config, max_frames=3
            ),
        ),
        "mono": (
            "mono camera's 2-D keypoints",
            lambda d: track_mono(session, d, camera="mono").motion,
            lambda: track_mono(session, None, camera="mono"),
        ),
    }
    report_dir = out / "report"
    rows: dict[str, TrackerRow] = {}
    for name, (inputs, track, warm_up) in runs.items():
        result_dir = out / f"result_{name}"
        with silenced():
            warm_up()
        with _timed() as times:
            motion = track(result_dir)
        report = evaluate_result(result_dir, session, joints=UPPER_BODY_JOINTS)
        tell(f"tracked {name} ({inputs}) -> {result_dir}")
        page = build_report(result_dir, session, report_dir / name)
        rows[name] = TrackerRow(
            name, inputs, result_dir, report, motion.n_frames, times[0], times[1], page
        )
    variants["with_video"] = rows["hybrid"].report

    v = {k: r.elbow_mm for k, r in variants.items()}
    hybrid_line = (
        f"hybrid elbow error, IK only -> with video: {v['ik_only']:.1f} -> "
        f"{v['with_video']:.1f} mm with the marker sets' orientation (default), "
        f"{v['positions_only_ik']:.1f} -> {v['positions_only_video']:.1f} mm with their "
        "positions only (the paper's input), where the video resolves the elbow swivel."
    )
    rendered = (
        f"{summary.motion}: {summary.n_frames} frames over {summary.duration_s:.2f} s seen by "
        f"{', '.join(summary.cameras)}; {summary.n_marker_samples} marker samples."
    )
    index = _index_page(report_dir, session, rows, hybrid_line, rendered)

    say("")
    say(f"builtin:table-tennis, {seconds:g} s, upper body against the truth:")
    for line in format_table(rows):
        say(line)
    say("")
    tell(hybrid_line)
    tell(
        "keypoints: the truth's joints projected into each camera (no detector noise). "
        "frames/s: wall clock of one run on this machine, loading the session included, "
        "after an untimed warm-up that compiles the Numba kernels."
    )
    tell(MONO_NOTE)
    tell(
        f"open {rows['hybrid'].result_dir / 'motion.bvh'} in Blender (File > Import > Motion "
        "Capture (.bvh), with Update Scene FPS and Update Scene Duration ticked)."
    )
    if not all(np.isfinite(row.report.elbow_mm) for row in rows.values()):
        say("warning: a tracker produced no comparable pose")
    for line in elbow_jump_warnings(elbow_jumps_in_folder(rows["stereo"].result_dir), 1)[:2]:
        say(f"stereo: {line.strip()}")
    for name, row in rows.items():  # motion faster than the inputs show: count and worst
        for line in implausible_warnings(implausible_spans_in_folder(row.result_dir), 1)[:2]:
            say(f"{name}: {line.strip()}")
    say(f"report: {index}")
    return DemoResult(out, session, rows, variants, index)
