"""The stereo tracker on real video: the 4-view Pose2Sim demo, with an overlay montage.

The data (``../shared/data/video/pose2sim_demo_singleperson``: four 60 fps portrait
videos of 100 frames and their Qualisys calibration, read by
`mocapkit.io.cameras.load_cameras`) is not copied into the repository. This script

1. builds a session folder from it: every view padded or cropped on the right to the
   calibration's 1088x1920 window (cam01 and cam02 are 1080 px wide; the calibration's
   principal point counts from the left edge, so the extra columns go on the right),
   downscaled by ``--scale`` (default 0.5: 544x960) with the intrinsics scaled to match
   (pixel centres at integers: ``c' = (c + 0.5) s - 0.5``), frames written as JPEG
   images (``video/<camera>/``), ``rates.video_hz`` 60;
2. runs `mocapkit.pipelines.stereo.track_stereo_session` over all four views (skin
   blobs: the paper's pipeline; the subject has no keypoints here);
3. with ``--openpose FOLDER`` (one OpenPose JSON folder per camera, ``FOLDER/<camera>/``,
   e.g. from `examples/mediapipe_openpose_json.py`), converts them into the session's
   ``keypoints/<camera>.csv`` (`mocapkit.io.openpose.read_openpose_folder`) and tracks
   a second time with head, hands and torso from the keypoints (``--keypoints --torso
   keypoints``: the accuracy study's ``keypoints+torso`` mode) into ``OUT/result_kp``,
   after writing the subject's arm lengths and shoulder and head vectors, measured from
   the triangulated keypoints, into ``session.json`` (`subject_from_keypoints`);
4. draws the tracked model (limb silhouettes, `mocapkit.viz.overlay.draw_body`, and the
   canonical sticks, `draw_sticks`) and the measured head and hands (dots) over each view
   at a few frames and writes the montage PNG (256 colours, to stay small).

Usage::

    .venv/bin/python examples/pose2sim_stereo.py --out /tmp/p2s \\
        --montage docs/stereo_pose2sim_montage.png

The session goes to ``OUT/session``, the result folder to ``OUT/result``; the command
``mocapkit track stereo OUT/session --out OUT/result --cameras cam01,cam02,cam03,cam04``
tracks the same session again.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import cv2
import numpy as np

from mocapkit.camera.pinhole import Camera
from mocapkit.io.cameras import load_cameras, write_cameras
from mocapkit.io.openpose import read_openpose_folder
from mocapkit.io.session import load_session, write_session_json
from mocapkit.io.session_csv import write_keypoints_csv
from mocapkit.pipelines.demo import find_shared_data
from mocapkit.pipelines.stereo import ARM_JOINTS, StereoRun, track_stereo_session
from mocapkit.tracking.stereo.hands import keypoint_targets
from mocapkit.tracking.stereo.tracker import StereoConfig, azad_skeleton
from mocapkit.viz.overlay import draw_body, draw_sticks

DEMO = Path("video") / "pose2sim_demo_singleperson"
FPS = 60.0


def scaled_camera(cam: Camera, scale: float) -> Camera:
    """The camera of images resized by ``scale`` (pixel centres at integer coordinates)."""
    k = cam.K.copy()
    k[0, 0] *= scale
    k[1, 1] *= scale
    k[0, 1] *= scale
    k[0, 2] = (k[0, 2] + 0.5) * scale - 0.5
    k[1, 2] = (k[1, 2] + 0.5) * scale - 0.5
    w, h = cam.image_size
    return dataclasses.replace(cam, image_size=(round(w * scale), round(h * scale)), K=k)


def fit_width(image: np.ndarray, width: int) -> np.ndarray:
    """Pad (black) or crop ``image`` on the right to ``width`` columns."""
    w = image.shape[1]
    if w > width:
        return image[:, :width]
    if w < width:
        pad = np.zeros((image.shape[0], width - w, 3), image.dtype)
        return np.concatenate([image, pad], axis=1)
    return image


def build_session(data: Path, session: Path, first: int, n_frames: int, scale: float) -> None:
    """Write the session folder (module notes, step 1)."""
    cams = load_cameras(data / "calibration" / "Calib.qca.txt")
    out_cams = []
    for cam in cams:
        video = data / "videos" / f"{cam.name}.mp4"
        cap = cv2.VideoCapture(str(video))
        if not cap.isOpened():
            raise SystemExit(f"{video}: cannot open")
        folder = session / "video" / cam.name
        folder.mkdir(parents=True, exist_ok=True)
        small = scaled_camera(cam, scale)
        k = 0
        written = 0
        while written < n_frames:
            ok, frame = cap.read()
            if not ok:
                break
            if k >= first:
                frame = fit_width(frame, cam.image_size[0])
                frame = cv2.resize(frame, small.image_size, interpolation=cv2.INTER_AREA)
                cv2.imwrite(
                    str(folder / f"{written:06d}.jpg"), frame, [cv2.IMWRITE_JPEG_QUALITY, 95]
                )
                written += 1
            k += 1
        cap.release()
        out_cams.append(small)
    write_cameras(session / "cameras.json", out_cams)
    write_session_json(
        session / "session.json",
        {
            "rates": {"video_hz": FPS},
            "source": f"built by examples/pose2sim_stereo.py from {data} (frames {first}+)",
        },
    )


def montage(session_dir: Path, run: StereoRun, frames: list[int], tile_h: int) -> np.ndarray:
    """Views (columns) x frames (rows) of the model drawn over the whole images."""
    session = load_session(session_dir)
    names = list(session.video_cameras)
    sk = azad_skeleton(session.bone_lengths_mm, session.segment_vectors_mm)
    m = run.motion
    rows = []
    for f in frames:
        row = []
        for name in names:
            cam = session.camera(name)
            img = np.ascontiguousarray(session.video(name).read(f))
            q = m.q[f]
            joints = m.joints_mm[f]
            meas = run.measured_mm[f]
            if np.all(np.isfinite(q)):
                body = draw_body(img.copy(), sk, cam, q, default_colour=(255, 160, 60))
                img = cv2.addWeighted(img, 0.6, body, 0.4, 0.0)
                draw_sticks(img, cam, m.joint_names, joints, colour=(0, 165, 255), thickness=2)
            for p, colour in zip(meas, ((0, 255, 0), (255, 0, 255), (0, 255, 255))):
                if np.all(np.isfinite(p)):
                    u, v = cam.project(p[None])[0]
                    if np.isfinite(u) and np.isfinite(v):
                        cv2.circle(img, (round(u), round(v)), 7, colour, 2, cv2.LINE_AA)
            w, h = cam.image_size
            tile = cv2.resize(img, (round(w * tile_h / h), tile_h), interpolation=cv2.INTER_AREA)
            label = f"{name} frame {f} ({f / FPS:.2f} s)"
            cv2.putText(tile, label, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1)
            row.append(tile)
        rows.append(np.concatenate(row, axis=1))
    return np.concatenate(rows, axis=0)


def write_small_png(path: Path, image: np.ndarray) -> None:
    """Write ``image`` (BGR) as a 256-colour PNG (a third of the size of a true-colour one)."""
    from PIL import Image

    rgb = Image.fromarray(np.ascontiguousarray(image[:, :, ::-1]))
    rgb.quantize(colors=256, method=Image.Quantize.MEDIANCUT).save(path, optimize=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, help="the demo folder (default: found in ../shared/data)")
    ap.add_argument("--out", type=Path, required=True, help="work folder (session, result)")
    ap.add_argument("--first", type=int, default=0, help="first video frame")
    ap.add_argument("--frames", type=int, default=100, help="frames to take (100: all)")
    ap.add_argument("--scale", type=float, default=0.5, help="image scale")
    ap.add_argument("--particles", type=int, default=150)
    ap.add_argument("--montage", type=Path, help="montage PNG to write")
    ap.add_argument("--openpose", type=Path, help="OpenPose JSON folders, one per camera")
    ap.add_argument("--montage-kp", type=Path, help="montage PNG of the keypoint run")
    ap.add_argument("--show", default="10,50,90", help="frames drawn in the montage")
    ap.add_argument("--tile-height", type=int, default=400)
    args = ap.parse_args(argv)
    if args.data is None:
        shared = find_shared_data()
        if shared is None:
            raise SystemExit("../shared/data not found: give --data")
        args.data = shared / DEMO
    session = args.out / "session"
    if not (session / "cameras.json").is_file():
        build_session(args.data, session, args.first, args.frames, args.scale)
    cameras = ",".join(c.name for c in load_cameras(session / "cameras.json"))
    info = json.loads((session / "session.json").read_text())
    if info.pop("subject", None) is not None:  # the skin run takes the model's own sizes
        write_session_json(session / "session.json", info)
    run = track_stereo_session(
        session,
        args.out / "result",
        cameras=cameras,
        config=StereoConfig(),
        n_particles=args.particles,
    )
    report(run, args.montage, session, args)
    if args.openpose is not None:
        for cam in cameras.split(","):
            times = load_session(session).video(cam).time_s
            kp = read_openpose_folder(args.openpose / cam, times)
            write_keypoints_csv(
                session / "keypoints" / f"{cam}.csv", kp.time_s, kp.joint_names, kp.pixels
            )
        info["subject"] = subject_from_keypoints(session)
        print(f"subject from the keypoints: {json.dumps(info['subject'])}")
        write_session_json(session / "session.json", info)
        run_kp = track_stereo_session(
            session,
            args.out / "result_kp",
            cameras=cameras,
            config=StereoConfig(use_keypoints=True, torso="keypoints"),
            n_particles=args.particles,
        )
        report(run_kp, args.montage_kp, session, args)
    return 0


def subject_from_keypoints(session_dir: Path) -> dict[str, dict[str, object]]:
    """The subject's arm lengths and trunk vectors from the keypoints, triangulated over
    every view (`keypoint_targets`): medians over the frames of the upper arm and forearm
    lengths, and of the neck-to-shoulder and neck-to-head vectors in the torso frame (x
    from the left to the right shoulder, z along pelvis-neck made orthogonal to x, y
    forward), as ``session.json``'s ``subject`` fields. The model's own (``azad14``)
    shoulders sit 40 mm below its neck, while a detector's neck (mapped from the shoulder
    and hip midpoints) lies below the shoulders: without these the shoulders are placed
    about 100 mm too low."""
    session = load_session(session_dir)
    names = list(session.video_cameras)
    cams = [session.camera(c) for c in names]
    kps = [session.keypoints[c] for c in names]
    wanted = ("neck", "pelvis", "head", "left_shoulder", "right_shoulder")
    wanted += ("left_elbow", "right_elbow", "left_wrist", "right_wrist")
    pts = np.array(
        [
            keypoint_targets(cams, [kp.pixels[k] for kp in kps], kps[0].joint_names, wanted)
            for k in range(kps[0].time_s.shape[0])
        ]
    )
    p = {n: pts[:, i] for i, n in enumerate(wanted)}
    x = p["right_shoulder"] - p["left_shoulder"]
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    up = p["neck"] - p["pelvis"]
    z = up - np.sum(up * x, axis=1, keepdims=True) * x
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    y = np.cross(z, x)

    def local(v: np.ndarray) -> list[float]:
        loc = np.stack([np.sum(v * x, 1), np.sum(v * y, 1), np.sum(v * z, 1)], axis=1)
        return [round(float(c), 1) for c in np.nanmedian(loc, axis=0)]

    def length(a: str, b: str) -> float:
        return round(float(np.nanmedian(np.linalg.norm(p[a] - p[b], axis=1))), 1)

    return {
        "bone_lengths_mm": {
            f"{s}_{seg}": length(f"{s}_{a}", f"{s}_{b}")
            for s in ("left", "right")
            for seg, a, b in (("upper_arm", "shoulder", "elbow"), ("forearm", "elbow", "wrist"))
        },
        "segment_vectors_mm": {
            "left_clavicle": local(p["left_shoulder"] - p["neck"]),
            "right_clavicle": local(p["right_shoulder"] - p["neck"]),
            "head": local(p["head"] - p["neck"]),
        },
    }


def joints_vs_keypoints(run: StereoRun, session_dir: Path) -> None:
    """Median distance (mm) of the tracked arm joints from the keypoints triangulated over
    every view, and the keypoints' median reprojection residual (px). The tracker takes
    the wrists (and with a keypoint torso the shoulders' line and the neck), never the
    elbows: the elbows are a check against an independent detection, itself a few px off
    and from cameras whose frames are not exactly synchronous."""
    session = load_session(session_dir)
    names = list(session.video_cameras)
    if any(c not in session.keypoints for c in names):
        return
    cams = [session.camera(c) for c in names]
    kps = [session.keypoints[c] for c in names]
    kn = list(kps[0].joint_names)
    m = run.motion
    for joint in ARM_JOINTS:
        dist, resid = [], []
        for k in range(m.n_frames):
            px = [kp.pixels[k] for kp in kps]
            p = keypoint_targets(cams, px, kn, (joint,))[0]
            if not np.all(np.isfinite(p)):
                continue
            dist.append(np.linalg.norm(m.joints_mm[k, m.joint_names.index(joint)] - p))
            r = [
                np.linalg.norm(c.project(p[None])[0] - q[kn.index(joint)]) for c, q in zip(cams, px)
            ]
            resid.append(np.nanmean(r))
        print(
            f"{joint}: {np.nanmedian(dist):.1f} mm (median) from the keypoints triangulated "
            f"({len(dist)} frames; their reprojection residual {np.median(resid):.1f} px)"
        )


def report(run: StereoRun, path: Path | None, session: Path, args: argparse.Namespace) -> None:
    """Print how often head and hands were measured; write the montage when asked."""
    status = np.array(
        [[r.status[k] for k in ("head", "left_hand", "right_hand")] for r in run.results]
    )
    for i, k in enumerate(("head", "left_hand", "right_hand")):
        seen = float(np.mean(status[:, i] == "seen"))
        print(f"{k}: seen on {100 * seen:.0f} % of {len(status)} frames")
    print(f"tracked {run.motion.n_frames} frames, {run.motion.n_frames / run.seconds:.1f} frames/s")
    joints_vs_keypoints(run, session)
    if path is not None:
        frames = [int(x) for x in args.show.split(",") if x.strip()]
        frames = [f for f in frames if f < run.motion.n_frames]
        image = montage(session, run, frames, args.tile_height)
        write_small_png(path, image)
        print(f"wrote {path} ({image.shape[1]}x{image.shape[0]})")


if __name__ == "__main__":
    sys.exit(main())
