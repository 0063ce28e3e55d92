"""The stick figure of the monocular tracker: canonical joints, links in search order, limits.

Mamania et al. (2004, §3.1, Fig. 2b) reason on an upper-body stick figure rooted at the
neck (§4.2: "We consider the neck as the root of the skeleton"). Here the figure is built
over canonical joint names (`mocapkit.skeleton.model.CANONICAL_JOINTS`), so any detector
or skeleton that provides them feeds it; legs are optional (§6: "similar concepts hold
for the full body").

Links are listed in the order the depth search (`mocapkit.tracking.mono.flips`) places
them: trunk first, then the clavicles, head, arms and legs, so that the constraints that
prune the most (clavicle pair, elbow) are checked as early as their joints exist.

Constraints (§4.2.2 joint-angle limits, §4.2.3 collisions) are plain data: each names the
links it reads and the search level (the last of those links) at which it is checked.
The paper leaves the limits open; the defaults below are the careful engineer's picks,
recorded in `LimitConfig`:

- elbow and knee included angle >= 30 deg (AAOS; errata recipe M, not the paper's 10 deg);
- the two clavicles at least 120 deg apart, each 50-130 deg from the trunk line (shoulder
  elevation/depression about +-40 deg);
- the head at most 60 deg from the trunk's up direction (cervical flexion/extension);
- the upper arm at most 40 deg behind the frontal plane (AAOS gives 60 deg of shoulder
  extension as the end of the range; 40 deg was chosen on the five accuracy clips, see
  below), the thigh at most 30 deg (AAOS hip extension);
- the knee bends only backwards (up to 15 deg the other way for hip rotation and noise);
- the elbow bends the forearm at most 10 deg backwards (behind the frontal plane, measured
  on the forearm's component normal to the upper arm) while the upper arm is below 17 deg
  above the horizontal: with the humerus' rotation range of about +-90 deg, a flexed elbow
  cannot point the hand backwards then (overhead, a hand behind the head is possible);
- capsules (recipe M: 40-50 mm arms, 120 mm torso) may not overlap for forearm-trunk,
  forearm-head, forearm-forearm, forearm-other upper arm, shank-shank. The trunk capsule
  here is 90 mm around the neck-pelvis line (the spine line lies behind the belly, so the
  recipe's 120 mm pruned true poses of hands resting on the belly in the CMU clips).

The shoulder-extension (60 -> 40 deg) and elbow-backward (30 -> 10 deg) limits were
tightened on the five clips of `mocapkit accuracy mono` (mean Procrustes error 67.4 ->
53.4 mm, flips right 81.1 -> 87.3 %) and checked on four CMU clips not used to choose
them (62.6 -> 57.8 mm, 65.9 -> 70.0 %; one of them got worse,
45.7 -> 50.5 mm). They prune true poses more often: 0-5.4 % of the frames of those nine
clips break them (0-1.3 % with the old values); a dance clip breaks the 30 deg elbow
angle in 24.8 % of its frames either way.

A tolerance on the limits was measured and not adopted (docs/design-notes/mono.md,
the true flips' pruning): with the estimated lengths and noisy 2-D, the
tracker pruned every candidate with the truth's flips in 0-9 % of the frames of eight of
those nine clips (the elbow-plane limit, the clavicle-trunk angle, shoulder extension)
and in 26 % of the dance clip's (its elbow closes to 25-30 deg). Loosening the elbow to 20
or 15 deg left the five accuracy clips unchanged; opening the clavicle-trunk range to
45-135 deg or the clavicle pair to 110 deg helped one clip set and cost the other. The
AAOS values therefore stay as they are: the wrong flips come less from pruning than
from candidate sets that lack the true flips altogether (a link estimated short, errata
M5), see `mocapkit.tracking.mono.lengths.raise_short_links`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import ConfigError

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: (parent, child, segment name of `CANONICAL_SEGMENTS`) in search order; the neck is the root.
UPPER_LINKS: tuple[tuple[str, str, str], ...] = (
    ("neck", "pelvis", "trunk"),
    ("neck", "left_shoulder", "left_clavicle"),
    ("neck", "right_shoulder", "right_clavicle"),
    ("neck", "head", "head"),
    ("left_shoulder", "left_elbow", "left_upper_arm"),
    ("left_elbow", "left_wrist", "left_forearm"),
    ("right_shoulder", "right_elbow", "right_upper_arm"),
    ("right_elbow", "right_wrist", "right_forearm"),
)
LEG_LINKS: tuple[tuple[str, str, str], ...] = (
    ("pelvis", "left_hip", "left_pelvis"),
    ("pelvis", "right_hip", "right_pelvis"),
    ("left_hip", "left_knee", "left_thigh"),
    ("left_knee", "left_ankle", "left_shank"),
    ("right_hip", "right_knee", "right_thigh"),
    ("right_knee", "right_ankle", "right_shank"),
)

# constraint kinds (see `Checks`)
ANGLE = 0
BACKWARD = 1
HINGE_SIGN = 2
CAPSULE = 3
ELBOW_PLANE = 4


class Checks(NamedTuple):
    """Constraints in the layout the compiled search reads.

    Attributes
    ----------
    kind : (C,) int
        `ANGLE`: the angle between link vectors ``links[c, 0]`` and ``links[c, 1]`` must
        have its cosine in ``[params[c, 0], params[c, 1]]``. `BACKWARD`: link ``links[c, 0]``
        may point behind the frontal plane (up = minus link ``links[c, 1]``, right = link
        ``links[c, 3]`` minus link ``links[c, 2]``) by at most asin(``params[c, 0]``).
        `HINGE_SIGN`: (proximal x distal) . right <= ``params[c, 0]`` |proximal||distal| for
        proximal ``links[c, 0]``, distal ``links[c, 1]``, right from ``links[c, 2:4]`` as above.
        `CAPSULE`: the segments of links ``links[c, 0]`` and ``links[c, 1]`` stay at least
        ``params[c, 0]`` mm apart. `ELBOW_PLANE`: with upper arm ``links[c, 0]`` at most
        ``params[c, 1]`` (a sine) above the horizontal of the body frame (up = minus link
        ``links[c, 2]``, right = link ``links[c, 4]`` minus link ``links[c, 3]``), the
        forearm ``links[c, 1]`` bends away from the upper arm's line backwards by at most
        asin(``params[c, 0]``).
    links : (C, 5) int
    params : (C, 2) float
    level : (C,) int
        Search level (link index) at which the check runs: the last link it reads.
    start : (L + 1,) int
        Checks of level ``l`` are ``start[l]:start[l + 1]`` (sorted by level).
    """

    kind: IntArray
    links: IntArray
    params: FloatArray
    level: IntArray
    start: IntArray


class StickArrays(NamedTuple):
    """The figure in the layout the compiled search reads.

    Attributes
    ----------
    parent, child : (L,) int
        Joint indices of each link, in search order (``parent[l]`` is placed before link l).
    lengths : (L,) float
        Link lengths (mm, or px for a pure orthographic camera).
    root : int
        The root joint (the neck).
    """

    parent: IntArray
    child: IntArray
    lengths: FloatArray
    root: int


@dataclass(frozen=True)
class LimitConfig:
    """Joint-angle limits (deg) and capsule radii (mm); see the module docstring."""

    elbow_min_included_deg: float = 30.0
    elbow_max_backward_deg: float = 10.0
    elbow_plane_max_elevation_deg: float = 17.0
    knee_min_included_deg: float = 30.0
    clavicle_pair_min_deg: float = 120.0
    clavicle_trunk_deg: tuple[float, float] = (50.0, 130.0)
    head_max_tilt_deg: float = 60.0
    shoulder_max_extension_deg: float = 40.0
    hip_max_extension_deg: float = 30.0
    knee_max_hyperextension_deg: float = 15.0
    upper_arm_radius_mm: float = 40.0
    forearm_radius_mm: float = 35.0
    trunk_radius_mm: float = 90.0
    head_radius_mm: float = 60.0
    thigh_radius_mm: float = 60.0
    shank_radius_mm: float = 45.0
    joint_limits: bool = True
    collisions: bool = True

    def __post_init__(self) -> None:
        lo, hi = self.clavicle_trunk_deg
        if not 0 <= lo < hi <= 180:
            raise ConfigError(
                f"LimitConfig.clavicle_trunk_deg: expected 0 <= low < high <= 180, found {lo, hi}"
            )
        for name in ("elbow_min_included_deg", "knee_min_included_deg", "clavicle_pair_min_deg"):
            v = getattr(self, name)
            if not 0 <= v <= 180:
                raise ConfigError(f"LimitConfig.{name}: expected 0-180 deg, found {v}")


@dataclass(frozen=True)
class StickModel:
    """A stick figure over canonical joints (see the module docstring).

    Attributes
    ----------
    joint_names : tuple of str
        Canonical joints (K); index 0 is the root (neck).
    links : tuple of (str, str, str)
        (parent, child, segment) per link (L), in search order.
    parent, child : (L,) int
        Joint indices of each link.
    checks : Checks
    limits : LimitConfig
    """

    joint_names: tuple[str, ...]
    links: tuple[tuple[str, str, str], ...]
    parent: IntArray
    child: IntArray
    checks: Checks
    limits: LimitConfig

    @property
    def n_links(self) -> int:
        """Number of links L."""
        return len(self.links)

    @property
    def n_joints(self) -> int:
        """Number of joints K."""
        return len(self.joint_names)

    @property
    def segments(self) -> tuple[str, ...]:
        """Segment name of each link."""
        return tuple(s for _, _, s in self.links)

    def link_index(self, segment: str) -> int:
        """Index of the link of a segment name."""
        if segment not in self.segments:
            from mocapkit.errors import unknown_name

            raise unknown_name("stick link", segment, self.segments)
        return self.segments.index(segment)

    def arrays(self, lengths: FloatArray) -> StickArrays:
        """The figure with link lengths, for the compiled search."""
        lengths = np.asarray(lengths, dtype=float)
        if lengths.shape != (self.n_links,) or not np.all(lengths > 0):
            from mocapkit.errors import ShapeError

            raise ShapeError(
                f"stick link lengths: expected {self.n_links} positive lengths, found "
                f"{lengths.shape} {lengths}"
            )
        return StickArrays(self.parent, self.child, lengths, 0)

    def link_vectors(self, positions: FloatArray) -> FloatArray:
        """Link vectors (..., L, 3) child minus parent of joint positions (..., K, 3)."""
        p = np.asarray(positions, dtype=float)
        return p[..., self.child, :] - p[..., self.parent, :]


def stick_model(legs: bool = False, limits: LimitConfig | None = None) -> StickModel:
    """The upper-body stick figure of the paper, optionally with legs.

    Parameters
    ----------
    legs : bool
        Add pelvis-hip, thigh and shank links.
    limits : LimitConfig, optional
        Joint-angle limits and capsule radii (defaults in the module docstring).
    """
    lim = limits or LimitConfig()
    links = UPPER_LINKS + (LEG_LINKS if legs else ())
    names: list[str] = ["neck"]
    for p, c, _ in links:
        if p not in names:
            raise ConfigError(f"stick link {p}->{c}: parent placed after its child")
        names.append(c)
    idx = {n: i for i, n in enumerate(names)}
    seg = {s: i for i, (_, _, s) in enumerate(links)}
    rows: list[tuple[int, tuple[int, ...], tuple[float, float]]] = []

    def cos(deg: float) -> float:
        return float(np.cos(np.radians(deg)))

    def angle(a: str, b: str, lo_deg: float, hi_deg: float) -> None:
        rows.append((ANGLE, (seg[a], seg[b]), (cos(hi_deg) - 1e-12, cos(lo_deg) + 1e-12)))

    if lim.joint_limits:
        lo, hi = lim.clavicle_trunk_deg
        angle("left_clavicle", "trunk", lo, hi)
        angle("right_clavicle", "trunk", lo, hi)
        angle("left_clavicle", "right_clavicle", lim.clavicle_pair_min_deg, 180.0)
        # the head link against the trunk's up direction (minus the neck->pelvis link)
        angle("head", "trunk", 180.0 - lim.head_max_tilt_deg, 180.0)
        for side in ("left", "right"):
            # included elbow angle = 180 deg - angle(upper arm, forearm)
            angle(f"{side}_upper_arm", f"{side}_forearm", 0.0, 180.0 - lim.elbow_min_included_deg)
            rows.append(
                (
                    BACKWARD,
                    (
                        seg[f"{side}_upper_arm"],
                        seg["trunk"],
                        seg["left_clavicle"],
                        seg["right_clavicle"],
                    ),
                    (float(np.sin(np.radians(lim.shoulder_max_extension_deg))), 0.0),
                )
            )
            rows.append(
                (
                    ELBOW_PLANE,
                    (
                        seg[f"{side}_upper_arm"],
                        seg[f"{side}_forearm"],
                        seg["trunk"],
                        seg["left_clavicle"],
                        seg["right_clavicle"],
                    ),
                    (
                        float(np.sin(np.radians(lim.elbow_max_backward_deg))),
                        float(np.sin(np.radians(lim.elbow_plane_max_elevation_deg))),
                    ),
                )
            )
        if legs:
            for side in ("left", "right"):
                angle(f"{side}_thigh", f"{side}_shank", 0.0, 180.0 - lim.knee_min_included_deg)
                rows.append(
                    (
                        BACKWARD,
                        (
                            seg[f"{side}_thigh"],
                            seg["trunk"],
                            seg["left_pelvis"],
                            seg["right_pelvis"],
                        ),
                        (float(np.sin(np.radians(lim.hip_max_extension_deg))), 0.0),
                    )
                )
                # knee flexion turns the shank backwards: thigh x shank points to the
                # subject's left, so its component along "right" is <= 0 (errata-free
                # physiology; the tolerance absorbs hip rotation and 2-D noise)
                rows.append(
                    (
                        HINGE_SIGN,
                        (
                            seg[f"{side}_thigh"],
                            seg[f"{side}_shank"],
                            seg["left_pelvis"],
                            seg["right_pelvis"],
                        ),
                        (float(np.sin(np.radians(lim.knee_max_hyperextension_deg))), 0.0),
                    )
                )
    if lim.collisions:
        radius = {
            "trunk": lim.trunk_radius_mm,
            "head": lim.head_radius_mm,
            "upper_arm": lim.upper_arm_radius_mm,
            "forearm": lim.forearm_radius_mm,
            "thigh": lim.thigh_radius_mm,
            "shank": lim.shank_radius_mm,
        }

        def capsule(a: str, b: str) -> None:
            ra = radius[a.split("_", 1)[-1] if a not in radius else a]
            rb = radius[b.split("_", 1)[-1] if b not in radius else b]
            rows.append((CAPSULE, (seg[a], seg[b]), (ra + rb, 0.0)))

        for side, other in (("left", "right"), ("right", "left")):
            capsule(f"{side}_forearm", "trunk")
            capsule(f"{side}_forearm", "head")
            capsule(f"{side}_forearm", f"{other}_upper_arm")
        capsule("left_forearm", "right_forearm")
        if legs:
            capsule("left_shank", "right_shank")
            capsule("left_thigh", "right_shank")
            capsule("right_thigh", "left_shank")
    kind = np.array([r[0] for r in rows], dtype=np.int64)
    lk = np.array([(*r[1], *([-1] * (5 - len(r[1])))) for r in rows], dtype=np.int64)
    lk = lk.reshape(-1, 5)
    params = np.array([r[2] for r in rows], dtype=float).reshape(-1, 2)
    level = lk.max(axis=1) if len(rows) else np.zeros(0, dtype=np.int64)
    order = np.argsort(level, kind="stable")
    kind, lk, params, level = kind[order], lk[order], params[order], level[order]
    start = np.searchsorted(level, np.arange(len(links) + 1)).astype(np.int64)
    return StickModel(
        joint_names=tuple(names),
        links=links,
        parent=np.array([idx[p] for p, _, _ in links], dtype=np.int64),
        child=np.array([idx[c] for _, c, _ in links], dtype=np.int64),
        checks=Checks(kind, lk, params, level.astype(np.int64), start),
        limits=lim,
    )
