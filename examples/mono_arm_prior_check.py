"""The arm prior checked without fitting on the clips it is tested on.

    python examples/mono_arm_prior_check.py WORK_DIR '[{"arm_prior_weight": 30}]'
    python examples/mono_arm_prior_check.py WORK_DIR '[{"arm_prior_weight": 0}, {}]' MOCAP

For each `MonoConfig` setting of the JSON list: the five clips of ``mocapkit accuracy
mono`` with the shipped table (fitted on none of them), and each of the four held-out
clips (01_12, 11_01, 131_01, 131_03) with a prior fitted as the shipped one
(``tools/mono_fit_arm_prior.py``) but without that clip (leave one clip out). Sessions
are rendered into WORK_DIR on first use (as ``mocapkit accuracy mono --work``), tracked
from the true 2-D keypoints plus 2 px noise (seed 0). Prints one JSON line per setting:
per clip (name, Procrustes upper-body mm, flips right %) and the means of each group.
"""

from __future__ import annotations

import importlib.util
import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from mocapkit.pipelines.demo import find_shared_data
from mocapkit.pipelines.mono_accuracy import MONO_CLIPS, mono_accuracy
from mocapkit.tracking.mono.tracker import MonoConfig

HELD_OUT = ("01_12.amc", "11_01.amc", "131_01.bvh", "131_03.bvh")


def _fit_module():  # type: ignore[no-untyped-def]
    path = Path(__file__).resolve().parents[1] / "tools" / "mono_fit_arm_prior.py"
    spec = importlib.util.spec_from_file_location("mono_fit_arm_prior", path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def main(work: str, settings: str = "[{}]", mocap: str | None = None) -> None:
    if mocap is None:
        data = find_shared_data()
        if data is None:
            raise SystemExit("no MOCAP folder given and ../shared/data/mocap not found")
        mocap = str(data / "mocap")
    fit = _fit_module()
    loo = {c: fit.fit_on([x for x in fit.CLIPS if x != c], Path(mocap))[0] for c in HELD_OUT}
    for kw in json.loads(settings):
        cfg = MonoConfig(**kw)
        out: dict = {"settings": kw}
        five = mono_accuracy(mocap, work, clips=tuple(MONO_CLIPS), config=cfg)
        held = [
            r
            for c in HELD_OUT
            for r in mono_accuracy(mocap, work, clips=[c], config=replace(cfg, arm_prior=loo[c]))
        ]
        for group, rows in (("five", five), ("held_out_loo", held)):
            out[group] = [
                (r.clip, round(r.pa_mpjpe_mm, 1), round(100 * r.flips_right, 1)) for r in rows
            ]
            out[group + "_mean"] = (
                round(float(np.mean([r.pa_mpjpe_mm for r in rows])), 1),
                round(float(100 * np.mean([r.flips_right for r in rows])), 1),
            )
        print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main(*sys.argv[1:4])
