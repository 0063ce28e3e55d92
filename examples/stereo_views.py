"""The stereo tracker with two, three and four views of the same synthetic sessions.

Renders three 4 s excerpts (13_26 from 7.5 s, 01_12 from 5 s, charleston1 from 0 s) with
the four-camera rig (``mocapkit synth CLIP --rig multi --sleeve long``: ``stereo_left``,
``stereo_right``, ``mono`` and ``side``), tracks each in the accuracy study's
``keypoints+torso`` mode with the stereo pair, + mono, + side, and mono and side alone
(a wide two-view baseline), and prints the arm mean error (mm) of each.

Usage::

    .venv/bin/python examples/stereo_views.py [--work /tmp/stereo-views] [--seed 0]
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

from mocapkit.pipelines.demo import find_shared_data
from mocapkit.pipelines.stereo import ACCURACY_MODES, evaluate_stereo, track_stereo_session
from mocapkit.synth.session_writer import SynthOptions, synthesize_session

CLIPS = (("13_26.bvh", 7.5), ("01_12.amc", 5.0), ("charleston1.amc", 0.0))
VIEWS = (
    "stereo_left,stereo_right",
    "stereo_left,stereo_right,mono",
    "stereo_left,stereo_right,mono,side",
    "mono,side",
)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, default=Path("/tmp/stereo-views"))
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    shared = find_shared_data()
    if shared is None:
        raise SystemExit("../shared/data not found")
    cfg = replace(ACCURACY_MODES["keypoints+torso"], seed=args.seed)
    print("clip             " + " | ".join(VIEWS))
    for clip, start in CLIPS:
        session = args.work / f"{Path(clip).stem}_{start:g}s"
        if not (session / "truth.npz").is_file():
            synthesize_session(
                str(shared / "mocap" / clip),
                session,
                SynthOptions(
                    rig="multi", start_s=start, seconds=4.0, sleeve="long", overwrite=True
                ),
            )
        errors = []
        for cams in VIEWS:
            run = track_stereo_session(session, None, cameras=cams, config=cfg)
            errors.append(f"{evaluate_stereo(run, session)['arm_mean_mm']:.1f}")
        print(f"{clip:<16} " + " | ".join(errors), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
