"""Whether MediaPipe's depth and the tracker's err independently, per link.

    python tools/mono_depth_fusion_check.py --work W                   # the tuning clips
    python tools/mono_depth_fusion_check.py --work W --clips 01_01 11_01

Reads the sessions and detections that ``mocapkit accuracy mono --detector mediapipe
--work W`` left in ``W/<clip>/``, tracks each clip from MediaPipe's keypoints without the
depth blend (``depth_fusion_weight=0``, the rest the default) and prints per link, over
all the clips' posed frames: the correlation of the two out-of-plane sines' errors
against the truth's (``r``), each one's RMS error, the share of MediaPipe's sine that
minimises the blend's squared error (``best_w``) and how often the two agree in sign.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from mocapkit.io.session import load_session
from mocapkit.pipelines.mono import detector_link_sines, track_mono
from mocapkit.pipelines.mono_accuracy import truth_in_camera
from mocapkit.tracking.mono.tracker import MonoConfig

CLIPS = ("13_26", "01_09", "lambada", "charleston1", "zombie")


def _sines(joints: np.ndarray, parent: np.ndarray, child: np.ndarray) -> np.ndarray:
    v = joints[:, child] - joints[:, parent]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.asarray(v[..., 2] / np.linalg.norm(v, axis=-1))


def clip_sines(base: Path, detector: str = "mediapipe") -> tuple[list[str], np.ndarray]:
    """Per posed frame and link: the tracker's, the detector's and the truth's sines
    (3, T, L), NaN where one is missing."""
    session = load_session(base / "session")
    cam = session.cameras[0].name
    found = base / f"detect_{detector}"
    npz = found / "keypoints3d" / f"{cam}.npz"
    run = track_mono(
        base / "session",
        None,
        camera=cam,
        keypoints=found / "keypoints" / "openpose" / cam,
        config=MonoConfig(depth_fusion_weight=0.0),
        keypoints3d=npz,
    )
    m = run.model
    ours = _sines(run.frames.joints_in_camera, m.parent, m.child)
    truth = _sines(truth_in_camera(session, cam, m), m.parent, m.child)
    theirs = detector_link_sines(npz, session.keypoints[cam].time_s, m)
    return list(m.segments), np.stack([ours, theirs, truth])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", required=True, type=Path)
    ap.add_argument("--clips", nargs="+", default=list(CLIPS))
    args = ap.parse_args()
    runs = [clip_sines(args.work / c) for c in args.clips]
    segments = runs[0][0]
    s = np.concatenate([r[1] for r in runs], axis=1)
    print(f"{'link':<16}{'r':>6}{'rms_ours':>10}{'rms_det':>9}{'best_w':>8}{'agree':>7}")
    for i, seg in enumerate(segments):
        ours, theirs, truth = s[:, :, i]
        ok = np.isfinite(ours) & np.isfinite(theirs) & np.isfinite(truth)
        eo, ed = ours[ok] - truth[ok], theirs[ok] - truth[ok]
        best = float(np.sum(eo * (eo - ed)) / np.sum((eo - ed) ** 2))
        agree = float(np.mean(np.sign(ours[ok]) == np.sign(theirs[ok])))
        print(
            f"{seg:<16}{np.corrcoef(eo, ed)[0, 1]:6.2f}{np.sqrt(np.mean(eo**2)):10.3f}"
            f"{np.sqrt(np.mean(ed**2)):9.3f}{best:8.2f}{agree:7.1%}"
        )


if __name__ == "__main__":
    main()
