"""One rule for what was not observed, in every tracker's result folder (issue 14): the
joints of a released or missing effector or limb are NaN in joints.csv and motion.npz,
the BVH holds that part at its last observed pose, and the CLI lists the gaps."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mocapkit.cli.main import main
from mocapkit.io.bvh import parse_bvh
from mocapkit.io.joints_csv import read_joints_csv
from mocapkit.io.motion_npz import load_motion_npz
from mocapkit.io.session_csv import read_keypoints_csv, write_keypoints_csv
from mocapkit.pipelines.run import (
    FIT_FILE,
    find_gaps,
    motion_with_held_parts,
    read_fit_csv,
    run_tracker,
)
from mocapkit.skeleton import forward_kinematics, load_preset
from mocapkit.skeleton.limbs import arm, part_dofs
from mocapkit.tracking.base import BRIDGE_S, unobserved_part
from mocapkit.tracking.hybrid.tracker import HybridConfig, HybridSample, HybridTracker


def _bvh_channels(path: Path, joints: list[str]) -> np.ndarray:
    """The BVH's channel values (T, C) of the named joints, in file order."""
    data = parse_bvh(path)
    cols, start = [], 0
    for j in data.joints:
        n = len(j.channels)
        if j.name in joints:
            cols += list(range(start, start + n))
        start += n
    assert cols, f"none of {joints} in {path}"
    return data.values[:, cols]


def test_unobserved_part_names_the_joints_each_status_stands_for() -> None:
    assert unobserved_part("head") == ("head", ("head",))
    assert unobserved_part("left_hand") == ("left_arm", ("left_elbow", "left_wrist"))
    assert unobserved_part("right_arm") == ("right_arm", ("right_elbow", "right_wrist"))
    assert unobserved_part("left_foot") == ("left_leg", ("left_knee", "left_ankle"))
    assert unobserved_part("rms_mm") is None and unobserved_part("left_hand_tip") is None


def test_hybrid_released_hand_nan_joints_and_bvh_holds_the_last_bridged_arm(tmp_path) -> None:
    """A right hand set unseen for 0.4 s (past the 0.25 s bridge): its elbow and wrist are
    NaN in joints.csv and motion.npz while released, and the BVH's right-arm channels
    hold those of the last bridged frame, as the tracker's own pose does."""
    sk = load_preset("zhang21")
    tracker = HybridTracker(sk, config=HybridConfig(use_video=False))
    q0 = tracker.solver.secondary.omega.copy()
    pos = tracker.solver.effector_positions(q0)[:3]
    lift = np.array([0.0, -150.0, 250.0])  # the right hand held up and forward
    n, dt = 40, 0.02
    gone = range(10, 30)  # 0.20 .. 0.58 s
    samples = [
        HybridSample(
            dt * i,
            {"head": pos[0], "left_hand": pos[1]}
            | ({} if i in gone else {"right_hand": pos[2] + lift}),
        )
        for i in range(n)
    ]
    out = tmp_path / "res"
    run = run_tracker(tracker, samples, n, out)
    rows, _ = read_fit_csv(out / FIT_FILE)
    status = [r["right_hand_status"] for r in rows]
    released = np.array([s == "released" for s in status])
    bridged = [i for i, s in enumerate(status) if s == "bridged"]
    assert released.sum() >= 5 and bridged and max(bridged) < np.flatnonzero(released)[0]
    assert all(s == "seen" for i, s in enumerate(status) if i not in gone)
    _t, names, joints = read_joints_csv(out / "joints.csv")
    for j in ("right_elbow", "right_wrist"):
        col = joints[:, names.index(j)]
        assert np.all(np.isnan(col[released])) and np.all(np.isfinite(col[~released]))
    assert np.all(np.isfinite(joints[:, names.index("left_wrist")]))
    npz = load_motion_npz(out / "motion.npz")
    assert np.all(np.isnan(npz.joints_mm[released, npz.joint_names.index("right_wrist")]))
    # the BVH: right-arm channels of every released frame = those of the last bridged one
    right = arm(sk, "right")
    chain = [sk.joint_names[j] for j in right.chain]
    ch = _bvh_channels(out / "motion.bvh", chain)
    last = max(bridged)
    np.testing.assert_allclose(ch[released], np.tile(ch[last], (released.sum(), 1)), atol=1e-7)
    # ... which the tracker's own pose holds too: the arm's DoFs of the last bridged
    # frame, not an arm dropped into the relaxed pose
    own = np.asarray(run.motion.q)
    np.testing.assert_allclose(
        own[released][:, right.dofs], np.tile(own[last, right.dofs], (released.sum(), 1))
    )
    # nothing else is held: the BVH's other channels are those of the tracker's own pose
    from mocapkit.io.motion import Motion
    from mocapkit.io.motion_files import write_motion

    write_motion(tmp_path / "own.bvh", Motion.from_q(sk, npz.time_s, own))
    others = [n for n in sk.joint_names if n not in chain]
    np.testing.assert_allclose(
        _bvh_channels(out / "motion.bvh", others),
        _bvh_channels(tmp_path / "own.bvh", others),
        atol=1e-7,
    )
    assert [str(g) for g in run.gaps] == [str(g) for g in find_gaps(run.results)]
    assert any(g.name == "right_hand" and g.status == "released" for g in run.gaps)


# ------------------------------------------------------------------- stereo and mono


@pytest.fixture(scope="module")
def blackout_session(tmp_path_factory):
    """builtin:wave, stereo rig, 1.2 s at 320x240, every view blank 0.3-0.8 s."""
    from mocapkit.synth.realism import RealismOptions
    from mocapkit.synth.session_writer import SynthOptions, synthesize_session

    out = tmp_path_factory.mktemp("blackout") / "wave"
    synthesize_session(
        "builtin:wave",
        out,
        SynthOptions(
            rig="stereo",
            seconds=1.2,
            image_size=(320, 240),
            video_format="png",
            blackout_s=(0.3, 0.5),
            realism=RealismOptions(blur=0.0),
        ),
    )
    return out


def _released_rows(out: Path, name: str) -> np.ndarray:
    rows, _ = read_fit_csv(out / FIT_FILE)
    return np.array([r[f"{name}_status"] == "released" for r in rows])


def test_stereo_blackout_gives_nan_joints_a_held_bvh_and_printed_gaps(
    blackout_session, tmp_path, capsys
) -> None:
    out = tmp_path / "st"
    argv = ["track", "stereo", str(blackout_session), "--out", str(out), "--keypoints"]
    assert main([*argv, "--particles", "30"]) == 0
    text = capsys.readouterr().out
    rows, _ = read_fit_csv(out / FIT_FILE)
    t = np.array([float(r["time_s"]) for r in rows])
    blank = (t >= 0.3) & (t < 0.8)
    for name in ("head", "left_hand", "right_hand"):
        st = [r[f"{name}_status"] for r in rows]
        assert all(s == "seen" for s, b in zip(st, blank) if not b)
        # blank frames never report a pose as seen: bridged up to the bridge, then released
        assert all(s in ("bridged", "released") for s, b in zip(st, blank) if b)
        last_seen = t[~blank & (t < 0.3)].max()
        for s, ti in zip(st, t):
            if blank[t == ti][0]:
                assert s == ("bridged" if ti - last_seen <= BRIDGE_S else "released")
        assert f"gap: {name} released " in text
    released = _released_rows(out, "left_hand")
    assert released.any()
    _t, names, joints = read_joints_csv(out / "joints.csv")
    for j in ("head", "left_elbow", "left_wrist", "right_elbow", "right_wrist"):
        assert np.all(np.isnan(joints[released, names.index(j)]))
        assert np.all(np.isfinite(joints[~released, names.index(j)]))
    sk = load_motion_npz(out / "motion.npz").skeleton
    chain = [sk.joint_names[j] for j in arm(sk, "left").chain]
    ch = _bvh_channels(out / "motion.bvh", chain)
    last = np.flatnonzero(~released & (t < 0.8)).max()
    np.testing.assert_allclose(ch[released], np.tile(ch[last], (released.sum(), 1)), atol=1e-7)


def _mono_session_with_a_hidden_elbow(folder: Path, n: int = 30) -> tuple[Path, np.ndarray]:
    from tests.pipelines.test_mono import _session

    session = _session(folder, lengths=True, n=n)
    kp = read_keypoints_csv(session / "keypoints" / "mono.csv")
    px = np.array(kp.pixels, copy=True)
    hidden = (kp.time_s >= 0.3) & (kp.time_s < 0.8)  # left elbow only; its wrist is seen
    px[hidden, list(kp.joint_names).index("left_elbow")] = np.nan
    write_keypoints_csv(session / "keypoints" / "mono.csv", kp.time_s, kp.joint_names, px)
    return session, np.asarray(kp.time_s)


def test_mono_limb_unseen_past_the_bridge_is_released_with_nan_joints(tmp_path, capsys) -> None:
    """Mono: the left elbow's 2-D point missing for 0.5 s (its wrist seen throughout):
    the left arm is bridged while the gap is within both the 0.25 s bridge and the
    smoother's ``max_gap`` (5 frames, 0.167 s at 30 fps, which ends first here), then
    released; its elbow and wrist are NaN in joints.csv on those frames, and the CLI
    prints the gap."""
    from mocapkit.tracking.mono.tracker import MonoConfig

    session, t = _mono_session_with_a_hidden_elbow(tmp_path / "s")
    out = tmp_path / "r"
    argv = ["track", "mono", str(session), "--out", str(out), "--session-lengths"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    rows, _ = read_fit_csv(out / FIT_FILE)
    st = [r["left_arm_status"] for r in rows]
    last_seen = t[t < 0.3].max()
    bridge_s = min(BRIDGE_S, MonoConfig().max_gap / 30.0)
    for s, ti in zip(st, t):
        if 0.3 <= ti < 0.8:
            assert s == ("bridged" if ti - last_seen <= bridge_s + 1e-9 else "released"), ti
        else:
            assert s == "seen", ti
    assert all(r["right_arm_status"] == "seen" for r in rows)
    released = np.array([s == "released" for s in st])
    assert released.sum() >= 5
    _t, names, joints = read_joints_csv(out / "joints.csv")
    for j in ("left_elbow", "left_wrist"):
        assert np.all(np.isnan(joints[released, names.index(j)]))
        assert np.all(np.isfinite(joints[~released, names.index(j)]))
    assert np.all(np.isfinite(joints[:, names.index("right_wrist")]))
    gap = [line for line in text.splitlines() if line.startswith("gap: left_arm released")]
    assert len(gap) == 1 and f"({released.sum()} frames)" in gap[0]


def test_mono_released_arm_is_held_then_blended_back_once_in_motion_npz_and_bvh(tmp_path) -> None:
    """Mono, the left elbow's 2-D point missing for 0.5 s: the tracker's own angles put
    the released arm at rest (no joints to follow); in the result folder (motion.npz's
    q and the BVH, the same poses) its DoFs hold those of its last observed frame, then
    go from them to the tracked ones linearly over GAP_BLEND_S = REJOIN_BLEND_S, once:
    weight (t - t_last_held) / 0.5 s of the way on each frame, not its square."""
    from mocapkit.io.bvh import read_bvh
    from mocapkit.pipelines.mono import track_mono
    from mocapkit.pipelines.run import GAP_BLEND_S
    from mocapkit.tracking.base import REJOIN_BLEND_S

    assert GAP_BLEND_S == REJOIN_BLEND_S == 0.5
    folder, _ = _mono_session_with_a_hidden_elbow(tmp_path / "s", n=45)  # 1.5 s at 30 Hz
    out = tmp_path / "r"
    run = track_mono(folder, out, use_session_lengths=True)
    tracked = np.asarray(run.motion.q)  # the tracker's own pose
    npz = load_motion_npz(out / "motion.npz")
    bvh = read_bvh(out / "motion.bvh", unit_mm=1000.0)
    sk = npz.skeleton
    # the arm's DoFs and its clavicle's (`motion_with_held_parts`'s part)
    clavicle = sk.parents[arm(sk, "left").chain[0]]
    dofs = np.union1d(arm(sk, "left").dofs, np.flatnonzero(sk.dof_joint == clavicle))
    st = np.array([r.status["left_arm"] for r in run.results])
    released = np.flatnonzero(st == "released")
    assert released.size >= 5
    first, last = released[0], released[-1]
    held = npz.q[first - 1, dofs]
    np.testing.assert_array_equal(held, tracked[first - 1, dofs])  # last observed angles
    np.testing.assert_array_equal(npz.q[released][:, dofs], np.tile(held, (released.size, 1)))
    assert np.abs(tracked[released][:, dofs] - held).max() > 0.2  # the tracker's: at rest
    tt = npz.time_s
    back = np.flatnonzero((tt > tt[last]) & (tt < tt[last] + GAP_BLEND_S - 1e-9))
    assert back.size == round(GAP_BLEND_S * 30) - 1  # 30 frames/s
    w = (tt[back] - tt[last]) / GAP_BLEND_S
    np.testing.assert_allclose(
        npz.q[back][:, dofs], held + w[:, None] * (tracked[back][:, dofs] - held), atol=1e-12
    )
    after = np.flatnonzero(tt >= tt[last] + GAP_BLEND_S - 1e-9)
    assert after.size >= 5
    np.testing.assert_allclose(npz.q[after], tracked[after], rtol=0, atol=1e-12)
    others = np.setdiff1d(np.arange(sk.n_dofs), dofs)
    np.testing.assert_array_equal(npz.q[:, others], tracked[:, others])
    # the BVH is written from the same poses: its joints are those of motion.npz's q
    fk = forward_kinematics(sk, npz.q)[:, :, :3, 3]
    fk_bvh = forward_kinematics(bvh.skeleton, bvh.q)[:, :, :3, 3]
    np.testing.assert_allclose(fk_bvh, fk, atol=1e-3)


def test_motion_with_held_parts_leaves_the_dofs_a_tracker_declares_and_holds_the_rest() -> None:
    """A hybrid-like result: the left hand set released on frames 5-9 (0.1 s apart), the
    tracker declaring the arm below the clavicle held (``held_dofs``). The result
    folder's poses leave those DoFs as given (the tracker's own hold and blend, once);
    the clavicle, which the tracker did not declare, holds frame 4's values and is
    blended back linearly over GAP_BLEND_S (weights 0.2, 0.4, 0.6, 0.8 on frames
    10-13); the rest of the pose is the tracker's. The same from a ResultTable."""
    from mocapkit.io.motion import Motion
    from mocapkit.pipelines.result_table import ResultTable
    from mocapkit.pipelines.run import GAP_BLEND_S
    from mocapkit.tracking.base import FrameResult

    assert GAP_BLEND_S == 0.5
    sk = load_preset("zhang21", ("clavicle",))
    n, dt = 20, 0.1
    t = dt * np.arange(n)
    q = np.random.default_rng(7).uniform(-0.5, 0.5, (n, sk.n_dofs))
    declared = arm(sk, "left").dofs
    clavicle = np.flatnonzero(sk.dof_joint == sk.parents[arm(sk, "left").chain[0]])
    assert clavicle.size > 0 and not np.isin(clavicle, declared).any()
    released = range(5, 10)
    results = [
        FrameResult(
            t[i],
            q[i],
            np.zeros((15, 3)),
            {"head": "seen", "left_hand": "released" if i in released else "seen"},
            {},
            "",
            declared if i in released else np.zeros(0, dtype=np.int64),
        )
        for i in range(n)
    ]
    table = ResultTable(4)  # grows past its capacity
    table.extend(results)
    motion = Motion.from_q(sk, t, q)
    for res in (results, table):
        out = motion_with_held_parts(motion, res).q
        expected = q.copy()
        expected[5:10, clavicle] = q[4, clavicle]
        for i, w in zip(range(10, 14), (0.2, 0.4, 0.6, 0.8)):
            expected[i, clavicle] = q[4, clavicle] + w * (q[i, clavicle] - q[4, clavicle])
        np.testing.assert_allclose(out, expected, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(out[:, declared], q[:, declared])
    # without the declaration the arm is held and blended back too
    undeclared = [replace(r, held_dofs=np.zeros(0, dtype=np.int64)) for r in results]
    out = motion_with_held_parts(motion, undeclared).q
    np.testing.assert_array_equal(out[5:10, declared], np.tile(q[4, declared], (5, 1)))
    np.testing.assert_allclose(
        out[10, declared], q[4, declared] + 0.2 * (q[10, declared] - q[4, declared]), atol=1e-12
    )


def test_hybrid_hand_blanked_for_one_second_is_held_then_blended_back_in_the_bvh(
    tmp_path,
) -> None:
    """The left hand set blanked for 1 s while the hand moves on (a skeleton with
    clavicles): the tracker holds the arm and its clavicle at their last observed pose
    and, when the set comes back, blends its IK targets back
    (`HybridConfig.rejoin_blend_s`), so the hand does not snap; it declares those DoFs
    (``held_dofs``), and the BVH shows that one blend, not a second one on top."""
    from mocapkit.io.bvh import read_bvh

    sk = load_preset("zhang21", ("clavicle",))
    tracker = HybridTracker(sk, config=HybridConfig(use_video=False))
    q0 = tracker.solver.secondary.omega.copy()
    pos = tracker.solver.effector_positions(q0)[:3]
    n, dt = 100, 0.02
    gone = range(25, 75)  # 0.50 .. 1.48 s
    raise_mm = np.array([0.0, -250.0, 350.0])  # the left hand lifted forward over the take

    def left(i: int) -> np.ndarray:
        return pos[1] + raise_mm * min(i / 60.0, 1.0)

    samples = [
        HybridSample(
            dt * i,
            {"head": pos[0], "right_hand": pos[2]} | ({} if i in gone else {"left_hand": left(i)}),
        )
        for i in range(n)
    ]
    out = tmp_path / "res"
    run = run_tracker(tracker, samples, n, out)
    status = [r.status["left_hand"] for r in run.results]
    released = np.array([s == "released" for s in status])
    assert released.sum() >= 30
    back = read_bvh(out / "motion.bvh", unit_mm=1000.0)
    # the wrist in the frame of the arm's parent (the clavicle): the part's own pose
    parent = int(sk.parents[arm(sk, "left").chain[0]])
    wrist_j = sk.joint_index("l_hand")

    def in_parent(skel, q) -> np.ndarray:
        world = forward_kinematics(skel, q)
        rel = world[:, wrist_j, :3, 3] - world[:, parent, :3, 3]
        return np.einsum("tji,tj->ti", world[:, parent, :3, :3], rel)

    wrist = in_parent(back.skeleton, back.q)
    tracked = in_parent(sk, np.asarray(run.motion.q))
    gap = np.flatnonzero(released)
    np.testing.assert_allclose(wrist[gap], np.tile(wrist[gap[0] - 1], (gap.size, 1)), atol=1e-3)
    first_back = int(gap[-1]) + 1
    held_hand = forward_kinematics(back.skeleton, back.q[first_back - 1])[wrist_j, :3, 3]
    jump = np.linalg.norm(left(first_back) - held_hand)
    assert jump > 100.0  # the hand moved on while unseen: snapping back would jump this far
    for skel, q in ((back.skeleton, back.q), (sk, np.asarray(run.motion.q))):  # BVH, tracked
        hand = forward_kinematics(skel, q[first_back - 1 :])[:, wrist_j, :3, 3]
        assert np.linalg.norm(np.diff(hand, axis=0), axis=1).max() < 0.2 * jump  # no snap
    # the part held is the arm with its clavicle; the result folder's poses are the tracker's
    part = part_dofs(sk, "left_arm")
    clavicle = np.flatnonzero(sk.dof_joint == sk.parents[arm(sk, "left").chain[0]])
    assert clavicle.size > 0 and np.isin(clavicle, part).all()
    for r, gone_now in zip(run.results, released, strict=True):
        np.testing.assert_array_equal(np.sort(r.held_dofs), part if gone_now else [])
    q = np.asarray(run.motion.q)
    np.testing.assert_array_equal(q[gap][:, part], np.tile(q[gap[0] - 1, part], (gap.size, 1)))
    np.testing.assert_array_equal(motion_with_held_parts(run.motion, run.results).q, q)
    np.testing.assert_allclose(wrist, tracked, atol=1e-3)
