"""Batch processing of a study on Dask: take discovery, method registry, resuming, failures."""

from __future__ import annotations

import csv
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import ConfigError, SessionError, UnknownNameError
from mocapkit.pipelines import registry
from mocapkit.pipelines.batch import (
    STUDY_COLUMNS,
    STUDY_FILE,
    TAKE_FILE,
    Take,
    TakeJob,
    batch,
    completed_row,
    discover_takes,
    run_take,
    source_fingerprint,
)

TAKES = ("s1/t1", "s1/t2", "s2/deep/t3", "s3/t4")


def _render(folder: Path, seed: int, rig: str = "mono") -> None:
    from mocapkit.synth.session_writer import SynthOptions, synthesize_session

    # 0.5 s into the wave the arm is rising; 7 frames at 96x72 px keep a take well under 1 s
    options = SynthOptions(rig=rig, start_s=0.5, seconds=0.2, image_size=(96, 72), seed=seed)
    synthesize_session("builtin:wave", folder, options)


@pytest.fixture(scope="module")
def rendered(tmp_path_factory) -> Path:
    """Four tiny sessions at different depths, rendered once; tests copy them."""
    root = tmp_path_factory.mktemp("rendered")
    for i, name in enumerate(TAKES):
        _render(root / name, seed=i)
    return root


@pytest.fixture
def study(rendered, tmp_path) -> Path:
    dst = tmp_path / "study"
    shutil.copytree(rendered, dst)
    return dst


@pytest.fixture(scope="module")
def client():
    """An in-process Dask cluster (threads, inproc transport: no network)."""
    from distributed import Client

    with Client(processes=False, n_workers=2, threads_per_worker=1, dashboard_address=None) as c:
        yield c


def _read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert rows and tuple(rows[0]) == STUDY_COLUMNS
    return rows


def _break(session: Path) -> None:
    """Cut the session's video off after 2 KB, as a failed copy would."""
    video = session / "video" / "mono.mp4"
    with open(video, "r+b") as fh:
        fh.truncate(2048)


# ---------------------------------------------------------------- discovery


def test_discover_takes_at_any_depth_skipping_results_and_temporaries(study):
    (study / "results").mkdir()
    shutil.copytree(study / "s1" / "t1", study / "results" / "s1" / "t1")
    shutil.copytree(study / "s1" / "t1", study / "s1" / ".t1.new-abc")  # an atomic temporary
    takes = discover_takes(study, exclude=[study / "results"])
    assert [t.name for t in takes] == sorted(TAKES)
    assert all(t.kind == "session" and t.source == (study / t.name).resolve() for t in takes)


def test_discover_takes_through_linked_folders_without_looping(tmp_path):
    """A study of links to sessions stored elsewhere: the links are followed, a link to a
    folder above is no loop, a session linked twice is one take (the first link by name)."""
    store, study = tmp_path / "store", tmp_path / "study"
    for name in ("a", "b", "c"):
        (store / name).mkdir(parents=True)
        (store / name / "session.json").write_text("{}")
    (study / "group").mkdir(parents=True)
    (study / "x").symlink_to(store / "a", target_is_directory=True)
    (study / "again").symlink_to(store / "a", target_is_directory=True)
    (study / "group" / "y").symlink_to(store / "b", target_is_directory=True)
    (study / "group" / "up").symlink_to(study, target_is_directory=True)  # a loop
    (study / "out").mkdir()
    (study / "out" / "c").symlink_to(store / "c", target_is_directory=True)
    takes = discover_takes(study, exclude=[study / "out"])
    assert [(t.name, t.source) for t in takes] == [
        ("again", study.resolve() / "again"),
        ("group/y", study.resolve() / "group" / "y"),
    ]


def test_discover_marker_files_but_not_those_inside_sessions(study):
    from mocapkit.io.marker_files import read_markers, write_markers

    markers = read_markers(study / "s1" / "t1" / "markers.csv")
    write_markers(study / "s2" / "raw" / "trial9.trc", markers)
    takes = discover_takes(study, markers_glob="**/*.[ct][sr][vc]")
    kinds = {t.name: t.kind for t in takes}
    assert kinds == {**dict.fromkeys(TAKES, "session"), "s2/raw/trial9": "markers"}
    write_markers(study / "s2" / "raw" / "trial9.csv", markers)
    with pytest.raises(SessionError, match="would share the result folder 's2/raw/trial9'"):
        discover_takes(study, markers_glob="**/*.[ct][sr][vc]")


def test_no_study_or_no_take(tmp_path):
    with pytest.raises(SessionError, match="study folder not found"):
        discover_takes(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(SessionError, match="no take found"):
        batch(tmp_path / "empty", tmp_path / "out")


# ---------------------------------------------------------------- registry


def test_registry_names_and_availability(monkeypatch):
    monkeypatch.setattr(registry, "TRACKERS", dict(registry.TRACKERS))
    assert "hybrid" in registry.available_methods()
    assert registry.session_tracker("hybrid").__name__ == "track_hybrid_session"
    with pytest.raises(UnknownNameError, match="unknown tracking method 'kalman'.*hybrid"):
        registry.session_tracker("kalman")
    registry.register_tracker("absent", "mocapkit.pipelines.no_such_module:track")
    with pytest.raises(ConfigError, match="absent tracker is not available.*not part of"):
        registry.session_tracker("absent")
    registry.register_tracker("nofunc", "mocapkit.pipelines.hybrid:no_such_function")
    with pytest.raises(ConfigError, match="hybrid has no function no_such_function"):
        registry.session_tracker("nofunc")
    with pytest.raises(ConfigError, match="'module:function'"):
        registry.register_tracker("bad", "mocapkit.pipelines.hybrid")
    with pytest.raises(ConfigError, match="not 'auto'"):
        registry.register_tracker("auto", "a:b")


def test_auto_picks_by_what_the_session_holds(study, tmp_path, monkeypatch):
    monkeypatch.setattr(registry, "TRACKERS", dict(registry.TRACKERS))
    for m in ("stereo", "mono"):
        registry.register_tracker(m, f"mocapkit.pipelines.no_{m}:track")
    hybrid = study / "s1" / "t1"
    assert registry.candidate_methods(hybrid)[0] == ("hybrid", "mono")
    assert registry.choose_method(hybrid) == "hybrid"
    # one camera, no markers: mono, which this test makes unavailable
    (hybrid / "markers.csv").unlink()
    assert registry.candidate_methods(hybrid) == (("mono",), "1 camera with video, no markers")
    with pytest.raises(ConfigError, match=r"auto chose mono \(1 camera with video, no markers\)"):
        registry.choose_method(hybrid)
    registry.register_tracker("mono", lambda session, out: None)
    assert registry.choose_method(hybrid) == "mono"
    # a stereo pair without markers: stereo first, mono (first camera) as the fall-back
    pair = tmp_path / "pair"
    _render(pair, seed=5, rig="stereo")
    (pair / "markers.csv").unlink()
    assert registry.candidate_methods(pair)[0] == ("stereo", "mono")
    assert registry.choose_method(pair) == "mono"
    registry.register_tracker("stereo", lambda session, out: None)
    assert registry.choose_method(pair) == "stereo"
    # no video at all
    shutil.rmtree(pair / "video")
    with pytest.raises(SessionError, match="no tracking method fits"):
        registry.choose_method(pair)


# ---------------------------------------------------------------- one take


def test_run_take_writes_a_complete_folder_and_a_failed_row(study, tmp_path):
    out = tmp_path / "out"
    opts = {"method": "auto", "joints": "upper"}
    take = Take("s1/t1", "session", (study / "s1" / "t1").resolve())
    row = run_take(TakeJob(take, out, opts))
    assert row.status == "done" and row.method == "hybrid" and row.frames == 7
    assert row.coverage == 1.0 and np.isfinite([row.fit_px, row.mpjpe_mm, row.elbow_mm]).all()
    folder = out / "s1" / "t1"
    assert sorted(p.name for p in folder.iterdir()) == sorted(
        ["eval.json", "fit.csv", "joints.csv", "motion.bvh", "motion.npz", "opensim", TAKE_FILE]
    )
    doc = json.loads((folder / TAKE_FILE).read_text())
    assert doc["source"] == str(take.source) and doc["row"]["mpjpe_mm"] == row.mpjpe_mm
    assert json.loads((folder / "eval.json").read_text())["mpjpe_mm"] == pytest.approx(row.mpjpe_mm)
    assert completed_row(take, out, opts) == row
    # what makes it incomplete: other options, a changed source, a lost or cut file
    assert completed_row(take, out, {**opts, "joints": "all"}) is None
    before = source_fingerprint(take.source)
    os.utime(take.source / "markers.csv", ns=(1, 1))
    assert source_fingerprint(take.source) != before
    assert completed_row(take, out, opts) is None
    row = run_take(TakeJob(take, out, opts))
    assert completed_row(take, out, opts) == row
    (folder / "motion.bvh").write_text("cut")
    assert completed_row(take, out, opts) is None
    (folder / TAKE_FILE).write_text("{not json")
    assert completed_row(take, out, opts) is None
    # a broken take comes back as a row with its error; its old result stays whole
    _break(take.source)
    failed = run_take(TakeJob(take, out, opts))
    assert failed.status == "failed" and failed.frames == 0
    assert "SessionError" in failed.error and "mono.mp4" in failed.error
    assert (folder / "motion.npz").is_file() and not list((out / "s1").glob(".t1.*"))


# ---------------------------------------------------------------- the study on Dask


def test_batch_on_an_in_process_cluster(study, tmp_path, client):
    out = tmp_path / "results"
    _break(study / "s3" / "t4")
    lines: list[str] = []
    result = batch(study, out, "auto", client=client, say=lines.append)
    assert [r.take for r in result.rows] == sorted(TAKES)
    assert result.n_failed == 1 and result.counts == {
        "done": 3,
        "poor": 0,
        "skipped": 0,
        "failed": 1,
    }
    # an address where bokeh is installed, else a line saying there is none
    assert len(lines) == 1 and lines[0].startswith("dask dashboard: ")
    table = {r["take"]: r for r in _read_csv(out / "study.csv")}
    assert table["s3/t4"]["status"] == "failed" and "mono.mp4" in table["s3/t4"]["error"]
    assert table["s3/t4"]["frames"] == "" and table["s3/t4"]["mpjpe_mm"] == ""
    for name in TAKES[:3]:
        row = table[name]
        assert row["status"] == "done" and row["method"] == "hybrid" and row["frames"] == "7"
        assert float(row["mpjpe_mm"]) > 0 and row["error"] == ""
        # each folder holds its own take's motion, nothing mixed
        doc = json.loads((out / name / TAKE_FILE).read_text())
        assert doc["take"] == name and doc["source"] == str((study / name).resolve())
    assert not (out / "s3" / "t4").exists()

    # again: complete takes are skipped (not even sent), the failed one is tried again
    stamp = {n: (out / n / TAKE_FILE).stat().st_mtime_ns for n in TAKES[:3]}
    again = batch(study, out, "auto", client=client)
    assert again.counts == {"done": 0, "poor": 0, "skipped": 3, "failed": 1}
    assert {n: (out / n / TAKE_FILE).stat().st_mtime_ns for n in TAKES[:3]} == stamp
    assert [r.mpjpe_mm for r in again.rows[:3]] == [r.mpjpe_mm for r in result.rows[:3]]
    # the explicit method is another option set: redone; --force redoes the rest
    shutil.rmtree(study / "s3")
    forced = batch(study, out, "hybrid", client=client)
    assert forced.counts == {"done": 3, "poor": 0, "skipped": 0, "failed": 0}
    assert batch(study, out, "hybrid", client=client, force=True).counts["done"] == 3


def test_batch_option_errors(study, tmp_path, monkeypatch):
    monkeypatch.setattr(registry, "TRACKERS", dict(registry.TRACKERS))
    registry.register_tracker("stereo", "mocapkit.pipelines.no_stereo:track")
    out = tmp_path / "out"
    with pytest.raises(ConfigError, match="--method stereo: the stereo tracker is not available"):
        batch(study, out, "stereo")
    with pytest.raises(ConfigError, match="--markers-glob and --marker-set go together"):
        batch(study, out, markers_glob="**/*.c3d")
    registry.register_tracker("stereo", lambda session, out: None)
    with pytest.raises(ConfigError, match="tracked by hybrid IK, not stereo"):
        batch(study, out, "stereo", markers_glob="*.c3d", marker_sets=["head=A"])
    with pytest.raises(ValueError, match="head"):
        batch(study, out, "hybrid", markers_glob="*.c3d", marker_sets=["head"])
    assert not out.exists()


# ---------------------------------------------------------------- killed and resumed


def _swapped_in(out):
    """Takes whose result folder is in place: a ``take.json`` still inside a folder being
    built (``.NAME.new-*``, hidden) is not a finished take, and a kill then deletes it.
    The running batch renames and removes such folders while the tree is walked: a walk
    that meets one vanishing is taken again."""
    while True:
        try:
            found = [p.parent.relative_to(out) for p in out.glob(f"**/{TAKE_FILE}")]
        except FileNotFoundError:
            continue
        return sorted(r.as_posix() for r in found if not any(s.startswith(".") for s in r.parts))


def test_killed_run_resumes_without_redoing_or_mixing(study, tmp_path):
    from mocapkit.cli.main import main

    out = tmp_path / "results"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    cmd = [sys.executable, "-m", "mocapkit.cli.main", "batch", str(study), "--out", str(out)]
    # one worker thread: takes finish one after another, so the kill lands between them
    proc = subprocess.Popen(
        [*cmd, "--workers", "1", "--in-process"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 300.0
        while not _swapped_in(out):
            assert proc.poll() is None, "the batch ended before any take completed"
            assert time.monotonic() < deadline, "no take completed within 300 s"
            time.sleep(0.02)
        os.killpg(proc.pid, signal.SIGKILL)
    finally:
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
    finished = _swapped_in(out)
    assert 1 <= len(finished) < len(TAKES), "the kill came after the last take"
    table = {r["take"]: r["status"] for r in _read_csv(out / "study.csv")}
    assert set(table) == set(TAKES) and "pending" in table.values()
    kept = {n: (out / n / TAKE_FILE).read_bytes() for n in finished}
    inode = {n: (out / n / "motion.npz").stat().st_ino for n in finished}

    code = main(["batch", str(study), "--out", str(out), "--workers", "2", "--in-process"])
    assert code == 0
    table = {r["take"]: r["status"] for r in _read_csv(out / "study.csv")}
    assert table == {n: "skipped" if n in finished else "done" for n in TAKES}
    for n in finished:  # not redone: the very same files
        assert (out / n / TAKE_FILE).read_bytes() == kept[n]
        assert (out / n / "motion.npz").stat().st_ino == inode[n]
    from mocapkit.io.motion_npz import load_motion_npz

    for n in TAKES:
        doc = json.loads((out / n / TAKE_FILE).read_text())
        assert doc["take"] == n and doc["source"] == str((study / n).resolve())
        assert load_motion_npz(out / n / "motion.npz").source.endswith(str((study / n).resolve()))
    leftovers = [p for p in out.rglob(".*")]
    assert leftovers == [], leftovers


def test_cli_exit_code_counts_failed_takes(study, tmp_path, capsys):
    from mocapkit.cli.main import main

    _break(study / "s1" / "t2")
    _break(study / "s3" / "t4")
    for name in ("s1/t1", "s2/deep/t3"):
        shutil.rmtree(study / name)
    code = main(["batch", str(study), "--out", str(tmp_path / "out"), "--in-process"])
    assert code == 2
    printed = capsys.readouterr().out
    assert "2 takes: 0 done, 0 skipped, 2 failed" in printed
    # --scheduler: an existing cluster (here an in-process one, reached by its address)
    from distributed import LocalCluster

    with LocalCluster(
        processes=False, n_workers=1, threads_per_worker=1, dashboard_address=None
    ) as cluster:
        args = ["batch", str(study), "--out", str(tmp_path / "out")]
        assert main([*args, "--scheduler", cluster.scheduler_address, "--force"]) == 2
    assert "2 takes: 0 done, 0 skipped, 2 failed" in capsys.readouterr().out
    assert main(["batch", str(study), "--out", str(study)]) == 2
    assert "is the study folder" in capsys.readouterr().err
    bad = ["batch", str(study), "--out", "x", "--scheduler", "tcp://h:1", "--workers", "2"]
    assert main(bad) == 2
    assert "size a local cluster, not --scheduler" in capsys.readouterr().err
    # bad values are usage errors, before any work
    for bad, says in (
        (["--workers", "0"], "argument --workers: expected an integer >= 1, found 0"),
        (["--joints", "knees"], "argument --joints: unknown canonical joint 'knees'"),
        (["--marker-set", "head"], "argument --marker-set: marker set 'head'"),
    ):
        with pytest.raises(SystemExit) as exc:
            main(["batch", str(study), "--out", str(tmp_path / "o"), *bad])
        assert exc.value.code == 2 and says in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_raw_marker_files_tracked_by_hybrid_ik(study, tmp_path, client):
    from mocapkit.io.marker_files import read_markers, write_markers

    markers = read_markers(study / "s1" / "t1" / "markers.csv")
    write_markers(study / "raw" / "serve.trc", markers)
    for name in TAKES[1:]:
        shutil.rmtree(study / name)
    sets = [
        "head=head+head_left+head_right",
        "left_hand=left_hand+left_hand_tip+left_hand_side",
        "right_hand=right_hand+right_hand_tip+right_hand_side",
    ]
    out = tmp_path / "out"
    result = batch(
        study, out, client=client, markers_glob="**/*.trc", marker_sets=sets, joints="all"
    )
    rows = {r.take: r for r in result.rows}
    raw = rows["raw/serve"]
    assert raw.kind == "markers" and raw.method == "hybrid" and raw.status == "done"
    # IK at the marker rate, no keypoints or truth to compare with
    assert raw.frames == markers.time_s.shape[0] and raw.coverage == 1.0
    assert np.isnan([raw.fit_px, raw.mpjpe_mm]).all()
    assert "serve.trc" in json.loads((out / "raw" / "serve" / TAKE_FILE).read_text())["source"]
    assert rows["s1/t1"].status == "done" and np.isfinite(rows["s1/t1"].mpjpe_mm)
    # other marker sets are other options: the marker take is redone, the session is not
    again = batch(
        study, out, client=client, markers_glob="**/*.trc", marker_sets=sets[::-1], joints="all"
    )
    assert {r.take: r.status for r in again.rows} == {"raw/serve": "done", "s1/t1": "skipped"}


# ---------------------------------------------------------------- bad input (issue 30)


def test_batch_refuses_a_folder_it_did_not_write_before_any_work(study, tmp_path, capsys):
    """`mocapkit batch STUDY --out DIR` deleted whatever DIR held (notes.txt, a thesis/
    folder): a folder that is not a results folder is refused, its files kept."""
    from mocapkit.cli.main import main

    mine = tmp_path / "mine"
    (mine / "thesis").mkdir(parents=True)
    (mine / "notes.txt").write_text("keep me")
    with pytest.raises(
        ConfigError,
        match=r"mine: mocapkit batch replaces its results folder "
        r"whole, but this folder is not a results folder \(no study.csv; it "
        r"holds notes.txt, thesis\)",
    ):
        batch(study, mine)
    assert main(["batch", str(study), "--out", str(mine), "--in-process"]) == 2
    assert "not a results folder" in capsys.readouterr().err
    assert sorted(p.name for p in mine.rglob("*")) == ["notes.txt", "thesis"]
    # a take's folder holding a user's files inside a results folder: refused too
    results = tmp_path / "results"
    (results / "s1" / "t1").mkdir(parents=True)
    (results / STUDY_FILE).write_text("take\n")
    (results / "s1" / "t1" / "notes.txt").write_text("keep me")
    with pytest.raises(ConfigError, match=r"t1: mocapkit batch replaces its take result folder"):
        batch(study, results)
    assert (results / "s1" / "t1" / "notes.txt").read_text() == "keep me"


def test_batch_out_inside_a_take_of_the_study_is_refused(study, tmp_path):
    """`batch --out study/a` silently dropped that subfolder's take."""
    for out in (study / "s1" / "t1", study / "s1" / "t1" / "results"):
        with pytest.raises(ConfigError, match=r"lies inside .*t1, the take 's1/t1' of the study"):
            batch(study, out)
    assert not (study / "s1" / "t1" / "results").exists()
    # a folder holding takes is not empty and holds no study.csv
    with pytest.raises(ConfigError, match=r"s1: mocapkit batch replaces its results folder"):
        batch(study, study / "s1")


def test_ctrl_c_stops_the_cluster_quietly_and_says_what_finished(study, tmp_path):
    """Ctrl-C in `batch` printed the Dask workers' tracebacks: the workers (separate
    processes, which the terminal's Ctrl-C reaches too) ignore it; the batch stops them,
    says what finished and exits 130."""
    out = tmp_path / "results"
    cmd = [sys.executable, "-m", "mocapkit.cli.main", "batch", str(study), "--out", str(out)]
    proc = subprocess.Popen(
        [*cmd, "--workers", "2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    try:
        deadline = time.monotonic() + 300.0
        while not any(out.glob(".*.new-*")) and not any(out.glob("*/.*.new-*")):
            assert proc.poll() is None, proc.stderr.read() if proc.stderr else ""
            assert time.monotonic() < deadline, "no take started within 300 s"
            time.sleep(0.05)
        os.killpg(proc.pid, signal.SIGINT)  # a take is running in a worker
        _, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130, err[-3000:]
    assert "Traceback" not in err and "WARNING" not in err, err[-3000:]
    assert re.search(r"interrupted: \d+ of 4 takes finished \(0 failed\) and are in .*study.csv",
                     err), err  # fmt: skip
    assert err.strip().splitlines()[-1] == "mocapkit batch: interrupted"
    table = {r["take"]: r["status"] for r in _read_csv(out / "study.csv")}
    assert set(table) == set(TAKES) and "pending" in table.values()
