"""Hybrid IK on real Plug-in-Gait markers: elbow error against the LELB/RELB markers.

Reproduces README's tennis-serve row: the hybrid tracker's IK (no video), run as
``mocapkit track hybrid --markers`` runs it, on ``kinematics_tennis_serve.c3d`` with three
choices of marker sets: README's (head, and each wrist bar turned by its forearm marker),
the wrist bars alone, and README's with the pelvis and foot sets. The elbow markers sit on
the skin over the lateral epicondyle, 30-40 mm from the joint centre, so about 30 mm of
each figure is the marker's own offset.

Usage::

    .venv/bin/python examples/tennis_serve_elbows.py [PATH/TO/kinematics_tennis_serve.c3d]

The default path is ``c3d/kinematics_tennis_serve.c3d`` in ``$MOCAPKIT_SHARED_DATA``, else
in the first ``shared/data`` or ``../shared/data`` above this example (the repository).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from mocapkit.io.marker_files import read_markers
from mocapkit.pipelines.demo import find_shared_data
from mocapkit.pipelines.hybrid_markers import track_hybrid_markers

HEAD = "head=LFHD+RFHD+LBHD+RBHD"
ARMS = ("left_hand=LWRA+LWRB/LFRM", "right_hand=RWRA+RWRB/RFRM")
LEGS = ("pelvis=LASI+RASI+LPSI+RPSI", "left_foot=LHEE+LTOE+LANK", "right_foot=RHEE+RTOE+RANK")
#: The marker-set choices compared, README's first.
CHOICES = {
    "wrist bars + forearm markers": [HEAD, *ARMS],
    "wrist bars alone": [HEAD, "left_hand=LWRA+LWRB", "right_hand=RWRA+RWRB"],
    "+ forearm markers, pelvis and feet": [HEAD, *ARMS, *LEGS],
}


def main(path: Path) -> None:
    markers = read_markers(path)
    elbow_markers_mm = np.stack([markers.trajectory("LELB"), markers.trajectory("RELB")], axis=1)
    print(f"{'marker sets':36s} elbow to LELB / RELB: mean mm, median mm")
    for label, sets in CHOICES.items():
        motion = track_hybrid_markers(path, sets)
        elbows_mm = np.stack([motion.joint("left_elbow"), motion.joint("right_elbow")], axis=1)
        err = np.linalg.norm(elbows_mm - elbow_markers_mm, axis=2)
        mean, median = np.nanmean(err, axis=0), np.nanmedian(err, axis=0)
        print(
            f"{label:36s} {mean[0]:4.0f} / {mean[1]:4.0f}  "
            f"      {median[0]:4.0f} / {median[1]:4.0f}"
        )


def default_path() -> Path:
    """The serve's C3D in the shared data beside the repository, or exit naming what was
    tried."""
    data = find_shared_data(Path(__file__).resolve().parent)
    path = data / "c3d" / "kinematics_tennis_serve.c3d" if data else None
    if path is None or not path.is_file():
        raise SystemExit(
            f"kinematics_tennis_serve.c3d not found: looked in {path or 'no shared/data'} "
            f"($MOCAPKIT_SHARED_DATA, else shared/data or ../shared/data above "
            f"{Path(__file__).resolve().parent}); set MOCAPKIT_SHARED_DATA or pass the path"
        )
    return path


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else default_path())
