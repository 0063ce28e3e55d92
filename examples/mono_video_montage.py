"""Montages of the monocular tracker on real video (docs/mono.md, "Real video").

    python examples/mono_video_montage.py sports2d   # -> docs/mono_sports2d_montage.png
    python examples/mono_video_montage.py pose2sim   # -> docs/mono_pose2sim_montage.png

Reads the videos from the first ``shared/data/video`` above the repository
(``MOCAPKIT_SHARED_DATA`` overrides ``shared/data``, as for the tests); nothing
is copied into the repository. Prints the tracking summary.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from mocapkit.io.cameras import read_qualisys
from mocapkit.pipelines.mono_video import montage, track_video, write_png

ROOT = Path(__file__).resolve().parents[1]


def _video_dir() -> Path:
    env = os.environ.get("MOCAPKIT_SHARED_DATA")
    if env:
        return Path(env) / "video"
    for parent in ROOT.parents:
        if (parent / "shared" / "data" / "video").is_dir():
            return parent / "shared" / "data" / "video"
    raise SystemExit("shared/data/video not found above the repository; set MOCAPKIT_SHARED_DATA")


def main(which: str) -> None:
    data = _video_dir()
    if which == "sports2d":
        track = track_video(data / "sports2d_demo.mp4", start_s=2.0, seconds=4.0)
    elif which == "pose2sim":
        p2s = data / "pose2sim_demo_singleperson"
        cams = {c.name: c for c in read_qualisys(p2s / "calibration" / "Calib.qca.txt")}
        cam = cams.get("cam01")
        track = track_video(p2s / "videos" / "cam01.mp4", start_s=0.0, seconds=1.67, camera=cam)
    else:
        raise SystemExit(f"expected sports2d or pose2sim, found {which!r}")
    for key, value in track.summary().items():
        print(f"{key}: {value:.3g}")
    out = ROOT / "docs" / f"mono_{which}_montage.png"
    write_png(out, montage(track))
    print(f"wrote {out}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "sports2d")
