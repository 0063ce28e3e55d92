"""Follow one person through a video, frame by frame, among the people a detector finds.

Each frame's candidates are 2-D points (J, 2) px, NaN where a keypoint is not seen (a
detector's keypoints below `MIN_CONFIDENCE`: `seen_points`). The person is chosen on the
first frame with anyone in it (two points or more): the largest (bounding box of the seen
points, the one nearest the camera, usually the subject) or, given an image point, the
one whose box holds it (else the nearest box centre; nobody while no box grown by half its
size holds it). In every later frame the candidate is taken whose points lie nearest (mean
distance over the points seen in it and seen before) to the followed person's last seen
ones, if that distance is within ``max_jump`` times the person's size per frame since they
were last seen (at most ``max_reach`` sizes however long the gap), and the spread of those
points about their mean is within a factor ``max_scale`` of the last (a nearer person at
the same place is someone else; not checked on a single point); otherwise the frame has
nobody, and a bystander is never taken in the followed person's place. The size is the
diagonal of the box of every point at its last seen place, so that a partial view (legs
out of the image, a subject down to one arm at the image's edge) neither shrinks it nor,
being compared point by point, moves the person. That box is also where a detector that
finds one person per call looks again (`PersonFollower.search_region`).

`mocapkit.detect.run` follows during detection, which it steers, on a detector's
keypoints; `mocapkit.io.openpose.read_openpose_folder` after the fact, on an OpenPose
folder's own keypoints, so that on a folder the detection wrote it keeps every frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ShapeError

FloatArray = NDArray[np.float64]
Box = tuple[float, float, float, float]

#: Keypoints below this confidence count as not seen (OpenPose's and the detectors' floor).
MIN_CONFIDENCE = 0.3


def seen_points(keypoints: ArrayLike, min_confidence: float = MIN_CONFIDENCE) -> FloatArray:
    """A detector's keypoints (J, 3: x, y, confidence) as points (J, 2), NaN where the
    confidence is below ``min_confidence`` or the point is written 0, 0, 0 (OpenPose's
    missing point)."""
    kp = np.asarray(keypoints, dtype=float)
    if kp.ndim != 2 or kp.shape[1] != 3:
        raise ShapeError(f"seen_points: expected (J, 3) keypoints, found {kp.shape}")
    seen = (kp[:, 2] >= min_confidence) & np.any(kp != 0.0, axis=1)
    return np.where(seen[:, None], kp[:, :2], np.nan)


def points_box(points: ArrayLike) -> Box | None:
    """Bounding box (x0, y0, x1, y1 px) of the seen points (J, 2; NaN: not seen); None
    with fewer than two."""
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ShapeError(f"points_box: expected (J, 2) points, found {p.shape}")
    xy = p[np.isfinite(p).all(axis=1)]
    if xy.shape[0] < 2:
        return None
    return (float(xy[:, 0].min()), float(xy[:, 1].min()),
            float(xy[:, 0].max()), float(xy[:, 1].max()))  # fmt: skip


def _centre(b: Box) -> FloatArray:
    return np.array([0.5 * (b[0] + b[2]), 0.5 * (b[1] + b[3])])


def _diag(b: Box) -> float:
    return float(np.hypot(b[2] - b[0], b[3] - b[1]))


@dataclass
class PersonFollower:
    """Chooses the followed person among each frame's candidates (module docstring).

    Parameters
    ----------
    start_px : (x, y) or None
        Follow the person at this image point on the first frame; None: the largest.
    max_jump : float
        Largest mean move of the points per frame, in person sizes.
    max_scale : float
        Largest change of the points' spread between two frames (factor; it grows by a
        tenth per frame missed).
    max_reach : float
        Cap of the allowed move after a gap, in person sizes: a person unseen for long
        is taken again only near where they were lost (else someone entering elsewhere
        after the subject left the image would be taken for them).
    """

    start_px: tuple[float, float] | None = None
    max_jump: float = 0.25
    max_scale: float = 1.6
    max_reach: float = 2.0

    def __post_init__(self) -> None:
        self.last_px: FloatArray | None = None
        self.first_box: Box | None = None
        self.first_frame: int | None = None
        self._last_t = 0

    @property
    def last_box(self) -> Box | None:
        """Box of every point at its last seen place (None before the first sighting)."""
        return None if self.last_px is None else points_box(self.last_px)

    def choose(self, t: int, people: Sequence[FloatArray]) -> int | None:
        """Index of the followed person among ``people`` (each (J, 2) px, NaN where not
        seen) at frame ``t``; None: not there.

        Call with increasing ``t``; a chosen person updates the follower's state.
        """
        if self.last_px is None:
            boxes = [points_box(p) for p in people]
            idx = [i for i, b in enumerate(boxes) if b is not None]
            if not idx:
                return None
            if self.start_px is None:
                pick = max(idx, key=lambda i: _diag(boxes[i]))  # type: ignore[arg-type]
            else:
                pick = min(idx, key=lambda i: self._start_cost(boxes[i]))  # type: ignore[arg-type]
                if not self._holds_start(boxes[pick]):  # type: ignore[arg-type]
                    return None
            self.first_box, self.first_frame = boxes[pick], t
            self.last_px = np.full((people[pick].shape[0], 2), np.nan)
        else:
            if not people:
                return None
            gap = max(t - self._last_t, 1)
            size = _diag(self.last_box)  # type: ignore[arg-type]
            cost = [self._distance(p) for p in people]
            pick = min(range(len(people)), key=lambda i: cost[i][0])
            dist, ratio = cost[pick]
            bound = self.max_scale * (1.0 + 0.1 * (gap - 1))
            reach = min(self.max_jump * gap, self.max_reach) * size
            if not (dist <= reach and 1 / bound <= ratio <= bound):
                return None
        p = people[pick]
        seen = np.isfinite(p).all(axis=1)
        self.last_px[seen] = p[seen]
        self._last_t = t
        return pick

    def _distance(self, points: FloatArray) -> tuple[float, float]:
        """Mean distance to the last seen points and the ratio of the spreads, over the
        points seen in both; (inf, 1) with none, ratio 1 with one."""
        assert self.last_px is not None
        both = np.isfinite(points).all(axis=1) & np.isfinite(self.last_px).all(axis=1)
        if not both.any():
            return float("inf"), 1.0
        a, b = points[both], self.last_px[both]
        dist = float(np.linalg.norm(a - b, axis=1).mean())
        if a.shape[0] < 2:
            return dist, 1.0
        spread_a = float(np.sqrt(((a - a.mean(axis=0)) ** 2).sum(axis=1).mean()))
        spread_b = float(np.sqrt(((b - b.mean(axis=0)) ** 2).sum(axis=1).mean()))
        return dist, spread_a / max(spread_b, 1e-9)

    def _start_cost(self, box: Box) -> float:
        assert self.start_px is not None
        inside = box[0] <= self.start_px[0] <= box[2] and box[1] <= self.start_px[1] <= box[3]
        d = float(np.linalg.norm(_centre(box) - np.asarray(self.start_px)))
        return d - (1e9 if inside else 0.0)

    def _holds_start(self, box: Box) -> bool:
        """Whether ``box``, grown by half its size, holds the start point."""
        assert self.start_px is not None
        c, half = _centre(box), 0.75 * np.array([box[2] - box[0], box[3] - box[1]])
        return bool(np.all(np.abs(np.asarray(self.start_px) - c) <= half))

    def search_region(self, image_shape: tuple[int, ...]) -> Box | None:
        """Where to look again for the followed person (None before the first sighting,
        when there is no start point): the last box, or a square of half the image's
        height round the start point."""
        if self.last_box is not None:
            return self.last_box
        if self.start_px is None:
            return None
        half = 0.25 * float(image_shape[0])
        x, y = self.start_px
        return (x - half, y - half, x + half, y + half)

    def describe(self) -> str:
        """Which person was followed (for the output's summary)."""
        if self.first_box is None:
            return "nobody was found"
        rule = (
            "the largest person"
            if self.start_px is None
            else f"the person nearest ({self.start_px[0]:.0f}, {self.start_px[1]:.0f}) px"
        )
        b = self.first_box
        return (
            f"{rule} on frame {self.first_frame}, box x {b[0]:.0f}-{b[2]:.0f}, "
            f"y {b[1]:.0f}-{b[3]:.0f} px"
        )


__all__ = ["MIN_CONFIDENCE", "PersonFollower", "points_box", "seen_points"]
