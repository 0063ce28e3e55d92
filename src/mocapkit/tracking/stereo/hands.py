"""3-D head and hand tracking from skin blobs in several views (Azad et al. 2008 §II-C.2).

The distance cue needs the 3-D head and hands. The paper tracks them with separate
particle filters on the skin images ([12]); this module does the same job with
explicit blob matching, which is deterministic and cheap:

1. per view, the connected components of the skin mask larger than ``min_area_px``
   (the ``max_blobs`` largest) are candidate 2-D points (their centroids);
2. every pair of candidates from the first two views that see any is triangulated
   (with every other view's nearest candidate added when it reprojects within
   ``max_reproj_px``), and kept when its reprojection error is below ``max_reproj_px``
   in each used view: candidate 3-D points;
3. the three targets (head, left hand, right hand) are assigned to candidates by
   minimum total distance to their constant-velocity predictions (Hungarian
   assignment, gated at ``gate_mm``), so that the hands keep their identity through
   crossings; a hand without a candidate coasts on its prediction for up to
   ``coast_frames`` frames and is then reported lost (NaN); when the two hands' blobs
   merge (a crossing: one candidate is the nearest to both predictions) both coast
   through it, since the merged centroid is neither hand; an unseen head is held
   differently (below);
4. initialisation (and re-initialisation of a lost target): the head is the largest
   candidate (a face is the largest skin blob; the highest candidate can be a ghost
   from a wrong pair), taken only when no other candidate lies more than 100 mm above
   it (a subject turned away shows no face); the hands the others farther than
   `HAND_HEAD_MIN_MM` from the head, left/right by their side of the head in the
   torso frame (x to the subject's right).

The unseen head (a gap in the paper, which tracks the head by its skin blob alone and
does not say what happens when there is none). When the subject turns the face away,
the skin blobs give only the hands, for as long as the subject looks away (often
longer than a hand is hidden). A constant-velocity coast would carry the head off
along the velocity it had when it turned (a turning head's centroid moves sideways
as the face leaves the view), and releasing it after ``coast_frames`` opens the way
for `_initialise` to take the next largest blob, a hand, for the head. So the head is
held instead: its velocity is halved every unseen frame (the held point moves at most
one frame's motion beyond where it was last seen: v dt (1/2 + 1/4 + ...) <= v dt),
it keeps its gate, so the face is taken back where it reappears, and it is released
(NaN) only after ``head_coast_frames`` unseen frames. While held it is not a
measurement: `HeadHandTracker.update` reports NaN for it, as for a coasting hand.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from mocapkit.camera.pinhole import Camera
from mocapkit.camera.triangulation import triangulate_views
from mocapkit.errors import ConfigError

FloatArray = NDArray[np.float64]

#: Nearest a hand may be to the head when it is (re-)initialised (mm).
HAND_HEAD_MIN_MM = 200.0

#: Targets, in output order.
TARGETS = ("head", "left_hand", "right_hand")


@dataclass(frozen=True)
class BlobConfig:
    """Settings of `skin_blobs` and `HeadHandTracker` (areas in full-resolution pixels).

    Parameters
    ----------
    min_area_px : int
        Smallest skin component taken as a blob (px, full resolution).
    max_blobs : int
        Largest components kept per view.
    max_reproj_px : float
        Largest reprojection error of a candidate 3-D point in each view (px).
    gate_mm : float
        Largest distance (mm) of a candidate from a target's prediction for a match.
    coast_frames : int
        Unseen frames a hand coasts on its constant-velocity prediction before it is
        released (NaN).
    head_coast_frames : int
        Unseen frames the head is held (its velocity halved every frame) before it is
        released (module notes: the unseen head); 15 = 0.5 s at 30 frames/s.
    max_speed_mm_s : float
        Cap on a target's velocity estimate (mm/s).
    downsample : int
        Blobs are found on every ``downsample``-th pixel.
    max_area_ratio : float
        Largest area ratio of two blobs paired across views.
    """

    min_area_px: int = 25
    max_blobs: int = 6
    max_reproj_px: float = 12.0
    gate_mm: float = 250.0
    coast_frames: int = 10
    head_coast_frames: int = 15
    max_speed_mm_s: float = 6000.0
    downsample: int = 2
    max_area_ratio: float = 2.5

    def __post_init__(self) -> None:
        if self.min_area_px < 1 or self.max_blobs < 1:
            raise ConfigError(
                f"BlobConfig: expected min_area_px >= 1 and max_blobs >= 1, found "
                f"{self.min_area_px} and {self.max_blobs}"
            )
        if not (self.max_reproj_px > 0 and self.gate_mm > 0 and self.coast_frames >= 0):
            raise ConfigError("BlobConfig: max_reproj_px, gate_mm must be > 0, coast_frames >= 0")
        if not self.head_coast_frames >= 0:
            raise ConfigError(
                f"BlobConfig: head_coast_frames: expected >= 0, found {self.head_coast_frames}"
            )


def skin_blobs(mask: NDArray[np.uint8], config: BlobConfig) -> tuple[FloatArray, FloatArray]:
    """Centroids (K, 2) px and areas (K,) px of the ``max_blobs`` largest skin components.

    The components are found on every ``config.downsample``-th pixel (a quarter of the
    work at 2; hands and faces span tens of pixels), centroids and areas scaled back.
    """
    k = max(int(config.downsample), 1)
    small = mask[::k, ::k] if k > 1 else mask
    _n, _labels, stats, centroids = cv2.connectedComponentsWithStats(
        (small > 0).astype(np.uint8), connectivity=8
    )
    areas = stats[1:, cv2.CC_STAT_AREA].astype(float) * (k * k)
    cents = np.asarray(centroids[1:], dtype=float) * k
    keep = areas >= config.min_area_px
    areas, cents = areas[keep], cents[keep]
    order = np.argsort(-areas)[: config.max_blobs]
    return cents[order], areas[order]


def candidates_3d(
    cameras: Sequence[Camera],
    blobs: Sequence[FloatArray],
    config: BlobConfig,
    areas: Sequence[FloatArray] | None = None,
) -> FloatArray:
    """Candidate 3-D points (M, 3) from per-view blob centroids (module notes, step 2).

    With the blobs' ``areas``, pairs whose areas differ by more than
    ``config.max_area_ratio`` are not matched (one object has about the same size in
    nearby views; a face paired with a hand gives a ghost point), and the candidates
    come largest first (by the smaller area of their pair).
    """
    views = [i for i, b in enumerate(blobs) if b.shape[0] > 0]
    if len(views) < 2:
        return np.zeros((0, 3))
    v0, v1 = views[0], views[1]
    pairs = [(i, j) for i in range(blobs[v0].shape[0]) for j in range(blobs[v1].shape[0])]
    size = np.zeros(len(pairs))
    if areas is not None:
        a0, a1 = areas[v0], areas[v1]
        keep = []
        for i, j in pairs:
            lo, hi = sorted((float(a0[i]), float(a1[j])))
            if hi <= config.max_area_ratio * max(lo, 1.0):
                keep.append((i, j))
        pairs = keep
        size = np.array([min(a0[i], a1[j]) for i, j in pairs], dtype=float)
    if not pairs:
        return np.zeros((0, 3))
    n_v = len(cameras)
    px = np.full((n_v, len(pairs), 2), np.nan)
    for k, (i, j) in enumerate(pairs):
        px[v0, k] = blobs[v0][i]
        px[v1, k] = blobs[v1][j]
    pts = triangulate_views(cameras, px)
    # add the other views' nearest blobs that agree, then re-triangulate
    if n_v > 2:
        for v in range(n_v):
            if v in (v0, v1) or blobs[v].shape[0] == 0:
                continue
            proj = cameras[v].project(pts)
            d = np.linalg.norm(proj[:, None, :] - blobs[v][None, :, :], axis=-1)
            best = np.argmin(d, axis=1)
            ok = d[np.arange(len(pairs)), best] < config.max_reproj_px
            px[v, ok] = blobs[v][best[ok]]
        pts = triangulate_views(cameras, px)
    good = np.all(np.isfinite(pts), axis=1)
    for v in range(n_v):
        proj = cameras[v].project(pts)
        err = np.linalg.norm(proj - px[v], axis=-1)
        seen = np.isfinite(px[v, :, 0])
        good &= ~seen | (err < config.max_reproj_px)
    order = np.argsort(-size[good], kind="stable")
    return pts[good][order]


class HeadHandTracker:
    """Head and hand positions with identity over time (module notes).

    Parameters
    ----------
    cameras : sequence of Camera
    config : BlobConfig
    right_axis : (3,) array
        World direction of the subject's right (for the initial left/right decision);
        updated by the caller with `set_right_axis`.
    """

    def __init__(
        self, cameras: Sequence[Camera], config: BlobConfig, right_axis: FloatArray
    ) -> None:
        self.cameras = list(cameras)
        self.config = config
        self.right_axis = np.asarray(right_axis, dtype=float)
        self.pos = np.full((3, 3), np.nan)
        self.vel = np.zeros((3, 3))
        self.missed = np.full(3, 10**9)
        self.last_t: float | None = None

    def set_right_axis(self, right_axis: FloatArray) -> None:
        """Direction (3,) of the subject's right in the world."""
        self.right_axis = np.asarray(right_axis, dtype=float)

    def _initialise(self, cands: FloatArray, which: list[int]) -> None:
        if cands.shape[0] == 0:
            return
        taken: set[int] = set()
        known = [k for k in range(3) if k not in which and np.all(np.isfinite(self.pos[k]))]
        for k in known:
            d = np.linalg.norm(cands - self.pos[k], axis=1)
            if d.min() < self.config.gate_mm:
                taken.add(int(np.argmin(d)))
        free = [i for i in range(cands.shape[0]) if i not in taken]
        if 0 in which and free:
            # candidates come largest first: the face is the largest skin blob, and the
            # head is above the hands; wait for a frame where both hold (a subject
            # turned away shows no face, and a hand would be taken for it)
            i = free[0]
            top = max(float(cands[c, 2]) for c in free)
            if cands[i, 2] >= top - 100.0:
                self._set(0, cands[i])
                free.remove(i)
        head = self.pos[0]
        if np.all(np.isfinite(head)):
            # a hand is not taken from the face's surroundings (a split face blob)
            free = [c for c in free if np.linalg.norm(cands[c] - head) > HAND_HEAD_MIN_MM]
        for k in (1, 2):
            if k not in which or not free:
                continue
            side = -1.0 if k == 1 else 1.0
            if np.all(np.isfinite(head)):
                score = [side * float((cands[c] - head) @ self.right_axis) for c in free]
            else:
                score = [side * float(cands[c] @ self.right_axis) for c in free]
            j = int(np.argmax(score))
            if score[j] > 0:
                self._set(k, cands[free[j]])
                free.pop(j)

    def _set(self, k: int, p: FloatArray) -> None:
        self.pos[k] = p
        self.vel[k] = 0.0
        self.missed[k] = 0

    def update(
        self,
        time_s: float,
        masks: Sequence[NDArray[np.uint8]],
        rois: Sequence[tuple[int, int, int, int] | None] | None = None,
    ) -> FloatArray:
        """Head and hands (3, 3) world mm for this frame's skin masks; NaN rows: lost.

        ``rois`` (per view, optional): only that part of each mask is searched.
        """
        blobs = []
        areas = []
        for i, m in enumerate(masks):
            r = None if rois is None else rois[i]
            if r is None:
                cents, area = skin_blobs(m, self.config)
            else:
                x0, y0, x1, y1 = r
                cents, area = skin_blobs(m[y0:y1, x0:x1], self.config)
                cents = cents + np.array([x0, y0], dtype=float)
            blobs.append(cents)
            areas.append(area)
        cands = candidates_3d(self.cameras, blobs, self.config, areas)
        return self.update_candidates(time_s, cands)

    def update_candidates(self, time_s: float, cands: FloatArray) -> FloatArray:
        """As `update`, from candidate 3-D points (M, 3)."""
        c = self.config
        dt = 0.0 if self.last_t is None else max(time_s - self.last_t, 0.0)
        self.last_t = time_s
        live = np.all(np.isfinite(self.pos), axis=1)
        pred = np.where(live[:, None], self.pos + self.vel * dt, np.nan)
        measured = np.zeros(3, dtype=bool)
        match: dict[int, int] = {}
        if cands.shape[0] and live.any():
            rows = np.flatnonzero(live)
            cost = np.linalg.norm(pred[rows, None, :] - cands[None, :, :], axis=-1)
            big = 1e9
            gated = np.where(cost < c.gate_mm, cost, big)
            ri, ci = linear_sum_assignment(gated)
            for r, j in zip(ri, ci):
                if gated[r, j] < big:
                    match[int(rows[r])] = int(j)
            # merged blobs (crossing hands): when an unmatched hand's nearest candidate is
            # the other hand's, neither is measured; both coast on their predictions so
            # that they keep their identity when the blobs part again
            for k, other in ((1, 2), (2, 1)):
                if live[k] and k not in match and other in match:
                    d = np.linalg.norm(cands - pred[k], axis=1)
                    j = int(np.argmin(d))
                    if j == match[other] and d[j] < 0.5 * c.gate_mm:
                        del match[other]
            for k, j in match.items():
                self._measure(k, cands[j], dt)
                measured[k] = True
        for k in range(3):
            if not measured[k] and live[k]:
                self.missed[k] += 1
                if k == 0:
                    # the head is held: its velocity halves every unseen frame (module notes)
                    self.vel[0] *= 0.5
                    self.pos[0] = self.pos[0] + self.vel[0] * dt
                    limit = c.head_coast_frames
                else:
                    self.pos[k] = pred[k]
                    limit = c.coast_frames
                if self.missed[k] > limit:
                    self.pos[k] = np.nan
                    self.vel[k] = 0.0
        lost = [k for k in range(3) if not np.all(np.isfinite(self.pos[k]))]
        if lost:
            self._initialise(cands, lost)
        out = self.pos.copy()
        # coasting targets are predictions, not measurements: report NaN for them
        out[self.missed > 0] = np.nan
        return out

    def _measure(self, k: int, p: FloatArray, dt: float) -> None:
        if dt > 0 and self.missed[k] == 0:
            v = (p - self.pos[k]) / dt
            speed = float(np.linalg.norm(v))
            lim = self.config.max_speed_mm_s
            if speed > lim:
                v *= lim / speed
            self.vel[k] = 0.5 * self.vel[k] + 0.5 * v
        else:
            self.vel[k] = 0.0
        self.pos[k] = p
        self.missed[k] = 0

    def predicted(self) -> FloatArray:
        """Current (possibly coasting) positions (3, 3); NaN rows: lost."""
        return self.pos.copy()


def keypoint_targets(
    cameras: Sequence[Camera],
    keypoints: Sequence[FloatArray],
    joint_names: Sequence[str],
    wanted: Sequence[str] = ("head", "left_wrist", "right_wrist"),
) -> FloatArray:
    """Joints (len(wanted), 3) triangulated from 2-D keypoints: by default head and hands
    (the ``head``, ``left_wrist``, ``right_wrist`` rows of each view's (K, 2)
    keypoints); NaN where fewer than two views see one."""
    idx = []
    for name in wanted:
        idx.append(list(joint_names).index(name) if name in joint_names else -1)
    px = np.full((len(cameras), len(idx), 2), np.nan)
    for v, kp in enumerate(keypoints):
        for k, j in enumerate(idx):
            if j >= 0:
                px[v, k] = kp[j]
    out = triangulate_views(cameras, px)
    return np.where(np.isfinite(out), out, math.nan)


__all__ = [
    "TARGETS",
    "BlobConfig",
    "HeadHandTracker",
    "candidates_3d",
    "keypoint_targets",
    "skin_blobs",
]
