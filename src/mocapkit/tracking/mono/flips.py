"""Enumerating the forward/backward flips of every link, pruned during the search.

Mamania et al. (2004, §4.1-4.2, Fig. 4): with known link lengths each link seen in the
image has two 3-D configurations (towards or away from the camera), so a frame has
2^L candidate poses; joint-angle limits and collisions prune them (§4.2.2-4.2.3).
The search is a depth-first walk from the neck (recipe M step 4): a child joint lies
``sqrt(L^2 - d^2)`` in front of or behind its parent. Each constraint runs as soon as
the last link it reads is placed, so a pruned branch is never expanded; the survivors
are exactly those that full enumeration followed by filtering would keep (tested).

Two cameras:

- ``orthographic`` (the paper's, also weak perspective): joint inputs are image-plane
  positions in mm (or px) at the subject's depth; child z = parent z +- sqrt(L^2 - d^2).
- ``perspective``: joint inputs are viewing rays (x_n, y_n, 1) of a calibrated camera;
  the child is where its ray meets the sphere of radius L around the parent (two
  points, the same pixel). The root lies on its ray at a given depth.

Errata M5: a link whose projection is at least as long as the link (parallel to the
image, or longer through noise) has one configuration, not two; it is placed at its full
length along its projected direction (dz = 0), so its pixel moves by the excess. Then
there are 2^(L-1) distinct poses, not 2^L with duplicates.

Reach tolerance (beyond the paper; ``reach_tolerance``, 0 by default here): with lengths
estimated from the video a link is often a few per cent short (docs/design-notes/mono.md),
so a child that truly lies 12-20 deg out of the image plane falls just beyond
its parent's reach and M5 leaves the link one configuration in the plane: its true flip
is absent from every candidate. With a tolerance t the link's length is taken as
uncertain by the share t: for a parent at distance D from the child's ray in the band
[L (1 - t), L (1 + t)] the child is placed on its ray at the length
``L + (D - L (1 - t)) / 2`` (rising from L to L (1 + t) across the band), so a child
just beyond L keeps both flips, and the out-of-plane angle falls continuously to zero at
the band's far edge, beyond which M5 applies. Links outside the band are untouched, so
the counts above hold for links more than t from parallel; with t > 0 a link exactly
parallel keeps two configurations.

Fixed joints (``fixed``): joints given in 3-D are placed there, their links with one
configuration, while the constraints still run. The tracker enumerates the legs this
way, one chain at a time: the upper body first, then the legs below its chosen pose
(`mocapkit.tracking.mono.tracker`), so a frame has at most 2^8 + 2^6 poses, not 2^14.

A joint without a 2-D position (NaN) has no candidates: it and the joints below it are
NaN in every pose, its link does not branch and constraints reading it pass.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ShapeError
from mocapkit.tracking.mono.stick import (
    ANGLE,
    BACKWARD,
    CAPSULE,
    ELBOW_PLANE,
    HINGE_SIGN,
    Checks,
    StickArrays,
    StickModel,
)

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Relative tolerance under which a link counts as parallel to the image (errata M5).
PARALLEL_TOL = 1e-6


class FramePoses(NamedTuple):
    """Candidate 3-D poses of one frame.

    Attributes
    ----------
    codes : (N,) int
        Bit l set: link l takes its far configuration (child farther from the camera).
    positions : (N, K, 3) float
        Joints in the camera frame (x right, y down, z along the optical axis; mm).
    n_candidates : int
        Distinct poses before pruning: 2^(links with two configurations).
    pruned_all : bool
        Every candidate violated a constraint; ``codes`` then holds the unpruned set
        (recipe M: such a frame keeps its unpruned set).
    """

    codes: IntArray
    positions: FloatArray
    n_candidates: int
    pruned_all: bool


# ---------------------------------------------------------------- compiled helpers


@nb.njit(cache=True)
def _vec(pos: FloatArray, stick: StickArrays, link: int) -> FloatArray:
    return pos[stick.child[link]] - pos[stick.parent[link]]


@nb.njit(cache=True)
def _clamp01(x: float) -> float:
    return 0.0 if x < 0.0 else (1.0 if x > 1.0 else x)


@nb.njit(cache=True)
def _segment_distance(p0: FloatArray, p1: FloatArray, q0: FloatArray, q1: FloatArray) -> float:
    """Shortest distance between segments p0-p1 and q0-q1 (clamped closest points)."""
    d1 = p1 - p0
    d2 = q1 - q0
    r = p0 - q0
    a = float(d1 @ d1)
    e = float(d2 @ d2)
    f = float(d2 @ r)
    s = 0.0
    t = 0.0
    if a <= 1e-18 and e <= 1e-18:
        return float(np.sqrt(r @ r))
    if a <= 1e-18:
        t = _clamp01(f / e)
    else:
        c = float(d1 @ r)
        if e <= 1e-18:
            s = _clamp01(-c / a)
        else:
            b = float(d1 @ d2)
            den = a * e - b * b
            s = _clamp01((b * f - c * e) / den) if den > 1e-18 else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                t = 0.0
                s = _clamp01(-c / a)
            elif t > 1.0:
                t = 1.0
                s = _clamp01((b - c) / a)
    w = (p0 + d1 * s) - (q0 + d2 * t)
    return float(np.sqrt(w @ w))


@nb.njit(cache=True)
def _fails(pos: FloatArray, stick: StickArrays, checks: Checks, c: int) -> bool:
    """Whether check ``c`` is violated; any NaN input passes (comparisons are False)."""
    kind = checks.kind[c]
    lk = checks.links[c]
    par = checks.params[c]
    if kind == ANGLE:
        u = _vec(pos, stick, lk[0])
        v = _vec(pos, stick, lk[1])
        cs = (u @ v) / np.sqrt((u @ u) * (v @ v))
        return cs < par[0] or cs > par[1]
    if kind == CAPSULE:
        a, b = lk[0], lk[1]
        d = _segment_distance(
            pos[stick.parent[a]], pos[stick.child[a]], pos[stick.parent[b]], pos[stick.child[b]]
        )
        return d < par[0]
    if kind == ELBOW_PLANE:
        up = -_vec(pos, stick, lk[2])
        up = up / np.sqrt(up @ up)
        right = _vec(pos, stick, lk[4]) - _vec(pos, stick, lk[3])
        right = right - (right @ up) * up
        right = right / np.sqrt(right @ right)
        fwd = np.cross(up, right)
        u = _vec(pos, stick, lk[0])
        u = u / np.sqrt(u @ u)
        if u @ up > par[1]:
            return False
        f = _vec(pos, stick, lk[1])
        w = f - (f @ u) * u
        nw = np.sqrt(w @ w)
        return bool(nw > 1e-9 * np.sqrt(f @ f)) and bool(-(w @ fwd) > par[0] * nw)
    # BACKWARD and HINGE_SIGN share the body frame: up = -link1, right = link3 - link2
    up = -_vec(pos, stick, lk[1]) if kind == BACKWARD else np.zeros(3)
    right = _vec(pos, stick, lk[3]) - _vec(pos, stick, lk[2])
    if kind == BACKWARD:
        up = up / np.sqrt(up @ up)
        right = right - (right @ up) * up
        right = right / np.sqrt(right @ right)
        fwd = np.cross(up, right)
        u = _vec(pos, stick, lk[0])
        return -(u @ fwd) > par[0] * np.sqrt(u @ u)
    if kind == HINGE_SIGN:
        t = _vec(pos, stick, lk[0])
        s = _vec(pos, stick, lk[1])
        right = right / np.sqrt(right @ right)
        return np.cross(t, s) @ right > par[0] * np.sqrt((t @ t) * (s @ s))
    return False


@nb.njit(cache=True)
def _reach_length(length: float, dist: float, reach: float) -> float:
    """Length at which a link meets its child's ray at distance ``dist`` from its parent.

    ``length`` itself with ``reach`` 0 (errata M5 exactly). Otherwise the length is
    uncertain by the share ``reach`` (video lengths err by a few per cent): across the band
    ``dist`` in [L (1 - reach), L (1 + reach)] it rises linearly from L to L (1 + reach),
    so a child just beyond L keeps both flips, and the link's out-of-plane angle falls
    continuously to zero at the band's far edge (beyond it, M5: one configuration).
    """
    if reach <= 0.0:
        return length
    return length + 0.5 * max(0.0, dist - length * (1.0 - reach))


@nb.njit(cache=True)
def _branches(
    stick: StickArrays,
    obs: FloatArray,
    pos: FloatArray,
    link: int,
    perspective: bool,
    reach: float,
    fixed: FloatArray,
    out: FloatArray,
) -> int:
    """Candidate child positions of ``link`` given its placed parent; returns their count
    (one where the child is ``fixed``)."""
    if not np.isnan(fixed[stick.child[link], 0]):
        out[0, :] = fixed[stick.child[link]]
        return 1
    p = pos[stick.parent[link]]
    o = obs[stick.child[link]]
    length = stick.lengths[link]
    if np.isnan(o[0]) or np.isnan(o[1]) or np.isnan(p[0]):
        out[0, :] = np.nan
        return 1
    if not perspective:
        dx = o[0] - p[0]
        dy = o[1] - p[1]
        d2 = dx * dx + dy * dy
        reach_len = _reach_length(length, np.sqrt(d2), reach)
        rest = reach_len * reach_len - d2
        if rest <= (PARALLEL_TOL * length) ** 2:
            # errata M5: parallel (or longer than the link): one configuration, dz = 0
            d = np.sqrt(d2)
            out[0, 0] = p[0] + length * dx / d if d > 0 else p[0]
            out[0, 1] = p[1] + length * dy / d if d > 0 else p[1]
            out[0, 2] = p[2]
            return 1
        dz = np.sqrt(rest)
        out[0, 0] = o[0]
        out[0, 1] = o[1]
        out[0, 2] = p[2] - dz
        out[1, 0] = o[0]
        out[1, 1] = o[1]
        out[1, 2] = p[2] + dz
        return 2
    # perspective: |t r - p| = L on the viewing ray r = (x_n, y_n, 1)
    r = o.copy()
    r[2] = 1.0
    a = r @ r
    b = r @ p
    dist = np.sqrt(max((p @ p) - b * b / a, 0.0))
    reach_len = _reach_length(length, dist, reach)
    disc = b * b - a * ((p @ p) - reach_len * reach_len)
    if disc <= a * (PARALLEL_TOL * length) ** 2:
        t0 = b / a
        w = t0 * r - p
        nw = np.sqrt(w @ w)
        out[0, :] = p + length * w / nw if nw > 0 else t0 * r
        return 1
    sq = np.sqrt(disc)
    t_near = (b - sq) / a
    t_far = (b + sq) / a
    if t_near <= 0.0:
        out[0, :] = t_far * r
        return 1
    out[0, :] = t_near * r
    out[1, :] = t_far * r
    return 2


@nb.njit(cache=True)
def _enumerate(
    stick: StickArrays,
    checks: Checks,
    obs: FloatArray,
    root: FloatArray,
    perspective: bool,
    prune: bool,
    reach: FloatArray,
    fixed: FloatArray,
    out_codes: IntArray,
    out_pos: FloatArray,
) -> int:
    n_links = stick.parent.shape[0]
    pos = np.full((obs.shape[0], 3), np.nan)
    pos[stick.root] = root
    cand = np.zeros((n_links, 2, 3))
    n_branch = np.zeros(n_links, dtype=np.int64)
    branch = np.full(n_links, -1, dtype=np.int64)
    code = np.zeros(n_links + 1, dtype=np.int64)  # code[l]: bits of links < l
    n = 0
    level = 0
    while level >= 0:
        branch[level] += 1
        if branch[level] == 0:
            n_branch[level] = _branches(
                stick, obs, pos, level, perspective, reach[level], fixed, cand[level]
            )
        if branch[level] >= n_branch[level]:
            branch[level] = -1
            pos[stick.child[level]] = np.nan
            level -= 1
            continue
        b = branch[level]
        pos[stick.child[level]] = cand[level, b]
        ok = True
        if prune:
            for c in range(checks.start[level], checks.start[level + 1]):
                if _fails(pos, stick, checks, c):
                    ok = False
                    break
        if not ok:
            continue
        # far: bit l
        if b == 0:
            code[level + 1] = code[level]
        else:
            code[level + 1] = code[level] | (np.int64(1) << level)
        if level == n_links - 1:
            out_codes[n] = code[level + 1]
            out_pos[n] = pos
            n += 1
        else:
            level += 1
    return n


@nb.njit(cache=True)
def _violations(stick: StickArrays, checks: Checks, positions: FloatArray) -> NDArray[np.bool_]:
    out = np.zeros(positions.shape[0], dtype=np.bool_)
    for i in range(positions.shape[0]):
        for c in range(checks.kind.shape[0]):
            if _fails(positions[i], stick, checks, c):
                out[i] = True
                break
    return out


# ---------------------------------------------------------------- public API


def enumerate_poses(
    model: StickModel,
    lengths: ArrayLike,
    observed: ArrayLike,
    root: ArrayLike,
    *,
    perspective: bool = False,
    prune: bool = True,
    reach_tolerance: float | ArrayLike = 0.0,
    fixed: ArrayLike | None = None,
) -> FramePoses:
    """All flip configurations of one frame that satisfy the constraints.

    Parameters
    ----------
    model : StickModel
    lengths : (L,) float
        Link lengths (mm; px for an uncalibrated orthographic camera).
    observed : (K, 2) or (K, 3) float
        Orthographic: image-plane positions (x right, y down) in the units of
        ``lengths``. Perspective: normalised undistorted image coordinates (x_n, y_n)
        (a third column is ignored). NaN where a joint is not seen.
    root : (3,) float
        The root (neck) position in the camera frame; for a perspective camera it should
        lie on the neck's ray.
    perspective : bool
        See the module docstring.
    prune : bool
        Apply the model's constraints during the search.
    reach_tolerance : float or (L,) float
        Length band t of errata M5, one for every link or one per link (module
        docstring): a link whose parent lies at a distance D in [L (1 - t), L (1 + t)]
        from its child's ray (orthographic: from its projected end) has its child placed
        on that ray at the length ``L + (D - L (1 - t)) / 2``, two configurations up to
        D = L (1 + t); 0: the paper's (M5 exactly).
    fixed : (K, 3) float, optional
        Joints already placed (camera frame, as the poses), NaN where free: each such
        joint is put there and its link has one configuration (module docstring).

    Returns
    -------
    FramePoses
    """
    stick = model.arrays(np.asarray(lengths, dtype=float))
    obs = np.asarray(observed, dtype=float)
    if obs.ndim != 2 or obs.shape[0] != model.n_joints or obs.shape[1] not in (2, 3):
        raise ShapeError(
            f"enumerate_poses: expected observed ({model.n_joints}, 2), found {obs.shape}"
        )
    obs3 = np.zeros((model.n_joints, 3))
    obs3[:, :2] = obs[:, :2]
    obs3[np.isnan(obs[:, :2]).any(axis=1)] = np.nan
    r = np.asarray(root, dtype=float)
    if r.shape != (3,) or not np.all(np.isfinite(r)):
        raise ShapeError(f"enumerate_poses: expected a finite root (3,), found {r}")
    fix = _fixed(model, fixed)
    cap = _capacity(model, fix)
    codes = np.zeros(cap, dtype=np.int64)
    pos = np.zeros((cap, model.n_joints, 3))
    n_all = -1
    tol = _per_link(reach_tolerance, model.n_links, "reach_tolerance")
    n = _enumerate(stick, model.checks, obs3, r, perspective, prune, tol, fix, codes, pos)
    pruned_all = False
    if prune and n == 0:
        n = _enumerate(stick, model.checks, obs3, r, perspective, False, tol, fix, codes, pos)
        n_all, pruned_all = n, True
    if n_all < 0:
        n_all = count_candidates(model, stick.lengths, obs3, r, perspective, tol, fixed)
    return FramePoses(codes[:n].copy(), pos[:n].copy(), n_all, pruned_all)


def _fixed(model: StickModel, fixed: ArrayLike | None) -> FloatArray:
    """The fixed joints (K, 3) as the compiled search reads them (all NaN: none)."""
    if fixed is None:
        return np.full((model.n_joints, 3), np.nan)
    f = np.array(fixed, dtype=float, order="C")
    if f.shape != (model.n_joints, 3):
        raise ShapeError(f"fixed: expected ({model.n_joints}, 3) joints, found {f.shape}")
    f[~np.isfinite(f).all(axis=1)] = np.nan
    return f


def _per_link(value: float | ArrayLike, n_links: int, name: str) -> FloatArray:
    """A number per link (L,) from one number or one per link (the reach band)."""
    if isinstance(value, (int, float)):
        return np.full(n_links, float(value))
    tol = np.asarray(value, dtype=float)
    if tol.ndim > 1 or (tol.ndim == 1 and tol.shape != (n_links,)):
        raise ShapeError(f"{name}: expected a number or ({n_links},) per link, found {tol.shape}")
    if tol.ndim == 1 and tol.flags.c_contiguous and tol.flags.writeable:
        return tol  # the per-frame arrays of `MonoTracker`: no copy (read only here)
    # else a fresh writeable C array: one numba signature (a read-only view would
    # compile a second one)
    return np.array(np.broadcast_to(tol, (n_links,)), dtype=float, order="C")


def _capacity(model: StickModel, fixed: FloatArray) -> int:
    """Most poses of one frame: 2 per link whose child is not fixed."""
    free = np.isnan(fixed[model.child, 0])
    return 1 << int(free.sum())


def count_candidates(
    model: StickModel,
    lengths: ArrayLike,
    observed: ArrayLike,
    root: ArrayLike,
    perspective: bool = False,
    reach_tolerance: float | ArrayLike = 0.0,
    fixed: ArrayLike | None = None,
) -> int:
    """Number of distinct poses before pruning (one full unpruned search; arguments as
    `enumerate_poses`)."""
    stick = model.arrays(np.asarray(lengths, dtype=float))
    obs = np.asarray(observed, dtype=float)
    obs3 = np.zeros((model.n_joints, 3))
    obs3[:, :2] = obs[:, :2]
    obs3[np.isnan(obs[:, :2]).any(axis=1)] = np.nan
    fix = _fixed(model, fixed)
    cap = _capacity(model, fix)
    return int(
        _enumerate(
            stick,
            model.checks,
            obs3,
            np.asarray(root, dtype=float),
            perspective,
            False,
            _per_link(reach_tolerance, model.n_links, "reach_tolerance"),
            fix,
            np.zeros(cap, dtype=np.int64),
            np.zeros((cap, model.n_joints, 3)),
        )
    )


def violates(model: StickModel, lengths: ArrayLike, positions: ArrayLike) -> NDArray[np.bool_]:
    """Whether each full pose (N, K, 3) breaks any constraint (pruning after the search)."""
    p = np.ascontiguousarray(positions, dtype=float)
    if p.ndim != 3 or p.shape[1:] != (model.n_joints, 3):
        raise ShapeError(f"violates: expected poses (N, {model.n_joints}, 3), found {p.shape}")
    return np.asarray(_violations(model.arrays(np.asarray(lengths, dtype=float)), model.checks, p))
