"""Does the arm prior favour one side of the image plane? The true arm against its mirror.

    python examples/mono_arm_prior_mirror.py WORK_DIR [CLIP ...]

For each clip (sessions rendered into WORK_DIR as ``mocapkit accuracy mono --work
WORK_DIR`` does; default: the five of ``mocapkit accuracy mono``) and each arm, the true
joints in the camera frame are compared with the same pose whose upper arm is mirrored
through the image plane at the shoulder (its depth component negated; the forearm vector
kept, so the forearm's flip is the truth's), which is the mirror the enumeration offers
under near-orthography. Over the link-frames the flip figure counts (the upper arm at
least 12 deg out of the image plane), one JSON line per clip and arm: the share where the
shipped arm prior (`mocapkit.tracking.mono.arm_prior.default_arm_prior`) costs the truth
less than the mirror, that share among the frames whose true upper arm points away from
the camera and among those pointing towards it, and the median costs (nats) of both.
A prior biased towards forward reach would prefer the mirror of arms pointing away.
"""

from __future__ import annotations

import json
import sys

import numpy as np

from mocapkit.io.session import load_session
from mocapkit.pipelines.demo import find_shared_data
from mocapkit.pipelines.mono_accuracy import (
    FLIP_MIN_SINE,
    MONO_CLIPS,
    mono_session,
    truth_in_camera,
)
from mocapkit.tracking.mono.arm_prior import arm_features, default_arm_prior
from mocapkit.tracking.mono.stick import stick_model


def _share(mask: np.ndarray, better: np.ndarray) -> float | None:
    return round(100 * float(better[mask].mean()), 1) if mask.any() else None


def main(work: str, *clips: str) -> None:
    model = stick_model()
    prior = default_arm_prior()
    for clip in clips or tuple(MONO_CLIPS):
        data = find_shared_data()
        if data is None:
            raise SystemExit("../shared/data/mocap not found")
        session = mono_session(data / "mocap", work, clip)  # rendered unless already there
        s = load_session(session)
        cam = truth_in_camera(s, s.cameras[0].name, model)
        for arm, side in enumerate(("left", "right")):
            sh, el, wr = (
                model.joint_names.index(f"{side}_{j}") for j in ("shoulder", "elbow", "wrist")
            )
            upper = cam[:, el] - cam[:, sh]
            mirror = cam.copy()
            mirror[:, el] = cam[:, sh] + upper * np.array([1.0, 1.0, -1.0])
            mirror[:, wr] = mirror[:, el] + (cam[:, wr] - cam[:, el])
            true_cost = prior.arm_cost(arm_features(model, cam))[:, arm]
            mirror_cost = prior.arm_cost(arm_features(model, mirror))[:, arm]
            counted = np.abs(upper[:, 2]) >= FLIP_MIN_SINE * np.linalg.norm(upper, axis=1)
            away = upper[:, 2] > 0
            better = true_cost < mirror_cost
            print(json.dumps({
                "clip": clip, "arm": side, "counted": int(counted.sum()),
                "prefers_truth_pct": _share(counted, better),
                "away_frames": int((counted & away).sum()),
                "prefers_truth_away_pct": _share(counted & away, better),
                "prefers_truth_towards_pct": _share(counted & ~away, better),
                "median_nats_truth": round(float(np.median(true_cost[counted])), 1),
                "median_nats_mirror": round(float(np.median(mirror_cost[counted])), 1),
            }))  # fmt: skip


if __name__ == "__main__":
    main(*sys.argv[1:])
