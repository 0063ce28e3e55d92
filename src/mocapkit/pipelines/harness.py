"""Settings the accuracy and speed harnesses share, light to import (the CLI help shows them)."""

from __future__ import annotations

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
