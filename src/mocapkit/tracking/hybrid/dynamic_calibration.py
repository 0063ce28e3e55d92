"""Member-marker offsets of the hybrid tracker's marker sets, calibrated on the motion itself.

A raw marker file does not say where each member marker of a set sits on the body; the
static calibration (`mocapkit.tracking.hybrid.static_calibration`) finds it on a still second.
Where a take has none (or none is wanted), the offsets are calibrated on the motion, as
biomechanics does with a functional calibration or OpenSim's marker placement on a
dynamic trial: the take is tracked from the set centres alone (positions only), each
member is put in its effector joint's frame on every frame, and its offset is the median
over the frames where the calibration's assumption can hold (`calibration_frames`) and
that agree with one another on where the members sit (`consensus_frames`).

The assumption is the static calibration's, on many frames rather than one still second:
the head faces the way the trunk does and the forearm is turned as the relaxed pose turns
it. With positions only the head's turn and the forearm's (the elbow's swivel about the
shoulder-wrist line, and no pronation at all) come from the IK's relaxed-pose task, and
they are wrong on part of a moving take (the tennis serve's ball-tossing arm swings down
with its elbow up, the head looks up at the ball, the forearms turn). The candidate frames
are those where the assumption is most likely: the set's centre fits the model (within
`MAX_FIT_MM`), it moves slower than its median speed over the take (no swing under way,
where the warm-started IK lags and the forearm turns), and for a hand set the model's arm
hangs (wrist below the shoulder by `HANGING_FRACTION` of the arm's length: the relaxed
pose, near which the relaxed-pose task's swivel is right).

Why the consensus rather than the median over the candidates: the assumption fails on
many of them too, and not at random. On the tennis serve the toss arm's wrist bar, put
in the positions-only model's wrist frame, lies anywhere over 0-180 deg round the forearm
on its hanging, slow frames (the player holds the forearm turned in different ways
between serves), with one tight cluster, the still stance's 100 frames within a few
degrees of each other; the median of all of them came out 23 deg round from the static
calibration's bar, the consensus 0.5 deg. Frames where the assumption holds all give the
same layout; frames where it fails each give their own, so they scatter (RANSAC's
maximum consensus, with `CONSENSUS_DEG`). Elbows, mean left / right over eight copies
of the tennis serve jittered by 1e-6 mm (the tracker is chaotic in round-off;
docs/design-notes/hybrid.md): median 97 / 107 mm, consensus 94 / 98, static calibration 92 / 93; on
the ezc3d Qualisys take, which moves throughout, 87 / 40 -> 52 / 32 (at 10-12.5 deg
only: its left elbow has two states, about 50 and 89 mm; positions only 105 / 39).
Offsets are from the effector's default point, as ``HybridConfig.member_offsets_mm``.

One pass only: tracking again with the offsets and calibrating again returns nearly the
offsets it started from (the IK now follows the members: per-frame offsets within 1 mm of
their median), and on the tennis serve (every fitting frame used) it moved the right
elbow's error 114 -> 123 mm.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ConfigError, ShapeError
from mocapkit.geometry.transforms import points_in_frame
from mocapkit.skeleton.kinematics import forward_kinematics
from mocapkit.skeleton.limbs import arm
from mocapkit.skeleton.model import Skeleton
from mocapkit.tracking.hybrid.tracker import default_marker_effectors

FloatArray = NDArray[np.float64]

#: Largest distance (mm) of a set's centre from its model point on a frame that is used:
#: frames where the positions-only model does not reach the set (the tennis serve's
#: racket drop: 30-110 mm) say nothing about where the members sit on it. The tennis
#: serve's figures at 5 / 10 / 30 mm with this the only condition: elbows 94 / 123,
#: 91 / 114, 89 / 126 mm (left / right mean).
MAX_FIT_MM = 10.0
#: Share of the arm's length (shoulder-elbow plus elbow-wrist) by which a hand set's
#: wrist must sit below its shoulder on a frame that is used: the arm hanging, as in the
#: relaxed pose (the tennis serve: 0.8 keeps 47-52 % of the frames).
HANGING_FRACTION = 0.8
#: Percentile of a set's speed over the take below which its frames are used.
SLOW_PERCENTILE = 50.0
#: Fewest such frames a set needs to be calibrated (1 s at 50 Hz, as the static window),
#: and fewest of them that must agree on its members' layout (`consensus_frames`).
MIN_FRAMES = 50
#: Largest turn (deg) of a frame's member layout from another's for the two to agree
#: (`consensus_frames`): a still stance's frames agree within 2-5 deg (the tennis serve's
#: first 2 s), what the positions-only track gets wrong turns a frame's layout by tens of
#: degrees (the toss arm's wrist bar over its hanging frames: 0-180 deg about the forearm).
CONSENSUS_DEG = 10.0
#: Rounds in which the agreeing frames are chosen again about their own median layout.
CONSENSUS_ROUNDS = 5
#: Most frames tried as the seed of the consensus (evenly spaced over the candidates), so
#: that a long take's search stays O(frames) (the tennis serve's 300-450 are all tried).
MAX_SEEDS = 500


@dataclass(frozen=True)
class DynamicCalibration:
    """Member offsets calibrated on a moving take.

    Attributes
    ----------
    offsets_mm : dict of str to dict of str to tuple
        Per set, per member: offset (mm) in the effector joint's frame from the effector's
        default point (``HybridConfig.member_offsets_mm``).
    spread_mm : dict of str to float
        Per set: the largest over its members of the median distance of the per-frame
        offsets from their median over the frames used (the tennis serve's glasses 6.1
        mm, wrist bars 2.7 and 3.5 mm; over every candidate frame, without the consensus,
        33, 21 and 16 mm).
    frames_used : dict of str to int
        Per set: the frames the median is over (the candidates that agree on the layout:
        the tennis serve's 112 / 96 / 92 of 449 / 324 / 349).
    n_frames : int
        Frames of the take.
    """

    offsets_mm: dict[str, dict[str, tuple[float, float, float]]]
    spread_mm: dict[str, float]
    frames_used: dict[str, int]
    n_frames: int

    def summary(self) -> str:
        """One line for the terminal."""
        sets = ", ".join(
            f"{n} on {self.frames_used[n]} frames (spread {self.spread_mm[n]:.1f} mm)"
            for n in self.offsets_mm
        )
        return (
            f"member offsets calibrated on the motion (median over the frames of the "
            f"{self.n_frames} tracked from the set centres where the set fits within "
            f"{MAX_FIT_MM:g} mm, moves slower than its median and a hand's arm hangs, and "
            f"that agree on its layout within {CONSENSUS_DEG:g} deg): {sets}"
        )


def calibration_frames(
    skeleton: Skeleton,
    world: ArrayLike,
    set_name: str,
    time_s: ArrayLike,
    centre_mm: ArrayLike,
    fit_mm: ArrayLike,
    max_fit_mm: float = MAX_FIT_MM,
) -> NDArray[np.bool_]:
    """The frames a set's members are calibrated on (see the module docstring).

    Parameters
    ----------
    skeleton : Skeleton
    world : array_like, shape (T, J, 4, 4)
        The joints' world transforms of the positions-only track (NaN where no pose), in
        the tracker's Z-up world.
    set_name : str
        ``head``, ``left_hand`` or ``right_hand``; a hand set also needs its arm hanging.
    time_s : array_like, shape (T,)
    centre_mm : array_like, shape (T, 3)
        The set's centre (NaN where unseen).
    fit_mm : array_like, shape (T,)
        The set's distance to its model point (NaN where not in the task).
    max_fit_mm : float

    Returns
    -------
    ndarray of bool, shape (T,)
    """
    w = np.asarray(world, dtype=float)
    t = np.asarray(time_s, dtype=float)
    c = np.asarray(centre_mm, dtype=float)
    fit = np.asarray(fit_mm, dtype=float)
    n = t.size
    if c.shape != (n, 3) or fit.shape != (n,) or w.shape[0] != n:
        raise ShapeError(
            f"calibration_frames: expected {n} frames of centre (T, 3), fit (T,) and world, "
            f"found {c.shape}, {fit.shape}, {w.shape}"
        )
    # NaN fits (set not in the task) compare False: not used
    good = np.all(np.isfinite(w[:, :, :3, 3]), axis=(1, 2)) & (fit <= max_fit_mm)
    if n >= 2:
        speed = np.linalg.norm(np.gradient(c, t, axis=0), axis=1)
        if np.isfinite(speed).any():
            good &= speed <= np.nanpercentile(speed, SLOW_PERCENTILE)
        else:
            good[:] = False
    side = {"left_hand": "left", "right_hand": "right"}.get(set_name)
    if side is not None:
        limb = arm(skeleton, side)
        shoulder, elbow, wrist = (w[:, k, :3, 3] for k in (limb.root, limb.middle, limb.end))
        reach = np.linalg.norm(elbow - shoulder, axis=1) + np.linalg.norm(wrist - elbow, axis=1)
        with np.errstate(invalid="ignore"):
            good &= shoulder[:, 2] - wrist[:, 2] >= HANGING_FRACTION * reach
    return good


def layout_turn_deg(directions: ArrayLike, reference: ArrayLike) -> FloatArray:
    """How far each frame's member layout is turned from a reference layout.

    Parameters
    ----------
    directions : array_like, shape (N, M, 3)
        Per frame, the unit directions of a set's M members from their centre (in the
        effector joint's frame).
    reference : array_like, shape (K, M, 3)
        K reference layouts, the same way (e.g. other frames'); need not be unit length.

    Returns
    -------
    ndarray, shape (K, N)
        The largest over the members of the angle (deg) between a member's direction in
        the frame and in the reference: for two members the angle between the bars; for
        more, at least as much as any member moved (a turn about an axis through one
        member still moves the others).
    """
    d = np.asarray(directions, dtype=float)
    r = np.asarray(reference, dtype=float)
    if d.ndim != 3 or d.shape[2] != 3 or r.ndim != 3 or r.shape[1:] != d.shape[1:]:
        raise ShapeError(
            f"layout_turn_deg: expected directions (N, M, 3) and reference (K, M, 3), found "
            f"{d.shape} and {r.shape}"
        )
    r = r / np.linalg.norm(r, axis=2, keepdims=True)
    cos = np.einsum("kmi,nmi->knm", r, d).min(axis=2)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def consensus_frames(
    local_mm: ArrayLike,
    max_turn_deg: float = CONSENSUS_DEG,
    rounds: int = CONSENSUS_ROUNDS,
    max_seeds: int = MAX_SEEDS,
) -> NDArray[np.bool_]:
    """The largest set of frames that agree on where a set's members sit on its joint.

    Where the calibration's assumption holds (the subject in the relaxed pose the
    positions-only IK takes), every frame puts the members at the same place in the
    effector joint's frame; where it fails (the swivel flipped, the forearm turned, the
    head turned from the trunk), each frame fails its own way, so those frames scatter
    rather than agree. The offsets are therefore taken over the frames that agree with
    the most others (maximum consensus, as RANSAC), not over all of them: a median needs
    the assumption to hold on more than half the frames, and on the tennis serve's hanging,
    slow frames the toss arm's wrist bar lies 0-180 deg round the forearm, the still
    stance's 100 frames within a few degrees of each other (34 deg) and the median at 57.

    Parameters
    ----------
    local_mm : array_like, shape (N, M, 3)
        Per frame, the M >= 2 members in the effector joint's frame (mm), all finite.
    max_turn_deg : float
        Largest turn (`layout_turn_deg`) between frames that agree.
    rounds : int
        Times the agreeing frames are chosen again about their median layout (each a
        step of mean shift towards the cluster's middle).
    max_seeds : int
        Most frames tried as the seed (evenly spaced).

    Returns
    -------
    ndarray of bool, shape (N,)
        The agreeing frames: those within ``max_turn_deg`` of the median layout of the
        best seed's agreeing frames, after ``rounds`` such steps.
    """
    loc = np.asarray(local_mm, dtype=float)
    if loc.ndim != 3 or loc.shape[1] < 2 or loc.shape[2] != 3 or loc.shape[0] < 1:
        raise ShapeError(
            f"consensus_frames: expected members (N >= 1, M >= 2, 3), found {loc.shape}"
        )
    if not 0 < max_turn_deg < 180 or rounds < 0 or max_seeds < 1:
        raise ConfigError(
            f"consensus_frames: expected 0 < max_turn_deg < 180, rounds >= 0 and max_seeds "
            f">= 1, found {max_turn_deg}, {rounds}, {max_seeds}"
        )
    v = loc - loc.mean(axis=1, keepdims=True)
    d = v / np.linalg.norm(v, axis=2, keepdims=True)
    n = d.shape[0]
    seeds = np.unique(np.linspace(0, n - 1, min(n, max_seeds)).round().astype(int))
    support = np.zeros(seeds.size, dtype=int)
    for k in range(0, seeds.size, 64):  # a block of seeds at a time: (64, N) angles
        block = seeds[k : k + 64]
        support[k : k + 64] = (layout_turn_deg(d, d[block]) < max_turn_deg).sum(axis=1)
    agree = layout_turn_deg(d, d[seeds[int(np.argmax(support))]][None])[0] < max_turn_deg
    for _ in range(rounds):
        middle = np.median(v[agree], axis=0)
        shifted = layout_turn_deg(d, middle[None])[0] < max_turn_deg
        if not shifted.any():  # a median layout no frame is near: keep the last frames
            break
        agree = shifted
    return agree


def calibrate_members_on_motion(
    skeleton: Skeleton,
    q: ArrayLike,
    time_s: ArrayLike,
    fit_mm: Mapping[str, ArrayLike],
    members_mm: Mapping[str, Mapping[str, ArrayLike]],
    max_fit_mm: float = MAX_FIT_MM,
    min_frames: int = MIN_FRAMES,
) -> DynamicCalibration:
    """Member offsets from a tracked motion (see the module docstring).

    Parameters
    ----------
    skeleton : Skeleton
        The model ``q`` poses; its effector joints' frames are the offsets' frames (a model
        with more DoFs that has the same frames at those DoFs' zero, as
        ``raw_marker_skeleton``'s oriented one, takes the same offsets).
    q : array_like, shape (T, D)
        The poses tracked from the set centres alone (rad, mm; the tracker's Z-up world);
        rows with NaN are skipped.
    time_s : array_like, shape (T,)
        Frame times (s), for the sets' speed.
    fit_mm : mapping of str to array_like (T,)
        Per set: its centre's distance (mm) to its model point on each frame (the
        tracker's ``fit["<set>_mm"]``), NaN where the set was not in the task.
    members_mm : mapping of str to mapping of str to array_like (T, 3)
        Per set, its member markers' trajectories (mm, the tracker's world), NaN where
        unseen; sets with fewer than two members are not calibrated.
    max_fit_mm : float
        Largest set fit (mm) of a frame that is used (`MAX_FIT_MM`).
    min_frames : int
        Fewest usable frames (`calibration_frames`) for a set to be calibrated
        (`MIN_FRAMES`).

    Returns
    -------
    DynamicCalibration

    Raises
    ------
    ShapeError
        ``q``, a fit or a trajectory of the wrong shape.
    ConfigError
        No set has two members seen on ``min_frames`` usable frames.
    """
    qs = np.asarray(q, dtype=float)
    t = np.asarray(time_s, dtype=float)
    if qs.ndim != 2 or qs.shape[1] != len(skeleton.dof_names):
        raise ShapeError(f"q: expected shape (T, {len(skeleton.dof_names)}), found {qs.shape}")
    if not max_fit_mm > 0 or min_frames < 1:
        raise ConfigError(
            f"dynamic calibration: expected max_fit_mm > 0 and min_frames >= 1, found "
            f"{max_fit_mm}, {min_frames}"
        )
    n = qs.shape[0]
    if t.shape != (n,):
        raise ShapeError(f"time_s: expected shape ({n},), found {t.shape}")
    posed = np.all(np.isfinite(qs), axis=1)
    world = np.full((n, len(skeleton.joint_names), 4, 4), np.nan)
    if posed.any():
        world[posed] = forward_kinematics(skeleton, qs[posed])
    effectors = default_marker_effectors(skeleton)
    offsets: dict[str, dict[str, tuple[float, float, float]]] = {}
    spread: dict[str, float] = {}
    used: dict[str, int] = {}
    for name, members in members_mm.items():
        if len(members) < 2:
            continue
        if name not in effectors:
            raise ConfigError(
                f"dynamic calibration: expected marker sets {sorted(effectors)}, found {name!r}"
            )
        fit = np.asarray(fit_mm[name], dtype=float)
        if fit.shape != (n,):
            raise ShapeError(f"fit_mm[{name!r}]: expected shape ({n},), found {fit.shape}")
        eff = effectors[name]
        world_from_joint = world[:, skeleton.joint_index(eff.joint)]
        local: dict[str, FloatArray] = {}
        traj_mm: list[FloatArray] = []
        for member, traj in members.items():
            m = np.asarray(traj, dtype=float)
            if m.shape != (n, 3):
                raise ShapeError(
                    f"members_mm[{name!r}][{member!r}]: expected shape ({n}, 3), found {m.shape}"
                )
            local[member] = points_in_frame(world_from_joint, m) - np.asarray(eff.point_mm)
            traj_mm.append(m)
        # the set's centre as the tracker sees it: the members' mean
        centre = np.mean(traj_mm, axis=0)
        good = calibration_frames(skeleton, world, name, t, centre, fit, max_fit_mm)
        for loc in local.values():
            good &= np.all(np.isfinite(loc), axis=1)
        if int(good.sum()) < min_frames:
            continue
        rows = np.flatnonzero(good)
        agree = consensus_frames(np.stack([loc[rows] for loc in local.values()], axis=1))
        if int(agree.sum()) < min_frames:
            continue
        good[:] = False
        good[rows[agree]] = True
        out: dict[str, tuple[float, float, float]] = {}
        worst = 0.0
        for member, loc in local.items():
            med = np.median(loc[good], axis=0)
            out[member] = (float(med[0]), float(med[1]), float(med[2]))
            worst = max(worst, float(np.median(np.linalg.norm(loc[good] - med, axis=1))))
        offsets[name] = out
        spread[name] = worst
        used[name] = int(good.sum())
    if not offsets:
        raise ConfigError(
            f"dynamic calibration: expected a marker set with two or more members seen on "
            f"at least {min_frames} usable frames (fit within {max_fit_mm:g} mm, slow, a "
            "hand's arm hanging), found none"
        )
    return DynamicCalibration(offsets, spread, used, n)


__all__ = [
    "CONSENSUS_DEG",
    "CONSENSUS_ROUNDS",
    "HANGING_FRACTION",
    "MAX_FIT_MM",
    "MAX_SEEDS",
    "MIN_FRAMES",
    "SLOW_PERCENTILE",
    "DynamicCalibration",
    "calibrate_members_on_motion",
    "calibration_frames",
    "consensus_frames",
    "layout_turn_deg",
]
