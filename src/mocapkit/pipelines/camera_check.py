"""The cameras of a session checked against its data before any tracker runs.

`check_session_cameras` is called by the pipeline entry of every tracker (hybrid,
stereo / multi-view, mono) before the tracker is built; it gathers what the session
holds (the cameras' intrinsics, the 2-D keypoints of the first frames, the marker sets)
and runs the checks of `mocapkit.camera.plausibility` that those data allow. Refusals
raise `SessionError` naming the camera, the check and the numbers; ambiguous findings are
passed to ``warn``.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

from mocapkit.camera.pinhole import Camera
from mocapkit.camera.plausibility import (
    FLOOR_CHECK_FRAMES,
    VIEW_CHECK_FRAMES,
    CameraFinding,
    floor_findings,
    intrinsic_findings,
    keypoint_findings,
    pose_findings,
    refuse_or_warn,
    sees_findings,
    view_findings,
    view_floor_findings,
    view_up_findings,
)
from mocapkit.io.session import Session
from mocapkit.io.session_csv import Keypoints
from mocapkit.skeleton.kinematics import canonical_positions
from mocapkit.skeleton.model import Skeleton

#: Seconds at the start over which the subject's 3-D points (the hybrid's marker sets)
#: must be seen by the camera.
SEES_CHECK_S = 1.0


def _print_warning(line: str) -> None:
    print(f"WARNING: {line}", file=sys.stderr)


def _first_frames(kp: Keypoints) -> np.ndarray:
    """Row indices of the first `VIEW_CHECK_FRAMES` frames with any keypoint."""
    seen = np.flatnonzero(np.any(np.isfinite(kp.pixels), axis=(1, 2)))
    return seen[:VIEW_CHECK_FRAMES]


def _spread_frames(kp: Keypoints) -> np.ndarray:
    """Row indices of at most `FLOOR_CHECK_FRAMES` frames with any keypoint, spread
    evenly over the take."""
    seen = np.flatnonzero(np.any(np.isfinite(kp.pixels), axis=(1, 2)))
    if seen.size <= FLOOR_CHECK_FRAMES:
        return seen
    return seen[np.linspace(0, seen.size - 1, FLOOR_CHECK_FRAMES).round().astype(int)]


def _matched_views(
    keypoints: Sequence[Keypoints],
    rows_of: Callable[[Keypoints], np.ndarray] = _first_frames,
    joints: Sequence[str] | None = None,
) -> tuple[np.ndarray, tuple[str, ...]] | None:
    """The views' keypoints (V, T, K, 2) of the first view's frames ``rows_of`` picks
    (default: the first ones), matched by time stamp (within half a frame), on the joints
    all views name (of ``joints``, when given)."""
    first = keypoints[0]
    names = tuple(
        n
        for n in first.joint_names
        if all(n in k.joint_names for k in keypoints) and (joints is None or n in joints)
    )
    rows = rows_of(first)
    if not names or rows.size == 0:
        return None
    t = first.time_s[rows]
    dt = float(np.median(np.diff(first.time_s))) if first.time_s.size > 1 else 1.0 / 30.0
    out = np.full((len(keypoints), rows.size, len(names), 2), np.nan)
    for v, kp in enumerate(keypoints):
        cols = [kp.joint_names.index(n) for n in names]
        i = np.clip(np.searchsorted(kp.time_s, t), 0, kp.time_s.size - 1)
        j = np.clip(i - 1, 0, kp.time_s.size - 1)
        near = np.where(np.abs(kp.time_s[j] - t) < np.abs(kp.time_s[i] - t), j, i)
        ok = np.abs(kp.time_s[near] - t) <= 0.5 * dt
        out[v, ok] = kp.pixels[near[ok]][:, cols]
    return out, names


def _placement_findings(
    cameras: Sequence[Camera], keypoints: Sequence[Keypoints]
) -> list[CameraFinding]:
    """The floor and up warnings, from the neck and ankles of frames spread over the take
    triangulated from the views (cameras that agree on the first frames)."""
    spread = _matched_views(keypoints, _spread_frames, ("neck", "left_ankle", "right_ankle"))
    if spread is None:
        return []
    px, names = spread
    feet = [i for i, n in enumerate(names) if n != "neck"]
    out = view_floor_findings(cameras, px[:, :, feet]) if feet else []
    return out + view_up_findings(cameras, px, names)


def check_session_cameras(
    session: Session,
    cameras: Sequence[str],
    *,
    skeleton: Skeleton | None = None,
    keypoints: Mapping[str, Keypoints] | None = None,
    subject_points: tuple[ArrayLike, ArrayLike] | None = None,
    warn: Callable[[str], None] | None = None,
) -> list[CameraFinding]:
    """Refuse cameras that do not fit the session's data; call before building a tracker.

    Parameters
    ----------
    session : Session
    cameras : sequence of str
        The cameras the tracker will use.
    skeleton : Skeleton, optional
        The subject's body model: with keypoints in two or more views, the limb lengths
        triangulated from the views are compared with it (and, where the views agree,
        the triangulated ankles with the floor and the neck above them with +z, warnings).
    keypoints : mapping of camera name to Keypoints, optional
        The 2-D keypoints the tracker will use (default: the session's
        ``keypoints/<camera>.csv``, used for the check even when the tracker reads the
        images instead).
    subject_points : (time_s (T,), points_mm (T, S, 3)), optional
        3-D points of the subject known apart from the cameras (the hybrid's marker
        sets): each camera must see them over the first `SEES_CHECK_S`.
    warn : callable, optional
        Receives one line per ambiguous finding (default: printed to stderr as
        ``WARNING: ...``).

    Returns
    -------
    list of CameraFinding
        The warnings (refusals raise).

    Raises
    ------
    SessionError
        A principal point outside the image, keypoints mostly outside the image, the
        subject behind a camera or outside its image, views that disagree, limb lengths
        far from the subject's.
    """
    cams = [session.camera(c) for c in cameras]
    kps = dict(session.keypoints if keypoints is None else keypoints)
    findings: list[CameraFinding] = []
    for cam in cams:
        findings += intrinsic_findings(cam)
        if cam.name in kps:
            kp = kps[cam.name]
            findings += keypoint_findings(cam, kp.pixels[_first_frames(kp)])
    if subject_points is not None:
        t = np.asarray(subject_points[0], dtype=float)
        pts = np.asarray(subject_points[1], dtype=float)
        first = pts[t <= t[0] + SEES_CHECK_S] if t.size else pts
        for cam in cams:
            findings += sees_findings(
                cam, first, f"marker-set positions in the first {SEES_CHECK_S:g} s"
            )
    with_kp = [c for c in cams if c.name in kps]
    if subject_points is None and len(with_kp) < 2:  # nothing 3-D to check the poses by
        for cam in cams:
            findings += pose_findings(cam)
    if len(with_kp) >= 2 and not any(f.refuse for f in findings):
        matched = _matched_views([kps[c.name] for c in with_kp])
        if matched is not None:
            px, names = matched
            rest: dict[str, np.ndarray] = {}
            if skeleton is not None:
                known = [n for n in names if n in skeleton.canonical]
                if known:
                    pos = canonical_positions(skeleton, skeleton.zero_pose(), known)
                    rest = dict(zip(known, pos))
            views = view_findings(with_kp, px, names, rest)
            findings += views
            if not views:
                findings += _placement_findings(with_kp, [kps[c.name] for c in with_kp])
    refuse_or_warn(findings, str(session.path), warn or _print_warning)
    return [f for f in findings if not f.refuse]


def warn_placed_subject(
    session: Session,
    camera: str,
    joints_mm: ArrayLike,
    joint_names: Sequence[str],
    warn: Callable[[str], None] | None = None,
) -> None:
    """After a one-camera tracker placed the subject: warn when its ankles lie far from
    the floor (`mocapkit.camera.plausibility.floor_findings`), the one sign one view
    gives of focal lengths or translations in the wrong unit."""
    names = list(joint_names)
    idx = [names.index(n) for n in ("left_ankle", "right_ankle") if n in names]
    if not idx:
        return
    pts = np.asarray(joints_mm, dtype=float)[:, idx]
    findings = floor_findings(
        camera,
        pts,
        "as placed from this one camera",
        "; its depth from the feet on the floor or the subject's limb lengths, not triangulated",
    )
    refuse_or_warn(findings, str(session.path), warn or _print_warning)


__all__ = ["SEES_CHECK_S", "check_session_cameras", "warn_placed_subject"]
