"""Each link's depth offset blended with a detector's own 3-D, the image kept exactly.

The tracker's pose puts each child joint on its camera ray at the depth where its link
has its length; the sign of that out-of-plane offset is the flip the Viterbi chose. A
detector with its own 3-D (MediaPipe's world landmarks) gives a second, partly
independent estimate of the same offset: its link sine ``dz / L`` times the tracker's
length. `fuse_link_depths` sets each child's depth relative to its (already fused)
parent to the weighted mean of the two offsets and moves the child along its ray there,
so its projection does not change and the link's length follows. Where the two disagree
in sign the mean lies nearer the image plane than either. Per frame: online and offline
alike.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ShapeError

FloatArray = NDArray[np.float64]


def fuse_link_depths(
    joints_in_camera: ArrayLike,
    parent: ArrayLike,
    child: ArrayLike,
    lengths: ArrayLike,
    link_sines: ArrayLike,
    weight: float,
) -> FloatArray:
    """A pose (K, 3) in the camera frame with each link's depth offset blended.

    Links are taken in their order (``parent[l]`` placed before link ``l``, as
    `mocapkit.tracking.mono.stick.StickModel`'s search order). For link ``l`` from joint
    ``p`` to ``c``: the tracker's offset ``dz = z_c - z_p`` (of the input pose), the
    detector's ``link_sines[l] * lengths[l]``; the child is moved along its ray (through
    the camera's centre, the frame's origin) to the depth ``z_p' + (1 - weight) dz +
    weight * sine * L``, ``z_p'`` the parent's fused depth. A link whose sine is NaN, or
    whose fused depth would not lie in front of the camera, and the links beyond the
    first L', keep their own offsets from their parents' fused depths.

    Parameters
    ----------
    joints_in_camera : (K, 3) float
        Stick joints in the camera frame (mm; z the depth); NaN where unposed.
    parent, child : (L,) int
        Joint indices of each link.
    lengths : (L,) float
        Link lengths (mm) the detector's sines are scaled by.
    link_sines : (L',) float
        The detector's ``dz / L`` of the first L' <= L links (NaN where it has none).
    weight : float
        Share of the detector's offset, in [0, 1]: 0 the tracker's pose unchanged, 1 the
        detector's offset.

    Returns
    -------
    (K, 3) float
        A new array; every joint on its input ray.
    """
    q = np.array(joints_in_camera, dtype=float)
    par = np.asarray(parent, dtype=int)
    chi = np.asarray(child, dtype=int)
    length = np.asarray(lengths, dtype=float)
    sines = np.asarray(link_sines, dtype=float)
    if q.ndim != 2 or q.shape[1] != 3 or par.shape != chi.shape or length.shape != par.shape:
        raise ShapeError(
            "fuse_link_depths: expected joints (K, 3) and parent, child, lengths of one "
            f"shape (L,), found {q.shape}, {par.shape}, {chi.shape}, {length.shape}"
        )
    if sines.ndim != 1 or sines.shape[0] > par.shape[0]:
        raise ShapeError(
            f"fuse_link_depths: expected at most {par.shape[0]} link sines, found {sines.shape}"
        )
    if weight == 0.0:
        return q
    own = q.copy()
    sine = np.full(par.shape[0], np.nan)
    sine[: sines.shape[0]] = sines
    for link in range(par.shape[0]):
        p, c = par[link], chi[link]
        offset = own[c, 2] - own[p, 2]
        blended = (1.0 - weight) * offset + weight * sine[link] * length[link]
        for dz in (blended, offset):  # its own offset where the blend is not usable
            z = q[p, 2] + dz
            if np.isfinite(z) and z > 0.0 and own[c, 2] > 0.0:
                q[c] = own[c] * (z / own[c, 2])
                break
    return q
