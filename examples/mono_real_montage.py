"""`track mono` on real video from `mocapkit detect` (MediaPipe): montages for docs/mono.md.

Pose2Sim's demo (four calibrated 60 fps views; each tracked alone, drawn in the tracked
camera and in another one) and Sports2D's clip (no calibration: a nominal camera, so it
is drawn in the tracked camera and from a virtual camera at the subject's side). The
data is read from ``../shared/data/video`` and not copied into the repository::

    D=../shared/data/video/pose2sim_demo_singleperson
    mocapkit session $D/videos/cam0{1,2,3,4}.mp4 --calibration $D/calibration/Calib.qca.txt \\
        --out /tmp/p2s
    mocapkit detect /tmp/p2s
    for c in cam01 cam02 cam03 cam04; do
        mocapkit track mono /tmp/p2s --camera $c --out /tmp/p2s_mono/$c; done
    python examples/mono_real_montage.py pose2sim /tmp/p2s /tmp/p2s_mono \\
        docs/mono_pose2sim_montage.png

    mocapkit detect ../shared/data/video/sports2d_demo.mp4 --out /tmp/s2d --person 1300,700
    python examples/mono_real_montage.py sports2d-session \\
        ../shared/data/video/sports2d_demo.mp4 /tmp/s2d /tmp/s2d_session
    mocapkit track mono /tmp/s2d_session --out /tmp/s2d_mono
    python examples/mono_real_montage.py sports2d /tmp/s2d_session /tmp/s2d_mono \\
        docs/mono_sports2d_montage.png

Prints, per tracked camera, the median distance (px) of the result's upper-body joints
projected into each camera from that camera's own detections: in the tracked camera it
measures the fit, in the others where the world placement puts the person.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from pose2sim_stereo import write_small_png

from mocapkit.camera.pinhole import Camera, intrinsics_from_fov, look_at
from mocapkit.io.cameras import write_cameras
from mocapkit.io.motion_npz import load_motion_npz
from mocapkit.io.session import load_session
from mocapkit.viz.overlay import draw_sticks, draw_sticks_px

UPPER = (
    "neck", "head", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
    "left_wrist", "right_wrist",
)  # fmt: skip
#: Height of a tile (px).
TILE_H = 300
#: The other camera each Pose2Sim view is drawn in.
OTHER = {"cam01": "cam03", "cam02": "cam04", "cam03": "cam01", "cam04": "cam02"}


def distance_px(session, camera: str, motion) -> float:
    """Median distance (px) of the result's upper-body joints projected into ``camera``
    from that camera's detections."""
    kp = session.keypoints[camera]
    cam = session.camera(camera)
    names = [n for n in UPPER if n in motion.joint_names and n in kp.joint_names]
    est = motion.joints_mm[:, [motion.joint_names.index(n) for n in names]]
    n = min(est.shape[0], kp.pixels.shape[0])
    proj = cam.project(est[:n].reshape(-1, 3)).reshape(n, len(names), 2)
    det = kp.pixels[:n, [kp.joint_names.index(j) for j in names]]
    d = np.linalg.norm(proj - det, axis=-1)
    return float(np.nanmedian(d))


def tile(session, camera: str, frame: int, motion, label: str, height: int = TILE_H) -> np.ndarray:
    """The camera's frame: its detections (thin: right orange, left cyan) and the result
    drawn through its calibration (thick green)."""
    img = np.ascontiguousarray(session.video(camera).read(frame))
    kp = session.keypoints[camera]
    thick = max(2, img.shape[0] // 250)
    draw_sticks_px(img, kp.joint_names, kp.pixels[frame], (0, 140, 255), thick, (255, 200, 0))
    draw_sticks(img, session.camera(camera), motion.joint_names, motion.joints_mm[frame],
                colour=(0, 220, 0), thickness=2 * thick)  # fmt: skip
    w = round(img.shape[1] * height / img.shape[0])
    t = cv2.resize(img, (w, height), interpolation=cv2.INTER_AREA)
    (tw, th), _ = cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, 0.38, 1)
    cv2.rectangle(t, (0, 0), (tw + 6, th + 8), (0, 0, 0), -1)
    cv2.putText(t, label, (3, th + 3), cv2.FONT_HERSHEY_SIMPLEX, 0.38, (255, 255, 255), 1,
                cv2.LINE_AA)  # fmt: skip
    return t


def pose2sim(session_dir: Path, results: Path, dest: Path, frames=(20, 80)) -> None:
    session = load_session(session_dir)
    cams = sorted(session.keypoints)
    print(f"{'tracked':<9}" + "".join(f"{c:>8}" for c in cams) + "   (median px to detections)")
    rows = []
    for c in cams:
        m = load_motion_npz(results / c / "motion.npz")
        print(f"{c:<9}" + "".join(f"{distance_px(session, o, m):8.0f}" for o in cams))
        row = []
        for f in frames:
            row.append(tile(session, c, f, m, f"tracked {c} #{f}"))
            row.append(tile(session, OTHER[c], f, m, f"{c}'s result in {OTHER[c]}"))
        rows.append(np.concatenate(row, axis=1))
    width = max(r.shape[1] for r in rows)
    rows = [np.pad(r, ((0, 0), (0, width - r.shape[1]), (0, 0))) for r in rows]
    write_small_png(dest, np.concatenate(rows, axis=0))


def sports2d_session(video: Path, detected: Path, session_dir: Path) -> None:
    """A session of the clip with a nominal camera: focal length = image width (a 53 deg
    horizontal field), 1.2 m above the floor, looking level (no calibration exists)."""
    cap = cv2.VideoCapture(str(video))
    w, h = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
    cap.release()
    name = video.stem
    r = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])  # camera x, y, z from world
    cfw = np.eye(4)
    cfw[:3, :3] = r
    cfw[:3, 3] = -r @ np.array([0.0, 0.0, 1200.0])
    cam = Camera(name, (w, h), np.array([[w, 0, w / 2], [0, w, h / 2], [0, 0, 1.0]]),
                 np.zeros(0), cfw)  # fmt: skip
    calib = session_dir.parent / f"{session_dir.name}_cameras.json"
    write_cameras(calib, [cam])
    subprocess.run(["mocapkit", "session", str(video), "--calibration", str(calib), "--out",
                    str(session_dir)], check=True)  # fmt: skip
    for sub in ("keypoints", "keypoints3d"):
        shutil.copytree(detected / sub, session_dir / sub, dirs_exist_ok=True)


def side_tile(motion, frame: int, width: int, height: int) -> np.ndarray:
    """The result seen from a virtual camera on the image's left (2 m from the frame's
    neck, level, looking along the image's x): the tracked camera's depth runs left to
    right, so flips towards or away from it show."""
    mid = motion.joints_mm[frame, motion.joint_names.index("neck")] - np.array([0, 0, 250.0])
    size = (width, height)
    side = Camera("side", size, intrinsics_from_fov(size, 40.0), np.zeros(0),
                  look_at(mid - np.array([2000.0, 0, 0]), mid))  # fmt: skip
    img = np.full((height, width, 3), 60, np.uint8)
    draw_sticks(img, side, motion.joint_names, motion.joints_mm[frame], (0, 220, 0), 3)
    cv2.putText(img, f"#{frame} from the left", (3, 14), cv2.FONT_HERSHEY_SIMPLEX,
                0.38, (255, 255, 255), 1, cv2.LINE_AA)  # fmt: skip
    return img


def sports2d(session_dir: Path, result: Path, dest: Path, frames=(70, 110, 150, 190)) -> None:
    session = load_session(session_dir)
    c = next(iter(session.keypoints))
    m = load_motion_npz(result / "motion.npz")
    print(f"{c}: median px to detections {distance_px(session, c, m):.0f}")
    h = 270
    row = [tile(session, c, f, m, f"tracked {c} #{f}", h) for f in frames]
    sides = [side_tile(m, f, h * 2 // 3, h) for f in frames]
    rows = [np.concatenate([row[i], sides[i], row[i + 1], sides[i + 1]], axis=1) for i in (0, 2)]
    write_small_png(dest, np.concatenate(rows, axis=0))


if __name__ == "__main__":
    what, *paths = sys.argv[1:]
    args = [Path(p) for p in paths]
    {"pose2sim": pose2sim, "sports2d-session": sports2d_session, "sports2d": sports2d}[what](*args)
