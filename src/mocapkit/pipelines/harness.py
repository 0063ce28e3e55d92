"""Settings and steps the accuracy and speed harnesses share, light to import (the CLI help
shows the settings; a step imports what it needs when called)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

#: Half-width (mm) of the uniform marker jitter of
#: `mocapkit.pipelines.accuracy.hybrid_accuracy_repeats`: far below the rendered marker
#: noise (about 1 mm) and the 1 mm the comparisons resolve, far above double round-off at
#: 1-2 m (2e-13 mm).
JITTER_MM = 1e-6

#: The project's split of the CMU clips of ``shared/data/mocap``: constants are chosen on
#: the tuning clips and figures reported on the report clips, which nothing was fitted or
#: tuned on. The accuracy harnesses' default clips are the tuning set; each harness keeps
#: its own excerpt window per clip.
TUNING_CLIPS: tuple[str, ...] = (
    "13_26.bvh",
    "01_09.amc",
    "lambada.amc",
    "charleston1.amc",
    "zombie.amc",
)
REPORT_CLIPS: tuple[str, ...] = (
    "01_01.amc",
    "01_12.amc",
    "11_01.amc",
    "131_01.bvh",
    "131_03.bvh",
)
#: The clip sets by the name ``mocapkit accuracy --clip-set`` takes.
CLIP_SETS: dict[str, tuple[str, ...]] = {"tuning": TUNING_CLIPS, "report": REPORT_CLIPS}

#: The 2-D detectors an accuracy harness can run on its rendered video: the backends that
#: need no model file (`mocapkit.detect.backend.BACKENDS`).
HARNESS_DETECTORS: tuple[str, ...] = ("mediapipe",)


def detector_keypoints(
    base: str | os.PathLike[str],
    session: str | os.PathLike[str],
    detector: str,
    overwrite: bool,
    cameras: Sequence[str] | None = None,
) -> Path:
    """Run ``detector`` on the rendered video of a session's ``cameras`` (default every
    camera with a video) into ``base/detect_<detector>`` (kept: a rerun reuses each
    camera's detections unless ``overwrite``); returns that folder
    (`mocapkit.detect.run` layout: ``keypoints/<camera>.csv``,
    ``keypoints/openpose/<camera>/``, ``keypoints3d/<camera>.npz``)."""
    from mocapkit.detect.run import detect_session, detect_sources
    from mocapkit.io.session import load_session

    out = Path(base) / f"detect_{detector}"
    if cameras is None:
        detect_session(session, detector, overwrite=overwrite, out_dir=out)
    else:
        s = load_session(session)
        detect_sources([s.video(c) for c in cameras], out, detector, overwrite=overwrite)
    return out
