"""The camera checks on a known rig: each refuses its bad case with the numbers, and
passes the good one."""

from __future__ import annotations

import re

import numpy as np
import pytest

from mocapkit.camera.pinhole import Camera, intrinsics_from_fov, look_at
from mocapkit.camera.plausibility import (
    CameraFinding,
    intrinsic_findings,
    keypoint_findings,
    pose_findings,
    refuse_or_warn,
    sees_findings,
    view_findings,
    view_floor_findings,
    view_up_findings,
)
from mocapkit.errors import SessionError

NAMES = ("left_shoulder", "left_elbow", "left_wrist", "right_shoulder", "right_elbow")
REST = {
    "left_shoulder": np.array([-180.0, 0.0, 1400.0]),
    "left_elbow": np.array([-180.0, 0.0, 1100.0]),
    "left_wrist": np.array([-180.0, 0.0, 830.0]),
    "right_shoulder": np.array([180.0, 0.0, 1400.0]),
    "right_elbow": np.array([180.0, 0.0, 1100.0]),
}


def _camera(name: str, eye: tuple[float, float, float], k: np.ndarray | None = None) -> Camera:
    size = (640, 480)
    return Camera(
        name,
        size,
        intrinsics_from_fov(size, 60.0) if k is None else k,
        np.zeros(5),
        look_at(eye, (0.0, 0.0, 1100.0)),
    )


def _rig() -> list[Camera]:  # two cameras 40 deg apart, 3 m from the subject
    a = np.deg2rad(20.0)
    return [
        _camera("left", (-3000.0 * np.sin(a), -3000.0 * np.cos(a), 1300.0)),
        _camera("right", (3000.0 * np.sin(a), -3000.0 * np.cos(a), 1300.0)),
    ]


def _points(rng: np.random.Generator, n: int = 20) -> np.ndarray:
    """(n, K, 3): the rest joints swaying a little."""
    rest = np.stack([REST[k] for k in NAMES])
    return rest + rng.normal(0.0, 20.0, (n, 1, 3))


def test_good_rig_passes_every_check(rng):
    cams = _rig()
    pts = _points(rng)
    px = np.stack([c.project(pts) for c in cams])
    px += rng.normal(0.0, 1.0, px.shape)  # a detector's noise
    assert view_findings(cams, px, NAMES, REST) == []
    for i, c in enumerate(cams):
        assert intrinsic_findings(c) == []
        assert keypoint_findings(c, px[i]) == []
        assert sees_findings(c, pts, "joints") == []
        assert pose_findings(c) == []


def test_a_detectors_wild_points_pass(rng):
    """8 % of the keypoints 50-150 px off (limbs about 55 px long): the limbs' 90th
    percentile is not theirs (taken over all frames, it refused such keypoints most times)."""
    cams = _rig()
    pts = _points(rng, 60)
    px = np.stack([c.project(pts) for c in cams]) + rng.normal(0.0, 2.0, (2, 60, 5, 2))
    wild = rng.random(px.shape[:-1]) < 0.08
    ang = rng.uniform(0.0, 2.0 * np.pi, px.shape[:-1])
    r = rng.uniform(50.0, 150.0, px.shape[:-1])
    px[..., 0] += np.where(wild, r * np.cos(ang), 0.0)
    px[..., 1] += np.where(wild, r * np.sin(ang), 0.0)
    assert [f for f in view_findings(cams, px, NAMES, REST) if f.refuse] == []


@pytest.mark.parametrize("noise_px", [4.0, 8.0])
def test_a_narrow_pair_with_a_detectors_noise_passes(rng, noise_px):
    """90 mm apart at 3 m: a joint's depth from one frame is off by a quarter or more,
    the checks that use depth use the subject's median depth and still pass."""
    cams = [_camera(name, (x, -3000.0, 1300.0), None) for name, x in (("l", -45.0), ("r", 45.0))]
    cams = [  # parallel: both look along +y
        Camera(c.name, c.image_size, c.K, c.dist, look_at((x, -3000.0, 1300.0), (x, 0.0, 1100.0)))
        for c, x in zip(cams, (-45.0, 45.0))
    ]
    pts = _points(rng, 30)
    px = np.stack([c.project(pts) for c in cams]) + rng.normal(0.0, noise_px, (2, 30, 5, 2))
    assert [f for f in view_findings(cams, px, NAMES, REST) if f.refuse] == []


def test_views_that_disagree_are_refused_with_the_error(rng):
    cams = _rig()
    pts = _points(rng)
    px = np.stack([c.project(pts) for c in cams])
    px[1, ..., 1] += 80.0  # the right view's keypoints 80 px off its epipolar lines
    found = view_findings(cams, px, NAMES, REST)
    assert [f.check for f in found] == ["views agree", "views agree"]
    assert "reproject" in found[1].text and "expected at most 16 px" in found[1].text
    with pytest.raises(
        SessionError,
        match=r"camera 'right' \(views agree\): its keypoints "
        r"disagree with the other views: .* reproject [\d.]+ px \(median\)",
    ):
        refuse_or_warn(found, "S")


def test_limb_lengths_off_by_a_factor_are_refused(rng):
    cams = _rig()
    pts = _points(rng)
    px = np.stack([c.project(pts) for c in cams])
    half = {k: v * 2.0 for k, v in REST.items()}  # the subject twice as tall as the views say
    found = view_findings(cams, px, NAMES, half)
    assert [f.check for f in found] == ["limb lengths"]
    assert re.search(r"are 0\.(49|50)\d* times the subject's", found[0].text), found[0].text


def test_keypoints_outside_the_image_and_subject_behind(rng):
    cam = _rig()[0]
    pts = _points(rng)
    px = cam.project(pts) + np.array([2000.0, 0.0])
    (f,) = keypoint_findings(cam, px)
    assert f.check == "in image" and f"{px.size // 2} of {px.size // 2} keypoints" in f.text
    turned = Camera(cam.name, cam.image_size, cam.K, cam.dist,
                    np.diag([-1.0, 1.0, -1.0, 1.0]) @ cam.camera_from_world)  # fmt: skip
    (f,) = sees_findings(turned, pts, "joints")
    assert f.check == "in front" and "0 inside its 640x480 image" in f.text
    (w,) = pose_findings(turned)
    assert not w.refuse and "the world origin lies behind it" in w.text


def test_warnings_go_to_the_callback_and_refusals_raise():
    lines: list[str] = []
    refuse_or_warn([CameraFinding("c", "floor", "low", refuse=False)], "S", lines.append)
    assert lines == ["S: camera 'c' (floor): low"]
    with pytest.raises(
        SessionError,
        match=r"S: the cameras do not fit the data.*\n  camera "
        r"'c' \(intrinsics\): bad",
    ):
        refuse_or_warn([CameraFinding("c", "intrinsics", "bad")], "S", lines.append)


def _ankles(rng: np.random.Generator, n: int = 60) -> np.ndarray:
    """(n, 2, 3): two ankles 90 mm above the floor (z = 0), stepping a little."""
    feet = np.array([[-100.0, 0.0, 90.0], [100.0, 0.0, 90.0]])
    return feet + rng.normal(0.0, 30.0, (n, 2, 3)) * np.array([1.0, 1.0, 0.3])


def _world_moved(cams: list[Camera], up_mm: float = 0.0, turn_deg: float = 0.0) -> list[Camera]:
    """The calibration in another world: the points it triangulates turned ``turn_deg``
    about the x axis (a world whose z is not up), then ``up_mm`` higher."""
    a = np.deg2rad(turn_deg)
    new_from_world = np.eye(4)
    new_from_world[1:3, 1:3] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    new_from_world[2, 3] = up_mm
    world_from_new = np.linalg.inv(new_from_world)
    return [
        Camera(c.name, c.image_size, c.K, c.dist, c.camera_from_world @ world_from_new)
        for c in cams
    ]


def test_the_floor_from_triangulated_ankles(rng):
    """Ankles 90 mm above z = 0 seen by two views: no finding; the same pixels with the
    calibration's world 1 m lower or higher put them 1 m off the floor: warned, with
    the cameras named as a list and the height of each ankle triangulated at its own
    depth (not the subject's median depth)."""
    cams = _rig()
    ank = _ankles(rng)
    px = np.stack([c.project(ank) for c in cams]) + rng.normal(0.0, 1.0, (2, 60, 2, 2))
    assert view_floor_findings(cams, px) == []
    for up, z in ((1000.0, r"1\d\d\d"), (-1000.0, r"-9\d\d")):
        (f,) = view_floor_findings(_world_moved(cams, up_mm=up), px)
        assert f.camera == ("left", "right") and f.check == "floor" and not f.refuse
        assert re.match(
            rf"the subject's ankles, placed from cameras left, right, lie at z = {z} mm "
            r"\(median of 120, 5-95 % .* mm; each triangulated from the views that see it\); "
            r"expected within 3\d\d mm of z = 0",
            f.text,
        ), f.text
    lines: list[str] = []
    refuse_or_warn([f], "S", lines.append)
    assert lines[0].startswith("S: cameras 'left', 'right' (floor): the subject's ankles")


def test_a_narrow_pair_widens_the_floor_by_its_uncertainty(rng):
    """90 mm apart at 3 m: exact keypoints place the ankles within mm, a calibration 1 m
    off is warned; with 8 px of noise one triangulated ankle is hundreds of mm off and
    the median moves (the linear triangulation of nearly parallel rays is biased): the
    limit widens by that uncertainty, so the right calibration is not warned about."""
    cams = [
        Camera(c.name, c.image_size, c.K, c.dist, look_at((x, -3000.0, 1300.0), (x, 0.0, 1100.0)))
        for c, x in zip(_rig(), (-45.0, 45.0))
    ]
    ank = _ankles(rng, 120)
    exact = np.stack([c.project(ank) for c in cams])
    assert view_floor_findings(cams, exact) == []
    (f,) = view_floor_findings(_world_moved(cams, up_mm=1000.0), exact)
    assert "expected within 300 mm of z = 0, the floor." in f.text, f.text
    noisy = exact + rng.normal(0.0, 8.0, exact.shape)
    assert view_floor_findings(cams, noisy) == []
    (f,) = view_floor_findings(_world_moved(cams, up_mm=3000.0), noisy)
    limit = re.search(
        r"expected within (\d+) mm of z = 0, the floor \(300 mm plus 2 x (\d+) mm", f.text
    )
    assert limit is not None, f.text
    assert 300 < int(limit[2]) < 2000 and int(limit[1]) == 300 + 2 * int(limit[2])


def test_the_camera_names_of_a_finding():
    lines: list[str] = []
    findings = [
        CameraFinding(("a",), "floor", "one", refuse=False),
        CameraFinding(("a", "b", "c", "d"), "floor", "all", refuse=False),
    ]
    refuse_or_warn(findings, "S", lines.append)
    assert lines == ["S: camera 'a' (floor): one", "S: cameras 'a', 'b', 'c', 'd' (floor): all"]


def test_a_world_turned_is_warned_by_the_up_check(rng):
    """The neck 1360 mm above the ankles: upright in the world. The same pixels in a world
    turned upside down (a board lying face up: z down) or onto its side (y up) stand
    180 and 90 deg from +z; upside down the ankles stay near z = 0, so the floor check
    alone passes it. A narrow pair with 8 px of noise cannot tell: no finding."""
    names = ("neck", "left_ankle", "right_ankle")
    ank = _ankles(rng)
    neck = ank.mean(axis=1, keepdims=True) + np.array([0.0, 0.0, 1360.0])
    pts = np.concatenate([neck, ank], axis=1)
    cams = _rig()
    px = np.stack([c.project(pts) for c in cams]) + rng.normal(0.0, 1.0, (2, 60, 3, 2))
    assert view_up_findings(cams, px, names) == []
    for turn, tilt in ((180.0, r"1(79|80)"), (90.0, r"(89|90|91)")):
        (f,) = view_up_findings(_world_moved(cams, turn_deg=turn), px, names)
        assert f.camera == ("left", "right") and f.check == "up" and not f.refuse
        assert re.match(
            rf"the subject, triangulated from cameras left, right, stands {tilt} deg from the "
            r"world's \+z \(from the ankles to the neck, median of 60 frames\); expected "
            r"within 60 deg of it. A world whose z is not up",
            f.text,
        ), f.text
    assert view_floor_findings(_world_moved(cams, turn_deg=180.0), px[:, :, 1:]) == []
    narrow = [
        Camera(c.name, c.image_size, c.K, c.dist, look_at((x, -3000.0, 1300.0), (x, 0.0, 1100.0)))
        for c, x in zip(cams, (-45.0, 45.0))
    ]
    noisy = np.stack([c.project(pts) for c in narrow]) + rng.normal(0.0, 8.0, (2, 60, 3, 2))
    assert view_up_findings(_world_moved(narrow, turn_deg=180.0), noisy, names) == []
