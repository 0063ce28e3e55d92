"""The hybrid benchmark's sessions tracked again with markers moved by round-off amounts.

The shipped tracker is chaotic in round-off (docs/hybrid.md, Speed, fifth round): moving
every marker by 1e-6 mm changes which frames the balance step leans, and with it the
balance stage's time. One run of ``mocapkit bench hybrid`` is therefore one draw. This
script tracks the benchmark's sessions (`mocapkit.pipelines.bench.bench_sessions`) and
``--copies`` jittered copies of them (`mocapkit.pipelines.accuracy.jitter_session`,
seeded) with the default configuration, as the benchmark does (a warm-up, OpenCV on one
thread, process CPU time), and prints frames per CPU second and the balance and IK
stages' CPU ms a frame for each copy and repeat, then the mean and range over copies.

Run from the repository root (so that ``../shared/data/mocap`` is found)::

    python bench/hybrid_jitter.py [--copies 4] [--repeats 2] [--jitter-mm 1e-6]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from mocapkit.pipelines.accuracy import jitter_session
from mocapkit.pipelines.bench import bench_sessions
from mocapkit.pipelines.hybrid import track_hybrid_session_run
from mocapkit.timing import StageTimer


def main() -> None:
    """Parse the arguments, track each copy, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--copies", type=int, default=4, help="jittered copies (default 4)")
    parser.add_argument("--repeats", type=int, default=2, help="timed runs a copy (default 2)")
    parser.add_argument("--jitter-mm", type=float, default=1e-6, help="half-width, mm")
    parser.add_argument(
        "--work",
        type=Path,
        default=Path(tempfile.gettempdir()) / "mocapkit-bench-hybrid",
        help="the benchmark's cache folder (as `mocapkit bench hybrid --work`)",
    )
    args = parser.parse_args()
    sessions = bench_sessions(args.work / "sessions")
    cv2.setNumThreads(1)
    means = []
    with tempfile.TemporaryDirectory(prefix="mocapkit-jitter-") as tmp:
        track_hybrid_session_run(sessions[0], Path(tmp) / "warm")  # compile, warm up
        for copy in range(args.copies + 1):
            if copy == 0:
                label, copies = "plain", sessions
            else:
                label = f"copy {copy}"
                copies = [
                    jitter_session(
                        s,
                        Path(tmp) / f"c{copy}" / s.name,
                        args.jitter_mm,
                        np.random.default_rng([copy, i]),
                    )
                    for i, s in enumerate(sessions)
                ]
            fps = []
            for rep in range(args.repeats):
                timer = StageTimer(clock=time.process_time)
                c0, frames = time.process_time(), 0
                for s in copies:
                    out = Path(tmp) / f"r{copy}_{rep}_{s.name}"
                    frames += track_hybrid_session_run(s, out, timer=timer).motion.n_frames
                fps.append(frames / (time.process_time() - c0))
                t = timer.totals_s()
                print(
                    f"{label:7s} repeat {rep}: {fps[-1]:6.1f} frames/s, balance "
                    f"{1e3 * t.get('balance', 0.0) / frames:.2f} ms, ik "
                    f"{1e3 * t.get('ik', 0.0) / frames:.2f} ms a frame",
                    flush=True,
                )
            if copy > 0:
                means.append(float(np.median(fps)))
    if means:
        print(
            f"jittered copies: mean {np.mean(means):.1f} frames/s "
            f"(medians over repeats {min(means):.1f}-{max(means):.1f})"
        )


if __name__ == "__main__":
    main()
