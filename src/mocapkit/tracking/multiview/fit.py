"""The compiled model fit: a jointed skeleton posed so that its points reproject onto every
view's 2-D detections (robust weighted least squares, Levenberg-Marquardt).

Residuals live in the normalised image plane of each camera (detections undistorted once,
`mocapkit.camera.pinhole.Camera.undistort_pixels`), scaled by the subject's depth in that
view, so that a residual reads as millimetres across the ray at the subject and every
threshold is independent of the image size. The loss per (view, joint) is Huber's on the
2-D residual's length, times the detection's weight; a prior pulls each DoF towards a
reference pose (the previous frame), and a weak one each fitted point towards its place
there in 3-D (holding the depth that views nearly in line leave free). Joint limits are
kept by projecting every step onto the box. The Jacobian is analytic: the skeleton's point Jacobian
(`mocapkit.skeleton.kinematics.points_jacobian_pose_nb`) through the camera rotation and
the perspective division.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
from numpy.typing import NDArray

from mocapkit.skeleton.kinematics import (
    KinematicArrays,
    fk_points_jacobian_pose_nb,
    fk_pose_nb,
)

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


class ViewArrays(NamedTuple):
    """The views of one fit in kernel layout.

    Attributes
    ----------
    rotation : ndarray, shape (V, 3, 3)
        Rotations of ``camera_from_world``.
    translation_mm : ndarray, shape (V, 3)
    """

    rotation: FloatArray
    translation_mm: FloatArray


class FitTargets(NamedTuple):
    """What one frame's fit is asked to match.

    Attributes
    ----------
    observed : ndarray, shape (V, K, 2)
        Undistorted normalised image coordinates of each detection (NaN: none).
    weight : ndarray, shape (V, K)
        Weight of each detection (0: not used).
    scale_mm : ndarray, shape (V,)
        Depth of the subject in each view (mm): residuals are normalised coordinates
        times this, millimetres across the ray at the subject.
    q_ref : ndarray, shape (D,)
        Reference pose of the prior.
    prior : ndarray, shape (D,)
        Square root of each DoF's prior weight (mm per rad, or per mm); positive.
    point_ref_mm : ndarray, shape (K, 3)
        Reference place of each fitted point (the previous frame's; NaN: none).
    point_prior : ndarray, shape (K,)
        Square root of the weight (mm of residual per mm) pulling each point towards
        ``point_ref_mm`` in 3-D: it holds a point along the rays where its views do not
        fix its depth (two views nearly in line); 0: none.
    """

    observed: FloatArray
    weight: FloatArray
    scale_mm: FloatArray
    q_ref: FloatArray
    prior: FloatArray
    point_ref_mm: FloatArray
    point_prior: FloatArray


@numba.njit(cache=True)
def points_nb(
    q: FloatArray, kin: KinematicArrays, target_joint: IntArray, target_point: FloatArray
) -> FloatArray:
    """World places (K, 3) of the fitted points at pose ``q``."""
    n_dofs = q.shape[0]
    world = np.empty((kin.parents.shape[0], 4, 4))
    fk_pose_nb(q, kin, world, np.empty((n_dofs, 3)), np.empty((n_dofs, 3)))
    n_pts = target_joint.shape[0]
    pts = np.empty((n_pts, 3))
    for k in range(n_pts):
        jk = target_joint[k]
        for a in range(3):
            pts[k, a] = (
                world[jk, a, 0] * target_point[k, 0]
                + world[jk, a, 1] * target_point[k, 1]
                + world[jk, a, 2] * target_point[k, 2]
                + world[jk, a, 3]
            )
    return pts


@numba.njit(cache=True, inline="always")
def view_residual_nb(
    r: FloatArray, t: FloatArray, s: float, p: FloatArray, ox: float, oy: float
) -> tuple[float, float, float, float, float]:
    """A point ``p`` (3,) in a view's camera frame (``r``, ``t``) and its residual (mm
    across the ray: normalised coordinates times ``s``) against the detection ``(ox,
    oy)``; the residual is meaningless when the depth is below 1 mm (not visible)."""
    x, y, z = p[0], p[1], p[2]
    xc = r[0, 0] * x + r[0, 1] * y + r[0, 2] * z + t[0]
    yc = r[1, 0] * x + r[1, 1] * y + r[1, 2] * z + t[1]
    zc = r[2, 0] * x + r[2, 1] * y + r[2, 2] * z + t[2]
    if zc < 1.0:
        return xc, yc, zc, np.nan, np.nan
    return xc, yc, zc, s * (xc / zc - ox), s * (yc / zc - oy)


@numba.njit(cache=True)
def evaluate_nb(
    q: FloatArray,
    kin: KinematicArrays,
    target_joint: IntArray,
    target_point: FloatArray,
    views: ViewArrays,
    tg: FitTargets,
    delta_mm: float,
    want_normal: bool,
    hess: FloatArray,
    grad: FloatArray,
    norms: FloatArray,
) -> float:
    """Robust cost of pose ``q``; with ``want_normal`` also the Gauss-Newton normal
    equations ``hess`` (D, D) and ``grad`` (D,) of the iteratively reweighted problem.

    ``norms`` (V, K) receives each residual's length (mm; NaN without a detection or
    behind the camera), whatever its weight.
    """
    n_dofs = q.shape[0]
    n_views = views.rotation.shape[0]
    n_pts = target_joint.shape[0]
    n_joints = kin.parents.shape[0]
    world = np.empty((n_joints, 4, 4))
    axis_world = np.empty((n_dofs, 3))
    pivot_world = np.empty((n_dofs, 3))
    pts = np.empty((n_pts, 3))
    jac = np.empty((3 * n_pts, n_dofs))
    if want_normal:
        fk_points_jacobian_pose_nb(
            q, kin, target_joint, target_point, world, axis_world, pivot_world, pts, jac
        )
        hess[:, :] = 0.0
        grad[:] = 0.0
    else:
        pts[:, :] = points_nb(q, kin, target_joint, target_point)
    row_x = np.empty(n_dofs)
    row_y = np.empty(n_dofs)
    nz = np.empty(n_dofs, dtype=np.int64)
    # a point moves with the DoFs of its chain only: each point's nonzero columns, once
    chain = np.empty((n_pts, n_dofs), dtype=np.int64)
    n_chain = np.zeros(n_pts, dtype=np.int64)
    if want_normal:
        for k in range(n_pts):
            for d in range(n_dofs):
                if jac[3 * k, d] != 0.0 or jac[3 * k + 1, d] != 0.0 or jac[3 * k + 2, d] != 0.0:
                    chain[k, n_chain[k]] = d
                    n_chain[k] += 1
    cost = 0.0
    for v in range(n_views):
        r = views.rotation[v]
        t = views.translation_mm[v]
        s = tg.scale_mm[v]
        for k in range(n_pts):
            norms[v, k] = np.nan
            ox, oy = tg.observed[v, k, 0], tg.observed[v, k, 1]
            if not (np.isfinite(ox) and np.isfinite(oy)):
                continue
            xc, yc, zc, rx, ry = view_residual_nb(r, t, s, pts[k], ox, oy)
            if zc < 1.0:
                continue
            n = np.sqrt(rx * rx + ry * ry)
            norms[v, k] = n
            wk = tg.weight[v, k]
            if wk <= 0.0:
                continue
            if n <= delta_mm:
                cost += wk * 0.5 * n * n
                irls = wk
            else:
                cost += wk * delta_mm * (n - 0.5 * delta_mm)
                irls = wk * delta_mm / n
            if not want_normal:
                continue
            a0 = s / zc
            ax = -s * xc / (zc * zc)
            ay = -s * yc / (zc * zc)
            n_nz = n_chain[k]
            for ia in range(n_nz):
                d = chain[k, ia]
                j0, j1, j2 = jac[3 * k, d], jac[3 * k + 1, d], jac[3 * k + 2, d]
                c0 = r[0, 0] * j0 + r[0, 1] * j1 + r[0, 2] * j2
                c1 = r[1, 0] * j0 + r[1, 1] * j1 + r[1, 2] * j2
                c2 = r[2, 0] * j0 + r[2, 1] * j1 + r[2, 2] * j2
                row_x[ia] = a0 * c0 + ax * c2
                row_y[ia] = a0 * c1 + ay * c2
                nz[ia] = d
            for ia in range(n_nz):
                a = nz[ia]
                xa, ya = row_x[ia], row_y[ia]
                grad[a] += irls * (xa * rx + ya * ry)
                for ib in range(ia, n_nz):
                    hess[a, nz[ib]] += irls * (xa * row_x[ib] + ya * row_y[ib])
    for k in range(n_pts):
        pp = tg.point_prior[k]
        if pp > 0.0:
            for a in range(3):
                ref = tg.point_ref_mm[k, a]
                if not np.isfinite(ref):
                    continue
                e = pp * (pts[k, a] - ref)
                cost += 0.5 * e * e
                if not want_normal:
                    continue
                n_nz = 0
                for d in range(n_dofs):
                    if jac[3 * k + a, d] != 0.0:
                        nz[n_nz] = d
                        n_nz += 1
                for ia in range(n_nz):
                    d = nz[ia]
                    ja = pp * jac[3 * k + a, d]
                    grad[d] += ja * e
                    for ib in range(ia, n_nz):
                        hess[d, nz[ib]] += ja * pp * jac[3 * k + a, nz[ib]]
    for d in range(n_dofs):
        e = tg.prior[d] * (q[d] - tg.q_ref[d])
        cost += 0.5 * e * e
        if want_normal:
            hess[d, d] += tg.prior[d] * tg.prior[d]
            grad[d] += tg.prior[d] * e
    if want_normal:
        for a in range(n_dofs):
            for b in range(a):
                hess[a, b] = hess[b, a]
    return cost


@numba.njit(cache=True)
def cholesky_solve_nb(a: FloatArray, grad: FloatArray, out: FloatArray) -> bool:
    """``out = -a^-1 grad`` for a symmetric positive definite ``a`` (D, D) by Cholesky,
    in place on ``a``'s lower triangle; False (``a`` spoilt) when it is not positive
    definite."""
    n = a.shape[0]
    for j in range(n):
        d = a[j, j]
        for k in range(j):
            d -= a[j, k] * a[j, k]
        if not d > 0.0:
            return False
        d = np.sqrt(d)
        a[j, j] = d
        for i in range(j + 1, n):
            v = a[i, j]
            for k in range(j):
                v -= a[i, k] * a[j, k]
            a[i, j] = v / d
    for i in range(n):  # L y = -grad
        v = -grad[i]
        for k in range(i):
            v -= a[i, k] * out[k]
        out[i] = v / a[i, i]
    for i in range(n - 1, -1, -1):  # L^T x = y
        v = out[i]
        for k in range(i + 1, n):
            v -= a[k, i] * out[k]
        out[i] = v / a[i, i]
    return True


@numba.njit(cache=True)
def fit_pose_nb(
    q: FloatArray,
    kin: KinematicArrays,
    target_joint: IntArray,
    target_point: FloatArray,
    views: ViewArrays,
    tg: FitTargets,
    lower: FloatArray,
    upper: FloatArray,
    delta_mm: float,
    max_iter: int,
    norms: FloatArray,
) -> tuple[float, int]:
    """Levenberg-Marquardt (Marquardt's diagonal scaling) on the robust cost, in place
    on ``q``, each step projected onto the joint limits ``[lower, upper]``; the damped
    normal equations solved by Cholesky (`cholesky_solve_nb`; LU if not positive definite).

    Stops when a step lowers the cost by less than 1e-6 of it, when the damping grows
    past 1e8, or after ``max_iter`` accepted or rejected steps. Returns the final cost
    and the number of steps; ``norms`` (V, K) holds the residual lengths at the result.
    """
    n = q.shape[0]
    hess = np.empty((n, n))
    grad = np.empty(n)
    for d in range(n):
        q[d] = min(max(q[d], lower[d]), upper[d])
    cost = evaluate_nb(
        q, kin, target_joint, target_point, views, tg, delta_mm, True, hess, grad, norms
    )
    lam = 1e-3
    trial = np.empty(n)
    a = np.empty((n, n))
    dq = np.empty(n)
    steps = 0
    for _ in range(max_iter):
        steps += 1
        for i in range(n):
            for j in range(n):
                a[i, j] = hess[i, j]
            a[i, i] += lam * hess[i, i] + 1e-9
        if not cholesky_solve_nb(a, grad, dq):  # not positive definite: LU (a again)
            for i in range(n):
                for j in range(n):
                    a[i, j] = hess[i, j]
                a[i, i] += lam * hess[i, i] + 1e-9
            dq[:] = np.linalg.solve(a, -grad)
        for d in range(n):
            trial[d] = min(max(q[d] + dq[d], lower[d]), upper[d])
        c_new = evaluate_nb(
            trial, kin, target_joint, target_point, views, tg, delta_mm, False, hess, grad, norms
        )
        if c_new < cost:
            gain = cost - c_new
            q[:] = trial
            cost = evaluate_nb(
                q, kin, target_joint, target_point, views, tg, delta_mm, True, hess, grad, norms
            )
            lam = max(lam / 3.0, 1e-9)
            if gain < 1e-6 * cost:
                break
        else:
            lam *= 4.0
            if lam > 1e8:
                break
    evaluate_nb(q, kin, target_joint, target_point, views, tg, delta_mm, False, hess, grad, norms)
    return cost, steps


def view_arrays(camera_from_world: list[FloatArray]) -> ViewArrays:
    """`ViewArrays` of cameras given by their ``camera_from_world`` (4, 4) matrices."""
    m = np.stack([np.asarray(c, dtype=float) for c in camera_from_world])
    return ViewArrays(np.ascontiguousarray(m[:, :3, :3]), np.ascontiguousarray(m[:, :3, 3]))


__all__ = [
    "FitTargets",
    "ViewArrays",
    "cholesky_solve_nb",
    "evaluate_nb",
    "fit_pose_nb",
    "points_nb",
    "view_arrays",
    "view_residual_nb",
]
