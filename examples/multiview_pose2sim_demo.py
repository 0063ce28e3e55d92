"""The multi-view fit on Pose2Sim's real 4-camera demo, beside Pose2Sim on the same detections.

The data (``../shared/data/video/pose2sim_demo_singleperson``: four 60 fps videos of
100 frames and their Qualisys calibration) is not copied into the repository. This script

1. builds a session folder from it at full resolution (`pose2sim_stereo.build_session`,
   the same rule for the 1080-pixel-wide videos);
2. runs MediaPipe Pose on its views in a separate environment
   (``examples/mediapipe_openpose_json.py``, ``--mediapipe-python``) and writes the
   session's keypoints (`mocapkit.io.openpose.read_openpose_folder`);
3. tracks it with the shipped default of ``mocapkit track stereo`` (the model-based fit)
   and, with ``--pose2sim-python``, runs Pose2Sim's triangulation and filtering on the
   same JSON files (``bench/multiview_peers.py``'s project folder);
4. prints the mean reprojection error (px) of the arm joints against the detections for
   both, on all frames and on the frames where no view swaps sides, the views whose
   labels the fit exchanged, and the fit's warnings;
5. writes a montage of both results over the four views at a few frames (``--montage``).

Usage::

    .venv/bin/python examples/multiview_pose2sim_demo.py --out /tmp/p2sdemo \\
        --mediapipe-python /tmp/mp/bin/python --pose2sim-python /tmp/p2s/bin/python \\
        --montage docs/multiview_pose2sim_montage.png
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))

from multiview_peers import BODY25, read_pose2sim_trc, run_pose2sim_project
from pose2sim_stereo import DEMO, build_session, write_small_png

from mocapkit.io.openpose import read_openpose_folder
from mocapkit.io.session import load_session
from mocapkit.io.session_csv import write_keypoints_csv
from mocapkit.pipelines.demo import find_shared_data
from mocapkit.pipelines.multiview import track_multiview_session
from mocapkit.viz.overlay import draw_sticks

ARMS = ("left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist")


def reprojection_px(session, joint_names, joints_mm) -> np.ndarray:
    """Distance (T, V, 6) px of the arm joints from each view's detections."""
    cams = sorted(session.keypoints)
    out = np.full((joints_mm.shape[0], len(cams), len(ARMS)), np.nan)
    for v, c in enumerate(cams):
        kp = session.keypoints[c]
        cam = session.camera(c)
        for a, j in enumerate(ARMS):
            p = joints_mm[:, list(joint_names).index(j)]
            proj = cam.project(p)
            det = kp.pixels[: p.shape[0], list(kp.joint_names).index(j)]
            out[: det.shape[0], v, a] = np.linalg.norm(proj[: det.shape[0]] - det, axis=1)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--mediapipe-python", required=True)
    ap.add_argument("--pose2sim-python", default=None)
    ap.add_argument("--montage", type=Path, default=None)
    ap.add_argument("--show", default="20,55,90")
    args = ap.parse_args()
    data = find_shared_data()
    if data is None:
        raise SystemExit("no shared data")
    session_dir = args.out / "session"
    if not (session_dir / "cameras.json").is_file():
        build_session(data / DEMO, session_dir, 0, 100, 1.0)
    js = args.out / "mediapipe_json"
    if not js.is_dir():
        subprocess.run(
            [
                args.mediapipe_python,
                str(Path(__file__).parent / "mediapipe_openpose_json.py"),
                str(session_dir),
                str(js),
            ],
            check=True,
        )
    if not (session_dir / "keypoints").is_dir():
        s = load_session(session_dir)
        (session_dir / "keypoints").mkdir()
        for cam in s.video_cameras:
            t = np.arange(s.video(cam).n_frames) / 60.0
            kp = read_openpose_folder(js / cam, t)
            write_keypoints_csv(
                session_dir / "keypoints" / f"{cam}.csv", t, kp.joint_names, kp.pixels
            )
    session = load_session(session_dir)
    run = track_multiview_session(session_dir, args.out / "result")
    m = run.motion
    ours = reprojection_px(session, m.joint_names, m.joints_mm)
    cams = sorted(session.keypoints)
    swapped = np.array([[r.fit[f"{c}_swapped"] for c in cams] for r in run.results], dtype=bool)
    clean = ~swapped.any(axis=1)
    print(f"fit: {m.n_frames} frames, {m.n_frames / run.seconds:.0f} frames per CPU s")
    for v, c in enumerate(cams):
        fr = np.flatnonzero(swapped[:, v])
        if fr.size:
            print(f"  {c}: labels exchanged on {fr.size} frames ({fr.min()}-{fr.max()})")
    for joint, t0, t1, n in run.far:
        print(f"  warning: {joint} far from its detections in most views {t0:.2f}-{t1:.2f} s ({n})")
    rows = [("mocapkit fit", ours)]
    p2s_joints = None
    if args.pose2sim_python:
        project = args.out / "pose2sim"
        trc, _fps = run_pose2sim_project(session_dir, js, project, args.pose2sim_python)
        frames, p2s_joints = read_pose2sim_trc(trc)
        full = np.full((m.n_frames, len(BODY25), 3), np.nan)
        full[frames[frames < m.n_frames]] = p2s_joints[frames < m.n_frames]
        p2s_joints = full
        rows.append(("Pose2Sim", reprojection_px(session, tuple(BODY25), full)))
    print(
        f"{'arm joints vs detections, px':<30}{'all frames':>12}{'no swap':>10}"
        f"{'elbows':>9}{'wrists':>9}"
    )
    for label, err in rows:
        print(
            f"{label:<30}{np.nanmean(err):12.1f}{np.nanmean(err[clean]):10.1f}"
            f"{np.nanmean(err[clean][:, :, 2:4]):9.1f}{np.nanmean(err[clean][:, :, 4:6]):9.1f}"
        )
    if args.montage:
        tiles = []
        for f in (int(x) for x in args.show.split(",")):
            row = []
            for c in cams:
                img = np.ascontiguousarray(session.video(c).read(f))
                cam = session.camera(c)
                kp = session.keypoints[c]
                for p in kp.pixels[f]:
                    if np.isfinite(p).all():
                        cv2.circle(img, (round(p[0]), round(p[1])), 12, (0, 255, 0), 3)
                if p2s_joints is not None:
                    draw_sticks(
                        img, cam, tuple(BODY25), p2s_joints[f], colour=(255, 0, 255), thickness=4
                    )
                draw_sticks(
                    img, cam, m.joint_names, m.joints_mm[f], colour=(0, 165, 255), thickness=4
                )
                h = 480
                w = round(img.shape[1] * h / img.shape[0])
                tile = cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA)
                label = f"{c} frame {f}" + (
                    " (labels exchanged)" if swapped[f, cams.index(c)] else ""
                )
                cv2.putText(tile, label, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1)
                row.append(tile)
            tiles.append(np.concatenate(row, axis=1))
        write_small_png(args.montage, np.concatenate(tiles, axis=0))
        print(f"wrote {args.montage} (green: MediaPipe, orange: mocapkit, magenta: Pose2Sim)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
