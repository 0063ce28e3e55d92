"""The swivel of an arm: its elbow's rotation about the shoulder-wrist axis (the IK's free angle).

With the hand fixed, a 4-DoF arm (3 shoulder + elbow) keeps one degree of freedom: the
elbow can circle the shoulder-wrist axis (Azad et al. 2008's swivel angle; recipe Z of
the errata, "hold the hand exactly"). Rotating the upper arm's world rotation about that
axis by ``alpha`` while keeping the elbow angle moves the elbow on that circle and leaves
the wrist (any point of the hand) in place. The shoulder's new local rotation is
decomposed back onto its DoFs: three revolute axes that are distinct signed basis
vectors (intrinsic Tait-Bryan angles, zhang21) or a ball joint's rotation vector
(azad14). Compiled kernels for the trackers' inner loops and a `swivel_arm` on poses.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ShapeError
from mocapkit.geometry.rotations import axis_angle_matrix_nb, matrix_rotvec_nb
from mocapkit.skeleton.kinematics import forward_kinematics
from mocapkit.skeleton.limbs import arm
from mocapkit.skeleton.model import BALL, REVOLUTE, Skeleton

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: `ShoulderDofs.kind`: three revolute DoFs about distinct signed basis axes.
TAIT_BRYAN = 0
#: `ShoulderDofs.kind`: one ball joint, a rotation vector.
ROTATION_VECTOR = 1


class ShoulderDofs(NamedTuple):
    """How a shoulder's three DoFs parametrise its local rotation (build with `shoulder_dofs`).

    Attributes
    ----------
    kind : int
        `TAIT_BRYAN` or `ROTATION_VECTOR`.
    basis : ndarray of int64, shape (3,)
        Tait-Bryan: the basis axis (0, 1, 2 for x, y, z) of each DoF in product order.
    signs : ndarray, shape (3,)
        Tait-Bryan: +1 or -1, the sign of each DoF's axis.
    """

    kind: int
    basis: IntArray
    signs: FloatArray


def shoulder_dofs(skeleton: Skeleton, dofs: ArrayLike) -> ShoulderDofs:
    """The parametrisation of three shoulder DoFs of ``skeleton``.

    Raises
    ------
    ShapeError
        When the DoFs are neither one ball joint nor three revolute DoFs about distinct
        signed basis axes.
    """
    d = np.asarray(dofs, dtype=np.int64)
    kinds = skeleton.dof_kind[d]
    if d.shape == (3,) and np.all(kinds == BALL):
        return ShoulderDofs(ROTATION_VECTOR, np.arange(3, dtype=np.int64), np.ones(3))
    if d.shape != (3,) or np.any(kinds != REVOLUTE):
        raise ShapeError(
            f"skeleton {skeleton.name!r}: a swivel needs 3 revolute or one ball shoulder DoFs, "
            f"found kinds {kinds.tolist()}"
        )
    axes = skeleton.dof_axis[d]
    basis = np.argmax(np.abs(axes), axis=1)
    if not np.allclose(np.abs(axes[np.arange(3), basis]), 1.0) or len(set(basis.tolist())) != 3:
        raise ShapeError(
            f"skeleton {skeleton.name!r}: shoulder axes {axes.tolist()} are not three distinct "
            "basis vectors"
        )
    return ShoulderDofs(
        TAIT_BRYAN, basis.astype(np.int64), np.sign(axes[np.arange(3), basis]).astype(float)
    )


@numba.njit(cache=True)
def swivel_local_nb(
    parent_rotation: FloatArray,
    upper_rotation: FloatArray,
    shoulder: FloatArray,
    hand: FloatArray,
    alpha: float,
    local: FloatArray,
) -> bool:
    """The shoulder's local rotation after a swivel of ``alpha`` rad (right-handed about
    shoulder -> hand).

    ``local = Rot(P^T n, alpha) @ P^T R_upper`` with ``P`` the world rotation of the
    shoulder's parent, ``R_upper`` the upper arm's and ``n`` the unit shoulder -> hand
    direction (world). Writes ``local`` (3, 3); False when hand and shoulder coincide.
    """
    n0 = hand[0] - shoulder[0]
    n1 = hand[1] - shoulder[1]
    n2 = hand[2] - shoulder[2]
    nn = math.sqrt(n0**2 + n1**2 + n2**2)
    if nn < 1e-9:
        return False
    pr = parent_rotation
    npar = np.empty(3)
    for i in range(3):
        npar[i] = (pr[0, i] * n0 + pr[1, i] * n1 + pr[2, i] * n2) / nn
    sw = np.empty((3, 3))
    axis_angle_matrix_nb(npar, alpha, sw)
    tmp = np.empty((3, 3))
    for i in range(3):  # tmp = P^T R_upper
        for j in range(3):
            tmp[i, j] = (
                pr[0, i] * upper_rotation[0, j]
                + pr[1, i] * upper_rotation[1, j]
                + pr[2, i] * upper_rotation[2, j]
            )
    for i in range(3):
        for j in range(3):
            local[i, j] = sw[i, 0] * tmp[0, j] + sw[i, 1] * tmp[1, j] + sw[i, 2] * tmp[2, j]
    return True


@numba.njit(cache=True)
def shoulder_params_nb(shoulder: ShoulderDofs, local: FloatArray, out: FloatArray) -> None:
    """Write the three shoulder DoF values (rad) of a local rotation (3, 3) into ``out``.

    Tait-Bryan: intrinsic angles about the DoFs' basis axes in product order
    (``R = R_i(phi1) R_j(phi2) R_k(phi3)``), the middle one in [-pi/2, pi/2], times the
    axes' signs. Ball: the rotation vector, angle in [0, pi].
    """
    if shoulder.kind == ROTATION_VECTOR:
        matrix_rotvec_nb(local, out)
        return
    i = shoulder.basis[0]
    j = shoulder.basis[1]
    k = shoulder.basis[2]
    eps = 1.0 if (j - i) % 3 == 1 else -1.0  # parity of the axis permutation
    phi2 = math.asin(min(max(eps * local[i, k], -1.0), 1.0))
    phi1 = math.atan2(-eps * local[j, k], local[k, k])
    phi3 = math.atan2(-eps * local[i, j], local[i, i])
    out[0] = phi1 * shoulder.signs[0]
    out[1] = phi2 * shoulder.signs[1]
    out[2] = phi3 * shoulder.signs[2]


@numba.njit(cache=True)
def swivel_angle_nb(
    shoulder: FloatArray, elbow: FloatArray, wrist: FloatArray, reference_elbow: FloatArray
) -> float:
    """Signed angle (rad, right-handed about shoulder -> wrist) from ``reference_elbow`` to
    ``elbow``, both projected on the plane orthogonal to the shoulder-wrist axis."""
    ax = wrist - shoulder
    ax = ax / math.sqrt(ax[0] ** 2 + ax[1] ** 2 + ax[2] ** 2)
    a = reference_elbow - shoulder
    b = elbow - shoulder
    a = a - (a[0] * ax[0] + a[1] * ax[1] + a[2] * ax[2]) * ax
    b = b - (b[0] * ax[0] + b[1] * ax[1] + b[2] * ax[2]) * ax
    cx = a[1] * b[2] - a[2] * b[1]
    cy = a[2] * b[0] - a[0] * b[2]
    cz = a[0] * b[1] - a[1] * b[0]
    sin = cx * ax[0] + cy * ax[1] + cz * ax[2]
    cos = a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    return math.atan2(sin, cos)


def swivel_angle(
    shoulder: ArrayLike, elbow: ArrayLike, wrist: ArrayLike, reference_elbow: ArrayLike
) -> float:
    """`swivel_angle_nb` on world points (3,) in mm; returns radians."""
    pts = [
        np.ascontiguousarray(p, dtype=np.float64) for p in (shoulder, elbow, wrist, reference_elbow)
    ]
    if any(p.shape != (3,) for p in pts):
        raise ShapeError(
            f"swivel_angle: expected four points (3,), found {[p.shape for p in pts]}"
        )
    if np.linalg.norm(pts[2] - pts[0]) < 1e-9:
        raise ShapeError("swivel_angle: the wrist coincides with the shoulder")
    return float(swivel_angle_nb(pts[0], pts[1], pts[2], pts[3]))


def swivel_arm(skeleton: Skeleton, q: ArrayLike, side: str, angle_rad: float) -> FloatArray:
    """Rotate an arm about its shoulder-wrist axis, keeping the wrist in place (the IK ambiguity).

    The upper arm's world rotation is pre-multiplied by the rotation of ``angle_rad``
    about the shoulder -> wrist axis; the elbow angle is unchanged, so the wrist stays
    put. The arm is found by canonical names (`mocapkit.skeleton.limbs.arm`).

    Parameters
    ----------
    skeleton : Skeleton
    q : array_like, shape (D,)
    side : {"left", "right"}
    angle_rad : float
        Right-handed rotation about the shoulder -> wrist direction.

    Returns
    -------
    ndarray, shape (D,)
        Not clipped to joint limits.
    """
    qa = np.array(q, dtype=float)
    skeleton.check_q(qa)
    if qa.ndim != 1:
        raise ShapeError(f"q: expected one pose of shape ({skeleton.n_dofs},), found {qa.shape}")
    limb = arm(skeleton, side)
    shoulder_d = limb.dofs[:3]
    params = shoulder_dofs(skeleton, shoulder_d)
    world = forward_kinematics(skeleton, qa)
    s, h = world[limb.root, :3, 3], world[limb.end, :3, 3]
    local = np.empty((3, 3))
    ok = swivel_local_nb(
        np.ascontiguousarray(world[limb.parent, :3, :3]),
        np.ascontiguousarray(world[limb.root, :3, :3]),
        np.ascontiguousarray(s),
        np.ascontiguousarray(h),
        float(angle_rad),
        local,
    )
    if not ok:
        raise ShapeError(f"swivel_arm: the {side} wrist coincides with the shoulder")
    out = np.empty(3)
    shoulder_params_nb(params, local, out)
    qa[shoulder_d] = out
    return qa


__all__ = [
    "ROTATION_VECTOR",
    "TAIT_BRYAN",
    "ShoulderDofs",
    "shoulder_dofs",
    "shoulder_params_nb",
    "swivel_angle",
    "swivel_angle_nb",
    "swivel_arm",
    "swivel_local_nb",
]
