"""The detector's error measures on known cases."""

from __future__ import annotations

import numpy as np

from mocapkit.pipelines.detect_accuracy import DetectErrors, compare
from mocapkit.skeleton.model import CANONICAL_JOINTS


def _acc() -> DetectErrors:
    return DetectErrors(CANONICAL_JOINTS, [np.zeros(0) for _ in CANONICAL_JOINTS])


def test_swaps_misses_and_errors_are_counted(rng: np.random.Generator) -> None:
    names = CANONICAL_JOINTS
    truth = np.tile(rng.uniform(100, 300, (1, len(names), 2)), (4, 1, 1))
    det = truth + 2.0  # every joint 2 px off in x and y
    left = [i for i, n in enumerate(names) if n.startswith("left_")]
    right = [names.index(names[i].replace("left_", "right_")) for i in left]
    det[1, left], det[1, right] = truth[1, right], truth[1, left]  # whole body swapped
    det[2, [names.index("left_wrist"), names.index("right_wrist")]] = truth[
        2, [names.index("right_wrist"), names.index("left_wrist")]
    ]  # one pair swapped
    det[3] = np.nan  # nobody
    truth[3, :, 0] += 1000  # ... and the subject out of view: not a miss
    acc = _acc()
    compare(det, truth, names, acc, (640, 480))
    assert acc.frames == 4 and acc.in_view == 3 and acc.no_person == 0
    assert acc.body_swaps == 1 and acc.limb_swaps == 2  # the body swap swaps limbs too
    head = acc.rows()[names.index("head")]
    assert head["median_px"] == np.hypot(2, 2) and head["frames"] == 3
    det[3] = np.nan
    truth[3, :, 0] -= 1000  # in view now: a miss
    acc = _acc()
    compare(det, truth, names, acc, (640, 480))
    assert acc.no_person == 1 and acc.shares()["no_person"] == 0.25
