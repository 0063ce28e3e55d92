"""The backend registry and its error messages."""

from __future__ import annotations

import pytest

from mocapkit.detect.backend import backend_names, crop_box, make_detector
from mocapkit.errors import ShapeError, UnknownNameError


def test_unknown_detector_lists_the_valid_names() -> None:
    with pytest.raises(UnknownNameError, match=r"openpose.*mediapipe, rtmpose"):
        make_detector("openpose")
    assert backend_names()[0] == "mediapipe"


def test_crop_box_is_square_and_clipped() -> None:
    assert crop_box((100, 100, 140, 200), (480, 640, 3)) == (70, 100, 170, 200)
    assert crop_box((0, 0, 100, 100), (480, 640), scale=2.0) == (0, 0, 150, 150)
    with pytest.raises(ShapeError, match="outside the 640x480 image"):
        crop_box((700, 10, 800, 90), (480, 640, 3))
    with pytest.raises(ShapeError, match="x0 < x1"):
        crop_box((10, 10, 5, 20), (480, 640, 3))
