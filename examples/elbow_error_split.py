"""Split a tracked elbow's error against its elbow marker: the shoulder, the swivel, the rest.

``examples/elbow_errors.py`` gives the elbow error of a ``track hybrid --markers`` result
folder; this splits it, per frame, to show what to fix (docs/hybrid.md, "Raw files: where
the elbow error comes from"):

* **shoulder**: the model's shoulder against a shoulder marker (e.g. ``LSHO`` or
  ``AcromionL``: on top of the joint, so 30-50 mm above it is the marker's own place);
* **upper arm / forearm direction**: the angle (deg) between the model's shoulder-elbow
  (elbow-wrist) line and the markers' shoulder-elbow (elbow-hand set) line;
* **swivel**: the model's elbow turned about its own shoulder-wrist axis to the point
  nearest the elbow marker (`mocapkit.eval.metrics.best_swivel_elbow`: the same
  shoulder, wrist and segment lengths, only the elbow's turn about that axis changed)
  gives the *best-swivel floor*; the model's turn from it (deg, signed) is what the
  swivel costs. With positions-only hand sets nothing but the IK's relaxed-pose task
  chooses that turn.

All positions are the file's (``joints.csv`` of ``track hybrid --markers`` is written in
the marker file's frame). Frames where any of the markers or the model's arm is missing
are left out.

Usage::

    .venv/bin/python examples/elbow_error_split.py RESULT_DIR MARKER_FILE SIDE \\
        ELBOW_MARKER SHOULDER_MARKER HAND_SET

e.g. ``... /tmp/basket ../shared/data/c3d/kinematics_basket_sprint.c3d left
LateralEpicondyleL AcromionL HandL`` or ``... /tmp/tennis
../shared/data/c3d/kinematics_tennis_serve.c3d right RELB RSHO RWRA+RWRB``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from mocapkit.eval.metrics import best_swivel_elbow
from mocapkit.io.joints_csv import read_joints_csv
from mocapkit.io.marker_files import read_markers

FloatArray = NDArray[np.float64]


def _unit(v: FloatArray) -> FloatArray:
    return np.asarray(v / np.linalg.norm(v, axis=-1, keepdims=True), dtype=float)


def _angle_deg(a: FloatArray, b: FloatArray) -> FloatArray:
    c = np.sum(_unit(a) * _unit(b), axis=-1)
    return np.asarray(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))), dtype=float)


def main(
    result_dir: Path, marker_file: Path, side: str, elbow: str, shoulder: str, hand: str
) -> None:
    time_s, names, joints_mm = read_joints_csv(result_dir / "joints.csv")
    markers = read_markers(marker_file)
    if markers.n_frames != time_s.size:
        raise SystemExit(
            f"{result_dir}: {time_s.size} frames against {markers.n_frames} in {marker_file}"
        )

    def model(joint: str) -> FloatArray:
        return np.asarray(joints_mm[:, names.index(f"{side}_{joint}")], dtype=float)

    s_m, e_m, w_m = model("shoulder"), model("elbow"), model("wrist")
    e_ref, s_ref = markers.trajectory(elbow), markers.trajectory(shoulder)
    h_ref = np.mean([markers.trajectory(m) for m in hand.split("+")], axis=0)
    ok = np.all(np.isfinite(np.hstack([s_m, e_m, w_m, e_ref, s_ref, h_ref])), axis=1)
    if not ok.any():
        raise SystemExit(f"{result_dir}: no frame with the {side} arm and all markers seen")
    s_m, e_m, w_m, e_ref, s_ref, h_ref = (a[ok] for a in (s_m, e_m, w_m, e_ref, s_ref, h_ref))
    best, turn_rad = best_swivel_elbow(s_m, e_m, w_m, e_ref)
    d_sh = s_m - s_ref
    rows = [
        ("elbow error (mm)", np.linalg.norm(e_m - e_ref, axis=1)),
        (f"shoulder - {shoulder} (mm)", np.linalg.norm(d_sh, axis=1)),
        ("  horizontal (mm)", np.linalg.norm(d_sh[:, :2], axis=1)),
        ("  vertical (mm)", d_sh[:, 2]),
        ("upper arm direction (deg)", _angle_deg(e_m - s_m, e_ref - s_ref)),
        ("forearm direction (deg)", _angle_deg(w_m - e_m, h_ref - e_ref)),
        (f"model wrist - {hand} (mm)", np.linalg.norm(w_m - h_ref, axis=1)),
        (f"{elbow} - {hand} (mm)", np.linalg.norm(e_ref - h_ref, axis=1)),
        ("model elbow - wrist (mm)", np.linalg.norm(e_m - w_m, axis=1)),
        ("best-swivel floor (mm)", np.linalg.norm(best - e_ref, axis=1)),
        ("swivel turn to it (deg)", np.degrees(turn_rad)),
    ]
    print(f"{side} arm, {int(ok.sum())} frames ({elbow}, {shoulder}, {hand})")
    print(f"{'':34s} {'mean':>7s} {'median':>7s} {'p10':>7s} {'p90':>7s}")
    for label, v in rows:
        p10, med, p90 = np.percentile(v, [10, 50, 90])
        print(f"{label:34s} {np.mean(v):7.1f} {med:7.1f} {p10:7.1f} {p90:7.1f}")


if __name__ == "__main__":
    if len(sys.argv) != 7:
        raise SystemExit(__doc__)
    main(Path(sys.argv[1]), Path(sys.argv[2]), *sys.argv[3:7])
