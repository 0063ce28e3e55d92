"""Soft costs on the candidate poses beyond eq. 3: clavicle direction, girdle angle.

The paper scores a path by its angular acceleration alone (eq. 3); the limits then only
prune. Under near-orthography a limb mirrored through the image plane is as smooth as
the true one, so these terms add evidence that eq. 3 lacks. Each is a weight times a
plain cost; a weight of 0 leaves the tracker as the paper's.

- `clavicle_forward_cost` (unary, sine): the clavicles point sideways or slightly
  backwards from the neck; on nine CMU clips (2026-11-25) their forward sine in the
  body frame lay in -0.21..+0.02 (1st-99th percentiles). The cost is the sum over both
  clavicles of the forward sine beyond ``margin`` (0.05), clipped at 0.
- `girdle_angle_cost` (unary, 0-2): the neck and both shoulders are one rigid triangle;
  the departure of the cosine of the angle between the clavicles from the girdle's. Used
  where the neck is rebuilt from a detector's shoulders and hips (its clavicles mirror
  images in 2-D, their flips undecided by their own lengths; docs/design-notes/mono.md).
- `depth_order_cost` (unary, 0-L): a detector's own 3-D (MediaPipe's world landmarks)
  says which end of each link is nearer the camera; each link whose flip disagrees costs
  how far the detector has it out of the image plane (|dz| / L), never a hard choice.
- `planted_feet_cost` (unary, leg lengths): a foot standing on the floor has its ankle
  where its viewing ray meets the floor's plane (a calibrated camera knows it,
  `mocapkit.tracking.mono.placement.floor_points`); with both feet down, the difference
  of the two ankles' depths away from the floor's, over the leg's length, costs the legs'
  flips that put one foot wrongly before the other.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ShapeError
from mocapkit.tracking.mono.stick import StickModel

FloatArray = NDArray[np.float64]


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


def depth_order_cost(model: StickModel, positions: ArrayLike, sines: ArrayLike) -> FloatArray:
    """Disagreement of each pose's link flips with a detector's depth order.

    Parameters
    ----------
    model : StickModel
    positions : (N, K, 3) float
        Candidate poses in the camera frame (z away from the camera).
    sines : (L_s,) float
        Per link of ``model`` (its first L_s links), the detector's ``dz / L`` (child minus
        parent depth over the link's length, in [-1, 1]); NaN where it has none.

    Returns
    -------
    (N,) float
        Sum over the links whose depth order differs from the detector's of ``|dz / L|``;
        0 for a pose with NaN positions.
    """
    pos = np.asarray(positions, dtype=float)
    sn = np.asarray(sines, dtype=float)
    if pos.ndim != 3 or pos.shape[1:] != (model.n_joints, 3) or sn.ndim != 1:
        raise ShapeError(
            f"depth_order_cost: expected positions (N, {model.n_joints}, 3) and sines (L,), "
            f"found {pos.shape} and {sn.shape}"
        )
    n = min(sn.shape[0], model.n_links)
    dz = pos[:, model.child[:n], 2] - pos[:, model.parent[:n], 2]  # (N, n)
    s = sn[:n]
    with np.errstate(invalid="ignore"):
        wrong = (np.sign(dz) * np.sign(s)) < 0
    return np.where(wrong & np.isfinite(s), np.abs(np.nan_to_num(s)), 0.0).sum(axis=1)


def planted_feet_cost(
    model: StickModel,
    positions: ArrayLike,
    ankles: tuple[int, int],
    floor_depths_mm: ArrayLike,
    leg_mm: float,
) -> FloatArray:
    """Disagreement of each pose's two ankles' depth difference with the floor's.

    Where both feet stand on the floor, each ankle lies where its viewing ray meets the
    floor's plane; the difference of the two depths tells which foot is nearer the
    camera and by how much, whatever the error of the subject's depth (it shifts both).

    Parameters
    ----------
    model : StickModel
        With legs.
    positions : (N, K, 3) float
        Candidate poses in the camera frame (z away from the camera; mm).
    ankles : (2,) int
        Joint indices of the two ankles in ``model``.
    floor_depths_mm : (2,) float
        Camera depth at which each ankle's ray meets the floor's plane; NaN where a foot
        is not planted (then no cost).
    leg_mm : float
        The leg's length (thigh and shank), the cost's unit.

    Returns
    -------
    (N,) float
        ``|(z_a - z_b) - (f_a - f_b)| / leg_mm``; 0 for a pose with NaN ankles and where
        not both feet are planted.
    """
    pos = np.asarray(positions, dtype=float)
    zf = np.asarray(floor_depths_mm, dtype=float)
    if pos.ndim != 3 or pos.shape[1:] != (model.n_joints, 3) or zf.shape != (2,):
        raise ShapeError(
            f"planted_feet_cost: expected positions (N, {model.n_joints}, 3) and two floor "
            f"depths, found {pos.shape} and {zf.shape}"
        )
    if not np.isfinite(zf).all():
        return np.zeros(pos.shape[0])
    a, b = ankles
    d = (pos[:, a, 2] - pos[:, b, 2]) - (zf[0] - zf[1])
    return np.nan_to_num(np.abs(d) / leg_mm)
