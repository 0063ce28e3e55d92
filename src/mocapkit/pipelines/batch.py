"""A lab's whole study on Dask: find every take, track and evaluate each as one task, tabulate.

A take is a session folder (one holding ``session.json``, at any depth under the study
folder) or, with ``markers_glob``, a raw marker file tracked by the hybrid tracker's IK
with the given marker sets. Each take becomes one Dask task (`run_take`) that tracks it
with the method of `mocapkit.pipelines.registry`, evaluates it where the session holds
truth (`mocapkit.eval.metrics.evaluate_result`) and writes its result folder
``OUT/<take>/`` atomically (`mocapkit.io.atomic.atomic_folder`).

Resuming. A result folder is complete when its ``take.json`` (`TAKE_FILE`), written last
and atomically, says that this take was produced from the same source (the same files
with the same sizes and modification times), with the same method choice and options,
and every file it lists is there with its recorded size. Complete takes are skipped
(their row is read back from ``take.json``); anything else (no ``take.json``, a failed
take, a changed source, changed options, a folder written by ``mocapkit track``) is
redone, the old folder kept whole until the new one is swapped in. A killed run leaves at
worst temporaries beside the result folders, which the next run removes.

``study.csv`` (`STUDY_COLUMNS`) is rewritten atomically whenever a take finishes, so a
killed run leaves a table that says which takes were done and which were pending.
"""

from __future__ import annotations

import contextlib
import csv
import hashlib
import json
import math
import os
import time
import uuid
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, TextIO

from mocapkit.errors import ConfigError, SessionError
from mocapkit.io.atomic import (
    atomic_folder,
    atomic_write,
    check_own_folder,
    remove_stale_temporaries,
)
from mocapkit.pipelines.registry import AUTO, choose_method, session_tracker
from mocapkit.progress import Progress, silenced

#: The file that marks a result folder complete (written last, atomically).
TAKE_FILE = "take.json"
TAKE_FORMAT = "mocapkit.batch.take"
#: The study table's file name in the results folder.
STUDY_FILE = "study.csv"
#: Columns of ``study.csv``: the take (its folder or file relative to the study, which is
#: also its result folder relative to the results), ``session`` or ``markers``, the method
#: that ran, frames tracked, share of them with a pose, mean distance (px) of the result's
#: joints from the session's 2-D keypoints in its first camera that has both, upper-body
#: errors against truth (mm), seconds the take took on its worker, ``done`` / ``poor``
#: (tracked, but a joint stays far from its detections in most views over a stretch:
#: `mocapkit.pipelines.multiview.far_spans`) / ``skipped``
#: (complete from an earlier run; figures from then) / ``failed`` / ``pending``, and the
#: error of a failed take.
STUDY_COLUMNS = (
    "take",
    "kind",
    "method",
    "frames",
    "coverage",
    "fit_px",
    "mpjpe_mm",
    "pa_mpjpe_mm",
    "elbow_mm",
    "seconds",
    "status",
    "error",
)


@dataclass(frozen=True)
class Take:
    """One unit of work: a session folder or a raw marker file.

    Attributes
    ----------
    name : str
        Its path relative to the study folder, ``/``-separated, without a marker file's
        extension; also its result folder relative to the results folder.
    kind : str
        ``"session"`` or ``"markers"``.
    source : Path
        Absolute path of the session folder or marker file.
    """

    name: str
    kind: str
    source: Path


@dataclass(frozen=True)
class TakeRow:
    """One row of ``study.csv`` (NaN where a figure is unknown)."""

    take: str
    kind: str
    method: str = ""
    frames: int = 0
    coverage: float = math.nan
    fit_px: float = math.nan
    mpjpe_mm: float = math.nan
    pa_mpjpe_mm: float = math.nan
    elbow_mm: float = math.nan
    seconds: float = math.nan
    status: str = "pending"
    error: str = ""

    def csv_fields(self) -> list[str]:
        """The row as ``study.csv`` text fields (empty where unknown)."""

        def num(v: float, digits: int) -> str:
            return "" if not math.isfinite(v) else f"{v:.{digits}f}"

        return [
            self.take,
            self.kind,
            self.method,
            str(self.frames) if self.frames else "",
            num(self.coverage, 3),
            num(self.fit_px, 2),
            num(self.mpjpe_mm, 1),
            num(self.pa_mpjpe_mm, 1),
            num(self.elbow_mm, 1),
            num(self.seconds, 2),
            self.status,
            self.error,
        ]


@dataclass(frozen=True)
class TakeJob:
    """What a worker needs to run one take (plain data: it travels to Dask workers)."""

    take: Take
    out_root: Path
    options: dict[str, Any]


@dataclass
class StudyResult:
    """What `batch` did.

    Attributes
    ----------
    rows : list of TakeRow
        One per take, in take order (sorted by name).
    study_csv : Path
    wall_s : float
        Wall time of the whole call (s).
    dashboard : str
        The Dask dashboard's address, empty when there is none.
    """

    rows: list[TakeRow]
    study_csv: Path
    wall_s: float
    dashboard: str = ""
    counts: dict[str, int] = field(default_factory=dict)

    @property
    def n_failed(self) -> int:
        """Number of takes that failed."""
        return sum(r.status == "failed" for r in self.rows)

    def table(self) -> str:
        """The study table as aligned text (errors cut to 120 characters)."""
        cells = [list(STUDY_COLUMNS)] + [r.csv_fields() for r in self.rows]
        for c in cells[1:]:
            c[-1] = c[-1] if len(c[-1]) <= 120 else c[-1][:117] + "..."
        widths = [max(len(c[i]) for c in cells) for i in range(len(STUDY_COLUMNS))]
        return "\n".join("  ".join(v.ljust(w) for v, w in zip(c, widths)).rstrip() for c in cells)


# ====================================================================== finding takes


def _hidden(rel: Path) -> bool:
    # atomic temporaries (.NAME.new-*, .NAME.old-*) and dot folders are never takes
    return any(part.startswith(".") for part in rel.parts)


def _session_folders(root: Path, excluded: Callable[[Path], bool]) -> list[Path]:
    """The folders under ``root`` holding a ``session.json``, sorted, following linked
    folders (a study of links to sessions stored elsewhere); each real folder is searched
    once, by the first path that reaches it, so a link to a folder above it is no loop
    and a session linked twice is one take."""
    found = []
    seen: set[Path] = set()
    for here, dirs, files in os.walk(root, followlinks=True):
        folder = Path(here)
        real = folder.resolve()
        if real in seen or excluded(folder):
            dirs[:] = []
            continue
        seen.add(real)
        dirs.sort()  # the first path to a folder linked twice: the first by name
        if "session.json" in files and (folder / "session.json").is_file():
            found.append(folder)
    return sorted(found)


def discover_takes(
    study_dir: str | os.PathLike[str],
    markers_glob: str | None = None,
    exclude: Sequence[str | os.PathLike[str]] = (),
) -> list[Take]:
    """Every take under a study folder, sorted by name.

    Parameters
    ----------
    study_dir : path
    markers_glob : str, optional
        Pattern, relative to ``study_dir`` (`pathlib.Path.glob`, ``**`` for any depth),
        of raw marker files to track as takes besides the sessions. Files inside a
        session folder belong to that session and are not takes.
    exclude : sequence of path
        Folders not searched (the results folder when it lies inside the study).

    Raises
    ------
    SessionError
        The study folder is missing, or two takes would share a result folder.
    """
    from mocapkit.io.marker_files import SUPPORTED_MARKER_EXTENSIONS

    root = Path(study_dir).resolve()
    if not root.is_dir():
        raise SessionError(f"{study_dir}: study folder not found")
    skip = [Path(e).resolve() for e in exclude]

    def excluded(p: Path) -> bool:
        real = p.resolve()  # a link into the results folder is the results folder
        inside = any(q == s or s in q.parents for s in skip for q in (p, real))
        return inside or _hidden(p.relative_to(root))

    sessions = _session_folders(root, excluded)
    takes = [
        # a study folder that is itself a session: one take named after it
        Take(p.relative_to(root).as_posix() if p != root else root.name, "session", p)
        for p in sessions
    ]
    if markers_glob:
        for f in sorted(root.glob(markers_glob)):
            if not f.is_file() or excluded(f):
                continue
            if any(s == f.parent or s in f.parents for s in sessions):
                continue
            if f.suffix.lower() not in SUPPORTED_MARKER_EXTENSIONS:
                continue
            takes.append(Take(f.relative_to(root).with_suffix("").as_posix(), "markers", f))
    seen: dict[str, Take] = {}
    for t in takes:
        if t.name in seen:
            raise SessionError(
                f"{root}: takes {seen[t.name].source} and {t.source} would share the result "
                f"folder {t.name!r}; rename one"
            )
        seen[t.name] = t
    return sorted(takes, key=lambda t: t.name)


# ====================================================================== completeness


def source_fingerprint(source: str | os.PathLike[str]) -> str:
    """SHA-256 over the relative path, size and modification time of each source file.

    Any file added, removed, rewritten or touched in a session folder (or the marker
    file itself) changes it; file contents are not read, so it costs one ``stat`` each.
    """
    p = Path(source)
    h = hashlib.sha256()
    files = (
        sorted(f for f in p.rglob("*") if f.is_file() and not _hidden(f.relative_to(p)))
        if p.is_dir()
        else [p]
    )
    for f in files:
        st = f.stat()
        rel = f.relative_to(p).as_posix() if p.is_dir() else f.name
        h.update(f"{rel}\0{st.st_size}\0{st.st_mtime_ns}\n".encode())
    return h.hexdigest()


def completed_row(
    take: Take, out_root: str | os.PathLike[str], options: dict[str, Any]
) -> TakeRow | None:
    """The stored row of a take whose result folder is complete for these options, else None.

    See the module docstring for what complete means; a ``take.json`` that cannot be
    read counts as incomplete (the take is redone), never as an error.
    """
    folder = Path(out_root) / take.name
    try:
        doc = json.loads((folder / TAKE_FILE).read_text(encoding="utf-8"))
        ok = (
            doc["format"] == TAKE_FORMAT
            and doc["take"] == take.name
            and doc["kind"] == take.kind
            and doc["options"] == options
            and doc["source_fingerprint"] == source_fingerprint(take.source)
            and all(
                (folder / n).is_file() and (folder / n).stat().st_size == s
                for n, s in doc["files"].items()
            )
        )
        if not ok:
            return None
        row: dict[str, Any] = {k: (math.nan if v is None else v) for k, v in doc["row"].items()}
        return TakeRow(**row)
    except (OSError, ValueError, KeyError, TypeError):
        return None


# ====================================================================== one take


def _version() -> str:
    # from the installed metadata: importing the package's top level from here would
    # tie it in a cycle (the top level exports `batch`)
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("mocapkit")
    except PackageNotFoundError:
        return "unknown"


def _resolve_method(take: Take, requested: str) -> str:
    if take.kind == "markers":
        return "hybrid"
    return choose_method(take.source) if requested == AUTO else requested


def keypoint_fit_px(
    session_dir: str | os.PathLike[str], result_dir: str | os.PathLike[str]
) -> float:
    """Mean image distance (px) between a result's joints and a session's 2-D keypoints.

    Uses the first camera with video that has keypoints; frames are matched by time
    stamp (`mocapkit.eval.metrics.match_by_time`), joints by canonical name. NaN when the
    session has no keypoints or nothing can be compared. This is how well the result
    agrees with what the images show, for any method (in a real session, with a 2-D
    detector's keypoints); on synthetic sessions the keypoints are the truth's exact
    projections, so there it is the accuracy seen in the image.
    """
    import numpy as np

    from mocapkit.eval.metrics import load_result_joints, match_by_time
    from mocapkit.io.session import load_session

    session = load_session(session_dir)
    cams = [c for c in session.video_cameras if c in session.keypoints]
    if not cams:
        return math.nan
    kp = session.keypoints[cams[0]]
    rt, rn, rj = load_result_joints(result_dir)
    common = [n for n in kp.joint_names if n in rn]
    if not common:
        return math.nan
    match = match_by_time(kp.time_s, rt)
    ok = match >= 0
    proj = session.camera(cams[0]).project(rj[match[ok]][:, [rn.index(n) for n in common]])
    obs = kp.pixels[ok][:, [kp.joint_names.index(n) for n in common]]
    err = np.linalg.norm(proj - obs, axis=-1)
    fin = np.isfinite(err)
    return float(err[fin].mean()) if fin.any() else math.nan


def _track_into(job: TakeJob, method: str, folder: Path) -> dict[str, float]:
    """Track the take into ``folder``, evaluate it; the row's figures."""
    import numpy as np

    from mocapkit.eval.metrics import evaluate_result, joint_subset, load_result_joints

    take, opts = job.take, job.options
    if take.kind == "markers":
        from mocapkit.pipelines.hybrid_markers import track_hybrid_markers

        track_hybrid_markers(take.source, opts["marker_sets"], None, folder)
    else:
        session_tracker(method)(take.source, folder)
    # figures from the folder written, whatever the tracker returns (Motion, a run record)
    _, _, joints = load_result_joints(folder)
    figures = {
        "frames": float(joints.shape[0]),
        "coverage": float(np.all(np.isfinite(joints), axis=(1, 2)).mean()) if joints.size else 0.0,
    }
    if take.kind == "session":
        from mocapkit.pipelines.multiview import far_spans_in_folder

        figures["fit_px"] = keypoint_fit_px(take.source, folder)
        figures["far_spans"] = float(len(far_spans_in_folder(folder)))
        if (take.source / "truth.npz").is_file():
            report = evaluate_result(folder, take.source, joints=joint_subset(opts["joints"]))
            with atomic_write(folder / "eval.json") as fh:
                fh.write(report.to_json())
            figures.update(
                mpjpe_mm=report.mpjpe_mm, pa_mpjpe_mm=report.pa_mpjpe_mm, elbow_mm=report.elbow_mm
            )
    return figures


def run_take(job: TakeJob) -> TakeRow:
    """Track, evaluate and write one take's result folder; never raises for the take's own
    errors (they come back as a ``failed`` row).

    This is the Dask task. The tracker's own progress meter is silenced: several takes
    run at once beside the batch's meter.
    """
    take = job.take
    folder = job.out_root / take.name
    start = time.perf_counter()
    method = ""
    try:
        with silenced():
            remove_stale_temporaries(folder.parent, folder.name)
            method = _resolve_method(take, job.options["method"])
            fingerprint = source_fingerprint(take.source)
            with atomic_folder(folder) as tmp:
                figures = _track_into(job, method, tmp)
                nan = math.nan
                row = TakeRow(
                    take.name,
                    take.kind,
                    method,
                    frames=int(figures["frames"]),
                    coverage=figures["coverage"],
                    fit_px=figures.get("fit_px", nan),
                    mpjpe_mm=figures.get("mpjpe_mm", nan),
                    pa_mpjpe_mm=figures.get("pa_mpjpe_mm", nan),
                    elbow_mm=figures.get("elbow_mm", nan),
                    seconds=time.perf_counter() - start,
                    status="poor" if figures.get("far_spans", 0.0) > 0 else "done",
                )
                doc = {
                    "format": TAKE_FORMAT,
                    "take": take.name,
                    "kind": take.kind,
                    "source": str(take.source),
                    "source_fingerprint": fingerprint,
                    "options": job.options,
                    "mocapkit_version": _version(),
                    "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                    "files": {
                        f.name: f.stat().st_size for f in sorted(tmp.iterdir()) if f.is_file()
                    },
                    "row": {
                        k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                        for k, v in asdict(row).items()
                    },
                }
                # last, so that a folder with a take.json holds everything it lists
                with atomic_write(tmp / TAKE_FILE) as fh:
                    json.dump(doc, fh, indent=2)
        return row
    except Exception as exc:  # a take's failure is its row's; the study goes on
        message = " ".join(f"{type(exc).__name__}: {exc}".split())
        return TakeRow(
            take.name,
            take.kind,
            method,
            seconds=time.perf_counter() - start,
            status="failed",
            error=message,
        )


# ====================================================================== the study


def write_study_csv(path: str | os.PathLike[str], rows: Sequence[TakeRow]) -> None:
    """Write ``study.csv`` atomically."""
    with atomic_write(path, newline="") as fh:
        w = csv.writer(fh)
        w.writerow(STUDY_COLUMNS)
        for r in rows:
            w.writerow(r.csv_fields())


def default_workers() -> int:
    """Worker processes of the default local cluster: the cores this process may use."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:  # not on Linux
        return max(os.cpu_count() or 1, 1)


@contextlib.contextmanager
def _dask_client(
    client: Any, scheduler: str | None, n_workers: int | None, processes: bool
) -> Iterator[Any]:
    if client is not None:
        yield client
        return
    from distributed import Client, LocalCluster

    if scheduler:
        with Client(scheduler) as own:
            yield own
        return
    # one thread per worker: tracking is CPU-bound Python/Numba, threads would share a GIL
    cluster = LocalCluster(
        n_workers=n_workers or default_workers(),
        threads_per_worker=1,
        processes=processes,
        # worker processes ignore Ctrl-C (it reaches the whole process group): this
        # process stops them and says what finished, without their tracebacks
        **({"preload": ["mocapkit.pipelines.batch_worker"]} if processes else {}),
    )
    with cluster, Client(cluster) as own:
        yield own


def _quiet_logs() -> None:
    import logging

    for name in ("distributed", "tornado"):
        logging.getLogger(name).setLevel(logging.CRITICAL)


def _quiet_cluster_shutdown(client: Any, own: bool) -> None:
    """After Ctrl-C, before the local cluster this batch started is closed: its closing
    (the scheduler, nannies and workers stopping takes midway) logs nothing."""
    if not own:
        return
    _quiet_logs()
    with contextlib.suppress(Exception):  # a worker that cannot answer is closed anyway
        client.run(_quiet_logs)


def _dashboard(client: Any) -> str:
    """The dashboard's address; empty where there is none (a local cluster without bokeh
    serves only a page asking for it)."""
    import importlib.util

    try:
        services = client.scheduler_info().get("services", {})
        local = client.cluster is not None
    except Exception:  # a scheduler that cannot say: no address to show
        return ""
    if "dashboard" not in services or (local and importlib.util.find_spec("bokeh") is None):
        return ""
    return str(client.dashboard_link)


def _check_results_folder(out: Path, study: Path) -> None:
    """Refuse, before any work, a results folder that is, or lies inside, a session (of
    the study: that take would be left out; elsewhere: a recording would be written
    into) or that holds files `batch` did not write (it replaces take folders whole)."""
    session = next((p for p in (out, *out.parents) if (p / "session.json").is_file()), None)
    if session is not None:
        what = (
            f"the take {session.relative_to(study).as_posix() or study.name!r} of the study"
            if session == study or study in session.parents
            else "a session"
        )
        raise ConfigError(
            f"batch: the results folder {out} is or lies inside {session}, {what}, which "
            "would not be tracked or would be written into; give a results folder outside "
            "every session"
        )
    check_own_folder(out, (STUDY_FILE,), "results folder", "mocapkit batch")


def _check_take_folders(out: Path, takes: Sequence[Take]) -> None:
    """Refuse, before any work, a take's result folder that holds something else than a
    result (it would be replaced whole)."""
    from mocapkit.pipelines.run import RESULT_MARKER_FILE

    for t in takes:
        check_own_folder(
            out / t.name, (TAKE_FILE, RESULT_MARKER_FILE), "take result folder", "mocapkit batch"
        )


def batch(
    study_dir: str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    method: str = AUTO,
    *,
    markers_glob: str | None = None,
    marker_sets: Sequence[str] = (),
    joints: str = "upper",
    force: bool = False,
    scheduler: str | None = None,
    client: Any = None,
    n_workers: int | None = None,
    processes: bool = True,
    stream: TextIO | None = None,
    say: Callable[[str], None] = lambda _line: None,
) -> StudyResult:
    """Track and evaluate every take of a study on Dask; write result folders and ``study.csv``.

    Parameters
    ----------
    study_dir : path
        Folder searched (at any depth) for sessions (folders with ``session.json``).
    out_dir : path
        Results folder: ``OUT/<take>/`` per take (result files, ``eval.json`` where the
        session has truth, ``take.json``) and ``OUT/study.csv``.
    method : str
        A method of `mocapkit.pipelines.registry.TRACKERS` or ``"auto"`` (chosen per
        session, `mocapkit.pipelines.registry.choose_method`).
    markers_glob : str, optional
        Also track raw marker files matching this pattern (relative to ``study_dir``)
        with the hybrid tracker's IK; needs ``marker_sets``.
    marker_sets : sequence of str
        ``name=M1+M2`` specs for ``head``, ``left_hand``, ``right_hand`` (as ``mocapkit
        track hybrid --markers F --marker-set ...``), the same for every marker file.
    joints : str
        Joints evaluated against truth (`mocapkit.eval.metrics.joint_subset`).
    force : bool
        Redo takes whose result folder is complete.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``); its workers must
        have mocapkit installed and see the study and results folders at the same paths.
    client : distributed.Client, optional
        A client to use as it is (a notebook's); neither started nor closed here.
    n_workers : int, optional
        Workers of the local cluster started when neither ``client`` nor ``scheduler``
        is given (default `default_workers`), one thread each.
    processes : bool
        Local cluster workers as processes (default) or threads of this process.
    stream : file-like, optional
        Where the progress line goes (default stderr; shown on a terminal only).
    say : callable, optional
        Receives one-line notices (the dashboard address, takes skipped).

    Returns
    -------
    StudyResult
        Rows in take order; ``n_failed`` takes failed (their ``error`` says why).

    Notes
    -----
    With ``auto``, the method chosen is recorded in each take's row; a complete take is not
    redone when a tracker installed since would change the choice (``force`` or an
    explicit ``method`` redoes it).

    Raises
    ------
    UnknownNameError, ConfigError
        Unknown or unavailable method, options that do not go together.
    SessionError
        No study folder or no take in it.
    """
    start = time.perf_counter()
    if method != AUTO:
        session_tracker(method)  # unknown or unavailable: fail before any work
    if bool(markers_glob) != bool(marker_sets):
        raise ConfigError(
            "batch: --markers-glob and --marker-set go together (raw marker files need "
            "the marker sets to track)"
        )
    if markers_glob and method not in (AUTO, "hybrid"):
        raise ConfigError(
            f"batch: raw marker files (--markers-glob) are tracked by hybrid IK, not {method}"
        )
    if marker_sets:
        from mocapkit.io.marker_sets import parse_marker_sets

        parse_marker_sets(list(marker_sets))  # a bad spec fails here, not in every take
    from mocapkit.eval.metrics import joint_subset

    joint_subset(joints)
    out = Path(out_dir).resolve()
    if out == Path(study_dir).resolve():
        raise ConfigError(f"batch: the results folder {out_dir} is the study folder; give another")
    _check_results_folder(out, Path(study_dir).resolve())
    takes = discover_takes(study_dir, markers_glob, exclude=[out])
    if not takes:
        raise SessionError(
            f"{study_dir}: no take found (no folder with session.json"
            + (f", no file matching {markers_glob!r})" if markers_glob else ")")
        )
    _check_take_folders(out, takes)
    options = {"method": method, "joints": joints}
    rows: dict[str, TakeRow] = {}
    jobs: list[TakeJob] = []
    # what a killed run may have left: temporaries of the table and of result folders
    remove_stale_temporaries(out, STUDY_FILE)
    for take in takes:
        remove_stale_temporaries((out / take.name).parent, Path(take.name).name)
        opts = {**options, **({"marker_sets": list(marker_sets)} if take.kind == "markers" else {})}
        old = None if force else completed_row(take, out, opts)
        if old is not None:
            rows[take.name] = replace(old, status="skipped")
        else:
            rows[take.name] = TakeRow(take.name, take.kind)
            jobs.append(TakeJob(take, out, opts))
    study_csv = out / STUDY_FILE

    def ordered() -> list[TakeRow]:
        return [rows[t.name] for t in takes]

    n_skipped = len(takes) - len(jobs)
    if n_skipped:
        say(f"{n_skipped} of {len(takes)} takes complete from an earlier run: skipped")
    write_study_csv(study_csv, ordered())
    dashboard = ""
    if jobs:
        with _dask_client(client, scheduler, n_workers, processes) as dask_client:
            from distributed import as_completed

            dashboard = _dashboard(dask_client)
            say(
                f"dask dashboard: {dashboard}"
                if dashboard
                else "dask dashboard: none (pip install 'mocapkit[dashboard]' adds it)"
            )
            token = uuid.uuid4().hex[:8]
            futures = {
                dask_client.submit(run_take, job, key=f"mocapkit-take-{token}-{i}", pure=False): job
                for i, job in enumerate(jobs)
            }
            n_failed = 0
            with Progress(
                len(jobs),
                "batch",
                stream=stream,
                min_interval_s=0.0,
                unit="takes",
                rate_unit="takes/min",
                rate_scale=60.0,
            ) as prog:
                prog.status = f"0 failed, {len(jobs)} remaining"
                prog.update(0)  # the line shows from the start, not from the first take
                try:
                    for future in as_completed(futures):
                        job = futures[future]
                        try:
                            row = future.result()
                        except Exception as exc:  # the worker died (killed, out of memory)
                            row = TakeRow(
                                job.take.name,
                                job.take.kind,
                                status="failed",
                                error=" ".join(f"{type(exc).__name__}: {exc}".split()),
                            )
                        rows[row.take] = row
                        n_failed += row.status == "failed"
                        write_study_csv(study_csv, ordered())
                        prog.status = f"{n_failed} failed, {len(jobs) - prog.done - 1} remaining"
                        prog.update()
                except KeyboardInterrupt:
                    _quiet_cluster_shutdown(dask_client, own=client is None and not scheduler)
                    finished = sum(r.status in ("done", "failed") for r in rows.values())
                    say(
                        f"interrupted: {finished} of {len(jobs)} takes finished "
                        f"({n_failed} failed) and are in {study_csv}; the next run redoes "
                        f"the {len(jobs) - finished} pending"
                    )
                    raise
    result_rows = ordered()
    counts = {
        s: sum(r.status == s for r in result_rows) for s in ("done", "poor", "skipped", "failed")
    }
    return StudyResult(result_rows, study_csv, time.perf_counter() - start, dashboard, counts)


__all__ = [
    "STUDY_COLUMNS",
    "TAKE_FILE",
    "StudyResult",
    "Take",
    "TakeRow",
    "batch",
    "discover_takes",
    "run_take",
]
