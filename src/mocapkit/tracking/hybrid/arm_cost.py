"""The compiled cost of one arm (Zhang et al. 2011 eq. 14) and its named kernel structures.

The arm problem of `mocapkit.tracking.hybrid.arm_refinement`, as Numba kernels on NamedTuples:
`ArmModel` holds the arm's chain below the shoulder's fixed parent
(`mocapkit.skeleton.chains.LimbChain`), its cones and hand effector (`ArmShape`), the
camera (`mocapkit.camera.projection.CameraArrays`) and the cost's targets and weights
(`ArmTerms`); the distance maps come as `mocapkit.cues.chamfer.ChamferMaps`. Arms are
found by canonical names (`arm_limb`), so ``zhang21``'s revolute shoulders and
``azad14``'s ball shoulders both work.

Cost (errata Z11). The literal eq. 13 sums the distance map over the *filled*
silhouette, which rewards poses that cover fewer pixels (foreshortened limbs, limbs
leaving the RoI). By default the cost is instead the mean truncated distance over
points sampled every ``sample_step_px`` along the projected **outlines** (contour
generators) of the upper-arm, forearm and hand cones (radii ``skeleton.radii_mm``; a
hand without a bone is left out); points outside the RoI or not visible count at the
cap. ``literal_sum=True`` runs the paper's sum over the filled silhouette (inside the
RoI, as §5.2 defines W and H). The hand term is ``lambda`` (px per mm) times the
distance of the hand effector from its marker target (recipe Z: lambda about 1-5 px/mm
with the normalised chamfer).

Outlines are the cones' exact contour generators (`mocapkit.geometry.cones`), scored by
`mocapkit.cues.chamfer`. The elbow-jump term adds ``elbow_jump_weight_per_mm`` times how
far the elbow lies beyond ``elbow_free_mm`` from the previous frame's elbow (see
`mocapkit.tracking.hybrid.arm_refinement`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.camera.projection import CameraArrays, to_camera_nb
from mocapkit.cues.chamfer import (
    ChamferMaps,
    filled_outline_sum_nb,
    outline_chamfer_nb,
    outline_points_px_nb,
)
from mocapkit.errors import ShapeError, unknown_name
from mocapkit.geometry.cones import cone_contour_generators_nb
from mocapkit.ik.swivel import ShoulderDofs, shoulder_dofs, shoulder_params_nb, swivel_local_nb
from mocapkit.skeleton.chains import LimbChain, chain_frames_nb
from mocapkit.skeleton.derived import PerSkeleton
from mocapkit.skeleton.limbs import SIDES, Limb, arm
from mocapkit.skeleton.model import Skeleton

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

_N_SEG = 3  # upper arm, forearm, hand


# ------------------------------------------------------------------ kernel structures


class ArmShape(NamedTuple):
    """The arm's cones and hand effector, and its shoulder's parametrisation (`ArmModel`).

    Attributes
    ----------
    bone_end_mm : ndarray, shape (3, 3)
        Bone ends of upper arm, forearm and hand in their own frames.
    radii_mm : ndarray, shape (3, 2)
        Proximal and distal cone radii.
    n_segments : int
        Cones scored: 2, or 3 with the hand.
    effector_mm : ndarray, shape (3,)
        Hand effector in the wrist joint's frame.
    shoulder : ShoulderDofs
        For the swivel (``kind`` -1: the shoulder's DoFs cannot express it).
    """

    bone_end_mm: FloatArray
    radii_mm: FloatArray
    n_segments: int
    effector_mm: FloatArray
    shoulder: ShoulderDofs


class ArmTerms(NamedTuple):
    """The cost's targets and weights (part of `ArmModel`); see `RefineConfig`.

    Attributes
    ----------
    hand_target_mm : ndarray, shape (3,)
    use_target : bool
    hand_weight_px_per_mm : float
    sample_step_px : float
    literal_sum : bool
    previous_elbow_mm : ndarray, shape (3,)
    elbow_jump_weight_per_mm : float
        0: no elbow-jump penalty.
    elbow_free_mm : float
    """

    hand_target_mm: FloatArray
    use_target: bool
    hand_weight_px_per_mm: float
    sample_step_px: float
    literal_sum: bool
    previous_elbow_mm: FloatArray
    elbow_jump_weight_per_mm: float
    elbow_free_mm: float


class ArmModel(NamedTuple):
    """Everything the compiled arm cost needs besides the distance maps.

    ``chain`` is the shoulder -> elbow -> wrist chain below the shoulder's parent, searched
    over the arm's 4 DoFs (`mocapkit.skeleton.chains`).
    """

    chain: LimbChain
    shape: ArmShape
    camera: CameraArrays
    terms: ArmTerms


# ------------------------------------------------------------------ compiled kernels


# The hot path passes the model's parts (chain, shape, camera, terms), not the whole
# `ArmModel`, down its calls: each call that takes the nested tuple copies its two dozen
# array structs, which cost more than the FK itself (1.5 us of 4.9 us per evaluation).


@numba.njit(cache=True, inline="always")
def arm_frames_nb(
    x: FloatArray,
    chain: LimbChain,
    shape: ArmShape,
    rots: FloatArray,
    orig: FloatArray,
    eff: FloatArray,
) -> None:
    """World rotations (3, 3, 3) and origins (3, 3) of upper arm, forearm and hand, and the
    hand effector (3,), at arm parameters ``x`` (4,)."""
    chain_frames_nb(x, chain, rots, orig)
    e = shape.effector_mm
    for i in range(3):
        eff[i] = rots[2, i, 0] * e[0] + rots[2, i, 1] * e[1] + rots[2, i, 2] * e[2] + orig[2, i]


@numba.njit(cache=True)
def arm_fk_nb(x: FloatArray, model: ArmModel, out: FloatArray) -> None:
    """Shoulder, elbow, wrist and hand effector (4, 3), world mm, at ``x`` (4,)."""
    rots = np.empty((3, 3, 3))
    orig = np.empty((3, 3))
    eff = np.empty(3)
    arm_frames_nb(x, model.chain, model.shape, rots, orig, eff)
    for k in range(3):
        out[k] = orig[k]
    out[3] = eff


@numba.njit(cache=True)
def _outline_segments_nb(
    rots: FloatArray, orig: FloatArray, shape: ArmShape, cam: CameraArrays, segments: FloatArray
) -> int:
    """Contour generators of the arm's cones in camera coordinates into ``segments`` (6, 2, 3):
    lines ``2 s`` and ``2 s + 1`` are cone ``s``'s two rulings (start, end; mm). Returns the
    number of cones."""
    a = np.empty(3)
    b = np.empty(3)
    for s in range(shape.n_segments):
        a[0], a[1], a[2] = to_camera_nb(cam, orig[s, 0], orig[s, 1], orig[s, 2])
        end = shape.bone_end_mm[s]
        r = rots[s]
        ex = r[0, 0] * end[0] + r[0, 1] * end[1] + r[0, 2] * end[2] + orig[s, 0]
        ey = r[1, 0] * end[0] + r[1, 1] * end[1] + r[1, 2] * end[2] + orig[s, 1]
        ez = r[2, 0] * end[0] + r[2, 1] * end[1] + r[2, 2] * end[2] + orig[s, 2]
        b[0], b[1], b[2] = to_camera_nb(cam, ex, ey, ez)
        cone_contour_generators_nb(
            a, b, shape.radii_mm[s, 0], shape.radii_mm[s, 1], segments[2 * s : 2 * s + 2]
        )
    return shape.n_segments


@numba.njit(cache=True)
def arm_outlines_nb(x: FloatArray, model: ArmModel, segments: FloatArray, eff: FloatArray) -> int:
    """Contour generators of the arm's cones at ``x`` (camera frame, see
    `_outline_segments_nb`) and the hand effector (world); returns the number of cones."""
    rots = np.empty((3, 3, 3))
    orig = np.empty((3, 3))
    arm_frames_nb(x, model.chain, model.shape, rots, orig, eff)
    return _outline_segments_nb(rots, orig, model.shape, model.camera, segments)


@numba.njit(cache=True, inline="always")
def _arm_cost_parts_nb(
    x: FloatArray,
    chain: LimbChain,
    shape: ArmShape,
    cam: CameraArrays,
    terms: ArmTerms,
    maps: ChamferMaps,
) -> tuple[float, float, float]:
    """Image term, hand offset (mm) and elbow jump (mm beyond the free distance; 0 when the
    penalty is off) at arm parameters ``x`` (4,)."""
    rots = np.empty((3, 3, 3))
    orig = np.empty((3, 3))
    eff = np.empty(3)
    arm_frames_nb(x, chain, shape, rots, orig, eff)
    segments = np.empty((2 * _N_SEG, 2, 3))
    n_seg = _outline_segments_nb(rots, orig, shape, cam, segments)
    tgt = terms.hand_target_mm
    hand = math.sqrt((eff[0] - tgt[0]) ** 2 + (eff[1] - tgt[1]) ** 2 + (eff[2] - tgt[2]) ** 2)
    jump = 0.0
    if terms.elbow_jump_weight_per_mm > 0.0:
        prev = terms.previous_elbow_mm
        d = math.sqrt(
            (orig[1, 0] - prev[0]) ** 2 + (orig[1, 1] - prev[1]) ** 2 + (orig[1, 2] - prev[2]) ** 2
        )
        jump = max(0.0, d - terms.elbow_free_mm)
    if terms.literal_sum:
        return filled_outline_sum_nb(cam, segments, n_seg, maps), hand, jump
    return outline_chamfer_nb(cam, segments, 2 * n_seg, maps, terms.sample_step_px), hand, jump


@numba.njit(cache=True)
def arm_cost_terms_nb(x: FloatArray, model: ArmModel, maps: ChamferMaps) -> tuple[float, float]:
    """Image term and hand offset (mm) of eq. 14 for arm parameters ``x`` (4,)."""
    image, hand, _jump = _arm_cost_parts_nb(
        x, model.chain, model.shape, model.camera, model.terms, maps
    )
    return image, hand


@numba.njit(cache=True)
def arm_cost_nb(x: FloatArray, model: ArmModel, maps: ChamferMaps) -> float:
    """Eq. 14: image term plus ``lambda * ||t - s||``, plus the elbow-jump penalty."""
    terms = model.terms
    image, hand, jump = _arm_cost_parts_nb(x, model.chain, model.shape, model.camera, terms, maps)
    cost = image + terms.hand_weight_px_per_mm * hand if terms.use_target else image
    if terms.elbow_jump_weight_per_mm > 0.0:
        cost += terms.elbow_jump_weight_per_mm * jump
    return cost


@numba.njit(cache=True)
def arm_outline_px_nb(x: FloatArray, model: ArmModel, out: FloatArray) -> int:
    """Projected outline sample points (px) the chamfer cost reads, into ``out`` (M, 2).

    Returns how many were written (at most M); points that are not visible are NaN.
    """
    segments = np.empty((2 * _N_SEG, 2, 3))
    eff = np.empty(3)
    n_seg = arm_outlines_nb(x, model, segments, eff)
    return outline_points_px_nb(model.camera, segments, 2 * n_seg, model.terms.sample_step_px, out)


@numba.njit(cache=True)
def swivel_x_nb(x: FloatArray, alpha: float, model: ArmModel, out: FloatArray) -> bool:
    """Arm parameters after a swivel of ``alpha`` rad about the shoulder -> effector axis
    (`mocapkit.ik.swivel`); the elbow is unchanged. Writes ``out`` (4,); returns False
    when the shoulder's DoFs cannot express it or the effector is at the shoulder."""
    if model.shape.shoulder.kind < 0:
        return False
    rots = np.empty((3, 3, 3))
    orig = np.empty((3, 3))
    eff = np.empty(3)
    arm_frames_nb(x, model.chain, model.shape, rots, orig, eff)
    local = np.empty((3, 3))
    if not swivel_local_nb(model.chain.parent_rotation, rots[0], orig[0], eff, alpha, local):
        return False
    shoulder_params_nb(model.shape.shoulder, local, out[:3])
    out[3] = x[3]
    return True


@numba.njit(cache=True)
def arm_cost_many_nb(xs: FloatArray, model: ArmModel, maps: ChamferMaps) -> FloatArray:
    """`arm_cost_nb` at each row of ``xs`` (N, 4); used for timing and grids."""
    out = np.empty(xs.shape[0])
    for i in range(xs.shape[0]):
        out[i] = arm_cost_nb(xs[i], model, maps)
    return out


class _ArmParts(NamedTuple):
    """What `arm_limb` and `arm_shape` derive from the skeleton alone (cached per skeleton)."""

    limb: Limb
    shoulder: ShoulderDofs
    bone_end_mm: FloatArray
    radii_mm: FloatArray
    hand_has_bone: bool


#: Per skeleton, per side: its checked arm. The refinement asks for it several times a
#: refined frame; the skeleton is immutable.
_ARM_PARTS: PerSkeleton[_ArmParts] = PerSkeleton()


def _arm_parts(skeleton: Skeleton, side: str) -> _ArmParts:
    return _ARM_PARTS.get(skeleton, side, _build_arm_parts, side)


def _build_arm_parts(skeleton: Skeleton, side: str) -> _ArmParts:
    limb = _checked_arm(skeleton, side)
    joints = list(limb.joints)
    try:
        shoulder = shoulder_dofs(skeleton, limb.dofs[:3])
    except ShapeError:  # no swivel for these axes: the scan is skipped
        shoulder = ShoulderDofs(-1, np.zeros(3, dtype=np.int64), np.ones(3))
    return _ArmParts(
        limb=limb,
        shoulder=shoulder,
        bone_end_mm=np.ascontiguousarray(skeleton.bone_end_mm[joints], dtype=np.float64),
        radii_mm=np.ascontiguousarray(skeleton.radii_mm[joints], dtype=np.float64),
        hand_has_bone=bool(np.any(skeleton.bone_end_mm[limb.end] != 0)),
    )


def arm_limb(skeleton: Skeleton, side: str) -> Limb:
    """The arm of ``side`` (`mocapkit.skeleton.limbs.arm`), checked for the refinement:
    a chain shoulder -> elbow -> wrist with 3 shoulder and 1 elbow rotational DoFs."""
    return _arm_parts(skeleton, side).limb


def _checked_arm(skeleton: Skeleton, side: str) -> Limb:
    if side not in SIDES:
        raise unknown_name("arm side", side, SIDES, "refine_arms")
    limb = arm(skeleton, side)
    names = [skeleton.joint_names[j] for j in limb.joints]
    if limb.chain.tolist() != list(limb.joints):
        raise ShapeError(
            f"skeleton {skeleton.name!r}: arm refinement needs the chain {' -> '.join(names)} "
            f"without joints between, found {[skeleton.joint_names[j] for j in limb.chain]}"
        )
    per_joint = [int(np.sum(skeleton.dof_joint[limb.dofs] == j)) for j in limb.joints]
    if per_joint != [3, 1, 0]:
        raise ShapeError(
            f"skeleton {skeleton.name!r}: arm refinement needs 3 rotational DoFs at "
            f"{names[0]!r}, 1 at {names[1]!r} and none at {names[2]!r}; found {per_joint}"
        )
    return limb


def arm_dofs(skeleton: Skeleton, side: str) -> IntArray:
    """Indices (4,) of an arm's shoulder (3 rotational) and elbow (1) DoFs."""
    return np.array(arm_limb(skeleton, side).dofs, dtype=np.int64)


def arm_shape(
    skeleton: Skeleton, side: str, effector_mm: ArrayLike, include_hand: bool = True
) -> ArmShape:
    """The `ArmShape` of one arm; a hand without a bone is never scored."""
    parts = _arm_parts(skeleton, side)
    sh = parts.shoulder
    # copies: the kernels' arrays are the caller's own, the cached ones stay untouched
    return ArmShape(
        bone_end_mm=parts.bone_end_mm.copy(),
        radii_mm=parts.radii_mm.copy(),
        n_segments=3 if include_hand and parts.hand_has_bone else 2,
        effector_mm=np.array(effector_mm, dtype=np.float64),
        shoulder=ShoulderDofs(sh.kind, sh.basis.copy(), sh.signs.copy()),
    )


__all__ = [
    "ArmModel",
    "ArmShape",
    "ArmTerms",
    "arm_cost_many_nb",
    "arm_cost_nb",
    "arm_cost_terms_nb",
    "arm_dofs",
    "arm_fk_nb",
    "arm_frames_nb",
    "arm_limb",
    "arm_outline_px_nb",
    "arm_outlines_nb",
    "arm_shape",
    "swivel_x_nb",
]
