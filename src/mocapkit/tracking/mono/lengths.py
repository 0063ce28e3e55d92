"""Link lengths of the stick figure from the video itself (Mamania et al. 2004, §4.1).

"Given a sufficiently long video sequence, each link will become parallel (or nearly
parallel) to the plane of screen at least once": a link's length is its longest
projection over the sequence (recipe M step 3), left and right sharing the longer of the
two ("for left and right fore-arms, we use maximum length of the two"). The paper then
normalises "with respect to anthropometric data" without saying how; here:

1. each link's observed length is a high percentile of its projected lengths (100 = the
   paper's maximum; a lower one keeps a few noisy frames from stretching the link);
2. each observed length implies a stature ``length / ratio`` with the body proportions of
   `ANTHROPOMETRIC_RATIOS`; the median of these is the video's stature;
3. a link never seen, or never near parallel (observed below ``1 - slack`` of its
   anthropometric length at that stature), takes the anthropometric length instead.

The ratios are segment length over standing height between canonical joints, medians
over the ten CMU clips of ``shared/data/mocap`` as the library reads them (the canonical
neck and pelvis of those files differ from `zhang21`'s, whose trunk ratio is 0.28 against
0.15-0.25 there, so the library's own model would mislead the fallback). The defaults
(90th percentile, slack 0.15) were picked on three synthetic clips, where the 90th
percentile of the projected lengths lay within 0.9-1.18 of the true lengths.

Lengths come out in the units of the input (px for image positions). `pixels_per_mm`
turns them into mm from a known stature (session.json) or, failing that, the
reference stature.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ConfigError, ShapeError

FloatArray = NDArray[np.float64]

#: Stature assumed when none is known (mm): that of the reference model.
DEFAULT_HEIGHT_MM = 1700.0


#: Segment length / standing height (see the module docstring for the source).
ANTHROPOMETRIC_RATIOS: dict[str, float] = {
    "trunk": 0.227,
    "head": 0.165,
    "left_clavicle": 0.13,
    "right_clavicle": 0.13,
    "left_upper_arm": 0.19,
    "right_upper_arm": 0.19,
    "left_forearm": 0.13,
    "right_forearm": 0.13,
    "left_pelvis": 0.09,
    "right_pelvis": 0.09,
    "left_thigh": 0.27,
    "right_thigh": 0.27,
    "left_shank": 0.285,
    "right_shank": 0.285,
}


def anthropometric_ratios(segments: Sequence[str]) -> FloatArray:
    """Segment length over stature for each segment name (`ANTHROPOMETRIC_RATIOS`)."""
    table = ANTHROPOMETRIC_RATIOS
    missing = [s for s in segments if s not in table]
    if missing:
        from mocapkit.errors import unknown_name

        raise unknown_name("body segment", missing[0], table, "anthropometric ratios")
    return np.array([table[s] for s in segments])


def _partner(segment: str) -> str | None:
    for a, b in (("left_", "right_"), ("right_", "left_")):
        if segment.startswith(a):
            return b + segment[len(a) :]
    return None


def estimate_link_lengths(
    projected: ArrayLike,
    segments: Sequence[str],
    percentile: float = 90.0,
    slack: float = 0.15,
) -> tuple[FloatArray, float]:
    """Link lengths from their projected lengths over a sequence.

    Parameters
    ----------
    projected : (T, L) float
        Projected length of each link per frame (NaN where unseen), any unit.
    segments : sequence of str
        Segment name of each link (`CANONICAL_SEGMENTS` keys).
    percentile : float
        Which high percentile of the projected lengths counts as the link seen parallel
        (100: the paper's maximum).
    slack : float
        A link observed shorter than ``(1 - slack)`` times its anthropometric length at the
        video's stature takes the anthropometric length.

    Returns
    -------
    lengths : (L,) float
        In the unit of ``projected``.
    stature : float
        The video's stature in the same unit (median of length / ratio).
    """
    d = np.asarray(projected, dtype=float)
    if d.ndim != 2 or d.shape[1] != len(segments):
        raise ShapeError(
            f"estimate_link_lengths: expected projected (T, {len(segments)}), found {d.shape}"
        )
    if not 0 < percentile <= 100:
        raise ConfigError(
            f"estimate_link_lengths: percentile: expected (0, 100], found {percentile}"
        )
    if not 0 <= slack < 1:
        raise ConfigError(f"estimate_link_lengths: slack: expected [0, 1), found {slack}")
    seen = np.isfinite(d).any(axis=0)
    if not seen.any():
        raise ShapeError("estimate_link_lengths: no link is ever seen")
    obs = np.full(d.shape[1], np.nan)
    obs[seen] = np.nanpercentile(d[:, seen], percentile, axis=0)
    index = {s: i for i, s in enumerate(segments)}
    pooled = obs.copy()
    for i, s in enumerate(segments):
        other = _partner(s)
        if other in index:
            pooled[i] = np.fmax(obs[i], obs[index[other]])
    ratios = anthropometric_ratios(segments)
    stature = float(np.nanmedian(pooled / ratios))
    expected = ratios * stature
    short = ~(pooled >= (1.0 - slack) * expected)  # also NaN: never seen
    # the trunk and head keep what the video shows unless never seen: their canonical ends
    # (neck, pelvis, head) differ most between skeleton sources (trunk/stature 0.15 in the
    # CMU BVH files, 0.23 in the ASF/AMC ones)
    steady = np.isin(np.asarray(segments), ("trunk", "head"))
    short &= ~steady | np.isnan(pooled)
    lengths = np.where(short, expected, pooled)
    return lengths, stature


def raise_short_links(
    lengths: ArrayLike,
    segments: Sequence[str],
    weight: float = 0.5,
    steady: Sequence[str] = ("trunk", "head"),
) -> FloatArray:
    """Move links estimated shorter than the body's proportions part of the way up.

    A link estimated too short cannot reach its child's ray whenever the true link lies
    within acos(estimate / truth) of the image plane: the enumeration then has one
    configuration for it (errata M5) and the true flip is not among the candidates at
    all. A link estimated too long only biases its depth. The loss is one-sided, so
    the correction is too: with the video's stature ``S = median(lengths / ratios)``
    (`ANTHROPOMETRIC_RATIOS`), each link shorter than ``ratio * S`` is moved the share
    ``weight`` of the way to it; longer links, and the ``steady`` ones (trunk and head,
    whose canonical ends differ most between skeleton sources, see
    `estimate_link_lengths`), are left alone. The result is rescaled to the input's sum,
    so the absolute scale stays tied to the stature.

    On the nine CMU clips of `git log -p docs/design-notes/mono.md`, 0.5 was the middle of the
    weights that helped both clip sets (0.5-0.7, with the ratios taken without the
    tested subject): in the frames whose true flips were absent from every candidate
    set, the trunk, clavicles and upper arms were the links cut short.

    Parameters
    ----------
    lengths : (L,) float
        Link lengths (any unit).
    segments : sequence of str
        Segment name of each link.
    weight : float
        Share of the gap to the proportional length closed, in [0, 1]; 0 leaves the
        lengths as they are.
    steady : sequence of str
        Segments never changed (other than by the rescaling).

    Returns
    -------
    (L,) float
    """
    if not 0.0 <= weight <= 1.0:
        raise ConfigError(f"raise_short_links: weight: expected [0, 1], found {weight}")
    lens = np.asarray(lengths, dtype=float)
    if lens.shape != (len(segments),) or not np.all(lens > 0):
        raise ShapeError(
            f"raise_short_links: expected {len(segments)} positive lengths, found {lens}"
        )
    ratios = anthropometric_ratios(segments)
    expected = ratios * float(np.median(lens / ratios))
    short = (lens < expected) & ~np.isin(np.asarray(segments), tuple(steady))
    out = np.where(short, lens + weight * (expected - lens), lens)
    return np.asarray(out * (lens.sum() / out.sum()), dtype=float)


def pixels_per_mm(stature_px: float, height_mm: float | None) -> float:
    """Image scale (px per mm) from the video's stature and the subject's, if known."""
    h = DEFAULT_HEIGHT_MM if height_mm is None else float(height_mm)
    if not (np.isfinite(stature_px) and stature_px > 0 and h > 0):
        raise ShapeError(f"pixels_per_mm: expected positive statures, found {stature_px}, {h}")
    return float(stature_px) / h
