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
from mocapkit.skeleton.limbs import arm
from mocapkit.tracking.dynamic_calibration import (
    HANGING_FRACTION,
    MAX_FIT_MM,
    calibrate_members_on_motion,
    calibration_frames,
)
from mocapkit.tracking.hybrid import HybridConfig, HybridTracker, default_marker_effectors
from mocapkit.tracking.static_calibration import rotation_between_deg

from .test_static_calibration import RATE_HZ, SPECS, TRUE_MEMBERS, _members_from_poses


def _moving_take(sk, n_frames):
    """The tracker's relaxed pose with the arms and head moving from the first frame on
    (no still second): both arms raised and lowered together (one alone turns a
    positions-only track's trunk towards it), the right elbow bending with them, a nod;
    at the turn between lowering and raising the arms hang, slowly, once every 2 s."""
    tracker = HybridTracker(sk, None, HybridConfig(use_video=False, start_upright=False))
    q0 = np.clip(tracker.solver.secondary.omega, sk.lower, sk.upper)
    t = np.arange(n_frames) / RATE_HZ
    q = np.tile(q0, (n_frames, 1))
    for side in ("l", "r"):
        q[:, sk.dof_index(f"{side}_shoulder_flexion")] += 0.4 - 0.4 * np.cos(2 * np.pi * 0.5 * t)
    q[:, sk.dof_index("r_elbow_flexion")] += 0.5 - 0.5 * np.cos(2 * np.pi * 0.5 * t)
    q[:, sk.dof_index("neck_flexion")] += 0.2 * np.sin(2 * np.pi * 0.4 * t)
    return np.clip(q, sk.lower, sk.upper)


def _hang_then_raise(sk, n_frames):
    """The relaxed pose held (arms hanging) for the first half, then the left arm raised
    forward 1.5 rad and waved, and the head nodding over the last third."""
    tracker = HybridTracker(sk, None, HybridConfig(use_video=False, start_upright=False))
    q0 = np.clip(tracker.solver.secondary.omega, sk.lower, sk.upper)
    t = np.arange(n_frames) / RATE_HZ
    q = np.tile(q0, (n_frames, 1))
    half, third = n_frames // 2, 2 * n_frames // 3
    ramp = np.clip((t - t[half]) / 0.5, 0.0, 1.0)  # raised over 0.5 s
    q[:, sk.dof_index("l_shoulder_flexion")] += ramp * (1.5 + 0.3 * np.sin(2 * np.pi * t))
    q[third:, sk.dof_index("neck_flexion")] += 0.3 * np.sin(2 * np.pi * 1.0 * t[third:])
    return np.clip(q, sk.lower, sk.upper), t


def test_calibration_frames_slow_and_hanging():
    """Known frames: a hand set is used where its arm hangs and it moves slower than its
    median (the held half), the head where it is slow (not the nod), neither where the
    set does not fit."""
    sk = raw_marker_skeleton(1700.0)
    rng = np.random.default_rng(8)
    q, t = _hang_then_raise(sk, 300)
    world = forward_kinematics(sk, q)
    members = _members_from_poses(sk, q, rng, noise_mm=0.5)
    centre = {n: np.mean([members[m] for m in ms], axis=0) for n, ms in TRUE_MEMBERS.items()}
    fit = np.zeros(300)
    fit[10:20] = MAX_FIT_MM + 1.0
    left = calibration_frames(sk, world, "left_hand", t, centre["left_hand"], fit)
    assert not left[10:20].any()
    assert not left[150:].any()  # raised and waving: the arm does not hang
    assert left[:150].sum() >= 120  # held: the slower half of the take
    # the relaxed pose's arm hangs well past the fraction
    limb = arm(sk, "left")
    s, e, w = (world[0, k, :3, 3] for k in (limb.root, limb.middle, limb.end))
    assert s[2] - w[2] > HANGING_FRACTION * (np.linalg.norm(e - s) + np.linalg.norm(w - e))
    head = calibration_frames(sk, world, "head", t, centre["head"], fit)
    assert not head[10:20].any()
    # the slower half of the take (150 frames) lies in the 200 frames before the nod
    assert head[200:].mean() < 0.2 and head[:200].sum() >= 130
    with pytest.raises(ShapeError, match="calibration_frames: expected 300 frames"):
        calibration_frames(sk, world, "head", t, centre["head"][:5], fit)


def test_median_leaves_out_frames_turned_wrong():
    """Exact poses with known offsets give them back; 30 % of the frames posed wrong, the
    arms turned 90 deg about the upper arm and the head bent 60 deg sideways (what a
    positions-only track gets wrong on part of a take: the swivel, the head's turn), move
    the mean over the same frames by over 10 mm and the median by less than 1 mm; only
    `calibration_frames` are used."""
    sk = raw_marker_skeleton(1700.0)
    rng = np.random.default_rng(6)
    q, t = _hang_then_raise(sk, 300)
    members = _members_from_poses(sk, q, rng, noise_mm=0.5)
    by_set = {name: {m: members[m] for m in ms} for name, ms in TRUE_MEMBERS.items()}
    wrong = q.copy()
    turned = rng.random(q.shape[0]) < 0.3
    for dof, turn in (("l_shoulder_rotation", 1.57), ("r_shoulder_rotation", 1.57)):
        wrong[turned, sk.dof_index(dof)] += turn
    wrong[turned, sk.dof_index("neck_lateral")] += 1.05
    fit = {name: np.zeros(q.shape[0]) for name in TRUE_MEMBERS}
    fit["left_hand"][:20] = MAX_FIT_MM + 1.0
    calib = calibrate_members_on_motion(sk, wrong, t, fit, by_set)
    eff = default_marker_effectors(sk)
    world = forward_kinematics(sk, wrong)
    for name, ms in TRUE_MEMBERS.items():
        centre = np.mean([members[m] for m in ms], axis=0)
        used = calibration_frames(sk, world, name, t, centre, fit[name])
        assert calib.frames_used[name] == used.sum() >= 50, name
        got = np.array([calib.offsets_mm[name][m] for m in ms])
        want = np.array(list(ms.values()))
        assert np.abs(got - want).max() < 1.0, name
        assert rotation_between_deg(got, want) < 1.0, name
        # the mean over the same frames is pulled off by the turned ones
        j = sk.joint_index(eff[name].joint)
        first = next(iter(ms))
        local = np.einsum(
            "nji,nj->ni", world[used, j, :3, :3], members[first][used] - world[used, j, :3, 3]
        ) - np.asarray(eff[name].point_mm)
        assert np.linalg.norm(local.mean(axis=0) - ms[first]) > 10.0, name
    with pytest.raises(ConfigError, match="expected a marker set with two or more members"):
        calibrate_members_on_motion(sk, wrong, t, fit, by_set, min_frames=q.shape[0] + 1)
    with pytest.raises(ShapeError, match=r"q: expected shape \(T, "):
        calibrate_members_on_motion(sk, wrong[:, :3], t, fit, by_set)
    with pytest.raises(ShapeError, match=r"time_s: expected shape \(300,\)"):
        calibrate_members_on_motion(sk, wrong, t[:5], fit, by_set)
    with pytest.raises(ShapeError, match=r"fit_mm\['head'\]: expected shape \(300,\)"):
        calibrate_members_on_motion(sk, wrong, t, {**fit, "head": fit["head"][:10]}, by_set)


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
