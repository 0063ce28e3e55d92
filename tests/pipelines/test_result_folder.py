"""A result folder is swapped in whole (issue 14): a kill or an error mid-write leaves the
earlier folder byte-identical, and the next run clears what the killed one left."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from mocapkit.errors import ConfigError
from mocapkit.io.motion_npz import load_motion_npz
from mocapkit.pipelines.run import FIT_FILE, run_tracker
from mocapkit.skeleton import canonical_positions, load_preset
from mocapkit.tracking.base import FrameResult, canonical_joints_mm

RESULT_FILES = {
    "motion.npz",
    "joints.csv",
    "motion.bvh",
    FIT_FILE,
    "opensim/markers.trc",
    "opensim/model.osim",
    "opensim/ik_setup.xml",
}


class Replay:
    def __init__(self, skeleton):
        self.skeleton = skeleton

    def update(self, sample):
        t, q = sample
        joints = canonical_joints_mm(self.skeleton, canonical_positions(self.skeleton, q))
        return FrameResult(t, q, joints, {"head": "seen"}, {}, "")


def _poses(seed: int, n: int = 5):
    sk = load_preset("upper_stick")
    rng = np.random.default_rng(seed)
    q = np.clip(rng.normal(0.0, 0.2, (n, sk.n_dofs)), sk.lower, sk.upper)
    return sk, np.arange(n) * 0.02, q


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()
    }


def _write(out: Path, seed: int) -> None:
    sk, t, q = _poses(seed)
    run_tracker(Replay(sk), zip(t, q), len(t), out)


def test_a_writer_failing_midway_leaves_the_earlier_folder_byte_identical(
    tmp_path, monkeypatch
) -> None:
    import mocapkit.io.motion_files as motion_files

    out = tmp_path / "res"
    _write(out, 1)
    before = _snapshot(out)
    assert set(before) == RESULT_FILES

    def crash(*_args, **_kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(motion_files, "write_bvh", crash)  # after motion.npz and joints.csv
    with pytest.raises(OSError, match="No space left"):
        _write(out, 2)
    assert _snapshot(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]  # no temporary left


_KILLED_RUN = textwrap.dedent(
    """
    import os, signal, sys
    import numpy as np
    import mocapkit.io.motion_files as motion_files
    from tests.pipelines.test_result_folder import _write

    def die(*_args, **_kwargs):  # motion.npz and joints.csv are written by now
        os.kill(os.getpid(), signal.SIGKILL)

    motion_files.write_bvh = die
    _write(__import__("pathlib").Path(sys.argv[1]), 2)
    """
)


def test_sigkill_midwrite_keeps_the_earlier_folder_and_the_next_run_cleans_up(tmp_path) -> None:
    out = tmp_path / "res"
    _write(out, 1)
    before = _snapshot(out)
    root = Path(__file__).resolve().parents[2]
    proc = subprocess.run(
        [sys.executable, "-c", _KILLED_RUN, str(out)],
        cwd=root,
        env={**os.environ, "PYTHONPATH": str(root)},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        timeout=300,
    )
    assert proc.returncode == -signal.SIGKILL, proc.stderr.decode()[-2000:]
    assert _snapshot(out) == before
    stale = [p.name for p in tmp_path.iterdir() if p.name != "res"]
    assert len(stale) == 1 and stale[0].startswith(".res.new-")
    assert {p.name for p in (tmp_path / stale[0]).iterdir()} == {"motion.npz", "joints.csv"}
    _write(out, 3)  # the next run
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]
    _sk, _t, q3 = _poses(3)
    np.testing.assert_array_equal(load_motion_npz(out / "motion.npz").q, q3)


def test_an_existing_result_folder_is_replaced_whole(tmp_path) -> None:
    out = tmp_path / "res"
    _write(out, 1)
    (out / "report").mkdir()
    (out / "report" / "index.html").write_text("<html>old result</html>")
    _write(out, 2)
    assert set(_snapshot(out)) == RESULT_FILES  # the old report went with it
    _sk, _t, q2 = _poses(2)
    np.testing.assert_array_equal(load_motion_npz(out / "motion.npz").q, q2)


def test_a_folder_that_is_not_a_result_is_refused_before_the_work(tmp_path) -> None:
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    sk, t, q = _poses(1)
    drawn = []

    def samples():
        for s in zip(t, q):
            drawn.append(s)
            yield s

    refused = r"mine: .*not a result folder \(no motion.npz; it holds notes.txt\)"
    with pytest.raises(ConfigError, match=refused):
        run_tracker(Replay(sk), samples(), len(t), out)
    assert drawn == []  # refused before any sample was tracked
    assert (out / "notes.txt").read_text() == "keep me"
    empty = tmp_path / "empty"
    empty.mkdir()
    run_tracker(Replay(sk), zip(t, q), len(t), empty)
    assert set(_snapshot(empty)) == RESULT_FILES


def test_ctrl_c_during_track_exits_130_and_keeps_the_earlier_result(
    tmp_path, monkeypatch, capsys
) -> None:
    """`mocapkit track mono` interrupted while writing: "interrupted", exit 130, the
    earlier result byte-identical and no temporaries (issue 14, "fine as it is")."""
    import mocapkit.io.motion_files as motion_files
    from mocapkit.cli.main import main
    from tests.pipelines.test_mono import _session

    session = _session(tmp_path / "s", lengths=True)
    out = tmp_path / "r"
    argv = ["track", "mono", str(session), "--out", str(out), "--session-lengths"]
    assert main(argv) == 0
    before = _snapshot(out)
    capsys.readouterr()

    def ctrl_c(*_args, **_kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(motion_files, "write_bvh", ctrl_c)
    assert main([*argv, "--lag", "3"]) == 130
    assert "mocapkit track: interrupted" in capsys.readouterr().err
    assert _snapshot(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r", "s"]
