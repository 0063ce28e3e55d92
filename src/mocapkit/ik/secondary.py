"""The relaxed-pose secondary task: pull joints towards a relaxed pose, weighted by gravity torque.

Zhang et al. 2011 §4.4 (eq. 9, after Boulic et al. 1994) with errata Z8 and Z13:

* the gradient of ``sum (theta_i - omega_i)^2`` is ``2 (theta_i - omega_i)``, so the
  task is ``dphi_i = -2 k w_i (theta_i - omega_i)`` (Z8a, Z8d);
* the weight ``w_i = m_i h_i / max(m h)`` uses the mass each DoF **carries** (its
  subtree with a pelvis root; on a leg whose foot is planted, the complement of
  the subtree, Z8b) and the lever arm ``h_i = |v_i . ((c_i - p_i) x g_hat)|`` of the
  carried centre of mass about the DoF axis (Z8c; zero for a vertical axis);
* DoFs of the root joint are left out (Z13);
* the result is clamped with ``ClampMaxAbs(., Gamma)`` (Z8d).

Everything here is computed from one pose's forward-kinematics arrays so the IK
kernel (:mod:`mocapkit.ik.sdls`) calls the same compiled code the tests check.
"""

from __future__ import annotations

from collections.abc import Sequence

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ShapeError
from mocapkit.skeleton import limbs
from mocapkit.skeleton.kinematics import (
    KinematicArrays,
    fk_pose_nb,
    kinematic_arrays,
    subtree_mass,
)
from mocapkit.skeleton.model import Skeleton

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Elbow flexion of the relaxed pose (recipe Z: arms down, 15 deg elbow flexion, spine 0).
RELAXED_ELBOW_FLEXION_RAD = float(np.radians(15.0))


def relaxed_pose(skeleton: Skeleton) -> FloatArray:
    """The relaxed configuration ``omega`` (D,): arms down, elbows flexed 15 deg, all else 0.

    The elbows are the flexion hinges of the arms the skeleton has
    (`mocapkit.skeleton.limbs.flexion_dofs`), each flexed 15 deg in its own model's
    sign: ``+15 deg`` for ``zhang21`` (range ``[0, 150] deg``), ``-15 deg`` for
    ``azad14`` (``theta_4 <= 0`` about ``-x``), the same forward bend. Every other DoF
    is 0 (for ``zhang21`` that is arms hanging, spine and neck straight, legs straight);
    the result is clipped into the joint limits.
    """
    omega = np.zeros(skeleton.n_dofs)
    for arm in limbs.limbs_present(skeleton, "arm"):
        dofs, signs = limbs.flexion_dofs(skeleton, arm)
        omega[dofs] = signs * RELAXED_ELBOW_FLEXION_RAD
    return np.clip(omega, skeleton.lower, skeleton.upper)


def planted_feet(skeleton: Skeleton) -> tuple[str, ...]:
    """Default planted joints: the canonical ankles of the legs the skeleton has.

    ``("l_foot", "r_foot")`` for ``zhang21``; none for an upper-body model (``azad14``).
    """
    return tuple(skeleton.joint_names[j] for j in limbs.ankle_joints(skeleton))


def secondary_mask(skeleton: Skeleton) -> BoolArray:
    """DoFs the secondary task acts on (D,): every DoF except those of the root joint (Z13)."""
    return np.asarray(skeleton.dof_joint != 0)


def planted_dofs(skeleton: Skeleton, planted_joints: Sequence[str]) -> BoolArray:
    """DoFs on the chain from the root to a planted joint (their load is the complement), (D,)."""
    anc = skeleton.ancestors_mask()
    flag = np.zeros(skeleton.n_dofs, dtype=bool)
    for name in planted_joints:
        j = skeleton.joint_index(name)
        flag |= anc[skeleton.dof_joint, j]
    flag &= skeleton.dof_joint != 0  # the root carries the whole body either way
    return flag


def carried_mass_planted(skeleton: Skeleton, planted_joints: Sequence[str] = ()) -> FloatArray:
    """Mass (kg) each DoF carries, shape (D,) (errata Z8b).

    The subtree below the DoF's joint; for a DoF on a leg whose foot is planted,
    the rest of the body (total minus that subtree), since the foot holds the leg
    and the joint bears everything above it.
    """
    sub = subtree_mass(skeleton)[skeleton.dof_joint]
    total = skeleton.total_mass_kg
    flag = planted_dofs(skeleton, planted_joints)
    return np.where(flag, total - sub, sub)


@numba.njit(cache=True)
def clamp_max_abs_nb(w: FloatArray, d: float) -> None:
    """ClampMaxAbs in place (errata Z6): shrink ``w`` so ``max|w| <= d``; never enlarge."""
    m = 0.0
    for i in range(w.shape[0]):
        a = abs(w[i])
        if a > m:
            m = a
    if m > d and m > 0.0:
        f = d / m
        for i in range(w.shape[0]):
            # clip the last ulp so that max|w| <= d holds exactly (idempotence)
            w[i] = min(max(w[i] * f, -d), d)


@numba.njit(cache=True)
def lever_weights_nb(
    kin: KinematicArrays,
    world: FloatArray,
    axis_world: FloatArray,
    pivot_world: FloatArray,
    mass: FloatArray,
    com_local: FloatArray,
    planted: BoolArray,
    mask: BoolArray,
    out: FloatArray,
) -> None:
    """Gravity-torque weights ``m_i h_i`` (unnormalised, kg mm) of every DoF into ``out`` (D,).

    ``com_local`` (J, 3) is each segment's centre of mass in its joint frame;
    ``planted`` flags DoFs that carry the complement of their subtree; DoFs
    outside ``mask`` get 0. Gravity is ``-Z`` (world frame is Z up).
    """
    parents = kin.parents
    dof_joint = kin.dof_joint
    n_joints = parents.shape[0]
    wsum = np.zeros((n_joints, 3))
    msum = np.zeros(n_joints)
    for j in range(n_joints):
        for a in range(3):
            c = (
                world[j, a, 0] * com_local[j, 0]
                + world[j, a, 1] * com_local[j, 1]
                + world[j, a, 2] * com_local[j, 2]
                + world[j, a, 3]
            )
            wsum[j, a] = c * mass[j]
        msum[j] = mass[j]
    for j in range(n_joints - 1, 0, -1):
        p = parents[j]
        for a in range(3):
            wsum[p, a] += wsum[j, a]
        msum[p] += msum[j]
    total_m = msum[0]
    # scalars, not array temporaries: this runs every IK iteration
    for d in range(axis_world.shape[0]):
        if not mask[d]:
            out[d] = 0.0
            continue
        j = dof_joint[d]
        if planted[d]:
            m = total_m - msum[j]
            wx = wsum[0, 0] - wsum[j, 0]
            wy = wsum[0, 1] - wsum[j, 1]
        else:
            m = msum[j]
            wx = wsum[j, 0]
            wy = wsum[j, 1]
        if m <= 1e-12:
            out[d] = 0.0
            continue
        rx = wx / m - pivot_world[d, 0]
        ry = wy / m - pivot_world[d, 1]
        # (c - p) x g_hat with g_hat = (0, 0, -1) is (-ry, rx, 0)
        h = abs(-axis_world[d, 0] * ry + axis_world[d, 1] * rx)
        out[d] = m * h


@numba.njit(cache=True)
def secondary_task_nb(
    q: FloatArray,
    omega: FloatArray,
    mh: FloatArray,
    gain: float,
    gamma: float,
    out: FloatArray,
) -> None:
    """``dphi_i = -2 k (m_i h_i / max m h)(theta_i - omega_i)``, then ClampMaxAbs(., Gamma) (Z8d).

    ``mh`` (D,) are the weights from `lever_weights_nb` (0 outside the task's DoFs).
    """
    top = 0.0
    for d in range(q.shape[0]):
        if mh[d] > top:
            top = mh[d]
    for d in range(q.shape[0]):
        if top > 0.0:
            out[d] = -2.0 * gain * (mh[d] / top) * (q[d] - omega[d])
        else:
            out[d] = 0.0
    clamp_max_abs_nb(out, gamma)


class SecondaryTask:
    """The relaxed-pose task of one skeleton (Python access for tests and diagnostics).

    Parameters
    ----------
    skeleton : Skeleton
    planted_joints : sequence of str, optional
        Joints held on the ground (their leg DoFs carry the complement mass);
        `planted_feet` (both ankles, none without legs) when omitted.
    omega : array_like, shape (D,), optional
        Relaxed pose; `relaxed_pose` when omitted.
    """

    def __init__(
        self,
        skeleton: Skeleton,
        planted_joints: Sequence[str] | None = None,
        omega: ArrayLike | None = None,
    ) -> None:
        self.skeleton = skeleton
        if planted_joints is None:
            planted_joints = planted_feet(skeleton)
        self.omega = relaxed_pose(skeleton) if omega is None else np.asarray(omega, float).copy()
        if self.omega.shape != (skeleton.n_dofs,):
            raise ShapeError(
                f"omega: expected the relaxed pose of shape ({skeleton.n_dofs},), "
                f"found {self.omega.shape}"
            )
        self.mask = secondary_mask(skeleton)
        self.planted = planted_dofs(skeleton, planted_joints)
        self.com_local = np.ascontiguousarray(skeleton.bone_end_mm * skeleton.com_fraction[:, None])
        self.mass = np.ascontiguousarray(skeleton.mass_kg, dtype=float)

    def weights(self, q: ArrayLike) -> FloatArray:
        """Unnormalised weights ``m_i h_i`` (D,) in kg mm at pose ``q`` (D,)."""
        qa = np.ascontiguousarray(q, dtype=float)
        self.skeleton.check_q(qa)
        kin = kinematic_arrays(self.skeleton)
        d, j = self.skeleton.n_dofs, self.skeleton.n_joints
        world = np.empty((j, 4, 4))
        axis_world = np.empty((d, 3))
        pivot_world = np.empty((d, 3))
        fk_pose_nb(qa, kin, world, axis_world, pivot_world)
        out = np.empty(d)
        lever_weights_nb(
            kin,
            world,
            axis_world,
            pivot_world,
            self.mass,
            self.com_local,
            self.planted,
            self.mask,
            out,
        )
        return out

    def cost(self, q: ArrayLike) -> float:
        """``sum_i m_i h_i (theta_i - omega_i)^2`` (kg mm rad^2) at ``q`` (D,), weights at ``q``."""
        qa = np.asarray(q, dtype=float)
        return float(np.sum(self.weights(qa) * (qa - self.omega) ** 2))

    def step(self, q: ArrayLike, gain: float, gamma_rad: float) -> FloatArray:
        """The secondary task ``dphi`` (D,) in joint space (rad) at ``q``."""
        qa = np.ascontiguousarray(q, dtype=float)
        out = np.empty(self.skeleton.n_dofs)
        secondary_task_nb(qa, self.omega, self.weights(qa), float(gain), float(gamma_rad), out)
        return out
