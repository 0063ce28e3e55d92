"""Skin blobs labelled and read as joints (Mamania et al. 2004 §3.3) on drawn images."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from mocapkit.cues.blobs import ellipse_of, mask_blobs
from mocapkit.errors import ConfigError
from mocapkit.tracking.mono.skin_tracking import SKIN_JOINTS, SkinTracker

SKIN_BGR = tuple(
    int(v)
    for v in cv2.cvtColor(np.array([[[150, 154, 104]]], dtype=np.uint8), cv2.COLOR_YCrCb2BGR)[0, 0]
)


def _figure(head=(320, 100), left=((400, 200), (430, 290)), right=((240, 200), (210, 290)),
            belt=True, gap=False) -> np.ndarray:  # fmt: skip
    img = np.full((480, 640, 3), (90, 110, 60), dtype=np.uint8)  # a green-grey backdrop
    cv2.ellipse(img, head, (28, 38), 0, 0, 360, SKIN_BGR, -1)
    for (x0, y0), (x1, y1) in (left, right):  # forearms as ellipses between their ends
        half = round(float(np.hypot(x1 - x0, y1 - y0)) / 2)
        angle = float(np.degrees(np.arctan2(y1 - y0, x1 - x0)))
        centre = (round((x0 + x1) / 2), round((y0 + y1) / 2))
        cv2.ellipse(img, centre, (half, 10), angle, 0, 360, SKIN_BGR, -1)
    if gap:  # a dark band breaks the left forearm in two
        cv2.line(img, (400, 245), (440, 245), (90, 110, 60), 2)
    if belt:
        cv2.ellipse(img, (320, 330), (90, 14), 0, 0, 360, SKIN_BGR, -1)
    return img


def test_moment_ellipse_of_a_drawn_ellipse() -> None:
    mask = np.zeros((200, 200), dtype=np.uint8)
    cv2.ellipse(mask, (100, 90), (60, 20), 30, 0, 360, 255, -1)
    ys, xs = np.nonzero(mask)
    e = ellipse_of(np.stack([xs, ys], axis=1))
    np.testing.assert_allclose(e.centre, (100, 90), atol=0.5)
    assert e.major == pytest.approx(60, rel=0.03) and e.minor == pytest.approx(20, rel=0.06)
    assert abs(abs(e.direction @ [np.cos(np.radians(30)), np.sin(np.radians(30))]) - 1) < 1e-3


def test_labels_and_joints_of_the_first_frame() -> None:
    tr = SkinTracker()
    f = tr.update(_figure())
    assert set(f.blobs) == {"head", "left_hand", "right_hand", "waist"}
    j = dict(zip(SKIN_JOINTS, f.joints_px))
    np.testing.assert_allclose(j["head"], (320, 100), atol=1.5)
    assert j["neck"][1] == pytest.approx(100 + 38, abs=3)
    np.testing.assert_allclose(j["left_elbow"], (400, 200), atol=4)
    np.testing.assert_allclose(j["left_wrist"], (430, 290), atol=4)
    np.testing.assert_allclose(j["right_wrist"], (210, 290), atol=4)
    np.testing.assert_allclose(j["pelvis"], (320, 330), atol=1.5)
    # shoulders: above the belt's ends, level with the neck
    assert j["left_shoulder"][0] == pytest.approx(410, abs=4)
    assert j["right_shoulder"][0] == pytest.approx(230, abs=4)
    assert j["left_shoulder"][1] == pytest.approx(j["neck"][1])


def test_a_broken_blob_is_reunited_and_labels_follow_the_motion() -> None:
    assert len(mask_blobs(_skin(_figure(gap=True)), close_px=0)) == 5
    assert len(mask_blobs(_skin(_figure(gap=True)), close_px=2)) == 4
    tr = SkinTracker()
    tr.update(_figure())
    f = tr.update(_figure(left=((410, 205), (445, 285)), right=((230, 205), (200, 280))))
    j = dict(zip(SKIN_JOINTS, f.joints_px))
    np.testing.assert_allclose(j["left_wrist"], (445, 285), atol=4)
    np.testing.assert_allclose(j["right_wrist"], (200, 280), atol=4)


def test_a_hand_merged_with_the_head_keeps_its_label() -> None:
    tr = SkinTracker()
    tr.update(_figure())
    tr.update(_figure(left=((370, 170), (345, 125))))  # the left hand comes near the face
    f = tr.update(_figure(left=((360, 160), (335, 112))))  # and touches it: one blob
    assert "left_hand" in f.blobs
    assert np.isfinite(f.joints_px[SKIN_JOINTS.index("left_wrist")]).all()


def test_bad_settings_are_refused() -> None:
    with pytest.raises(ConfigError, match="max_jump_px"):
        SkinTracker(max_jump_px=0)


def _skin(img: np.ndarray) -> np.ndarray:
    from mocapkit.cues.skin import skin_mask

    return skin_mask(img)


def test_trunk_from_head_without_a_belt_follows_the_anthropometric_ratios() -> None:
    from mocapkit.tracking.mono.lengths import ANTHROPOMETRIC_RATIOS as r

    plain = SkinTracker().update(_figure(belt=False))
    j = dict(zip(SKIN_JOINTS, plain.joints_px))
    assert np.isnan(j["pelvis"]).all() and np.isnan(j["left_shoulder"]).all()
    f = SkinTracker(trunk_from_head=True).update(_figure(belt=False))
    j = dict(zip(SKIN_JOINTS, f.joints_px))
    a = f.blobs["head"].major  # the drawn head's semi-axis is 38 px
    assert a == pytest.approx(38, rel=0.03)
    np.testing.assert_allclose(j["pelvis"], j["neck"] + (0, a * r["trunk"] / r["head"]))
    half = a * r["left_clavicle"] / r["head"]
    np.testing.assert_allclose(j["left_shoulder"], j["neck"] + (half, 0))
    np.testing.assert_allclose(j["right_shoulder"], j["neck"] - (half, 0))
    # with a belt the paper's heuristic is kept
    belted = SkinTracker(trunk_from_head=True).update(_figure())
    np.testing.assert_allclose(belted.joints_px[SKIN_JOINTS.index("pelvis")], (320, 330), atol=1.5)


def test_a_foreground_mask_hides_static_skin() -> None:
    img = _figure()
    cv2.circle(img, (540, 60), 30, SKIN_BGR, -1)  # two skin-coloured lamps up on the right
    cv2.circle(img, (610, 40), 30, SKIN_BGR, -1)
    top = SkinTracker().update(img)
    # the lamps are larger than the forearms and reach higher than the head: of the three
    # blobs reaching highest (head, lamps) the middle one from left to right, the nearer
    # lamp, is taken for the head
    np.testing.assert_allclose(top.blobs["head"].centre, (540, 60), atol=1.5)
    fg = np.full(img.shape[:2], 255, dtype=np.uint8)
    fg[:, 500:] = 0
    f = SkinTracker().update(img, foreground=fg)
    np.testing.assert_allclose(f.blobs["head"].centre, (320, 100), atol=1.5)
    with pytest.raises(ConfigError, match="foreground mask of shape"):
        SkinTracker().update(img, foreground=fg[:10])


def test_mask_blobs_equal_ellipse_of_each_component() -> None:
    """The one-pass moments of `mask_blobs` against `ellipse_of` on each component."""
    rng = np.random.default_rng(3)
    mask = (rng.random((120, 160)) < 0.35).astype(np.uint8)
    cv2.ellipse(mask, (80, 60), (40, 12), 25, 0, 360, 1, -1)
    blobs = mask_blobs(mask, min_area_px=4, close_px=0)
    n, labels = cv2.connectedComponents(mask, connectivity=8)
    want = []
    for i in range(1, n):
        ys, xs = np.nonzero(labels == i)
        if xs.size >= 4:
            want.append(ellipse_of(np.stack([xs, ys], axis=1)))
    assert len(blobs) == len(want) > 10
    by_centre = {tuple(np.round(b.centre, 6)): b for b in want}
    for b in blobs:
        w = by_centre[tuple(np.round(b.centre, 6))]
        assert b.area == w.area
        assert b.major == pytest.approx(w.major, abs=1e-9)
        assert b.minor == pytest.approx(w.minor, abs=1e-9)
        if w.major - w.minor > 1e-6:  # a round blob's axis is any direction
            np.testing.assert_allclose(b.ends, w.ends, atol=1e-9)
    assert [b.area for b in blobs] == sorted((b.area for b in blobs), reverse=True)


def test_arm_fractions_follow_the_visible_segment_lengths() -> None:
    from mocapkit.tracking.mono.skin_tracking import ARM_RATIOS, arm_fractions

    u, f, h = ARM_RATIOS["upper_arm"], ARM_RATIOS["forearm"], ARM_RATIOS["hand"]
    # the paper's costume: forearm and hand bare, the elbow is the proximal end
    assert arm_fractions("elbow") == pytest.approx((0.0, f / (f + h)))
    # short sleeves: the lower half of the upper arm is bare too (0.19 / 2, 0.13, 0.108)
    assert arm_fractions("mid_upper_arm") == pytest.approx(
        (0.5 * u / (0.5 * u + f + h), (0.5 * u + f) / (0.5 * u + f + h))
    )
    assert arm_fractions("mid_upper_arm") == pytest.approx((0.2853, 0.6757), abs=1e-4)
    assert arm_fractions("shoulder") == pytest.approx((u / (u + f + h), (u + f) / (u + f + h)))
    with pytest.raises(ConfigError, match="bare_from in"):
        arm_fractions("wrist")
    with pytest.raises(ConfigError, match="bare_from in"):
        SkinTracker(bare_from="sleeveless")


def _rod(img: np.ndarray, p0: np.ndarray, p1: np.ndarray, width: float) -> None:
    """A skin rectangle from p0 to p1 (its second moment along the axis is l^2 / 12)."""
    n = np.array([-(p1 - p0)[1], (p1 - p0)[0]]) / np.linalg.norm(p1 - p0) * width / 2
    quad = np.array([p0 + n, p1 + n, p1 - n, p0 - n]).round().astype(np.int32)
    cv2.fillPoly(img, [quad], SKIN_BGR)


def test_bare_from_places_elbow_and_wrist_on_the_arm_blob() -> None:
    """An arm bare from the middle of the upper arm to the fingertips, drawn straight as a
    rod: the elbow and wrist at the costume's fractions of its length, and the paper's
    rule (the ellipse's ends) beyond both ends of the drawn rod."""
    from mocapkit.tracking.mono.skin_tracking import arm_fractions

    img = np.full((480, 640, 3), (90, 110, 60), dtype=np.uint8)
    cv2.ellipse(img, (320, 100), (28, 38), 0, 0, 360, SKIN_BGR, -1)
    ends = {"left": (np.array([390.0, 170.0]), np.array([500.0, 330.0])),
            "right": (np.array([250.0, 170.0]), np.array([160.0, 340.0]))}  # fmt: skip
    for p0, p1 in ends.values():
        _rod(img, p0, p1, 18)
    fe, fw = arm_fractions("mid_upper_arm")
    f = SkinTracker(bare_from="mid_upper_arm").update(img)
    j = dict(zip(SKIN_JOINTS, f.joints_px))
    for side, (p0, p1) in ends.items():
        np.testing.assert_allclose(j[f"{side}_elbow"], p0 + fe * (p1 - p0), atol=2.0)
        np.testing.assert_allclose(j[f"{side}_wrist"], p0 + fw * (p1 - p0), atol=2.0)
    paper = dict(zip(SKIN_JOINTS, SkinTracker().update(img).joints_px))
    for side, (p0, p1) in ends.items():
        # the moment ellipse's ends lie 2 / sqrt(3) of the rod's half-length from its middle
        mid, half = (p0 + p1) / 2, (p1 - p0) / 2
        np.testing.assert_allclose(paper[f"{side}_elbow"], mid - half * 2 / np.sqrt(3), atol=2.5)
        np.testing.assert_allclose(paper[f"{side}_wrist"], mid + half * 2 / np.sqrt(3), atol=2.5)


def test_the_first_head_lies_between_the_forearms() -> None:
    """A hand raised beside the face, its centroid above the head's: the head is the
    middle one, left to right, of the three blobs reaching highest."""
    img = _figure(left=((430, 118), (440, 80)), belt=False)
    by_y = sorted(mask_blobs(_skin(img)), key=lambda b: b.centre[1])
    assert by_y[0].centre[0] > 400  # the raised hand's centroid is the topmost
    f = SkinTracker().update(img)
    np.testing.assert_allclose(f.blobs["head"].centre, (320, 100), atol=1.5)
    assert f.blobs["left_hand"].centre[0] > 400 and f.blobs["right_hand"].centre[0] < 250


def test_the_first_head_merged_with_a_forearm_is_the_blob_reaching_highest() -> None:
    """Lambada's first frame: the right forearm across the face (one blob with the head)
    and the left one raised, its centroid above the merged blob's; with two blobs the
    head is the one reaching highest, the raised forearm the left hand."""
    img = _figure(left=((430, 130), (440, 80)), right=((280, 130), (380, 150)), belt=False)
    blobs = mask_blobs(_skin(img))
    assert len(blobs) == 2
    merged = max(blobs, key=lambda b: b.area)
    raised = min(blobs, key=lambda b: b.area)
    assert raised.centre[1] < merged.centre[1]  # the topmost centroid is the forearm's
    f = SkinTracker().update(img)
    np.testing.assert_allclose(f.blobs["head"].centre, merged.centre)
    np.testing.assert_allclose(f.blobs["left_hand"].centre, raised.centre)


def test_with_the_belt_the_waist_is_labelled_among_fewer_blobs() -> None:
    """The right forearm merged with the belt (a hand hanging at the hip, as in the
    charleston1 and zombie clips' first frames under the paper's costume): three blobs.
    Without ``belt`` the waist needs four blobs and the merged one is taken for a hand;
    with it, the flat blob below the head is the waist."""
    img = _figure(right=((260, 250), (245, 330)))
    assert len(mask_blobs(_skin(img))) == 3
    plain = SkinTracker().update(img)
    assert "waist" not in plain.blobs and "right_hand" in plain.blobs
    belted = SkinTracker(belt=True).update(img)
    assert set(belted.blobs) == {"head", "left_hand", "waist"}


def test_reacquire_gives_a_lost_hand_the_blob_on_its_side() -> None:
    """A hand merged with the belt in the first frame, then lifted off it: only with
    ``reacquire`` does its label come back (on the image's left of the head: the
    subject's right, as in the first frame's rule)."""
    first = _figure(right=((260, 250), (245, 330)))
    later = _figure(right=((240, 200), (210, 290)))
    for reacquire, want in ((False, False), (True, True)):
        tr = SkinTracker(belt=True, reacquire=reacquire)
        tr.update(first)
        f = tr.update(later)
        assert ("right_hand" in f.blobs) is want
    j = dict(zip(SKIN_JOINTS, f.joints_px))
    np.testing.assert_allclose(j["right_wrist"], (210, 290), atol=4)
    np.testing.assert_allclose(j["pelvis"], (320, 330), atol=1.5)


def test_a_lost_belt_is_taken_up_again() -> None:
    tr = SkinTracker(belt=True)
    tr.update(_figure(belt=False))  # no belt in sight: no waist label
    f = tr.update(_figure())
    assert "waist" in f.blobs
    np.testing.assert_allclose(f.joints_px[SKIN_JOINTS.index("pelvis")], (320, 330), atol=1.5)
