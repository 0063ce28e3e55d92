"""Standing or seated subjects for the hybrid tracker: the seat, the stature, the choice.

A seated subject (wheelchair sport, desk VR, driving) sits with the pelvis on a seat; the
hybrid tracker then holds the legs in a sitting pose and the pelvis at the seat's height
(`seat_skeleton`), plants no feet and runs no balance step
(``HybridConfig.posture = "seated"``), and reports no leg joints.

What is estimated from the markers, and how:

* **Stature without assuming standing** (`stature_from_reach_mm`): the head set's greatest
  distance to a hand set (99th percentile over the frames where both are seen) is taken
  as the model's head-to-wrist distance with the arm hanging straight down beside the
  trunk, which scales with the stature (``zhang21``: 0.506 of it; 0.487 with a
  population's proportions, `mocapkit.skeleton.scaling.fit_anthropometric`, as raw marker
  files get). The assumption is that the take holds the hand about as far from the head
  as a hanging arm for at least 1 % of its frames (a wheelchair push ends with the arm
  straight down at the rim); a take that keeps the hands near the head underestimates,
  one that reaches straight overhead or out overestimates by up to the head-to-shoulder
  distance. ``--height-mm`` overrides it.
* **Seat** (`estimate_seat_height_mm`): the pelvis (root) height is the head set's height
  when the subject sits most upright (95th percentile over the take) less the model's
  pelvis-to-head distance when sitting upright. The head set's centre is taken as the
  model's head point (its offset on the head is not known in a raw file).
* **Posture** (`choose_posture`): seated when the head set's upright height above the
  floor is below `SEATED_HEAD_RATIO` of the stature (standing, the head point sits at
  0.97 of it; seated on a chair or a wheelchair, at 0.7-0.8).

A standing subject without leg markers (`Crouch`): the relaxed pose's legs follow the
head's height over the planted feet, so a head that drops is taken by the knees and hips
(the pelvis as low as the head allows with the trunk upright) rather than by a forward
bend on straight legs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ConfigError
from mocapkit.skeleton.kinematics import canonical_positions
from mocapkit.skeleton.limbs import arm, limbs_present, vertical_root_dof
from mocapkit.skeleton.model import CANONICAL_JOINTS, Skeleton
from mocapkit.skeleton.scaling import standing_height_mm

FloatArray = NDArray[np.float64]

#: Postures the hybrid tracker takes (``auto`` chooses one of the first two).
POSTURES: tuple[str, ...] = ("standing", "seated", "auto")
#: Hip and knee flexion (rad) of the held sitting legs: thighs forward, shanks down.
SEATED_HIP_FLEXION_RAD = math.pi / 2
SEATED_KNEE_FLEXION_RAD = math.pi / 2
#: Largest neck flexion (rad, either way) of a seated model. With the pelvis held on the
#: seat, the IK lowered a leaning athlete's head by bowing the neck to its 45 deg limit
#: with the trunk upright, putting the shoulders 100 mm ahead of the acromion marker
#: (basket sprint, frames 1600-2200: elbow 199 / 178 mm mean / median at 45 deg, 148 / 128
#: at 20 deg; freeing the pelvis' tilt instead gave 195 / 142, both 185 / 130).
SEATED_NECK_FLEXION_RAD = math.radians(20.0)
#: Percentile of the head set's height taken as its height when most upright.
UPRIGHT_PERCENTILE = 95.0
#: Percentile of the head-to-hand distance taken as the hanging arm's reach.
REACH_PERCENTILE = 99.0
#: Fewest frames with head and a hand seen together for `stature_from_reach_mm`.
MIN_REACH_FRAMES = 20
#: Upright head height over stature below which ``auto`` takes the subject as seated.
SEATED_HEAD_RATIO = 0.88
#: Canonical joints left out of a seated subject's outputs (NaN): the legs.
SEATED_LEFT_OUT: tuple[str, ...] = (
    "left_hip",
    "left_knee",
    "left_ankle",
    "right_hip",
    "right_knee",
    "right_ankle",
)


def check_posture(posture: str, where: str = "--posture") -> str:
    """Return ``posture`` if it is one of `POSTURES`, else raise `ConfigError`."""
    if posture not in POSTURES:
        raise ConfigError(f"{where}: expected one of {', '.join(POSTURES)}, found {posture!r}")
    return posture


def sitting_pose(skeleton: Skeleton, q: ArrayLike) -> FloatArray:
    """``q`` with both legs in the sitting pose (hips and knees flexed 90 deg, the rest 0).

    The legs' flexion DoFs are found by name (``<l|r>_hip_flexion``, ``<l|r>_knee_flexion``
    of ``zhang21``); a skeleton without legs is returned unchanged.
    """
    out = np.array(q, dtype=float, copy=True)
    for lmb in limbs_present(skeleton, "leg"):
        out[lmb.dofs] = 0.0
    for prefix in ("l", "r"):
        for name, value in (
            (f"{prefix}_hip_flexion", SEATED_HIP_FLEXION_RAD),
            (f"{prefix}_knee_flexion", SEATED_KNEE_FLEXION_RAD),
        ):
            if name in skeleton.dof_names:
                out[skeleton.dof_index(name)] = value
    return out


def pelvis_to_head_mm(skeleton: Skeleton, head_point_mm: ArrayLike) -> float:
    """Height (mm) of a point on the head (in the head joint's frame, e.g. the head
    effector's point) above the pelvis (root) when the trunk is upright (q = 0)."""
    from mocapkit.skeleton.kinematics import forward_kinematics
    from mocapkit.skeleton.limbs import head_joint

    q = np.clip(skeleton.zero_pose(), skeleton.lower, skeleton.upper)
    world = forward_kinematics(skeleton, q)
    h = world[head_joint(skeleton)]
    p = h[:3, :3] @ np.asarray(head_point_mm, dtype=float) + h[:3, 3]
    root = canonical_positions(skeleton, q)[CANONICAL_JOINTS.index("pelvis")]
    return float(p[2] - root[2])


def hanging_reach_ratio(skeleton: Skeleton, head_point_mm: ArrayLike) -> float:
    """The model's head-point-to-wrist distance with the arms hanging (q = 0), over its
    stature (`mocapkit.skeleton.scaling.standing_height_mm`)."""
    from mocapkit.skeleton.kinematics import forward_kinematics
    from mocapkit.skeleton.limbs import head_joint

    q = np.clip(skeleton.zero_pose(), skeleton.lower, skeleton.upper)
    world = forward_kinematics(skeleton, q)
    h = world[head_joint(skeleton)]
    p = h[:3, :3] @ np.asarray(head_point_mm, dtype=float) + h[:3, 3]
    wrists = [world[arm(skeleton, s).end, :3, 3] for s in ("left", "right")]
    reach = float(np.mean([np.linalg.norm(p - w) for w in wrists]))
    return reach / standing_height_mm(skeleton)


def stature_from_reach_mm(
    skeleton: Skeleton,
    head_point_mm: ArrayLike,
    head_mm: ArrayLike,
    hands_mm: Sequence[ArrayLike],
    where: str = "markers",
) -> float:
    """Stature (mm) from the head-to-hand reach, without assuming a standing subject.

    The `REACH_PERCENTILE` of the distance from the head set to each hand set (frames
    where both are seen; the larger over the hands) divided by the model's hanging-arm
    reach ratio (`hanging_reach_ratio`; scale-free, so any stature of ``skeleton`` gives
    the same ratio).

    Parameters
    ----------
    skeleton : Skeleton
        The model (any stature).
    head_point_mm : array_like, shape (3,)
        The head effector's point in the head joint's frame.
    head_mm : array_like, shape (T, 3)
        Head set positions (NaN where unseen).
    hands_mm : sequence of array_like, shape (T, 3)
        One or two hand sets.
    where : str
        The file, for the message.

    Raises
    ------
    ConfigError
        Fewer than `MIN_REACH_FRAMES` frames see the head and a hand together; give the
        stature (``--height-mm``).
    """
    head = np.asarray(head_mm, dtype=float)
    reaches = []
    for hand in hands_mm:
        d = np.linalg.norm(head - np.asarray(hand, dtype=float), axis=1)
        d = d[np.isfinite(d)]
        if d.size >= MIN_REACH_FRAMES:
            reaches.append(float(np.percentile(d, REACH_PERCENTILE)))
    if not reaches:
        raise ConfigError(
            f"{where}: cannot estimate the stature of a seated subject: expected at least "
            f"{MIN_REACH_FRAMES} frames seeing the head set and a hand set together, found "
            "fewer; give --height-mm"
        )
    return max(reaches) / hanging_reach_ratio(skeleton, head_point_mm)


def estimate_seat_height_mm(
    skeleton: Skeleton, head_point_mm: ArrayLike, head_z_mm: ArrayLike
) -> float:
    """Pelvis (root) height (mm above the floor, z = 0) of a seated subject.

    The `UPRIGHT_PERCENTILE` of the head set's height less `pelvis_to_head_mm` of
    ``skeleton`` (scaled to the subject).
    """
    z = np.asarray(head_z_mm, dtype=float)
    z = z[np.isfinite(z)]
    if z.size == 0:
        raise ConfigError("head set: expected some frames with the head seen, found none")
    return float(np.percentile(z, UPRIGHT_PERCENTILE)) - pelvis_to_head_mm(skeleton, head_point_mm)


def seat_skeleton(skeleton: Skeleton, seat_height_mm: float) -> Skeleton:
    """``skeleton`` sitting on a seat: the pelvis (canonical joint) held at
    ``seat_height_mm`` above the floor and the legs held in the sitting pose
    (`sitting_pose`), by setting those DoFs' lower and upper limits equal, so the IK
    leaves them where they are; the neck's flexion is limited to
    `SEATED_NECK_FLEXION_RAD` so that a lower head is a leaning trunk."""
    if not math.isfinite(seat_height_mm) or seat_height_mm <= 0:
        raise ConfigError(
            f"seat height: expected a height > 0 mm above the floor, found {seat_height_mm}"
        )
    sit = sitting_pose(skeleton, np.zeros(skeleton.n_dofs))
    lower, upper = skeleton.lower.copy(), skeleton.upper.copy()
    for lmb in limbs_present(skeleton, "leg"):
        lower[lmb.dofs] = upper[lmb.dofs] = sit[lmb.dofs]
    if "neck_flexion" in skeleton.dof_names:
        i = skeleton.dof_index("neck_flexion")
        lower[i] = max(lower[i], -SEATED_NECK_FLEXION_RAD)
        upper[i] = min(upper[i], SEATED_NECK_FLEXION_RAD)
    tz = vertical_root_dof(skeleton)
    # the root translation is added to the rest pose's pelvis height
    q0 = np.clip(skeleton.zero_pose(), skeleton.lower, skeleton.upper)
    q0[tz] = 0.0
    rest_mm = float(canonical_positions(skeleton, q0)[CANONICAL_JOINTS.index("pelvis"), 2])
    lower[tz] = upper[tz] = seat_height_mm - rest_mm
    return skeleton.replace(lower=lower, upper=upper)


#: Knee flexion (rad) of the standing relaxed pose: slightly bent, off the straight limit
#: where the IK locks a DoF (a locked knee takes no relaxed-pose step and stays straight).
STANDING_KNEE_FLEXION_RAD = math.radians(5.0)

#: The head's drop below its standing height that `Crouch` leaves to the neck and trunk:
#: a nod lowers the head point by a few mm (0.2 rad, 100-150 mm above the neck: 2-3 mm),
#: and near the straight leg a few mm take tens of degrees of knee (3 mm: 10 deg), which
#: turned a nodding take's positions-only head 14 mm off its members' true offsets.
CROUCH_DEAD_BAND_MM = 10.0


@dataclass
class Crouch:
    """The relaxed legs of a standing subject, from the head's height over the feet.

    Head and hands do not say whether a head that drops is a squat or a forward bend on
    straight legs; the IK's relaxed pose (its null-space task) decides. With straight
    relaxed legs it bends the trunk (the squat's knees 4-19 deg against the truth's 100).
    Here each leg's relaxed hip and knee flexion lower the pelvis by as much as the head
    is below its standing height over the planted feet, with the hip kept over the
    ankle (the trunk upright above the base of support): the thigh, the shank and the
    hip-to-ankle distance make a triangle, whose angles give the flexions
    (`flexion_rad`). The standing height is the highest the head target has been over
    the feet so far (a marker set's place on the head, and the subject's stature against
    the model's, are not known exactly). The knee stays at least
    `STANDING_KNEE_FLEXION_RAD`, and the first `CROUCH_DEAD_BAND_MM` of a drop are left
    to the neck and trunk.

    Attributes
    ----------
    dofs : ndarray of int, shape (2L,)
        Per leg its hip and knee flexion DoFs (``<l|r>_hip_flexion``,
        ``<l|r>_knee_flexion`` of ``zhang21``, as `sitting_pose`).
    thigh_mm, shank_mm : ndarray, shape (L,)
        Hip-to-knee and knee-to-ankle lengths.
    standing_mm : float
        The head's standing height over the feet: the highest seen (NaN before any).
    """

    dofs: NDArray[np.int64]
    thigh_mm: FloatArray
    shank_mm: FloatArray
    standing_mm: float = math.nan

    @classmethod
    def of(cls, skeleton: Skeleton) -> Crouch | None:
        """The crouch of ``skeleton``; None where it has no legs with hip and knee flexions."""
        dofs: list[int] = []
        thigh, shank = [], []
        joints = canonical_positions(
            skeleton, np.clip(skeleton.zero_pose(), skeleton.lower, skeleton.upper)
        )
        for side, prefix in (("left", "l"), ("right", "r")):
            names = (f"{prefix}_hip_flexion", f"{prefix}_knee_flexion")
            if not all(n in skeleton.dof_names for n in names):
                continue
            dofs += [skeleton.dof_index(n) for n in names]
            hip, knee, ankle = (
                joints[CANONICAL_JOINTS.index(f"{side}_{j}")] for j in ("hip", "knee", "ankle")
            )
            thigh.append(float(np.linalg.norm(knee - hip)))
            shank.append(float(np.linalg.norm(ankle - knee)))
        if not dofs:
            return None
        return cls(np.asarray(dofs, dtype=np.int64), np.asarray(thigh), np.asarray(shank))

    def flexion_rad(self, head_above_feet_mm: float) -> FloatArray:
        """Hip and knee flexion (rad) of each leg (in `dofs` order) for the head at this
        height over the mean ankle: the pelvis lowered by the head's drop below
        `standing_mm` (raised to this height where it is higher), the hip over the ankle."""
        h = float(head_above_feet_mm)
        if not h <= self.standing_mm:
            self.standing_mm = h
        return self.lowered_rad(self.standing_mm - h - CROUCH_DEAD_BAND_MM)

    def lowered_rad(self, drop_mm: float) -> FloatArray:
        """Hip and knee flexion (rad) of each leg (in `dofs` order) that lower the hip by
        ``drop_mm`` (>= 0) from the straight leg, the hip kept over the ankle."""
        drop = max(0.0, float(drop_mm))
        out = np.empty(self.dofs.size)
        for k, (a, b) in enumerate(zip(self.thigh_mm, self.shank_mm, strict=True)):
            reach = min(max(a + b - drop, abs(a - b) + 1e-6), a + b)
            # the triangle thigh a, shank b, hip-to-ankle ``reach``: the hip's angle from
            # the vertical and the knee's bend from straight
            inner = (a * a + b * b - reach * reach) / (2.0 * a * b)
            knee = math.pi - math.acos(max(-1.0, min(1.0, inner)))
            hip = math.acos(min(1.0, (a * a + reach * reach - b * b) / (2.0 * a * reach)))
            if knee < STANDING_KNEE_FLEXION_RAD:
                knee = STANDING_KNEE_FLEXION_RAD
                hip = knee * b / (a + b)  # the same bend, the hip over the ankle
            out[2 * k], out[2 * k + 1] = hip, knee
        return out


def standing_relaxed_pose(skeleton: Skeleton, omega: ArrayLike) -> FloatArray:
    """``omega`` (the IK's relaxed pose) with the legs of `Crouch` at full height: knees
    bent `STANDING_KNEE_FLEXION_RAD`, hips over the ankles; clipped into the limits."""
    out = np.array(omega, dtype=float, copy=True)
    crouch = Crouch.of(skeleton)
    if crouch is not None:
        out[crouch.dofs] = crouch.lowered_rad(0.0)
    return np.clip(out, skeleton.lower, skeleton.upper)


@dataclass(frozen=True)
class PostureChoice:
    """The posture used, and why (printed by the CLI)."""

    posture: str
    reason: str
    height_mm: float
    seat_height_mm: float = math.nan


def choose_posture(
    posture: str, upright_head_mm: float, stature_mm: float, stature_source: str
) -> PostureChoice:
    """Resolve ``auto``: seated when the upright head height (`UPRIGHT_PERCENTILE` of the
    head set's height above the floor) is below `SEATED_HEAD_RATIO` of the stature.

    Parameters
    ----------
    posture : str
        One of `POSTURES`.
    upright_head_mm : float
        The head set's upright height above the floor.
    stature_mm : float
        The subject's stature, not assuming a posture (given, or from the reach).
    stature_source : str
        How the stature was found, for the reason.
    """
    check_posture(posture)
    ratio = upright_head_mm / stature_mm
    why = (
        f"head set at {upright_head_mm:.0f} mm above the floor when most upright = "
        f"{ratio:.2f} of the stature {stature_mm:.0f} mm ({stature_source}); "
        f"seated below {SEATED_HEAD_RATIO:g}"
    )
    if posture != "auto":
        return PostureChoice(posture, f"as asked; {why}", stature_mm)
    chosen = "seated" if ratio < SEATED_HEAD_RATIO else "standing"
    return PostureChoice(chosen, f"auto: {why}", stature_mm)


__all__ = [
    "CROUCH_DEAD_BAND_MM",
    "POSTURES",
    "SEATED_HEAD_RATIO",
    "SEATED_LEFT_OUT",
    "SEATED_NECK_FLEXION_RAD",
    "STANDING_KNEE_FLEXION_RAD",
    "Crouch",
    "PostureChoice",
    "check_posture",
    "choose_posture",
    "estimate_seat_height_mm",
    "hanging_reach_ratio",
    "pelvis_to_head_mm",
    "seat_skeleton",
    "sitting_pose",
    "standing_relaxed_pose",
    "stature_from_reach_mm",
]
