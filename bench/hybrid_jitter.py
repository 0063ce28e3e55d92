"""The hybrid benchmark's sessions tracked again with markers moved by round-off amounts.

The shipped tracker is chaotic in round-off (docs/hybrid.md, Speed, fifth round): moving
every marker by 1e-6 mm changes which frames the balance step leans, and with it the
balance stage's time. One run of ``mocapkit bench hybrid`` is therefore one draw. This
script runs that benchmark (`mocapkit.pipelines.bench.bench_hybrid`, the default
configuration) on its sessions (`mocapkit.pipelines.bench.bench_sessions`) and on
``--copies`` seeded jittered copies of them (`mocapkit.pipelines.accuracy.jitter_session`),
and prints frames per CPU second (median over ``--repeats``) and the balance and IK
stages' CPU ms a frame for each, then the mean and range over the copies.

Run from the repository root (so that ``../shared/data/mocap`` is found)::

    python bench/hybrid_jitter.py [--copies 4] [--repeats 2] [--jitter-mm 1e-6]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from mocapkit.pipelines.accuracy import jitter_session
from mocapkit.pipelines.bench import bench_hybrid, bench_sessions


def main() -> None:
    """Parse the arguments, bench each copy, print the table."""
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
    fps = []
    with tempfile.TemporaryDirectory(prefix="mocapkit-jitter-") as tmp:
        for copy in range(args.copies + 1):
            copies = sessions
            if copy > 0:
                copies = [
                    jitter_session(
                        s,
                        Path(tmp) / f"c{copy}" / s.name,
                        args.jitter_mm,
                        np.random.default_rng([copy, i]),
                    )
                    for i, s in enumerate(sessions)
                ]
            run = bench_hybrid(args.repeats, work_dir=args.work, sessions=copies)
            stages = run["stages_ms"]
            print(
                f"{'as rendered' if copy == 0 else f'copy {copy}':11s} {run['fps']:6.1f} "
                f"frames/s (min {run['fps_min']:.1f}), balance {stages['balance']:.2f} ms, "
                f"ik {stages['ik']:.2f} ms a frame",
                flush=True,
            )
            if copy > 0:
                fps.append(run["fps"])
    if fps:
        print(
            f"jittered copies: mean {np.mean(fps):.1f} frames/s "
            f"(medians over repeats {min(fps):.1f}-{max(fps):.1f})"
        )


if __name__ == "__main__":
    main()
