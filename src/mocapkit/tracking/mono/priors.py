"""Soft costs on the candidate poses beyond eq. 3: image residual, elbow flex, depth velocity.

The paper scores a path by its angular acceleration alone (eq. 3); the limits then only
prune. Under near-orthography a limb mirrored through the image plane is as smooth as
the true one, so these terms add evidence that eq. 3 lacks. Each is a weight times a
plain cost; a weight of 0 leaves the tracker as the paper's.

- `reprojection_cost` (unary, px^2): under perspective both flips of a link lie on its
  child's viewing ray, but the child's depth moves the sphere the next link must reach:
  from one of the two depths the next link may be too short to reach its ray, so the
  enumeration places it at its nearest point (errata M5) and the pose's projection
  misses the 2-D input. The cost is the sum over the seen joints of the squared image
  distance between the pose's projection and the search's input (the smoothed points).
  Orthographic poses are in px already; weak-perspective ones are divided by the depth.
- `elbow_flex_cost` (unary, 0-2): the elbow bends the forearm towards the body's front;
  per arm the backward share of the forearm's bend direction (the forearm's part across
  the upper arm, unit length, against the trunk's forward axis), clipped at 0. The hard
  limit (`stick.ELBOW_PLANE`) applies only below a given upper-arm elevation and beyond
  a threshold; this soft version applies everywhere. Arms straighter than
  ``min_bend_sine`` carry no flex direction and cost 0.
- `clavicle_forward_cost` (unary, sine): the clavicles point sideways or slightly
  backwards from the neck; on nine CMU clips (2026-11-25) their forward sine in the
  body frame lay in -0.21..+0.02 (1st-99th percentiles). The cost is the sum over both
  clavicles of the forward sine beyond ``margin`` (0.05), clipped at 0.
- `girdle_angle_cost` (unary, 0-2): the neck and both shoulders are one rigid triangle;
  the departure of the cosine of the angle between the clavicles from the girdle's. Used
  where the neck is rebuilt from a detector's shoulders and hips (its clavicles mirror
  images in 2-D, their flips undecided by their own lengths; docs/design-notes/mono.md).
- `depth_velocity_cost` (pair, mm^2/s^2): the sum over joints of the squared change of
  each joint's depth relative to the root between consecutive frames over dt^2 (per-link
  depth continuity).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ShapeError
from mocapkit.tracking.mono.stick import StickModel

FloatArray = NDArray[np.float64]


def reprojection_cost(
    positions: ArrayLike,
    observed: ArrayLike,
    camera_model: str,
    focal_px: float = 1.0,
    depth_mm: float = float("nan"),
) -> FloatArray:
    """Sum of squared image residuals of each pose (px^2).

    Parameters
    ----------
    positions : (N, K, 3) float
        Candidate poses in the camera frame (mm; px for ``"orthographic"``).
    observed : (K, 2) float
        The enumeration's input: px (orthographic), normalised image coordinates
        (perspective) or normalised coordinates times the depth, mm (weak).
    camera_model : {"orthographic", "weak", "perspective"}
    focal_px : float
        Focal length (px) that turns normalised residuals into px (1 for orthographic).
    depth_mm : float
        Weak perspective: the depth the observations were scaled by.

    Returns
    -------
    (N,) float
        Joints unseen (NaN input or pose) add 0.
    """
    p = np.asarray(positions, dtype=float)
    o = np.asarray(observed, dtype=float)
    if p.ndim != 3 or p.shape[2] != 3 or o.shape != (p.shape[1], 2):
        raise ShapeError(
            f"reprojection_cost: expected positions (N, K, 3) and observed (K, 2), found "
            f"{p.shape} and {o.shape}"
        )
    if camera_model == "perspective":
        with np.errstate(invalid="ignore", divide="ignore"):
            proj = p[..., :2] / p[..., 2:3]
        d = (proj - o[None]) * focal_px
    elif camera_model == "weak":
        d = (p[..., :2] - o[None]) * (focal_px / depth_mm)
    else:
        d = p[..., :2] - o[None]
    sq = np.sum(d * d, axis=-1)
    return np.asarray(np.nansum(sq, axis=1), dtype=float)


def elbow_flex_cost(
    model: StickModel, positions: ArrayLike, min_bend_sine: float = 0.2
) -> FloatArray:
    """Backward share of each elbow's bend direction, summed over both arms (N,).

    Parameters
    ----------
    model : StickModel
        Needs the links ``trunk``, ``left_clavicle``, ``right_clavicle`` and per side
        ``<side>_upper_arm``, ``<side>_forearm``.
    positions : (N, K, 3) float
    min_bend_sine : float
        An arm whose forearm leaves the upper arm's line by less than this sine is
        straight: no flex direction, cost 0.

    Returns
    -------
    (N,) float
        0 (both elbows bend forwards or sideways) to 2 (both straight backwards).
    """
    p = np.asarray(positions, dtype=float)
    if p.ndim != 3 or p.shape[1:] != (model.n_joints, 3):
        raise ShapeError(
            f"elbow_flex_cost: expected positions (N, {model.n_joints}, 3), found {p.shape}"
        )
    v = model.link_vectors(p)  # (N, L, 3)
    _, fwd = _body_frame(model, v)
    out = np.zeros(p.shape[0])
    for side in ("left", "right"):
        u = v[:, model.link_index(f"{side}_upper_arm")]
        u = u / np.linalg.norm(u, axis=-1, keepdims=True)
        f = v[:, model.link_index(f"{side}_forearm")]
        w = f - np.sum(f * u, axis=-1, keepdims=True) * u
        nw = np.linalg.norm(w, axis=-1)
        nf = np.linalg.norm(f, axis=-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            back = -np.sum(w * fwd, axis=-1) / nw
            c = np.where(nw > min_bend_sine * nf, np.clip(back, 0.0, None), 0.0)
        out += np.nan_to_num(c, nan=0.0)
    return out


def _body_frame(model: StickModel, v: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Up and forward unit axes (N, 3) of link vectors (N, L, 3): up = -trunk, right from
    the clavicles (orthogonalised), forward = up x right (as `stick.BACKWARD`)."""
    up = -v[:, model.link_index("trunk")]
    up = up / np.linalg.norm(up, axis=-1, keepdims=True)
    right = v[:, model.link_index("right_clavicle")] - v[:, model.link_index("left_clavicle")]
    right = right - np.sum(right * up, axis=-1, keepdims=True) * up
    right = right / np.linalg.norm(right, axis=-1, keepdims=True)
    return up, np.cross(up, right)


def clavicle_forward_cost(
    model: StickModel, positions: ArrayLike, margin: float = 0.05
) -> FloatArray:
    """Forward sine of both clavicles beyond ``margin``, summed (N,).

    Parameters
    ----------
    model : StickModel
    positions : (N, K, 3) float
    margin : float
        Forward sine allowed without cost.

    Returns
    -------
    (N,) float
        NaN poses cost 0.
    """
    p = np.asarray(positions, dtype=float)
    if p.ndim != 3 or p.shape[1:] != (model.n_joints, 3):
        raise ShapeError(
            f"clavicle_forward_cost: expected positions (N, {model.n_joints}, 3), found {p.shape}"
        )
    # forward = up x right / |up x right| with up = -trunk/|trunk| and right the clavicle
    # difference (its part along up drops out of the cross product): (r x t) / |r x t|
    idx = [model.link_index(n) for n in ("trunk", "left_clavicle", "right_clavicle")]
    vec = p[:, model.child[idx]] - p[:, model.parent[idx]]  # (N, 3, 3)
    fwd = np.cross(vec[:, 2] - vec[:, 1], vec[:, 0])
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.einsum("nkc,nc->nk", vec[:, 1:], fwd) / (
            np.sqrt(np.einsum("nkc,nkc->nk", vec[:, 1:], vec[:, 1:]))
            * np.sqrt(np.einsum("nc,nc->n", fwd, fwd))[:, None]
        )
        c = np.clip(s - margin, 0.0, None)
    return np.asarray(np.nan_to_num(c, nan=0.0).sum(axis=1), dtype=float)


def girdle_angle_cost(model: StickModel, positions: ArrayLike, cosine: float) -> FloatArray:
    """Departure of the angle between the two clavicles from a rigid girdle's (N,).

    The neck and both shoulders are one rigid bone triangle (on the CMU clips the cosine
    of the angle between the clavicles is constant within a clip to three decimals), but
    the stick gives each clavicle its own flip. Where the neck is seen, the clavicles'
    2-D asymmetry tells their flips apart; where it is rebuilt on the hip-to-shoulder
    midpoint line (a detector's, `mocapkit.io.openpose`), the two clavicles are mirror
    images in the image and their depths carry no cue of their own. For two clavicles of
    out-of-plane components z_l and z_r the cosine holds ``z_l z_r`` with its sign, so a
    pose with one clavicle flipped (both forward, the shoulders brought together) has
    another angle than the true one: the cost tells the flip pairs apart, not the mirror
    of both (the trunk and the clavicle prior decide that).

    Parameters
    ----------
    model : StickModel
        Needs the links ``left_clavicle`` and ``right_clavicle``.
    positions : (N, K, 3) float
    cosine : float
        The girdle's cosine of the angle between the two clavicles (neck to shoulder).

    Returns
    -------
    (N,) float
        ``|cos(angle) - cosine|`` (0-2); NaN poses cost 0.
    """
    p = np.asarray(positions, dtype=float)
    if p.ndim != 3 or p.shape[1:] != (model.n_joints, 3):
        raise ShapeError(
            f"girdle_angle_cost: expected positions (N, {model.n_joints}, 3), found {p.shape}"
        )
    idx = [model.link_index(n) for n in ("left_clavicle", "right_clavicle")]
    vec = p[:, model.child[idx]] - p[:, model.parent[idx]]  # (N, 2, 3)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = np.einsum("nc,nc->n", vec[:, 0], vec[:, 1]) / np.sqrt(
            np.einsum("nc,nc->n", vec[:, 0], vec[:, 0])
            * np.einsum("nc,nc->n", vec[:, 1], vec[:, 1])
        )
    return np.asarray(np.nan_to_num(np.abs(c - cosine), nan=0.0), dtype=float)


def depth_velocity_cost(
    model: StickModel, previous: ArrayLike, current: ArrayLike, dt_s: float
) -> FloatArray:
    """Squared depth velocity of the joints relative to the root, per pair of poses.

    Parameters
    ----------
    model : StickModel
    previous : (Ni, K, 3) float
    current : (Nj, K, 3) float
    dt_s : float

    Returns
    -------
    (Ni, Nj) float
        ``sum_k ((z_jk - z_j0) - (z_ik - z_i0))^2 / dt^2`` (mm^2/s^2); joints NaN in
        either pose add 0.
    """
    a = np.asarray(previous, dtype=float)
    b = np.asarray(current, dtype=float)
    if (
        a.ndim != 3
        or b.ndim != 3
        or a.shape[1:] != (model.n_joints, 3)
        or b.shape[1:] != a.shape[1:]
    ):
        raise ShapeError(
            f"depth_velocity_cost: expected (Ni, {model.n_joints}, 3) and (Nj, "
            f"{model.n_joints}, 3), found {a.shape} and {b.shape}"
        )
    root = 0  # the stick is rooted at its first joint (the neck)
    za = a[:, :, 2] - a[:, root : root + 1, 2]
    zb = b[:, :, 2] - b[:, root : root + 1, 2]
    d = zb[None, :, :] - za[:, None, :]
    return np.asarray(np.nansum(d * d, axis=-1) / (dt_s * dt_s), dtype=float)
