"""Tests of the dynamic calibration of marker-set member offsets (on the motion itself)."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ConfigError, ShapeError, UnknownNameError
from mocapkit.geometry.rotations import matrix_from_axis_angle
from mocapkit.pipelines.hybrid_markers import (
    head_band_offset_mm,
    raw_marker_skeleton,
    track_hybrid_marker_file,
)
from mocapkit.skeleton.kinematics import forward_kinematics
from mocapkit.skeleton.limbs import arm
from mocapkit.tracking.hybrid.dynamic_calibration import (
    HANGING_FRACTION,
    MAX_FIT_MM,
    calibrate_members_on_motion,
    calibration_frames,
    consensus_frames,
    layout_turn_deg,
)
from mocapkit.tracking.hybrid.static_calibration import rotation_between_deg
from mocapkit.tracking.hybrid.tracker import HybridConfig, HybridTracker, default_marker_effectors

from .test_static_calibration import (
    RATE_HZ,
    SPECS,
    TRUE_MEMBERS,
    _members_from_poses,
    _recording,
)


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


def test_layout_turn_known_values():
    """A bar turned 30 deg is 30 deg off; a cross of four members turned 20 deg about the
    line through two of them is 20 deg off (the largest member's turn); unturned, 0."""
    bar = np.array([[[47.0, 0.0, 0.0], [-47.0, 0.0, 0.0]]])
    turned = bar @ matrix_from_axis_angle([0.0, 0.0, 1.0], np.radians(30.0)).T
    d = turned / np.linalg.norm(turned, axis=2, keepdims=True)
    assert layout_turn_deg(d, bar)[0, 0] == pytest.approx(30.0, abs=1e-9)
    cross = np.array([[[50.0, 0, 0], [-50.0, 0, 0], [0, 50.0, 0], [0, -50.0, 0]]])
    rot = cross @ matrix_from_axis_angle([1.0, 0.0, 0.0], np.radians(20.0)).T
    both = np.concatenate([cross, rot]) / 50.0
    np.testing.assert_allclose(layout_turn_deg(both, cross), [[0.0, 20.0]], atol=1e-6)
    with pytest.raises(ShapeError, match=r"layout_turn_deg: expected directions \(N, M, 3\)"):
        layout_turn_deg(both, cross[:, :3])


def test_consensus_frames_find_the_frames_that_agree():
    """40 frames of one layout (0.3 mm noise) among 60 turned each by its own angle
    (20-140 deg) about one axis, one way (a forearm pronated by varying amounts: a
    positions-only track's wrist frame does not turn with it): exactly the 40 agree, also
    with a few seeds tried; the per-member median over all 100 frames is tens of mm off,
    over the 40 within 0.5 mm."""
    rng = np.random.default_rng(11)
    layout = np.array(
        [[-60.0, 45.0, -10.0], [80.0, 70.0, -20.0], [-70.0, -60.0, -40.0], [85.0, -50.0, -45.0]]
    )
    n = 100
    loc = np.repeat(layout[None], n, axis=0) + rng.normal(0.0, 0.3, (n, 4, 3))
    wrong = rng.permutation(n)[:60]
    for k in wrong:
        angle = rng.uniform(np.radians(20.0), np.radians(140.0))
        loc[k] = loc[k] @ matrix_from_axis_angle([0.0, 0.0, 1.0], angle).T
    want = np.ones(n, dtype=bool)
    want[wrong] = False
    np.testing.assert_array_equal(consensus_frames(loc), want)
    np.testing.assert_array_equal(consensus_frames(loc, max_seeds=7), want)
    assert np.abs(np.median(loc, axis=0) - layout).max() > 20.0
    assert np.abs(np.median(loc[want], axis=0) - layout).max() < 0.5
    with pytest.raises(ShapeError, match=r"consensus_frames: expected members \(N >= 1, M >= 2"):
        consensus_frames(loc[:, :1])
    with pytest.raises(ConfigError, match="expected 0 < max_turn_deg < 180"):
        consensus_frames(loc, max_turn_deg=0.0)


def test_consensus_leaves_out_frames_turned_wrong():
    """Exact poses with known offsets give them back; 60 % of the frames posed wrong, each
    its own way (the arms turned 30-150 deg about the upper arm, the head bent 30-70 deg
    sideways, either sign: what a positions-only track gets wrong on part of a take, the
    swivel and the head's turn), move the median over the candidate frames by over 10 mm
    but the offsets, over the frames that agree, by less than 1 mm; those frames are the
    candidates (`calibration_frames`) posed right."""
    sk = raw_marker_skeleton(1700.0)
    rng = np.random.default_rng(6)
    q, t = _hang_then_raise(sk, 300)
    members = _members_from_poses(sk, q, rng, noise_mm=0.5)
    by_set = {name: {m: members[m] for m in ms} for name, ms in TRUE_MEMBERS.items()}
    wrong = q.copy()
    turned = rng.random(q.shape[0]) < 0.6
    k = int(turned.sum())
    for dof in ("l_shoulder_rotation", "r_shoulder_rotation"):
        wrong[turned, sk.dof_index(dof)] += rng.choice([-1, 1], k) * rng.uniform(0.52, 2.6, k)
    wrong[turned, sk.dof_index("neck_lateral")] += rng.choice([-1, 1], k) * rng.uniform(
        0.52, 1.22, k
    )
    fit = {name: np.zeros(q.shape[0]) for name in TRUE_MEMBERS}
    fit["left_hand"][:20] = MAX_FIT_MM + 1.0
    calib = calibrate_members_on_motion(sk, wrong, t, fit, by_set)
    eff = default_marker_effectors(sk)
    world = forward_kinematics(sk, wrong)
    for name, ms in TRUE_MEMBERS.items():
        centre = np.mean([members[m] for m in ms], axis=0)
        used = calibration_frames(sk, world, name, t, centre, fit[name])
        assert calib.frames_used[name] == (used & ~turned).sum() >= 50, name
        got = np.array([calib.offsets_mm[name][m] for m in ms])
        want = np.array(list(ms.values()))
        assert np.abs(got - want).max() < 1.0, name
        assert rotation_between_deg(got, want) < 1.0, name
        # the median over all the candidate frames is pulled off by the turned ones
        j = sk.joint_index(eff[name].joint)
        off = max(
            np.linalg.norm(
                np.median(
                    np.einsum(
                        "nji,nj->ni",
                        world[used, j, :3, :3],
                        members[m][used] - world[used, j, :3, 3],
                    ),
                    axis=0,
                )
                - np.asarray(eff[name].point_mm)
                - ms[m]
            )
            for m in ms
        )
        assert off > 10.0, name
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
    return _recording(sk, q, members, source), band


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
