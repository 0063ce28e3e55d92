"""The tracker interface shared by every capture method: ``update(sample) -> FrameResult``.

A tracker is fed one sample at a time (as a live feed would) and answers with a
`FrameResult`: the pose ``q``, the canonical joints in the world, a status per tracked
effector or limb and named fit-quality figures. The runner
(`mocapkit.pipelines.run.run_tracker`) streams any tracker over a recording and writes
the result folder plus ``fit.csv`` from these results alone. A tracker whose answer
comes with a latency (the mono tracker's Viterbi) is a `DelayedTracker` instead.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import ShapeError
from mocapkit.skeleton.model import CANONICAL_JOINTS, Skeleton

FloatArray = NDArray[np.float64]

#: Per-frame status of an effector or limb: observed this frame; extrapolated over a
#: short gap; dropped from the task after a long gap; never observed yet.
STATUSES: tuple[str, ...] = ("seen", "bridged", "released", "missing")

#: Statuses under which an effector or limb has no observation behind its pose.
UNOBSERVED: tuple[str, ...] = ("released", "missing")

#: Longest gap (s) in an effector's or limb's observations that trackers bridge by
#: default (status ``bridged``); longer gaps are ``released``.
BRIDGE_S = 0.25

#: Speed (mm/s) allowed for what an input cannot show: the hybrid re-plant's allowance
#: beyond the head set's speed (`HybridConfig.replant_min_speed_mm_s`), and the most the
#: mono placement's depth estimate may change in a second beyond the tracker's own depth
#: motion (`mocapkit.tracking.mono.placement.DepthRate`).
UNSEEN_SPEED_MM_S = 1000.0

#: Factor on an input's speed that a part may move at beyond `UNSEEN_SPEED_MM_S`: the
#: hybrid re-plant's bound on the pelvis and legs against the head set
#: (`HybridConfig.replant_speed_factor`), and every result's plausibility check of each
#: joint against the inputs near it (`mocapkit.pipelines.run.speed_bound`).
INPUT_SPEED_FACTOR = 1.5

#: Time (s) over which a part released after a long gap goes from its held pose back to
#: the tracked one when it is observed again, rather than snapping there: the hybrid's
#: hand sets (their IK targets) and every result folder's held parts (their joint
#: angles, `mocapkit.pipelines.run.GAP_BLEND_S`).
REJOIN_BLEND_S = 0.5


def unobserved_part(name: str) -> tuple[str, tuple[str, ...]] | None:
    """The body part an effector or limb status ``name`` stands for, and the canonical
    joints that it alone places, which are made up while it is released or missing.

    ``"head"`` -> ``("head", ("head",))``; ``"left_hand"`` or ``"left_arm"`` ->
    ``("left_arm", ("left_elbow", "left_wrist"))``; ``"left_foot"`` or ``"left_leg"`` ->
    ``("left_leg", ("left_knee", "left_ankle"))``; None for any other name (a fit term,
    a marker-set member). The shoulder or hip stays: the trunk places it.
    """
    if name == "head":
        return "head", ("head",)
    side, _, part = name.partition("_")
    if side not in ("left", "right"):
        return None
    if part in ("hand", "arm"):
        return f"{side}_arm", (f"{side}_elbow", f"{side}_wrist")
    if part in ("foot", "leg"):
        return f"{side}_leg", (f"{side}_knee", f"{side}_ankle")
    return None


def observation_status(unseen_s: float, ever_seen: bool, bridge_s: float = BRIDGE_S) -> str:
    """The status of an effector or limb (`STATUSES`), the one rule of every tracker.

    Parameters
    ----------
    unseen_s : float
        Time since it was last observed (s): 0 when observed this frame.
    ever_seen : bool
        Whether it has been observed at all (on this frame or before).
    bridge_s : float
        Longest gap bridged (`BRIDGE_S` by default).

    Returns
    -------
    str
        ``missing`` (never observed), ``seen`` (observed now), ``bridged`` (unseen for
        at most ``bridge_s``) or ``released`` (longer).
    """
    if not ever_seen:
        return "missing"
    if unseen_s <= 0.0:
        return "seen"
    return "bridged" if unseen_s <= bridge_s else "released"


def unobserved_joints(status: Mapping[str, str]) -> tuple[str, ...]:
    """The canonical joints with no observation behind them, the one NaN rule of every
    tracker: for each effector or limb whose status is in `UNOBSERVED`, the joints that
    it alone places (`unobserved_part`)."""
    out: list[str] = []
    for name, st in status.items():
        part = unobserved_part(name) if st in UNOBSERVED else None
        out += [j for j in (part[1] if part is not None else ()) if j not in out]
    return tuple(out)


def nan_unobserved(joints_mm: FloatArray, status: Mapping[str, str]) -> FloatArray:
    """Canonical joints (15, 3) with the `unobserved_joints` of ``status`` set to NaN."""
    out = np.array(joints_mm, dtype=float, copy=True)
    for joint in unobserved_joints(status):
        out[CANONICAL_JOINTS.index(joint)] = np.nan
    return out


@dataclass
class FrameResult:
    """What a tracker reports for one sample.

    Attributes
    ----------
    time_s : float
        Time of the sample (s).
    q : ndarray, shape (D,)
        Joint parameters (rad, mm); NaN when the frame has no pose.
    joints_mm : ndarray, shape (K, 3)
        Canonical joints in the world frame (mm). Trackers fill the
        `CANONICAL_JOINTS` order (K = 15), NaN where not estimated
        (`canonical_joints_mm` builds it).
    status : dict of str to str
        Per effector or limb (``"head"``, ``"left_hand"``, ...), one of `STATUSES`.
    fit : dict of str to float
        Named fit-quality figures of this frame, each with its unit in the name
        (``"head_mm"``: distance of an effector to its marker; ``"rms_mm"``,
        ``"max_mm"``; a video tracker's ``"edge_px"``).
    worst : str
        Name of the effector or term that gives ``fit["max_mm"]`` (empty if none).
    held_dofs : ndarray of int
        DoFs of ``q`` that the tracker itself holds on this frame at their values of the
        last frame their part was observed (a ``released`` part), and blends back itself
        when the part is observed again: the result folder leaves them as given
        (`mocapkit.pipelines.run.motion_with_held_parts`) and holds the rest of the part. Empty
        (the default): the tracker holds nothing.
    """

    time_s: float
    q: FloatArray
    joints_mm: FloatArray
    status: dict[str, str]
    fit: dict[str, float]
    worst: str
    held_dofs: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))


@runtime_checkable
class Tracker(Protocol):
    """A streaming tracker on one skeleton."""

    skeleton: Skeleton

    def update(self, sample: Any) -> FrameResult:
        """Track one sample."""
        ...


@runtime_checkable
class DelayedTracker(Protocol):
    """A streaming tracker that answers with a latency (a fixed-lag or offline decoder).

    ``push`` takes one sample and returns the results it makes final (none, one or
    several, in time order; with a fixed lag of L samples, the result of sample k comes
    with sample k + L); ``finish`` returns every result still pending (all of them for
    an offline decoder). Over a whole recording there is one result per sample.
    """

    skeleton: Skeleton

    def push(self, sample: Any) -> list[FrameResult]:
        """Track one sample; returns the results this makes final."""
        ...

    def finish(self) -> list[FrameResult]:
        """End of the recording: the results still pending."""
        ...


def canonical_joints_mm(skeleton: Skeleton, joints_mm: FloatArray) -> FloatArray:
    """Spread a skeleton's canonical joints (``skeleton.canonical_names`` order) over the
    full `CANONICAL_JOINTS` order, NaN for the joints the skeleton lacks; shape (15, 3)."""
    j = np.asarray(joints_mm, dtype=float)
    names = skeleton.canonical_names
    if j.shape != (len(names), 3):
        raise ShapeError(
            f"canonical_joints_mm: expected ({len(names)}, 3) joints of {skeleton.name!r}, "
            f"found {j.shape}"
        )
    if names == CANONICAL_JOINTS:
        return j.copy()
    out = np.full((len(CANONICAL_JOINTS), 3), np.nan)
    for k, n in enumerate(names):
        out[CANONICAL_JOINTS.index(n)] = j[k]
    return out


def fit_summary(distances_mm: Mapping[str, float]) -> tuple[dict[str, float], str]:
    """Per-effector distances (mm, NaN when not in the task) plus their RMS and maximum.

    Returns
    -------
    fit : dict
        ``"<name>_mm"`` per effector, ``"rms_mm"`` and ``"max_mm"`` over the finite ones
        (NaN when none).
    worst : str
        The effector at the maximum (empty when none).
    """
    fit = {f"{n}_mm": float(d) for n, d in distances_mm.items()}
    finite = {n: float(d) for n, d in distances_mm.items() if math.isfinite(d)}
    if finite:
        worst = max(finite, key=lambda n: finite[n])
        values = np.fromiter(finite.values(), dtype=float)
        fit["rms_mm"] = float(np.sqrt(np.mean(values * values)))
        fit["max_mm"] = finite[worst]
    else:
        worst = ""
        fit["rms_mm"] = fit["max_mm"] = math.nan
    return fit, worst


__all__ = [
    "BRIDGE_S",
    "REJOIN_BLEND_S",
    "STATUSES",
    "UNOBSERVED",
    "UNSEEN_SPEED_MM_S",
    "DelayedTracker",
    "FrameResult",
    "Tracker",
    "canonical_joints_mm",
    "fit_summary",
    "nan_unobserved",
    "observation_status",
    "unobserved_joints",
    "unobserved_part",
]
