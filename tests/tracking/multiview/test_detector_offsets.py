"""The multi-view fit's detector offsets: where the offset point lies, the segment lengths
without the offsets, and a fit to offset detections."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from mocapkit.skeleton.kinematics import canonical_positions, forward_kinematics, points_on_joints
from mocapkit.skeleton.model import CANONICAL_JOINTS, CANONICAL_SEGMENTS
from mocapkit.synth.rigs import make_rig
from mocapkit.tracking.multiview.detector_offsets import (
    detector_offsets,
    offset_points,
    offset_segments,
)
from mocapkit.tracking.multiview.tracker import MultiviewTracker, multiview_skeleton

NAMES = CANONICAL_JOINTS
LIMB_JOINTS = [n for n in NAMES if n.startswith(("left_", "right_"))]


@dataclass
class Sample:
    time_s: float
    keypoints_px: dict[str, Any]


#: Offsets of MediaPipe's size (mm; its full means on the tuning renders, unshrunk).
DETECTOR_LIKE: dict[str, tuple[float, float, float]] = {
    "head": (0.0, -0.1, -2.9),
    "left_wrist": (-0.4, 5.8, 0.0),
    "right_wrist": (0.4, 5.8, 0.0),
    "left_ankle": (11.7, 8.0, 61.8),
    "left_elbow": (3.1, 17.9, 31.5),
    "left_hip": (-15.7, 2.3, 24.1),
    "left_knee": (8.5, -3.1, 15.7),
    "left_shoulder": (-6.2, 12.7, 3.4),
    "right_ankle": (-11.7, 8.0, 61.8),
    "right_elbow": (-3.1, 17.9, 31.5),
    "right_hip": (15.7, 2.3, 24.1),
    "right_knee": (-8.5, -3.1, 15.7),
    "right_shoulder": (6.2, 12.7, 3.4),
}


def _offsets(rng: np.random.Generator) -> dict[str, tuple[float, float, float]]:
    return {n: tuple(rng.uniform(-40, 40, 3)) for n in [*LIMB_JOINTS, "head"]}  # type: ignore[misc]


def _pose(sk: Any, rng: np.random.Generator) -> np.ndarray:
    lo = np.where(np.isfinite(sk.lower), sk.lower, -0.5)
    hi = np.where(np.isfinite(sk.upper), sk.upper, 0.5)
    q = np.clip(0.5 * (lo + hi) + 0.3 * rng.uniform(-1, 1, sk.n_dofs) * (hi - lo) / 2, lo, hi)
    q[[sk.dof_index(n) for n in ("root_tx", "root_ty", "root_tz")]] = (0.0, 0.0, 1000.0)
    return q


def test_offset_point_is_the_joint_moved_in_its_segment_frame(rng: np.random.Generator) -> None:
    sk = multiview_skeleton()
    q = _pose(sk, rng)
    world = forward_kinematics(sk, q)
    plain = canonical_positions(sk, q, NAMES)
    tj0, tp0 = offset_points(sk, NAMES, {})
    np.testing.assert_allclose(points_on_joints(sk, q, tj0, tp0), plain, atol=1e-9)
    off = _offsets(rng)
    tj, tp = offset_points(sk, NAMES, off)
    got = points_on_joints(sk, q, tj, tp)
    for k, n in enumerate(NAMES):
        if n not in off:
            np.testing.assert_allclose(got[k], plain[k], atol=1e-9)
            continue
        jn, _ = sk.canonical[n]
        j = sk.joint_index(jn)
        frame = j if n == "head" else int(sk.parents[j])  # the head is not a joint's origin
        want = plain[k] + world[frame, :3, :3] @ np.asarray(off[n])
        np.testing.assert_allclose(got[k], want, atol=1e-9)


def test_a_backend_without_a_table_has_no_offsets() -> None:
    assert detector_offsets(None) == {}
    assert detector_offsets("rtmpose") == {}
    table = detector_offsets("mediapipe")
    assert {"left_ankle", "right_ankle"} <= set(table) <= {*LIMB_JOINTS, "head"}
    assert all(np.all(np.isfinite(v)) for v in table.values())


def _tool() -> Any:
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[3] / "tools" / "multiview_detector_offsets.py"
    spec = importlib.util.spec_from_file_location("multiview_detector_offsets", path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_held_out_shrinkage_keeps_offsets_that_carry_from_clip_to_clip() -> None:
    tool = _tool()
    same = np.array([3.0, 4.0, 0.0])  # every clip: the same offset
    flip = [np.array([0.0, 0.0, s * 10.0]) for s in (1, -1, 1, -1)]
    spread = [np.array([0.0, 0.0, z]) for z in (10.0, 20.0, 30.0, 40.0)]
    clips = [
        {"left_ankle": same, "right_ankle": same * tool.MIRROR, "head": f, "neck": g}
        for f, g in zip(flip, spread, strict=True)
    ]
    shrink = tool.held_out_shrinkage(clips)
    # the rest's mean predicts a consistent offset whole, for both sides
    assert shrink["left_ankle"] == pytest.approx(1.0)
    assert shrink["right_ankle"] == pytest.approx(1.0)
    # an offset whose sign changes between clips: the rest's mean points the wrong way
    assert shrink["head"] == 0.0
    # 10..40 mm: the others' means are 30, 26.7, 23.3, 20 mm; sum(b m) / sum(m m)
    assert shrink["neck"] == pytest.approx(2333.333 / 2555.556, rel=1e-5)


def test_segments_lose_the_offsets_at_rest(rng: np.random.Generator) -> None:
    sk = multiview_skeleton()
    off = _offsets(rng)
    # at rest every joint frame has the body's axes: the detector's points are the
    # joints plus their offsets, the midpoint joints the mean of their pair's
    rest = canonical_positions(sk, sk.zero_pose(), NAMES)
    pts = {n: rest[k] + np.asarray(off.get(n, (0.0, 0.0, 0.0))) for k, n in enumerate(NAMES)}
    pts["neck"] = rest[NAMES.index("neck")] + 0.5 * np.add(
        off["left_shoulder"], off["right_shoulder"]
    )
    pts["pelvis"] = rest[NAMES.index("pelvis")] + 0.5 * np.add(off["left_hip"], off["right_hip"])
    true_len = {
        s: float(np.linalg.norm(rest[NAMES.index(b)] - rest[NAMES.index(a)]))
        for s, (a, b) in CANONICAL_SEGMENTS.items()
        if s.endswith(("arm", "thigh", "shank"))
    }
    seen_len = {
        s: float(np.linalg.norm(pts[b] - pts[a]))
        for s, (a, b) in CANONICAL_SEGMENTS.items()
        if s in true_len
    }
    true_vec = {
        s: rest[NAMES.index(b)] - rest[NAMES.index(a)]
        for s, (a, b) in CANONICAL_SEGMENTS.items()
        if s in ("trunk", "left_pelvis")
    }
    seen_vec = {s: pts[b] - pts[a] for s, (a, b) in CANONICAL_SEGMENTS.items() if s in true_vec}
    lengths, vectors = offset_segments(sk, seen_len, seen_vec, off)
    for s, v in true_len.items():
        a, b = CANONICAL_SEGMENTS[s]
        d = np.asarray(off[b]) - np.asarray(off[a])  # the limbs hang along -z at rest
        # exact along the segment; across it, the second-order term is left
        across = float(np.hypot(d[0], d[1]))
        assert abs(lengths[s] - v) <= across**2 / (2.0 * (v - d[2])) + 1e-6
    for s, v in true_vec.items():
        np.testing.assert_allclose(vectors[s], v, atol=1e-9)
    assert offset_segments(sk, seen_len, seen_vec, {}) == (seen_len, seen_vec)


def test_fit_to_offset_detections_finds_the_joints(rng: np.random.Generator) -> None:
    sk = multiview_skeleton()
    cams = make_rig("ring", [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 1300.0)
    off = DETECTOR_LIKE  # detections where a detector with these offsets would put them
    tj, tp = offset_points(sk, NAMES, off)
    q0 = _pose(sk, rng)
    qs = [q0 + 0.02 * k * (sk.dof_kind == 0) for k in range(6)]
    frames = [{c.name: c.project(points_on_joints(sk, q, tj, tp)) for c in cams} for q in qs]
    with_off = MultiviewTracker(sk, cams, NAMES, point_offsets_mm=off)
    without = MultiviewTracker(sk, cams, NAMES)
    for i, (q, f) in enumerate(zip(qs, frames, strict=True)):
        truth = canonical_positions(sk, q)
        r = with_off.update(Sample(i / 30.0, f))
        r0 = without.update(Sample(i / 30.0, f))
    assert np.nanmax(np.linalg.norm(r.joints_mm - truth, axis=1)) < 5.0
    assert r.fit["mean_px"] < 1.0
    # without the offsets the fit follows the detections instead
    assert np.nanmax(np.linalg.norm(r0.joints_mm - truth, axis=1)) > 40.0
