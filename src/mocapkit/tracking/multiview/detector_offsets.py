"""The 2-D detectors' systematic keypoint offsets, per canonical joint, for the multi-view
fit (`MultiviewTracker`'s ``point_offsets_mm``).

A detector marks a joint where its training labels put it, not at the joint's centre; a
MediaPipe ankle, for one, sits above it, the same way in every view. Each offset is the
mean, over the fitted frames, of the fitted joint minus the true joint (mm) in the frame
of the segment that ends at the joint (the shank's for the ankle, the forearm's for the
wrist: `offset_points`), fixed by the detections where the joint's own frame (the foot's,
the hand's) is not; learned by
``tools/multiview_detector_offsets.py`` on the tuning clips; the table is
`mocapkit.tracking.multiview.detector_offsets_table`. A backend without a table (and
keypoints of unknown origin) has none; which backend wrote a session's keypoints is
`mocapkit.detect.run.detected_backend`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from mocapkit.skeleton.kinematics import canonical_positions
from mocapkit.skeleton.model import CANONICAL_SEGMENTS, Skeleton
from mocapkit.tracking.multiview.detector_offsets_table import OFFSETS_MM

FloatArray = NDArray[np.float64]

#: Joints a detector's reader places as midpoints of a pair (`mocapkit.io.openpose`):
#: their offset is the pair's mean.
MIDPOINTS: dict[str, tuple[str, str]] = {
    "neck": ("left_shoulder", "right_shoulder"),
    "pelvis": ("left_hip", "right_hip"),
}


def detector_offsets(backend: str | None) -> dict[str, tuple[float, float, float]]:
    """Offsets (mm, in each joint's segment frame) of ``backend``'s keypoints; empty for a
    backend without a table or ``None``."""
    if backend is None:
        return {}
    return {
        k: (float(v[0]), float(v[1]), float(v[2])) for k, v in OFFSETS_MM.get(backend, {}).items()
    }


def offset_points(
    skeleton: Skeleton, names: Sequence[str], offsets_mm: Mapping[str, Sequence[float]]
) -> tuple[NDArray[np.int64], FloatArray]:
    """The joint (K,) and the point in its frame (K, 3) that the fit matches to the
    detections of each canonical joint in ``names``: the canonical joint itself without
    an offset; with one, the joint's origin plus its offset in its parent joint's frame
    (the segment ending at the joint), or the canonical point plus the offset in its own
    frame for a point that is not a joint's origin (the head)."""
    tj, tp = skeleton.canonical_points(names)
    tj = np.array(tj, dtype=np.int64)
    tp = np.array(tp, dtype=float)
    for k, n in enumerate(names):
        if n not in offsets_mm:
            continue
        o = np.asarray(offsets_mm[n], dtype=float)
        parent = int(skeleton.parents[tj[k]])
        if parent >= 0 and not np.any(tp[k]):
            tp[k] = skeleton.offsets_mm[tj[k]] + o
            tj[k] = parent
        else:
            tp[k] = tp[k] + o
    return tj, tp


def offset_segments(
    skeleton: Skeleton,
    lengths_mm: dict[str, float],
    vectors_mm: dict[str, FloatArray],
    offsets_mm: Mapping[str, Sequence[float]],
) -> tuple[dict[str, float], dict[str, FloatArray]]:
    """The subject's segment lengths and trunk rest vectors measured from the detections
    (`mocapkit.tracking.multiview.lengths.subject_lengths_mm`) with the detector's offsets
    taken out: a segment from ``a`` to ``b`` measures its true rest vector plus ``o_b -
    o_a``. The offsets are taken as at ``skeleton``'s rest pose (its joint frames then
    share the body's axes), each length corrected along the segment's rest direction: a
    first-order correction, exact when the segment's joints are straight.
    """
    if not offsets_mm:
        return lengths_mm, vectors_mm
    off = {k: np.asarray(v, dtype=float) for k, v in offsets_mm.items()}
    for mid, (a, b) in MIDPOINTS.items():
        if mid not in off and a in off and b in off:
            off[mid] = 0.5 * (off[a] + off[b])
    names = list(skeleton.canonical_names)
    rest = canonical_positions(skeleton, skeleton.zero_pose())
    zero = np.zeros(3)
    lengths = dict(lengths_mm)
    for seg, length in lengths_mm.items():
        a, b = CANONICAL_SEGMENTS[seg]
        if a not in names or b not in names:
            continue
        u = rest[names.index(b)] - rest[names.index(a)]
        u = u / np.linalg.norm(u)
        lengths[seg] = float(length - np.dot(off.get(b, zero) - off.get(a, zero), u))
    vectors = {
        seg: np.asarray(v, dtype=float)
        - (off.get(CANONICAL_SEGMENTS[seg][1], zero) - off.get(CANONICAL_SEGMENTS[seg][0], zero))
        for seg, v in vectors_mm.items()
    }
    return lengths, vectors


__all__ = [
    "MIDPOINTS",
    "detector_offsets",
    "offset_points",
    "offset_segments",
]
