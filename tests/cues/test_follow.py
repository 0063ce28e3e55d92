"""Person following: the chosen person kept by position and size, bystanders never taken."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.cues.follow import PersonFollower, points_box, seen_points
from mocapkit.errors import ShapeError


def _person(cx: float, cy: float, height: float, rng: np.random.Generator) -> np.ndarray:
    """25 points spread over a box of the given height (width = height/3), moved by up to
    2 % of the height at random."""
    pts = np.zeros((25, 2))
    pts[:, 0] = cx + height / 6 * np.sin(np.arange(25)) + 0.02 * height * rng.uniform(-1, 1)
    pts[:, 1] = cy + height / 2 * np.linspace(-1, 1, 25)
    return pts


def test_points_box_needs_two_confident_points() -> None:
    kp = np.zeros((25, 3))
    kp[0] = [10, 20, 0.9]
    assert points_box(seen_points(kp)) is None
    kp[1] = [30, 60, 0.9]
    kp[2] = [500, 500, 0.1]  # below the confidence floor
    assert points_box(seen_points(kp)) == (10.0, 20.0, 30.0, 60.0)
    with pytest.raises(ShapeError, match=r"seen_points: expected \(J, 3\) keypoints, found"):
        seen_points(kp[:, :2])
    with pytest.raises(ShapeError, match=r"points_box: expected \(J, 2\) points, found"):
        points_box(kp)


def test_a_bystander_far_off_is_never_taken(rng: np.random.Generator) -> None:
    follower = PersonFollower()
    assert follower.choose(0, [_person(100, 240, 200, rng)]) == 0
    # the subject leaves; a person elsewhere appears: nobody, not the bystander
    assert follower.choose(1, [_person(500, 240, 200, rng)]) is None
    assert follower.choose(2, [_person(108, 240, 200, rng)]) == 0
    # right place, but twice the size: someone else (nearer the camera)
    assert follower.choose(3, [_person(110, 240, 420, rng)]) is None
    # the subject leaves the image; long after, someone enters far away: not them
    assert follower.choose(60, [_person(600, 240, 200, rng)]) is None
    assert follower.choose(61, [_person(150, 240, 200, rng)]) == 0


def test_a_subject_down_to_one_point_is_followed_and_a_start_point_waits(
    rng: np.random.Generator,
) -> None:
    follower = PersonFollower(start_px=(300.0, 240.0))
    # nobody near the start point yet: nobody is taken
    assert follower.choose(0, [_person(600, 240, 200, rng)]) is None
    assert follower.choose(1, [_person(600, 240, 200, rng), _person(300, 240, 200, rng)]) == 1
    assert follower.last_box is not None and follower.first_frame == 1
    size = float(np.hypot(*np.subtract(follower.last_box[2:], follower.last_box[:2])))
    one = np.full((25, 2), np.nan)
    one[3] = follower.last_px[3] + [4.0, 0.0]  # type: ignore[index]
    # one point left, near where it was: still them (no spread to compare); the
    # bystander is not taken although it is seen whole
    assert follower.choose(2, [_person(600, 240, 200, rng), one]) == 1
    # the size is the whole body's, so the one point may move a quarter of it per frame
    far = one.copy()
    far[3] += [0.3 * size, 0.0]
    assert follower.choose(3, [far]) is None
    assert "nearest (300, 240) px on frame 1" in follower.describe()
