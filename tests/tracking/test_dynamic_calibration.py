"""Tests of the dynamic calibration of marker-set member offsets (on the motion itself)."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ConfigError, ShapeError, UnknownNameError
from mocapkit.io.markers import MarkerData
from mocapkit.pipelines.hybrid import (
    head_band_offset_mm,
    raw_marker_skeleton,
    track_hybrid_marker_file,
)
from mocapkit.skeleton.kinematics import canonical_positions, forward_kinematics
from mocapkit.tracking.dynamic_calibration import MAX_FIT_MM, calibrate_members_on_motion
from mocapkit.tracking.hybrid import HybridConfig, HybridTracker, default_marker_effectors
from mocapkit.tracking.static_calibration import rotation_between_deg

from .test_static_calibration import RATE_HZ, SPECS, TRUE_MEMBERS, _members_from_poses


def _moving_take(sk, n_frames):
    """The tracker's relaxed pose with the arms and head moving from the first frame on
    (no still second): both arms raised and lowered together (one alone turns a
    positions-only track's trunk towards it), the right elbow bending, a nod."""
    tracker = HybridTracker(sk, None, HybridConfig(use_video=False, start_upright=False))
    q0 = np.clip(tracker.solver.secondary.omega, sk.lower, sk.upper)
    t = np.arange(n_frames) / RATE_HZ
    q = np.tile(q0, (n_frames, 1))
    for side in ("l", "r"):
        q[:, sk.dof_index(f"{side}_shoulder_flexion")] += 0.4 - 0.4 * np.cos(2 * np.pi * 0.5 * t)
    q[:, sk.dof_index("r_elbow_flexion")] += 0.6 - 0.6 * np.cos(2 * np.pi * 0.7 * t)
    q[:, sk.dof_index("neck_flexion")] += 0.2 * np.sin(2 * np.pi * 0.4 * t)
    return np.clip(q, sk.lower, sk.upper)


def test_median_leaves_out_frames_turned_wrong():
    """Exact poses with known offsets give them back; 30 % of the frames posed wrong, the
    arms turned 90 deg about the upper arm and the head bent 60 deg sideways (what a
    positions-only track gets wrong on part of a take: the swivel, the head's turn), move
    the mean by over 10 mm and the median by less than 1 mm; frames whose set does not
    fit are not used."""
    sk = raw_marker_skeleton(1700.0)
    rng = np.random.default_rng(6)
    q = _moving_take(sk, 300)
    members = _members_from_poses(sk, q, rng, noise_mm=0.5)
    by_set = {name: {m: members[m] for m in ms} for name, ms in TRUE_MEMBERS.items()}
    wrong = q.copy()
    turned = rng.random(q.shape[0]) < 0.3
    for dof, turn in (("l_shoulder_rotation", 1.57), ("r_shoulder_rotation", 1.57)):
        wrong[turned, sk.dof_index(dof)] += turn
    wrong[turned, sk.dof_index("neck_lateral")] += 1.05
    fit = {name: np.zeros(q.shape[0]) for name in TRUE_MEMBERS}
    fit["left_hand"][:20] = MAX_FIT_MM + 1.0  # not used, and not counted
    calib = calibrate_members_on_motion(sk, wrong, fit, by_set)
    assert calib.frames_used["left_hand"] == q.shape[0] - 20
    assert calib.frames_used["head"] == q.shape[0]
    eff = default_marker_effectors(sk)
    world = forward_kinematics(sk, wrong)
    for name, ms in TRUE_MEMBERS.items():
        got = np.array([calib.offsets_mm[name][m] for m in ms])
        want = np.array(list(ms.values()))
        assert np.abs(got - want).max() < 1.0, name
        assert rotation_between_deg(got, want) < 1.0, name
        # the mean over the same frames is pulled off by the turned ones
        j = sk.joint_index(eff[name].joint)
        first = next(iter(ms))
        local = np.einsum(
            "nji,nj->ni", world[:, j, :3, :3], members[first] - world[:, j, :3, 3]
        ) - np.asarray(eff[name].point_mm)
        assert np.linalg.norm(local.mean(axis=0) - ms[first]) > 10.0, name
    with pytest.raises(ConfigError, match="expected a marker set with two or more members"):
        calibrate_members_on_motion(sk, wrong, fit, by_set, min_frames=q.shape[0] + 1)
    with pytest.raises(ShapeError, match=r"q: expected shape \(T, "):
        calibrate_members_on_motion(sk, wrong[:, :3], fit, by_set)
    with pytest.raises(ShapeError, match=r"fit_mm\['head'\]: expected shape \(300,\)"):
        calibrate_members_on_motion(sk, wrong, {**fit, "head": fit["head"][:10]}, by_set)


def _marker_data(sk, q, rng, source):
    band = np.asarray(head_band_offset_mm(sk))
    members = _members_from_poses(sk, q, rng, set_offsets_mm={"head": band})
    # ankle markers: the floor is found from the lowest markers
    ankles = canonical_positions(sk, q, ["left_ankle", "right_ankle"])
    members.update({"LANK": ankles[:, 0], "RANK": ankles[:, 1]})
    names = list(members)
    t = np.arange(q.shape[0]) / RATE_HZ
    pos = np.stack([members[n] for n in names], axis=1)
    return MarkerData(t, names, pos, RATE_HZ, source), band


def test_marker_file_without_a_still_second_calibrates_on_the_motion():
    """A take that moves from its first frame: ``static`` finds no still second (positions
    only), ``auto`` falls back to the motion and ``dynamic`` calibrates on it directly;
    both recover the known offsets within 5 mm and 5 deg (3.2 mm, 3.5 deg: a positions-only
    track is not exact) and put the members in the IK."""
    sk = raw_marker_skeleton(1700.0)  # positions only: the model the first pass tracks with
    rng = np.random.default_rng(7)
    q = _moving_take(sk, 300)
    markers, band = _marker_data(sk, q, rng, "moving.c3d")
    static = track_hybrid_marker_file(
        markers, SPECS, height_mm=1700.0, up="z", calibration="static"
    )
    assert static.calibration is None
    assert "static: no window of 1 s in the take" in static.calibration_note
    assert "positions only" in static.calibration_note
    for mode in ("auto", "dynamic"):
        run = track_hybrid_marker_file(markers, SPECS, height_mm=1700.0, up="z", calibration=mode)
        assert run.calibration is not None, mode
        assert "dynamic: member offsets calibrated on the motion" in run.calibration_note
        assert ("static: no window" in run.calibration_note) == (mode == "auto")
        for name, ms in TRUE_MEMBERS.items():
            got = np.array([run.calibration.offsets_mm[name][m] for m in ms])
            want = np.array(list(ms.values())) + (band if name == "head" else 0.0)
            assert np.abs(got - want).max() < 5.0, (mode, name)
            assert rotation_between_deg(got, want) < 5.0, (mode, name)
        assert all("LWRA_mm" in r.fit for r in run.results)
        assert np.nanmedian([r.fit["LWRA_mm"] for r in run.results]) < 5.0
    with pytest.raises(ConfigError, match="a static trial is for calibration 'static' or 'auto'"):
        track_hybrid_marker_file(
            markers, SPECS, height_mm=1700.0, up="z", calibration="dynamic", static=markers
        )
    with pytest.raises(UnknownNameError, match="calibration"):
        track_hybrid_marker_file(markers, SPECS, height_mm=1700.0, up="z", calibration="walk")
