"""`track mono`'s memory is flat with the recording's length: the run keeps each frame's
result in compact columns (`ResultTable`, `MonoFrames`), not the per-frame objects, and
the writers work through the frames in chunks."""

from __future__ import annotations

import tracemalloc
from pathlib import Path

from mocapkit.pipelines.mono import track_mono
from mocapkit.pipelines.mono_frames import MonoFrames
from mocapkit.pipelines.result_table import ResultTable
from mocapkit.tracking.mono.tracker import MonoConfig
from tests.pipelines.test_mono import _session

#: Offline, the most frames left open (the default is 300: shorter here, so that both
#: runs are longer than it and the tracker's own memory is the same in both).
WINDOW = 30


def _peak_bytes(tmp_path: Path, n: int) -> int:
    """Peak of Python-allocated memory over a whole `track_mono` run of ``n`` frames
    (session read, tracking, result folder written), above what was held before."""
    session = _session(tmp_path / f"s{n}", lengths=True, n=n)
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        run = track_mono(
            session, tmp_path / f"r{n}", use_session_lengths=True, config=MonoConfig(window=WINDOW)
        )
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    assert run.motion.n_frames == len(run.frames) == len(run.results) == n
    assert isinstance(run.results, ResultTable) and isinstance(run.frames, MonoFrames)
    return peak


def test_track_mono_keeps_compact_columns_per_frame(tmp_path: Path) -> None:
    """Four times the frames: the whole run's peak grows by under 2.5 kB a frame (the
    inputs, the result columns and the motion: 2.1 kB here; with the per-frame result
    objects it was 2.9 kB at these lengths and 3.7 kB at 150 and 600 frames), so a
    2-minute session's process grows by a few MB on some 215 MB."""
    _peak_bytes(tmp_path, 20)  # compile and warm up
    short = _peak_bytes(tmp_path, 60)
    long = _peak_bytes(tmp_path, 240)
    assert (long - short) / 180 < 2500
