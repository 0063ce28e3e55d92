"""Marker sets: a named point taken as the centre (mean) of several labelled markers.

A set is written ``name=A+B+C``, e.g. ``head=LFHD+RFHD+LBHD+RBHD`` (Vicon Plug-in-Gait
head band). Its position in a frame is the mean of its visible members.

Dropout bias. When a member is missing the plain mean of the rest jumps towards them:
for members at offsets ``d_k`` from the centre, losing member ``j`` moves the mean by
``-d_j / (K - 1)`` (e.g. about 40 mm for a 150 mm head band losing one of four markers).
By default `evaluate_marker_sets` removes that jump using the cluster's own geometry
from frames where all members are visible (the *reference* frames):

- with 3 or more visible members that are not nearly collinear, the reference
  configuration of the nearest reference frame is fitted rigidly to the visible members
  (Kabsch / orthogonal Procrustes), and the fitted reference centre is returned. This is
  exact for a rigid cluster whatever its rotation;
- with fewer visible members the rotation is not determined, so each visible member's
  offset from the centre is taken from the reference frames on either side, linearly
  interpolated in time (the nearest one at the ends), and the centre is the mean of
  ``member - offset``. This is exact for a rigid cluster that only translates and
  close to it for short gaps.

Frames where no member is visible stay NaN; sets with no reference frame fall back to
the plain mean. ``compensate_dropout=False`` gives the plain mean everywhere.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import ConfigError, FormatError, UnknownNameError
from mocapkit.io.markers import MarkerData, longest_true_run

_SET_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\-]*$")
_FORBIDDEN_IN_MEMBER = re.compile(r"[\s=+,;/]")

#: Rigid fit only when the visible reference members spread in 2-D: second singular value
#: of their centred coordinates at least this fraction of the first (else nearly collinear,
#: and the rotation about that line, hence the centre, is poorly determined).
MIN_PLANAR_SPREAD = 0.1


@dataclass(frozen=True)
class MarkerSet:
    """A named set whose position is the mean of its member markers.

    Attributes
    ----------
    name : str
        Set name (letters, digits, ``_ . -``; not starting with a digit).
    members : tuple of str
        Marker names, matched as in `MarkerData.index` (``Subject:`` prefix optional).
    turning : tuple of str
        Markers that turn the set without placing it (written after a ``/``:
        ``left_hand=LWRA+LWRB/LFRM``): the tracker uses them as members (their offsets
        calibrated as the others'), so they show the set's orientation, but the set's
        position stays the mean of ``members``. A wrist bar's two markers and its
        centre lie on one line, which leaves the forearm free to turn about that line; a
        forearm marker off it fixes that turn while the set's point stays the wrist
        (docs/design-notes/hybrid.md).
    """

    name: str
    members: tuple[str, ...]
    turning: tuple[str, ...] = ()

    @property
    def all_members(self) -> tuple[str, ...]:
        """``members`` then ``turning``: every marker whose offset the tracker uses."""
        return self.members + self.turning

    @property
    def orientable(self) -> bool:
        """Two or more markers in all: their offsets, once calibrated, orient the set."""
        return len(self.all_members) >= 2

    def __post_init__(self) -> None:
        members = tuple(self.members)
        object.__setattr__(self, "members", members)
        object.__setattr__(self, "turning", tuple(self.turning))
        if not isinstance(self.name, str) or not _SET_NAME.match(self.name):
            raise FormatError(
                f"marker set name: expected letters, digits, '_', '.' or '-' not starting "
                f"with a digit, found {self.name!r}"
            )
        if not members:
            raise FormatError(f"marker set {self.name!r}: expected at least one member, found none")
        for m in members + self.turning:
            if not isinstance(m, str) or not m or _FORBIDDEN_IN_MEMBER.search(m):
                raise FormatError(
                    f"marker set {self.name!r}: expected member marker names without spaces, "
                    f"'=', '+', '/', ',' or ';', found {m!r}"
                )
        every = members + self.turning
        dupes = sorted({m for m in every if every.count(m) > 1})
        if dupes:
            raise FormatError(
                f"marker set {self.name!r}: expected distinct members, found {', '.join(dupes)} "
                f"more than once"
            )

    @property
    def spec(self) -> str:
        """The set written as ``name=A+B+C`` (parsed back by `parse_marker_set`)."""
        turning = f"/{'+'.join(self.turning)}" if self.turning else ""
        return f"{self.name}={'+'.join(self.members)}{turning}"


#: Vicon Plug-in-Gait sets: head band centre and the wrist-bar midpoints.
PLUG_IN_GAIT_SETS: dict[str, MarkerSet] = {
    "head": MarkerSet("head", ("LFHD", "RFHD", "LBHD", "RBHD")),
    "left_hand": MarkerSet("left_hand", ("LWRA", "LWRB")),
    "right_hand": MarkerSet("right_hand", ("RWRA", "RWRB")),
}


def parse_marker_set(spec: str) -> MarkerSet:
    """Parse ``"name=A+B+C"`` (or ``"name=A+B/C"``, ``C`` turning only) into a `MarkerSet`.

    Blanks around names are ignored. Raises `FormatError` for a missing or repeated
    ``=``, more than one ``/``, an empty or invalid set name, an empty member (``A++B``,
    a trailing ``+`` or ``/``), or a member listed twice.
    """
    if not isinstance(spec, str):
        raise FormatError(f"marker set: expected a string 'name=A+B', found {type(spec).__name__}")
    if spec.count("=") != 1:
        raise FormatError(
            f"marker set {spec!r}: expected exactly one '=' as in 'head=LFHD+RFHD+LBHD+RBHD', "
            f"found {spec.count('=')}"
        )
    name, _, rhs = spec.partition("=")
    name = name.strip()
    if not name:
        raise FormatError(f"marker set {spec!r}: expected a set name before '=', found none")
    if rhs.count("/") > 1:
        raise FormatError(
            f"marker set {spec!r}: expected at most one '/' before the turning markers, as in "
            f"'left_hand=LWRA+LWRB/LFRM', found {rhs.count('/')}"
        )
    placing, slash, turning_text = rhs.partition("/")
    members = [m.strip() for m in placing.split("+")]
    turning = [m.strip() for m in turning_text.split("+")] if slash else []
    if any(not m for m in members + turning):
        raise FormatError(
            f"marker set {spec!r}: expected marker names separated by single '+', found an "
            f"empty member"
        )
    return MarkerSet(name, tuple(members), tuple(turning))


def parse_marker_sets(specs: str | Iterable[str]) -> tuple[MarkerSet, ...]:
    """Parse several specs, given as an iterable or one string separated by ``;`` or ``,``.

    Raises `FormatError` when two sets share a name.
    """
    if isinstance(specs, str):
        items = [s for s in re.split(r"[;,]", specs) if s.strip()]
    else:
        items = list(specs)
    sets = tuple(parse_marker_set(s) for s in items)
    _check_unique(sets)
    return sets


def _check_unique(sets: Sequence[MarkerSet]) -> None:
    seen: set[str] = set()
    for s in sets:
        if s.name in seen:
            raise FormatError(f"marker sets: expected distinct set names, found {s.name!r} twice")
        seen.add(s.name)


def _as_sets(sets: MarkerSet | str | Iterable[MarkerSet | str]) -> tuple[MarkerSet, ...]:
    if isinstance(sets, MarkerSet | str):
        sets = [sets]
    out = tuple(s if isinstance(s, MarkerSet) else parse_marker_set(s) for s in sets)
    _check_unique(out)
    return out


def _resolve(markers: MarkerData, s: MarkerSet) -> list[int]:
    idx = []
    for m in s.members:
        try:
            idx.append(markers.index(m))
        except UnknownNameError as exc:
            raise UnknownNameError(f"marker set {s.name!r}: {exc}") from None
    return idx


def set_centre_mm(
    points_mm: NDArray[np.float64], compensate_dropout: bool = True
) -> NDArray[np.float64]:
    """Centre of one marker cluster per frame, with optional dropout compensation.

    Parameters
    ----------
    points_mm : (T, K, 3) float array
        Member positions in mm, NaN where missing.
    compensate_dropout : bool
        Remove the jump of the mean when members are missing (see the module docstring).

    Returns
    -------
    (T, 3) float array
        NaN only in frames where every member is missing.
    """
    p = np.asarray(points_mm, dtype=np.float64)
    vis = np.asarray(~np.isnan(p).any(axis=2), dtype=bool)  # (T, K)
    n_vis = vis.sum(axis=1)
    filled = np.where(vis[..., None], p, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        centre = filled.sum(axis=1) / n_vis[:, None]
    centre[n_vis == 0] = np.nan
    k = p.shape[1]
    full = n_vis == k
    partial = (n_vis > 0) & ~full
    if not compensate_dropout or k < 2 or not full.any() or not partial.any():
        return centre

    full_idx = np.flatnonzero(full)
    offsets = p[full_idx] - centre[full_idx][:, None, :]  # (F, K, 3), reference geometry
    part_idx = np.flatnonzero(partial)
    # Reference frames on either side of each partial frame.
    after = np.searchsorted(full_idx, part_idx)  # index into full_idx of the next full frame
    before = after - 1
    has_before = before >= 0
    has_after = after < full_idx.size
    b = np.clip(before, 0, full_idx.size - 1)
    a = np.clip(after, 0, full_idx.size - 1)
    t_b = full_idx[b].astype(np.float64)
    t_a = full_idx[a].astype(np.float64)
    span = np.where(t_a > t_b, t_a - t_b, 1.0)
    w_after = np.where(
        has_before & has_after, (part_idx - t_b) / span, np.where(has_after, 1.0, 0.0)
    )
    d = offsets[b] * (1.0 - w_after)[:, None, None] + offsets[a] * w_after[:, None, None]
    v = vis[part_idx]  # (P, K)
    pp = np.where(v[..., None], p[part_idx], 0.0)
    nv = v.sum(axis=1)
    centre_offset = (np.where(v[..., None], pp - d, 0.0)).sum(axis=1) / nv[:, None]

    # Rigid fit of the nearest reference configuration where >= 3 members are visible.
    nearest = np.where(
        has_before & has_after,
        np.where(part_idx - t_b <= t_a - part_idx, b, a),
        np.where(has_after, a, b),
    )
    q = offsets[nearest]  # (P, K, 3), reference centred at its centre (the origin)
    wv = v[..., None].astype(np.float64)
    q_bar = (q * wv).sum(axis=1) / nv[:, None]
    p_bar = pp.sum(axis=1) / nv[:, None]
    qc = (q - q_bar[:, None, :]) * wv
    pc = (pp - p_bar[:, None, :]) * wv
    spread = np.linalg.svd(qc, compute_uv=False)  # (P, 3) descending
    rigid = (nv >= 3) & (spread[:, 1] >= MIN_PLANAR_SPREAD * np.maximum(spread[:, 0], 1e-300))
    if rigid.any():
        h = np.einsum("pki,pkj->pij", qc[rigid], pc[rigid])  # sum of q p^T
        u, _, vt = np.linalg.svd(h)
        det = np.linalg.det(np.einsum("pji,pkj->pik", vt, u))  # det(V U^T)
        fix = np.ones((det.size, 3))
        fix[:, 2] = np.sign(det)
        rot = np.einsum("pji,pj,pkj->pik", vt, fix, u)  # V diag(1,1,s) U^T
        # The reference centre is the origin: its image is p_bar - R q_bar.
        centre_offset[rigid] = p_bar[rigid] - np.einsum("pij,pj->pi", rot, q_bar[rigid])
    centre[part_idx] = centre_offset
    return centre


def evaluate_marker_sets(
    markers: MarkerData,
    sets: MarkerSet | str | Iterable[MarkerSet | str],
    *,
    compensate_dropout: bool = True,
) -> NDArray[np.float64]:
    """Positions of marker sets over time.

    Parameters
    ----------
    markers : MarkerData
    sets : MarkerSet, spec string, or an iterable of them
        S sets; strings are parsed with `parse_marker_set`.
    compensate_dropout : bool
        Correct the jump of the mean when members are missing (default; see the module
        docstring). False gives the plain mean of the visible members.

    Returns
    -------
    (T, S, 3) float array
        Set centres in mm; NaN only in frames where all members of a set are missing.

    Raises
    ------
    UnknownNameError
        A member is not a marker of ``markers`` (the message names the set and lists the
        valid marker names), or is ambiguous across subjects.
    """
    resolved = _as_sets(sets)
    out = np.full((markers.n_frames, len(resolved), 3), np.nan)
    for j, s in enumerate(resolved):
        idx = _resolve(markers, s)
        out[:, j, :] = set_centre_mm(markers.positions_mm[:, idx, :], compensate_dropout)
    return out


@dataclass(frozen=True)
class MarkerSetCoverage:
    """How well a marker set is covered over a recording.

    Attributes
    ----------
    name : str
    members : tuple of str
        Member names as in the file.
    n_frames : int
    n_all_missing : int
        Frames where every member is missing (the set is NaN).
    n_partial : int
        Frames where some but not all members are missing (mean computed from the rest).
    n_reference : int
        Frames where all members are visible (used for dropout compensation).
    longest_all_missing_frames : int
        Longest run of frames where the set is NaN.
    longest_all_missing_s : float
        That run in seconds (frames / rate).
    """

    name: str
    members: tuple[str, ...]
    n_frames: int
    n_all_missing: int
    n_partial: int
    n_reference: int
    longest_all_missing_frames: int
    longest_all_missing_s: float

    def summary(self) -> str:
        """One readable line."""
        return (
            f"{self.name} ({'+'.join(self.members)}): {self.n_all_missing}/{self.n_frames} "
            f"frames fully missing (longest {self.longest_all_missing_frames} frames = "
            f"{self.longest_all_missing_s:.3f} s), {self.n_partial} partial, "
            f"{self.n_reference} complete"
        )


def marker_set_coverage(
    markers: MarkerData, sets: MarkerSet | str | Iterable[MarkerSet | str]
) -> tuple[MarkerSetCoverage, ...]:
    """Per-set report of fully missing, partial and complete frames."""
    out = []
    for s in _as_sets(sets):
        idx = _resolve(markers, s)
        vis = ~markers.missing[:, idx]
        n_vis = vis.sum(axis=1)
        none = n_vis == 0
        longest = int(longest_true_run(none))
        out.append(
            MarkerSetCoverage(
                name=s.name,
                members=tuple(markers.names[i] for i in idx),
                n_frames=markers.n_frames,
                n_all_missing=int(none.sum()),
                n_partial=int(((n_vis > 0) & (n_vis < len(idx))).sum()),
                n_reference=int((n_vis == len(idx)).sum()),
                longest_all_missing_frames=longest,
                longest_all_missing_s=longest / markers.rate_hz,
            )
        )
    return tuple(out)


# ---------------------------------------------------------------------- stature
#: Vertical distance from the Plug-in-Gait head-band centre (LFHD/RFHD over the temples,
#: LBHD/RBHD at the same level at the back) to the top of the head. Anthropometric
#: surveys put the vertex about 125-135 mm above the ear (tragion); the temple markers
#: sit a few cm higher, hence about 100 mm. Uncertainty about +-30 mm.
HEAD_TOP_OFFSET_MM = 100.0
#: A foot counts as on the floor when its lowest marker is within this height of it
#: (heel and toe markers sit 15-50 mm above the floor on a flat foot).
FOOT_CONTACT_MM = 60.0
#: Plug-in-Gait foot markers (those present in the file are used).
PLUG_IN_GAIT_LEFT_FOOT: tuple[str, ...] = ("LHEE", "LTOE", "LANK")
PLUG_IN_GAIT_RIGHT_FOOT: tuple[str, ...] = ("RHEE", "RTOE", "RANK")


def _present(markers: MarkerData, names: Sequence[str]) -> list[int]:
    idx = []
    for n in names:
        try:
            idx.append(markers.index(n))
        except UnknownNameError:
            continue
    return idx


def estimate_height_mm(
    markers: MarkerData,
    *,
    head: MarkerSet | str = PLUG_IN_GAIT_SETS["head"],
    left_foot: Sequence[str] | None = None,
    right_foot: Sequence[str] | None = None,
    percentile: float = 95.0,
    head_top_offset_mm: float = HEAD_TOP_OFFSET_MM,
    foot_contact_mm: float = FOOT_CONTACT_MM,
) -> float:
    """Estimate stature from the head markers' height above the floor (Z up).

    Rule:

    1. head height ``z_h(t)``: the Z of the head set centre (dropout-compensated);
    2. floor: z = 0 (the lab's calibrated floor), or lower if the feet go below it: the
       1st percentile of the per-frame lowest foot marker when that is negative;
    3. standing frames: both feet on the floor, i.e. each foot's lowest marker within
       ``foot_contact_mm`` of the floor (a foot without markers in the file is not
       checked; with no standing frame at all, every frame is used);
    4. stature = ``percentile``-th percentile of ``z_h`` over standing frames minus the
       floor, plus ``head_top_offset_mm`` (head-band centre to vertex).

    Assumptions: the lab's vertical axis is Z; the subject stands upright with both
    feet down for at least ``100 - percentile`` % of the standing frames (a crouching
    or seated recording gives a low estimate); the offset suits a head band at temple
    level. Expect an error of a few cm.

    Parameters
    ----------
    markers : MarkerData
    head : MarkerSet or spec
        Head markers (default Plug-in-Gait ``LFHD+RFHD+LBHD+RBHD``); must all exist.
    left_foot, right_foot : sequence of str, optional
        Foot markers; by default the Plug-in-Gait heel, toe and ankle markers, those
        present in the file (explicitly given names must exist).
    percentile : float
        Percentile of head height over standing frames, in (0, 100].
    head_top_offset_mm : float
        Head-set centre to top of head.
    foot_contact_mm : float
        Height below which a foot counts as on the floor.

    Returns
    -------
    float
        Estimated stature in mm.

    Raises
    ------
    FormatError
        The head set is never visible.
    UnknownNameError
        A head marker (or an explicitly given foot marker) is not in the file.
    """
    if not 0.0 < percentile <= 100.0:
        raise ConfigError(f"percentile: expected a value in (0, 100], found {percentile}")
    z_head = evaluate_marker_sets(markers, head)[:, 0, 2]
    feet = []
    sides = ((left_foot, PLUG_IN_GAIT_LEFT_FOOT), (right_foot, PLUG_IN_GAIT_RIGHT_FOOT))
    for given, default in sides:
        idx = markers.indices(given) if given is not None else _present(markers, default)
        if idx:
            z = markers.positions_mm[:, idx, 2]
            all_nan = np.isnan(z).all(axis=1)
            low = np.full(markers.n_frames, np.nan)
            low[~all_nan] = np.nanmin(z[~all_nan], axis=1)
            feet.append(low)
    floor = 0.0
    if feet:
        lowest = np.fmin.reduce(np.stack(feet), axis=0)
        if np.isfinite(lowest).any():
            floor = min(0.0, float(np.nanpercentile(lowest, 1.0)))
    ok = np.isfinite(z_head)
    if not ok.any():
        raise FormatError(
            f"{markers.source}: head set for stature: expected some frames with a visible head "
            f"marker, found none in {markers.n_frames} frames"
        )
    standing = ok.copy()
    for low in feet:
        with np.errstate(invalid="ignore"):
            standing &= low - floor <= foot_contact_mm
    if not standing.any():
        standing = ok
    return float(np.percentile(z_head[standing], percentile) - floor + head_top_offset_mm)
