"""Homogeneous 4x4 rigid transforms named ``dst_from_src``, batched over leading axes."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ShapeError

FloatArray = NDArray[np.float64]


def make_transform(rotation: ArrayLike, translation: ArrayLike) -> FloatArray:
    """Assemble ``dst_from_src`` from a rotation (..., 3, 3) and a translation (..., 3) in mm."""
    r = np.asarray(rotation, dtype=float)
    t = np.asarray(translation, dtype=float)
    if r.shape[-2:] != (3, 3) or t.shape[-1:] != (3,):
        raise ShapeError(
            f"make_transform: expected rotation (..., 3, 3) and translation (..., 3), "
            f"found {r.shape} and {t.shape}"
        )
    shape = np.broadcast_shapes(r.shape[:-2], t.shape[:-1])
    out = np.zeros((*shape, 4, 4))
    out[..., :3, :3] = r
    out[..., :3, 3] = t
    out[..., 3, 3] = 1.0
    return out


def invert_transform(dst_from_src: ArrayLike) -> FloatArray:
    """Return ``src_from_dst`` of a rigid transform (..., 4, 4), using ``R^T`` and ``-R^T t``."""
    m = np.asarray(dst_from_src, dtype=float)
    if m.shape[-2:] != (4, 4):
        raise ShapeError(f"invert_transform: expected (..., 4, 4), found {m.shape}")
    r_t = np.swapaxes(m[..., :3, :3], -1, -2)
    return make_transform(r_t, -np.einsum("...ij,...j->...i", r_t, m[..., :3, 3]))


def transform_points(dst_from_src: ArrayLike, points_in_src: ArrayLike) -> FloatArray:
    """Apply a rigid transform (..., 4, 4) to points (..., N, 3); returns points in ``dst``."""
    m = np.asarray(dst_from_src, dtype=float)
    p = np.asarray(points_in_src, dtype=float)
    if m.shape[-2:] != (4, 4) or p.shape[-1:] != (3,):
        raise ShapeError(
            f"transform_points: expected (..., 4, 4) and (..., 3), found {m.shape} and {p.shape}"
        )
    return np.einsum("...ij,...nj->...ni", m[..., :3, :3], p) + m[..., None, :3, 3]


def points_in_frame(world_from_frame: ArrayLike, points_in_world: ArrayLike) -> FloatArray:
    """Points (..., 3) expressed in the frames (..., 4, 4), one point per frame: ``R^T (p - t)``.

    The inverse of `transform_points` for one point per transform, without forming the
    inverse (e.g. a marker's place on a joint over frames: ``world_from_joint`` (T, 4, 4)
    from forward kinematics and the marker (T, 3) give it in the joint's frame, (T, 3)).
    NaN points give NaN rows.
    """
    m = np.asarray(world_from_frame, dtype=float)
    p = np.asarray(points_in_world, dtype=float)
    if m.shape[-2:] != (4, 4) or p.shape[-1:] != (3,):
        raise ShapeError(
            f"points_in_frame: expected (..., 4, 4) and (..., 3), found {m.shape} and {p.shape}"
        )
    return np.einsum("...ji,...j->...i", m[..., :3, :3], p - m[..., :3, 3])
