"""Elbow error of a result folder against elbow markers of the marker file it was tracked from.

``mocapkit track hybrid --markers FILE`` writes ``joints.csv`` in the file's own frame, so
the tracked elbows compare directly with the file's elbow markers (skin over the lateral
epicondyle, 30-40 mm from the joint centre, so that much of each figure is the marker's
own offset). A side without a marker name (``-``) or without tracked elbows (one-sided
marker sets: NaN) is reported as such.

Usage::

    .venv/bin/python examples/elbow_errors.py RESULT_DIR MARKER_FILE LEFT_MARKER RIGHT_MARKER

e.g. ``... /tmp/basket ../shared/data/c3d/kinematics_basket_sprint.c3d
LateralEpicondyleL -``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from mocapkit.io.joints_csv import read_joints_csv
from mocapkit.io.marker_files import read_markers


def main(result_dir: Path, marker_file: Path, left: str, right: str) -> None:
    time_s, names, joints_mm = read_joints_csv(result_dir / "joints.csv")
    markers = read_markers(marker_file)
    if markers.n_frames != time_s.size:
        raise SystemExit(
            f"{result_dir}: {time_s.size} frames against {markers.n_frames} in {marker_file}"
        )
    print("side   marker                 frames  mean mm  median mm")
    for side, marker in (("left", left), ("right", right)):
        if marker == "-":
            print(f"{side:6s} (none)")
            continue
        est = joints_mm[:, names.index(f"{side}_elbow")]
        err = np.linalg.norm(est - markers.trajectory(marker), axis=1)
        ok = np.isfinite(err)
        if not ok.any():
            print(f"{side:6s} {marker:22s} {0:6d}  (no frame with both)")
            continue
        print(
            f"{side:6s} {marker:22s} {int(ok.sum()):6d}  {np.mean(err[ok]):7.0f}  "
            f"{np.median(err[ok]):9.0f}"
        )


if __name__ == "__main__":
    if len(sys.argv) != 5:
        raise SystemExit(__doc__)
    main(Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3], sys.argv[4])
