"""Follow one person through a video, frame by frame, among the people a detector finds.

The person is chosen on the first frame with anyone in it: the largest (bounding box of
the confident keypoints, the one nearest the camera, usually the subject) or, given an
image point, the one whose box holds it (else the nearest box centre). In every later frame
the candidate is taken whose keypoints lie nearest (mean distance over the keypoints
confident in it and seen before) to the followed person's last seen ones, if that distance
is within ``max_jump`` times the person's size per frame since they were last seen (at most
``max_reach`` sizes however long the gap), and
the spread of those keypoints about their mean is within a factor ``max_scale`` of the
last (a nearer person at the same place is someone else); otherwise the frame has
nobody, and a bystander is never taken in the followed person's place. The size is the
diagonal of the box of every keypoint at its last seen place, so that a partial view
(legs out of the image) neither shrinks it nor, being compared joint by joint, moves the
person. That box is also where a backend that finds one person per call
(`mocapkit.detect.backend.Detector.multi_person` false) looks again. The same rule as
`mocapkit.io.openpose.follow_person` applies to OpenPose files, after the fact; this one
runs during detection, which it steers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from mocapkit.detect.backend import FloatArray, PersonPose
from mocapkit.errors import ShapeError

Box = tuple[float, float, float, float]


def person_box(keypoints: ArrayLike, min_confidence: float = 0.3) -> Box | None:
    """Bounding box (x0, y0, x1, y1 px) of the keypoints (J, 3) at or above
    ``min_confidence``; None with fewer than two such points."""
    kp = np.asarray(keypoints, dtype=float)
    if kp.ndim != 2 or kp.shape[1] != 3:
        raise ShapeError(f"person_box: expected (J, 3) keypoints, found {kp.shape}")
    ok = kp[:, 2] >= min_confidence
    if ok.sum() < 2:
        return None
    xy = kp[ok, :2]
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
        Largest mean move of the keypoints per frame, in person sizes.
    max_scale : float
        Largest change of the keypoints' spread between two frames (factor; it grows
        by a tenth per frame missed).
    min_confidence : float
        Keypoints below this confidence count as not seen.
    min_common : int
        Keypoints that must be seen in both frames for a comparison.
    max_reach : float
        Cap of the allowed move after a gap, in person sizes: a person unseen for long
        is taken again only near where they were lost (else someone entering elsewhere
        after the subject left the image would be taken for them).
    """

    start_px: tuple[float, float] | None = None
    max_jump: float = 0.25
    max_scale: float = 1.6
    min_confidence: float = 0.3
    min_common: int = 3
    max_reach: float = 2.0

    def __post_init__(self) -> None:
        self.last_px: FloatArray | None = None
        self.first_box: Box | None = None
        self.first_frame: int | None = None
        self._last_t = 0

    @property
    def last_box(self) -> Box | None:
        """Box of every keypoint at its last seen place (None before the first sighting)."""
        if self.last_px is None:
            return None
        xy = self.last_px[np.isfinite(self.last_px).all(axis=1)]
        return (float(xy[:, 0].min()), float(xy[:, 1].min()),
                float(xy[:, 0].max()), float(xy[:, 1].max()))  # fmt: skip

    def choose(self, t: int, people: list[PersonPose]) -> int | None:
        """Index of the followed person among ``people`` at frame ``t``; None: not there.

        Call with increasing ``t``; a chosen person updates the follower's state.
        """
        boxes = [person_box(p.keypoints, self.min_confidence) for p in people]
        idx = [i for i, b in enumerate(boxes) if b is not None]
        if not idx:
            return None
        if self.last_px is None:
            if self.start_px is None:
                pick = max(idx, key=lambda i: _diag(boxes[i]))  # type: ignore[arg-type]
            else:
                pick = min(idx, key=lambda i: self._start_cost(boxes[i]))  # type: ignore[arg-type]
                if not self._holds_start(boxes[pick]):  # type: ignore[arg-type]
                    return None
            self.first_box, self.first_frame = boxes[pick], t
            self.last_px = np.full((people[pick].keypoints.shape[0], 2), np.nan)
        else:
            gap = max(t - self._last_t, 1)
            size = _diag(self.last_box)  # type: ignore[arg-type]
            cost = {i: self._distance(people[i].keypoints) for i in idx}
            pick = min(idx, key=lambda i: cost[i][0])
            dist, ratio = cost[pick]
            bound = self.max_scale * (1.0 + 0.1 * (gap - 1))
            reach = min(self.max_jump * gap, self.max_reach) * size
            if not (dist <= reach and 1 / bound <= ratio <= bound):
                return None
        kp = people[pick].keypoints
        seen = kp[:, 2] >= self.min_confidence
        self.last_px[seen] = kp[seen, :2]
        self._last_t = t
        return pick

    def _distance(self, keypoints: FloatArray) -> tuple[float, float]:
        """Mean distance to the last seen keypoints and the ratio of the spreads, over the
        keypoints seen in both; (inf, 1) with fewer than ``min_common`` of them."""
        assert self.last_px is not None
        both = (keypoints[:, 2] >= self.min_confidence) & np.isfinite(self.last_px).all(axis=1)
        if both.sum() < self.min_common:
            return float("inf"), 1.0
        a, b = keypoints[both, :2], self.last_px[both]
        dist = float(np.linalg.norm(a - b, axis=1).mean())
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


__all__ = ["PersonFollower", "person_box"]
