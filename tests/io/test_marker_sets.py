"""Marker sets: parsing, evaluation with dropout compensation, coverage, stature estimate."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocapkit.errors import FormatError, UnknownNameError
from mocapkit.io.marker_files import read_markers
from mocapkit.io.marker_sets import (
    HEAD_TOP_OFFSET_MM,
    PLUG_IN_GAIT_SETS,
    MarkerSet,
    estimate_height_mm,
    evaluate_marker_sets,
    marker_set_coverage,
    parse_marker_set,
    parse_marker_sets,
    set_centre_mm,
)
from mocapkit.io.markers import MarkerData

# A head band: four markers 150-180 mm apart, centred on the origin.
HEAD_LOCAL_MM = np.array(
    [[-75.0, 90.0, 5.0], [75.0, 90.0, -5.0], [-70.0, -90.0, 0.0], [70.0, -90.0, 0.0]]
)


def _rigid_cluster(
    local_mm: np.ndarray, n_frames: int, rotvec_per_frame: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """(T, K, 3) member positions and (T, 3) true centres of a moving rigid cluster."""
    steps = np.arange(n_frames)[:, None]
    centre = np.array([100.0, 2000.0, 1600.0]) + steps * rng.normal(0.0, 3.0, size=3)
    rot = Rotation.from_rotvec(steps * rotvec_per_frame[None, :])
    members = centre[:, None, :] + np.stack([rot.apply(p) for p in local_mm], axis=1)
    return members, centre


def _markers(names: tuple[str, ...], pos: np.ndarray, rate_hz: float = 100.0) -> MarkerData:
    return MarkerData(np.arange(pos.shape[0]) / rate_hz, names, pos, rate_hz, "sets.c3d")


# ---------------------------------------------------------------------- parsing
def test_parse_marker_set() -> None:
    s = parse_marker_set(" head = LFHD + RFHD+LBHD+RBHD ")
    assert s == MarkerSet("head", ("LFHD", "RFHD", "LBHD", "RBHD"))
    assert s.spec == "head=LFHD+RFHD+LBHD+RBHD"
    assert parse_marker_set(s.spec) == s
    assert parse_marker_set("left_hand=Derrick:LWRA+Derrick:LWRB").members[0] == "Derrick:LWRA"
    assert parse_marker_set("c7=C7").members == ("C7",)
    assert PLUG_IN_GAIT_SETS["head"] == s


def test_parse_turning_markers() -> None:
    s = parse_marker_set("left_hand = LWRA+LWRB / LFRM")
    assert s == MarkerSet("left_hand", ("LWRA", "LWRB"), ("LFRM",))
    assert s.all_members == ("LWRA", "LWRB", "LFRM")
    assert s.spec == "left_hand=LWRA+LWRB/LFRM"
    assert parse_marker_set(s.spec) == s
    assert parse_marker_set("left_hand=LWRA+LWRB").turning == ()
    # one placing marker and one turning marker orient a set; one marker alone does not
    assert parse_marker_set("left_hand=HandL/ForearmL").orientable
    assert not parse_marker_set("left_hand=HandL").orientable


def test_turning_markers_do_not_move_the_centre() -> None:
    pos = np.array([[[0.0, -30, 0], [0.0, 30, 0], [40.0, 0, 120]]])
    m = _markers(("LWRA", "LWRB", "LFRM"), pos)
    centre = evaluate_marker_sets(m, "left_hand=LWRA+LWRB/LFRM")
    np.testing.assert_allclose(centre[0, 0], [0.0, 0.0, 0.0])
    np.testing.assert_allclose(
        evaluate_marker_sets(m, "left_hand=LWRA+LWRB+LFRM")[0, 0], [40.0 / 3, 0.0, 40.0]
    )


@pytest.mark.parametrize(
    ("spec", "pattern"),
    [
        ("left_hand=A/B/C", r"expected at most one '/' before the turning markers.*found 2"),
        ("left_hand=A+B/", r"found an empty member"),
        ("left_hand=/B", r"found an empty member"),
        ("left_hand=A+B/A", r"expected distinct members, found A more than once"),
    ],
)
def test_parse_turning_marker_errors(spec: str, pattern: str) -> None:
    with pytest.raises(FormatError, match=pattern):
        parse_marker_set(spec)


@pytest.mark.parametrize(
    ("spec", "pattern"),
    [
        ("head", r"marker set 'head': expected exactly one '='.*found 0"),
        ("head=A=B", r"expected exactly one '='.*found 2"),
        ("=A+B", r"expected a set name before '='"),
        ("head=A++B", r"'head=A\+\+B': expected marker names separated by single '\+'"),
        ("head=A+", r"found an empty member"),
        ("head=", r"found an empty member"),
        ("1head=A", r"marker set name: expected letters.*found '1head'"),
        ("my head=A", r"found 'my head'"),
        ("head=A B+C", r"expected member marker names without spaces.*found 'A B'"),
        ("head=A+B+A", r"marker set 'head': expected distinct members, found A more than once"),
    ],
)
def test_parse_marker_set_errors(spec: str, pattern: str) -> None:
    with pytest.raises(FormatError, match=pattern):
        parse_marker_set(spec)


def test_parse_marker_sets() -> None:
    sets = parse_marker_sets("head=LFHD+RFHD; left_hand=LWRA+LWRB,right_hand=RWRA+RWRB;")
    assert [s.name for s in sets] == ["head", "left_hand", "right_hand"]
    assert parse_marker_sets(["a=X", "b=Y"])[1] == MarkerSet("b", ("Y",))
    with pytest.raises(FormatError, match="expected distinct set names, found 'a' twice"):
        parse_marker_sets(["a=X", "a=Y"])


# ---------------------------------------------------------------------- evaluation
def test_plain_mean_and_nan_only_when_all_missing() -> None:
    pos = np.array(
        [
            [[0.0, 0, 0], [2.0, 0, 0], [4.0, 0, 0]],
            [[np.nan] * 3, [2.0, 0, 0], [4.0, 0, 0]],
            [[np.nan] * 3, [np.nan] * 3, [np.nan] * 3],
        ]
    )
    m = _markers(("S:A", "S:B", "S:C"), pos)
    plain = evaluate_marker_sets(m, "abc=A+B+C", compensate_dropout=False)
    assert plain.shape == (3, 1, 3)
    np.testing.assert_allclose(plain[:2, 0, 0], [2.0, 3.0])
    assert np.isnan(plain[2]).all()
    comp = evaluate_marker_sets(m, ["abc=A+B+C"])
    np.testing.assert_allclose(comp[:2, 0, 0], [2.0, 2.0])  # the offset of A removed
    assert np.isnan(comp[2]).all()


def test_dropped_member_no_longer_shifts_rotating_rigid_cluster(rng: np.random.Generator) -> None:
    """Three of four members visible: a rigid fit recovers the centre whatever the rotation."""
    pos, centre = _rigid_cluster(HEAD_LOCAL_MM, 80, np.array([0.02, -0.03, 0.015]), rng)
    pos[20:30, 0] = np.nan  # LFHD occluded mid-trial
    pos[0:8, 3] = np.nan  # RBHD occluded at the start: nearest reference is after the gap
    m = _markers(("Derrick:LFHD", "Derrick:RFHD", "Derrick:LBHD", "Derrick:RBHD"), pos)
    comp = evaluate_marker_sets(m, PLUG_IN_GAIT_SETS["head"])[:, 0]
    np.testing.assert_allclose(comp, centre, atol=1e-9)
    plain = evaluate_marker_sets(m, PLUG_IN_GAIT_SETS["head"], compensate_dropout=False)[:, 0]
    jump = np.linalg.norm(plain - centre, axis=1)
    # The plain mean moves by |offset of the lost member| / 3 = about 39 mm.
    assert jump[20:30].min() > 35.0
    assert jump[30:].max() < 1e-9


def test_two_members_lost_translating_cluster_is_exact(rng: np.random.Generator) -> None:
    pos, centre = _rigid_cluster(HEAD_LOCAL_MM, 50, np.zeros(3), rng)
    pos[10:20, :2] = np.nan  # only the back markers left
    pos[45:, 1:] = np.nan  # only one marker left until the end (no reference after)
    comp = set_centre_mm(pos)
    np.testing.assert_allclose(comp, centre, atol=1e-9)
    plain = set_centre_mm(pos, compensate_dropout=False)
    assert np.linalg.norm(plain[10:20] - centre[10:20], axis=1).min() > 80.0


def test_two_members_lost_slowly_rotating_cluster_interpolates_offsets(
    rng: np.random.Generator,
) -> None:
    # 0.5 degrees per frame: offsets interpolated across a 10-frame gap stay close.
    pos, centre = _rigid_cluster(HEAD_LOCAL_MM, 50, np.array([0.0, 0.0, np.radians(0.5)]), rng)
    pos[20:30, :2] = np.nan
    comp_err = np.linalg.norm(set_centre_mm(pos)[20:30] - centre[20:30], axis=1)
    plain_err = np.linalg.norm(set_centre_mm(pos, False)[20:30] - centre[20:30], axis=1)
    # Linear interpolation of a rotating offset (radius ~117 mm, 5.5 degrees between the
    # references) errs by at most r (1 - cos 2.75 deg) = 0.14 mm; the plain mean by 90 mm.
    assert comp_err.max() < 0.2
    assert plain_err.min() > 85.0


def test_hand_pair_dropout_compensated(rng: np.random.Generator) -> None:
    bar = np.array([[-30.0, 0.0, 0.0], [30.0, 0.0, 0.0]])
    pos, centre = _rigid_cluster(bar, 30, np.zeros(3), rng)
    pos[5:15, 1] = np.nan
    m = _markers(("LWRA", "LWRB"), pos)
    comp = evaluate_marker_sets(m, PLUG_IN_GAIT_SETS["left_hand"])[:, 0]
    np.testing.assert_allclose(comp, centre, atol=1e-9)
    plain = evaluate_marker_sets(m, PLUG_IN_GAIT_SETS["left_hand"], compensate_dropout=False)
    np.testing.assert_allclose(np.linalg.norm(plain[5:15, 0] - centre[5:15], axis=1), 30.0)


def test_collinear_visible_members_fall_back_to_offsets(rng: np.random.Generator) -> None:
    local = np.array([[-80.0, 0, 0], [0.0, 0, 0], [80.0, 0, 0], [0.0, 60.0, 0]])
    local -= local.mean(axis=0)
    pos, centre = _rigid_cluster(local, 40, np.zeros(3), rng)
    pos[10:20, 3] = np.nan  # the three left are collinear: no rigid fit, offsets instead
    np.testing.assert_allclose(set_centre_mm(pos), centre, atol=1e-9)


def test_no_reference_frame_gives_plain_mean() -> None:
    pos = np.array([[[0.0, 0, 0], [np.nan] * 3], [[np.nan] * 3, [10.0, 0, 0]]])
    np.testing.assert_allclose(set_centre_mm(pos), [[0.0, 0, 0], [10.0, 0, 0]])


def test_unknown_member_names_the_set() -> None:
    m = _markers(("Derrick:LFHD", "Derrick:RFHD"), np.zeros((2, 2, 3)))
    with pytest.raises(UnknownNameError, match=r"marker set 'head': unknown marker 'LBHD'.*LFHD"):
        evaluate_marker_sets(m, PLUG_IN_GAIT_SETS["head"])
    with pytest.raises(FormatError, match="distinct set names"):
        evaluate_marker_sets(m, ["a=LFHD", "a=RFHD"])


def test_coverage_report() -> None:
    pos = np.ones((10, 2, 3))
    pos[2:5, :] = np.nan  # both missing for 3 frames
    pos[7, 0] = np.nan  # one missing
    pos[8, :] = np.nan  # both missing, 1 frame
    m = _markers(("S:A", "S:B"), pos, rate_hz=50.0)
    (cov,) = marker_set_coverage(m, "ab=A+B")
    assert cov.members == ("S:A", "S:B")
    assert (cov.n_all_missing, cov.n_partial, cov.n_reference) == (4, 1, 5)
    assert (cov.longest_all_missing_frames, cov.longest_all_missing_s) == (3, pytest.approx(0.06))
    assert cov.summary() == (
        "ab (S:A+S:B): 4/10 frames fully missing (longest 3 frames = 0.060 s), "
        "1 partial, 5 complete"
    )
    np.testing.assert_array_equal(
        np.isnan(evaluate_marker_sets(m, "ab=A+B")[:, 0, 0]), np.isnan(pos[:, :, 0]).all(axis=1)
    )


# ---------------------------------------------------------------------- stature
def _standing_subject(n_frames: int = 200) -> tuple[MarkerData, float]:
    """Head band at 1600 mm, heels at -10 mm; a jump (frames 100-119) and a crouch (150+)."""
    head_z = np.full(n_frames, 1600.0)
    foot_z = np.full(n_frames, -10.0)
    head_z[100:120] = 1900.0
    foot_z[100:120] = 300.0
    head_z[150:] = 1200.0
    names = ("LFHD", "RFHD", "LBHD", "RBHD", "LHEE", "LTOE", "RHEE", "RTOE")
    pos = np.zeros((n_frames, len(names), 3))
    pos[:, :4] = HEAD_LOCAL_MM + np.array([0.0, 500.0, 0.0])
    pos[:, :4, 2] = head_z[:, None] + HEAD_LOCAL_MM[:, 2]
    pos[:, 4:, 0] = [-100.0, -100.0, 100.0, 100.0]
    pos[:, 4:, 2] = foot_z[:, None] + np.array([0.0, 20.0, 0.0, 20.0])
    pos[50:60, 0] = np.nan  # an occluded head marker must not bias the estimate
    return _markers(names, pos), 1600.0 + 10.0 + HEAD_TOP_OFFSET_MM


def test_estimate_height_uses_standing_frames_and_floor() -> None:
    m, expected = _standing_subject()
    assert estimate_height_mm(m) == pytest.approx(expected, abs=1e-9)
    # Without foot markers the floor is z = 0 and every frame counts (the jump wins).
    no_feet = m.select(["LFHD", "RFHD", "LBHD", "RBHD"])
    assert estimate_height_mm(no_feet) == pytest.approx(1900.0 + HEAD_TOP_OFFSET_MM)
    assert estimate_height_mm(m, head_top_offset_mm=0.0) == pytest.approx(1610.0)


def test_estimate_height_errors() -> None:
    m, _ = _standing_subject()
    with pytest.raises(UnknownNameError, match="unknown marker 'LANKX'"):
        estimate_height_mm(m, left_foot=["LANKX"])
    pos = m.positions_mm.copy()
    pos[:, :4] = np.nan
    blind = MarkerData(m.time_s, m.names, pos, m.rate_hz, "blind.c3d")
    with pytest.raises(FormatError, match=r"blind\.c3d: head set for stature: expected some"):
        estimate_height_mm(blind)
    with pytest.raises(ValueError, match=r"percentile: expected a value in \(0, 100\]"):
        estimate_height_mm(m, percentile=0.0)


def test_tennis_serve_sets_and_height(shared_data: Path) -> None:
    m = read_markers(shared_data / "c3d" / "kinematics_tennis_serve.c3d")
    sets = evaluate_marker_sets(m, PLUG_IN_GAIT_SETS.values())
    assert sets.shape == (1092, 3, 3)
    assert not np.isnan(sets).any()
    # Head band of a standing adult: 1.5-1.7 m up at its 95th percentile.
    assert 1500.0 < float(np.percentile(sets[:, 0, 2], 95)) < 1750.0
    height = estimate_height_mm(m)
    assert 1600.0 < height < 2000.0
    assert all(c.n_all_missing == 0 for c in marker_set_coverage(m, PLUG_IN_GAIT_SETS.values()))
