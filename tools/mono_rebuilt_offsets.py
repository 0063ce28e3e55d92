"""Where a detector's rebuilt neck and pelvis lie against the truth's, in the image.

    python tools/mono_rebuilt_offsets.py --work W                   # the tuning clips
    python tools/mono_rebuilt_offsets.py --work W --clips 01_01 11_01

Reads the sessions and detections that ``mocapkit accuracy mono --detector mediapipe
--work W`` left in ``W/<clip>/`` (``session/`` with its true keypoints,
``detect_mediapipe/keypoints/openpose/<camera>/``) and prints per clip the median offset
(px) of the detector's hip midpoint, shoulder midpoint, rebuilt pelvis and rebuilt neck
from the truth's along the true trunk (``_along``: + towards the shoulders) and across it
(``_across``), the truth's pelvis above its hip midpoint (``true_pelvis_up``), the
shoulder width over the trunk (90th percentiles, as the rebuild reads them:
`mocapkit.io.openpose.trunk_fractions`) of both, and the pelvis fraction the rebuild gives
each (``f_pelvis_``). Nothing is tracked.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from mocapkit.io.openpose import read_openpose_folder, trunk_fractions
from mocapkit.io.session import load_session

CLIPS = ("13_26", "01_09", "lambada", "charleston1", "zombie")


def _mid(px: np.ndarray, names: list[str], a: str, b: str) -> np.ndarray:
    return np.asarray(0.5 * (px[:, names.index(a)] + px[:, names.index(b)]))


def clip_offsets(base: Path, detector: str = "mediapipe") -> dict[str, float]:
    """One clip's offsets (px) and ratios (module docstring)."""
    s = load_session(base / "session")
    cam = s.cameras[0].name
    kp = s.keypoints[cam]
    det = read_openpose_folder(base / f"detect_{detector}/keypoints/openpose" / cam, kp.time_s)
    tn, dn = list(kp.joint_names), list(det.joint_names)
    tp, dp = kp.pixels, det.pixels
    hips_t = _mid(tp, tn, "left_hip", "right_hip")
    shoulders_t = _mid(tp, tn, "left_shoulder", "right_shoulder")
    up = shoulders_t - hips_t
    up = up / np.linalg.norm(up, axis=-1, keepdims=True)
    across = np.stack([-up[:, 1], up[:, 0]], axis=-1)

    def along(d: np.ndarray) -> float:
        return float(np.nanmedian((d * up).sum(-1)))

    def side(d: np.ndarray) -> float:
        return float(np.nanmedian((d * across).sum(-1)))

    def width_over_trunk(px: np.ndarray, names: list[str]) -> float:
        w = np.linalg.norm(
            px[:, names.index("left_shoulder")] - px[:, names.index("right_shoulder")], axis=-1
        )
        h = np.linalg.norm(
            _mid(px, names, "left_shoulder", "right_shoulder")
            - _mid(px, names, "left_hip", "right_hip"),
            axis=-1,
        )
        return float(np.nanpercentile(w, 90) / np.nanpercentile(h, 90))

    hips_d = _mid(dp, dn, "left_hip", "right_hip") - hips_t
    pelvis_d = dp[:, dn.index("pelvis")] - tp[:, tn.index("pelvis")]
    neck_d = dp[:, dn.index("neck")] - tp[:, tn.index("neck")]
    f_t, f_d = trunk_fractions(tp, tn), trunk_fractions(dp, dn)
    return {
        "trunk_px": float(np.nanmedian(np.linalg.norm(shoulders_t - hips_t, axis=-1))),
        "true_pelvis_up": along(tp[:, tn.index("pelvis")] - hips_t),
        "hips_along": along(hips_d),
        "hips_across": side(hips_d),
        "shoulders_along": along(_mid(dp, dn, "left_shoulder", "right_shoulder") - shoulders_t),
        "pelvis_along": along(pelvis_d),
        "pelvis_across": side(pelvis_d),
        "neck_along": along(neck_d),
        "neck_across": side(neck_d),
        "w_over_h_truth": width_over_trunk(tp, tn),
        "w_over_h_det": width_over_trunk(dp, dn),
        "f_pelvis_truth": f_t[1],
        "f_pelvis_det": f_d[1],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", required=True, type=Path, help="accuracy mono's --work folder")
    ap.add_argument("--clips", nargs="+", default=list(CLIPS), help="clip names (no suffix)")
    ap.add_argument("--detector", default="mediapipe")
    args = ap.parse_args()
    rows = {c: clip_offsets(args.work / c, args.detector) for c in args.clips}
    keys = list(next(iter(rows.values())))
    print("clip".ljust(12) + "".join(k.rjust(16) for k in keys))
    for c, r in rows.items():
        print(c.ljust(12) + "".join(f"{r[k]:16.2f}" for k in keys))


if __name__ == "__main__":
    main()
