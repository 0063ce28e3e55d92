"""What ``keypoints/detect.json`` says of a session's detections: the backend per camera."""

from __future__ import annotations

import json
from pathlib import Path

from mocapkit.detect.run import detected_backend, read_detect_summary


def test_detected_backend_reads_detect_json(tmp_path: Path) -> None:
    (tmp_path / "keypoints").mkdir()
    assert detected_backend(tmp_path, ["a", "b"]) is None
    path = tmp_path / "keypoints" / "detect.json"
    path.write_text(json.dumps({"a": {"backend": "mediapipe"}, "b": {"backend": "mediapipe"}}))
    assert detected_backend(tmp_path, ["a", "b"]) == "mediapipe"
    path.write_text(json.dumps({"a": {"backend": "mediapipe"}, "b": {"backend": "rtmpose"}}))
    assert detected_backend(tmp_path, ["a", "b"]) is None
    assert detected_backend(tmp_path, ["a", "c"]) is None
    path.write_text("{not json")
    assert detected_backend(tmp_path, ["a"]) is None


def test_summary_that_is_not_a_mapping_reads_as_empty(tmp_path: Path) -> None:
    (tmp_path / "keypoints").mkdir()
    (tmp_path / "keypoints" / "detect.json").write_text(json.dumps(["a", "b"]))
    assert read_detect_summary(tmp_path) == {}
    assert detected_backend(tmp_path, ["a"]) is None
