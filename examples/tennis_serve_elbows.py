"""Hybrid IK on real Plug-in-Gait markers: elbow error against the LELB/RELB markers.

Reproduces the tennis-serve table in ``docs/hybrid.md``: the hybrid tracker's IK (no
video) driven by the head and wrist marker sets of ``kinematics_tennis_serve.c3d``, with
the feet planted or free and the relaxed-pose secondary task on (k = 0.3) or off.
The elbow markers sit on the skin over the lateral epicondyle, 30-40 mm from the joint
centre, so about 30 mm of each figure is the marker's own offset.

Usage::

    .venv/bin/python examples/tennis_serve_elbows.py [PATH/TO/kinematics_tennis_serve.c3d]

The default path is ``../shared/data/c3d/kinematics_tennis_serve.c3d`` from the repo root.
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from mocapkit.io.marker_files import read_markers
from mocapkit.pipelines.hybrid_markers import RAW_MARKERS_REPLANT_MM, track_hybrid_markers
from mocapkit.tracking.hybrid.tracker import TRACKING_IK, HybridConfig

MARKER_SETS = ["head=LFHD+RFHD+LBHD+RBHD", "left_hand=LWRA+LWRB", "right_hand=RWRA+RWRB"]


def main(path: Path) -> None:
    markers = read_markers(path)
    elbow_markers_mm = np.stack([markers.trajectory("LELB"), markers.trajectory("RELB")], axis=1)
    print("feet     secondary  mean L/R mm  median L/R mm")
    for plant_feet in (True, False):
        for gain in (0.3, 0.0):
            # the same configuration `mocapkit track hybrid --markers` uses, but for the gain
            config = HybridConfig(
                use_video=False,
                plant_feet=plant_feet,
                start_upright=False,
                replant_mm=RAW_MARKERS_REPLANT_MM,
                ik=replace(TRACKING_IK, secondary_gain=gain),
            )
            motion = track_hybrid_markers(path, MARKER_SETS, config=config)
            elbows_mm = np.stack([motion.joint("left_elbow"), motion.joint("right_elbow")], axis=1)
            err = np.linalg.norm(elbows_mm - elbow_markers_mm, axis=2)
            mean, median = np.nanmean(err, axis=0), np.nanmedian(err, axis=0)
            print(
                f"{'planted' if plant_feet else 'free':8s} {'on' if gain else 'off':9s}  "
                f"{mean[0]:4.0f} / {mean[1]:4.0f}  {median[0]:4.0f} / {median[1]:4.0f}"
            )


if __name__ == "__main__":
    default = Path("..") / "shared" / "data" / "c3d" / "kinematics_tennis_serve.c3d"
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else default)
