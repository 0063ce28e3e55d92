"""Mono accuracy of one tracker setting on the five accuracy clips and four held-out clips.

    python examples/mono_prior_sweep.py WORK_DIR '{"clavicle_weight": 300}'
    python examples/mono_prior_sweep.py WORK_DIR '{"clavicle_weight": 0}'   # the paper's
    python examples/mono_prior_sweep.py WORK_DIR '{}' /path/to/shared/data/mocap

The JSON holds `MonoConfig` fields (``residual_weight``, ``elbow_flex_weight``,
``depth_velocity_weight``, ``joint_acceleration_weight``, ``clavicle_weight``,
``depth_window``, ``lag``, ...). Sessions are rendered into WORK_DIR on first use (as
`mocapkit accuracy mono --work WORK_DIR`), then tracked from the true 2-D keypoints plus
2 px noise (seed 0); the clips are read from the third argument (default
``../shared/data/mocap``). Prints one JSON line: per clip (name, Procrustes upper-body mm,
flips right %), the means of each group and the CPU seconds.
"""

from __future__ import annotations

import json
import sys
import time

from mocapkit.pipelines.mono_accuracy import MONO_CLIPS, mono_accuracy
from mocapkit.tracking.mono.tracker import MonoConfig

MOCAP = "../shared/data/mocap"
HELD_OUT = ("01_12.amc", "11_01.amc", "131_01.bvh", "131_03.bvh")


def main(work: str, settings: str = "{}", mocap: str = MOCAP) -> None:
    kw = json.loads(settings)
    cfg = MonoConfig(**kw)
    t0 = time.process_time()
    out: dict = {"settings": kw}
    for group, clips in (("five", tuple(MONO_CLIPS)), ("held_out", HELD_OUT)):
        rows = mono_accuracy(mocap, work, clips=clips, config=cfg)
        out[group] = [
            (r.clip, round(r.pa_mpjpe_mm, 1), round(100 * r.flips_right, 1)) for r in rows
        ]
        out[group + "_mean"] = (
            round(sum(r.pa_mpjpe_mm for r in rows) / len(rows), 1),
            round(100 * sum(r.flips_right for r in rows) / len(rows), 1),
        )
    out["cpu_s"] = round(time.process_time() - t0, 1)
    print(json.dumps(out))


if __name__ == "__main__":
    main(*sys.argv[1:4])
