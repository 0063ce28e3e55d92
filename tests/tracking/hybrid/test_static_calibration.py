"""Tests of the static calibration of marker-set member offsets."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ConfigError, ShapeError
from mocapkit.io.markers import MarkerData
from mocapkit.pipelines.hybrid import hybrid_skeleton
from mocapkit.pipelines.hybrid_markers import (
    RAW_MARKERS_REPLANT_MM,
    head_band_offset_mm,
    track_hybrid_marker_file,
)
from mocapkit.pipelines.run import read_fit_csv
from mocapkit.skeleton.kinematics import canonical_positions, forward_kinematics
from mocapkit.tracking.hybrid.static_calibration import (
    MAX_STATIC_RMS_MM,
    calibrate_member_offsets,
    find_static_interval,
    rotation_between_deg,
)
from mocapkit.tracking.hybrid.tracker import HybridConfig, HybridTracker, default_marker_effectors

RATE_HZ = 50.0
#: True member offsets (mm, effector joint frame, from the default point); zero mean per
#: set, so the set centre is the effector's point. Glasses turned 20 deg about the head's
#: vertical; wrist bars across the wrist.
_C, _S = np.cos(np.radians(20.0)), np.sin(np.radians(20.0))
_GLASSES = np.array(
    [[70.0, 60.0, 25.0], [-70.0, 60.0, 25.0], [70.0, -60.0, -25.0], [-70.0, -60.0, -25.0]]
)
TRUE_MEMBERS = {
    "head": dict(
        zip(
            ("LFHD", "RFHD", "LBHD", "RBHD"),
            _GLASSES @ np.array([[_C, _S, 0], [-_S, _C, 0], [0, 0, 1]]).T,
            strict=True,
        )
    ),
    "left_hand": {"LWRA": np.array([0.0, 30.0, 0.0]), "LWRB": np.array([0.0, -30.0, 0.0])},
    "right_hand": {"RWRA": np.array([0.0, 30.0, 0.0]), "RWRB": np.array([0.0, -30.0, 0.0])},
}
SPECS = ["head=LFHD+RFHD+LBHD+RBHD", "left_hand=LWRA+LWRB", "right_hand=RWRA+RWRB"]


def _raw_config() -> HybridConfig:
    return HybridConfig(use_video=False, start_upright=False, replant_mm=RAW_MARKERS_REPLANT_MM)


def _members_from_poses(sk, q, rng, noise_mm=0.5, set_offsets_mm=None):
    """Member trajectories (name -> (T, 3)) of poses ``q`` with the true offsets (plus
    ``set_offsets_mm[set]``, where the set's centre sits from the effector point)."""
    world = forward_kinematics(sk, q)
    eff = default_marker_effectors(sk)
    out = {}
    for name, members in TRUE_MEMBERS.items():
        j = sk.joint_index(eff[name].joint)
        shift = np.asarray((set_offsets_mm or {}).get(name, (0.0, 0.0, 0.0)))
        for m, off in members.items():
            local = np.asarray(eff[name].point_mm) + shift + off
            p = np.einsum("nij,j->ni", world[:, j, :3, :3], local) + world[:, j, :3, 3]
            out[m] = p + rng.normal(0.0, noise_mm, p.shape)
    return out


def _take(sk, n_static, n_move):
    """Relaxed pose (the tracker's) held still, then the arms and head moving."""
    tracker = HybridTracker(sk, None, _raw_config())
    q0 = np.clip(tracker.solver.secondary.omega, sk.lower, sk.upper)
    q = np.tile(q0, (n_static + n_move, 1))
    ramp = np.linspace(0.0, 1.0, n_move)
    q[n_static:, sk.dof_index("l_shoulder_flexion")] += 1.2 * ramp
    q[n_static:, sk.dof_index("r_elbow_flexion")] += 1.0 * ramp
    q[n_static:, sk.dof_index("neck_flexion")] += 0.3 * ramp
    return np.clip(q, sk.lower, sk.upper)


def test_find_static_interval():
    rng = np.random.default_rng(2)
    t = np.arange(300) / RATE_HZ
    p = np.cumsum(rng.normal(0.0, 20.0, (300, 3, 3)), axis=0)  # wandering
    p[100:160] = p[100] + rng.normal(0.0, 1.0, (60, 3, 3))  # still from 2.0 to 3.2 s
    found = find_static_interval(t, p)
    assert found is not None
    assert 100 <= found.start and found.stop <= 160
    assert found.rms_motion_mm < 3.0
    assert find_static_interval(t, p, search_s=1.0) is None  # only the wandering start
    p[100:160, 1] = np.nan  # a set unseen over the still part
    assert find_static_interval(t, p) is None
    assert MAX_STATIC_RMS_MM > 5.0
    with pytest.raises(ShapeError, match=r"sets_mm: expected shape \(300, S, 3\)"):
        find_static_interval(t, p[:, 0])


def test_member_offsets_recovered_from_static_interval():
    sk = hybrid_skeleton(1700.0)
    rng = np.random.default_rng(3)
    q = _take(sk, 60, 60)
    members = _members_from_poses(sk, q, rng)
    t = np.arange(q.shape[0]) / RATE_HZ
    sets = {name: np.mean([members[m] for m in ms], axis=0) for name, ms in TRUE_MEMBERS.items()}
    interval = find_static_interval(t, np.stack(list(sets.values()), axis=1))
    assert interval is not None and interval.stop <= 60
    calib = calibrate_member_offsets(
        sk,
        _raw_config(),
        t,
        sets,
        {name: {m: members[m] for m in ms} for name, ms in TRUE_MEMBERS.items()},
        interval,
    )
    for name, ms in TRUE_MEMBERS.items():
        got = np.array([calib.offsets_mm[name][m] for m in ms])
        want = np.array(list(ms.values()))
        assert np.abs(got - want).max() < 5.0, name
        assert rotation_between_deg(got, want) < 3.0, name
        assert calib.spread_mm[name] < 3.0
    with pytest.raises(ConfigError, match="expected a marker set with at least two member"):
        calibrate_member_offsets(
            sk, _raw_config(), t, sets, {"head": {"LFHD": members["LFHD"]}}, interval
        )


def _raw_model():
    """The model the raw-marker path builds for `SPECS` at 1700 mm: a population's
    proportions, and the forearm's turn since the hand sets are wrist bars."""
    return hybrid_skeleton(1700.0, proportions="anthropometric", forearm_rotation=True)


def _recording(sk, q, members, source="synthetic"):  # type: ignore[no-untyped-def]
    """``members`` (name -> (T, 3) mm) and ankle markers as a recording at `RATE_HZ`; the
    ankles because the floor is found from the lowest markers."""
    ankles = canonical_positions(sk, q, ["left_ankle", "right_ankle"])
    members = {**members, "LANK": ankles[:, 0], "RANK": ankles[:, 1]}
    names = list(members)
    t = np.arange(q.shape[0]) / RATE_HZ
    return MarkerData(t, names, np.stack([members[n] for n in names], axis=1), RATE_HZ, source)


def test_marker_file_calibrates_members_and_reports_them(tmp_path):
    """Through the raw-marker path: offsets calibrated on the still start, members in the
    IK and in fit.csv (each member's distance, the RMS, the largest and its name)."""
    sk = _raw_model()
    rng = np.random.default_rng(4)
    q = _take(sk, 60, 40)
    # a raw head set sits where a head band does on a standing model
    band = np.asarray(head_band_offset_mm(sk))
    members = _members_from_poses(sk, q, rng, set_offsets_mm={"head": band})
    markers = _recording(sk, q, members)
    run = track_hybrid_marker_file(markers, SPECS, height_mm=1700.0, up="z", out_dir=tmp_path)
    assert run.calibration is not None and "calibrated on the take" in run.calibration_note
    for name, ms in TRUE_MEMBERS.items():
        got = np.array([run.calibration.offsets_mm[name][m] for m in ms])
        want = np.array(list(ms.values())) + (band if name == "head" else 0.0)
        assert np.abs(got - want).max() < 5.0
    rows, fit = read_fit_csv(tmp_path / "fit.csv")
    assert {"LFHD_mm", "LWRA_mm", "rms_mm", "max_mm"} <= set(fit)
    assert rows[-1]["worst"] in {n for n in fit} | {k.removesuffix("_mm") for k in fit}
    assert np.nanmax(fit["LFHD_mm"]) < 10.0
    off = track_hybrid_marker_file(markers, SPECS, height_mm=1700.0, up="z", calibration="none")
    assert off.calibration is None and "positions only" in off.calibration_note
    assert not any("LFHD_mm" in r.fit for r in off.results)


def test_turning_marker_is_calibrated_and_tracked_without_moving_the_set(tmp_path):
    """A forearm marker after '/' (``right_hand=RWRA+RWRB/RFRM``): calibrated as a member
    and fitted by the IK, while the set's point stays the wrist bar's midpoint (with it in
    the mean, the wrist would be pulled 40 mm up the forearm)."""
    sk = _raw_model()
    rng = np.random.default_rng(5)
    q = _take(sk, 60, 40)
    band = np.asarray(head_band_offset_mm(sk))
    members = _members_from_poses(sk, q, rng, set_offsets_mm={"head": band})
    eff = default_marker_effectors(sk)["right_hand"]
    world = forward_kinematics(sk, q)[:, sk.joint_index(eff.joint)]
    forearm_local = np.array([40.0, 0.0, 120.0])  # 120 mm up the forearm, 40 mm aside
    local = np.asarray(eff.point_mm) + forearm_local
    members["RFRM"] = np.einsum("nij,j->ni", world[:, :3, :3], local) + world[:, :3, 3]
    markers = _recording(sk, q, members)
    specs = [*SPECS[:2], "right_hand=RWRA+RWRB/RFRM"]
    run = track_hybrid_marker_file(markers, specs, height_mm=1700.0, up="z", out_dir=tmp_path)
    assert run.calibration is not None
    got = run.calibration.offsets_mm["right_hand"]
    assert set(got) == {"RWRA", "RWRB", "RFRM"}
    assert np.abs(np.asarray(got["RFRM"]) - forearm_local).max() < 5.0
    for m, want in TRUE_MEMBERS["right_hand"].items():
        assert np.abs(np.asarray(got[m]) - want).max() < 5.0
    _rows, fit = read_fit_csv(tmp_path / "fit.csv")
    assert np.nanmax(fit["RFRM_mm"]) < 10.0
    assert np.nanmax(fit["right_hand_mm"]) < 10.0


def test_separate_static_trial():
    """``static=``: the offsets come from a separate still trial, not the moving take."""
    sk = _raw_model()
    rng = np.random.default_rng(5)
    q = _take(sk, 60, 40)
    band = np.asarray(head_band_offset_mm(sk))
    members = _members_from_poses(sk, q, rng, set_offsets_mm={"head": band})
    both = _recording(sk, q, members)
    t, names, pos = both.time_s, both.names, both.positions_mm
    static = MarkerData(t[:60], names, pos[:60], RATE_HZ, "static.c3d")
    take = MarkerData(t[60:], names, pos[60:], RATE_HZ, "take.c3d")
    alone = track_hybrid_marker_file(take, SPECS, height_mm=1700.0, up="z", calibration="static")
    assert alone.calibration is None and "no window of 1 s in the take" in alone.calibration_note
    run = track_hybrid_marker_file(take, SPECS, height_mm=1700.0, up="z", static=static)
    assert run.calibration is not None and "static trial static.c3d" in run.calibration_note
    got = np.array([run.calibration.offsets_mm["left_hand"][m] for m in ("LWRA", "LWRB")])
    want = np.array(list(TRUE_MEMBERS["left_hand"].values()))
    assert np.abs(got - want).max() < 5.0


#: Plug-in Gait's thorax markers about the chest joint (mm, its frame; the subject faces +Y).
THORAX_MEMBERS = {
    "CLAV": np.array([0.0, 90.0, 130.0]),
    "STRN": np.array([0.0, 110.0, 40.0]),
    "C7": np.array([0.0, -80.0, 170.0]),
    "T10": np.array([0.0, -110.0, -40.0]),
}
THORAX_SPEC = "thorax=CLAV+STRN+C7+T10"


def test_thorax_set_calibrates_and_holds_the_trunk_twist():
    """A thorax set (``thorax=CLAV+STRN+C7+T10``) rides on the chest joint: its members are
    calibrated about it on the still start, and on the motion (the trunk twisted 35 deg and
    bent 15 deg sideways while the head looks ahead) it holds the chest's turn, which head
    and hands alone leave free. A member the file lacks is refused, naming the set, the
    marker and the valid choices."""
    from mocapkit.errors import UnknownNameError
    from mocapkit.pipelines.hybrid_markers import raw_marker_skeleton
    from mocapkit.skeleton.limbs import thorax_joint

    sk = raw_marker_skeleton(1700.0, ("head", "left_hand", "right_hand", "thorax"))
    rng = np.random.default_rng(6)
    q = _take(sk, 60, 60)
    ramp = np.linspace(0.0, 1.0, 60)
    q[60:, sk.dof_index("spine_rotation")] = np.radians(35.0) * ramp
    q[60:, sk.dof_index("neck_rotation")] = -np.radians(35.0) * ramp
    q[60:, sk.dof_index("spine_lateral")] = np.radians(15.0) * ramp
    q = np.clip(q, sk.lower, sk.upper)
    band = np.asarray(head_band_offset_mm(sk))
    members = _members_from_poses(sk, q, rng, set_offsets_mm={"head": band})
    chest = forward_kinematics(sk, q)[:, thorax_joint(sk)]
    for m, off in THORAX_MEMBERS.items():
        p = np.einsum("nij,j->ni", chest[:, :3, :3], off) + chest[:, :3, 3]
        members[m] = p + rng.normal(0.0, 0.5, p.shape)
    markers = _recording(sk, q, members)

    def chest_turn_error_deg(run):  # type: ignore[no-untyped-def]
        got = forward_kinematics(run.motion.skeleton, run.motion.q)[60:, thorax_joint(sk), :3, :3]
        assert run.motion.skeleton.joint_names == sk.joint_names
        cos = (np.einsum("nij,nij->n", got, chest[60:, :3, :3]) - 1.0) / 2.0
        return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))

    run = track_hybrid_marker_file(markers, [*SPECS, THORAX_SPEC], height_mm=1700.0, up="z")
    assert run.calibration is not None and "thorax" in run.calibration.offsets_mm
    got = np.array([run.calibration.offsets_mm["thorax"][m] for m in THORAX_MEMBERS])
    assert np.abs(got - np.array(list(THORAX_MEMBERS.values()))).max() < 5.0
    assert max(r.residual_mm["thorax"] for r in run.results) < 5.0
    assert max(r.fit["T10_mm"] for r in run.results) < 5.0
    without = track_hybrid_marker_file(markers, SPECS, height_mm=1700.0, up="z")
    assert chest_turn_error_deg(run).max() < 2.0
    assert np.median(chest_turn_error_deg(without)) > 10.0
    with pytest.raises(
        UnknownNameError,
        match=r"marker set 'thorax': unknown marker 'CLAV2'.*expected one of: C7, CLAV,",
    ):
        track_hybrid_marker_file(markers, [*SPECS, "thorax=CLAV2+STRN+C7+T10"], up="z")
