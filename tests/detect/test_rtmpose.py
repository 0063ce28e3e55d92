"""The RTMPose/RTMO ONNX backend on models the test writes itself (known outputs)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.detect.backend import DetectorUnavailable, make_detector
from mocapkit.errors import FormatError
from mocapkit.io.openpose import BODY_25

onnx = pytest.importorskip("onnx", reason="onnx not installed (the test extra)")
pytest.importorskip("onnxruntime", reason="onnxruntime not installed (mocapkit[onnx])")
from onnx import TensorProto, helper, numpy_helper  # noqa: E402

from mocapkit.detect.rtmpose import BOX_PADDING, box_to_input, decode_simcc, to_body25  # noqa: E402


def _constant_model(path: Path, input_hw: tuple[int, int], outputs: dict[str, np.ndarray]) -> None:
    """An ONNX model with a (1, 3, H, W) input whose outputs are the given constants (plus
    0 x the input's mean, so that the graph reads its input)."""
    h, w = input_hw
    nodes = [
        helper.make_node("ReduceMean", ["image"], ["mean"], keepdims=0),
        helper.make_node("Mul", ["mean", "zero"], ["nothing"]),
    ]
    inits = [numpy_helper.from_array(np.array(0.0, dtype=np.float32), "zero")]
    outs = []
    for name, value in outputs.items():
        inits.append(numpy_helper.from_array(value.astype(np.float32), f"{name}_c"))
        nodes.append(helper.make_node("Add", [f"{name}_c", "nothing"], [name]))
        outs.append(helper.make_tensor_value_info(name, TensorProto.FLOAT, list(value.shape)))
    graph = helper.make_graph(
        nodes,
        "tiny",
        [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, h, w])],
        outs,
        inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    onnx.save(model, str(path))


def _simcc(points_in: np.ndarray, wh: tuple[int, int], ratio: int = 2) -> dict[str, np.ndarray]:
    """SimCC vectors peaking at the given input-pixel positions (K, 2), values 0.8 / 0.6."""
    k = points_in.shape[0]
    sx = np.zeros((1, k, wh[0] * ratio))
    sy = np.zeros((1, k, wh[1] * ratio))
    for i, (u, v) in enumerate(points_in):
        sx[0, i, round(u * ratio)] = 0.8
        sy[0, i, round(v * ratio)] = 0.6
    return {"simcc_x": sx, "simcc_y": sy}


def test_decode_simcc_takes_the_peaks_over_the_split_ratio() -> None:
    pts = np.array([[10.5, 20.0], [47.0, 0.0]])
    v = _simcc(pts, (48, 64))
    got = decode_simcc(v["simcc_x"][0], v["simcc_y"][0], (48, 64))
    np.testing.assert_allclose(got, [[10.5, 20.0, 0.6], [47.0, 0.0, 0.6]])


def test_box_to_input_keeps_the_aspect_ratio() -> None:
    m = box_to_input((100.0, 50.0, 140.0, 250.0), (48, 64))
    # the box's centre goes to the input's centre; the taller side fills the input
    np.testing.assert_allclose(m @ [120.0, 150.0, 1.0], [24.0, 32.0])
    np.testing.assert_allclose(m[0, 0], 64 / (BOX_PADDING * 200.0))


def test_rtmpose_model_round_trip(tmp_path: Path) -> None:
    wh = (48, 64)
    rng = np.random.default_rng(3)
    pts_in = np.column_stack([rng.integers(2, 46, 17), rng.integers(2, 62, 17)]).astype(float)
    path = tmp_path / "rtmpose.onnx"
    _constant_model(path, (64, 48), _simcc(pts_in, wh))
    det = make_detector("rtmpose", model_path=path)
    assert det.multi_person is False and det.roi_first is True
    img = np.zeros((480, 640, 3), dtype=np.uint8)
    roi = (200.0, 100.0, 300.0, 400.0)
    (person,) = det.detect(img, roi=roi)
    m = box_to_input(roi, wh)
    want = (pts_in - m[:, 2]) / m[0, 0]  # input pixels back to the image
    body = person.keypoints
    for i, name in enumerate(("Nose", "LEye", "REye", "LEar", "REar", "LShoulder")):
        np.testing.assert_allclose(body[BODY_25.index(name), :2], want[i], atol=1e-4)
    np.testing.assert_allclose(
        body[BODY_25.index("Neck"), :2], 0.5 * (want[5] + want[6]), atol=1e-4
    )
    assert body[BODY_25.index("Neck"), 2] == pytest.approx(0.6)
    assert body[BODY_25.index("LHeel"), 2] == 0.0  # COCO has no feet


def test_rtmo_model_keeps_scored_people_after_suppression(tmp_path: Path) -> None:
    kps = np.zeros((1, 3, 17, 3))
    kps[0, :, :, 2] = 0.9
    for n, (x, y) in enumerate([(10, 10), (11, 11), (40, 30)]):
        kps[0, n, :, 0], kps[0, n, :, 1] = x, y
    dets = np.array([[[0, 0, 20, 20, 0.9], [1, 1, 21, 21, 0.8], [30, 20, 50, 40, 0.7]]])
    path = tmp_path / "rtmo.onnx"
    _constant_model(path, (64, 64), {"dets": dets, "keypoints": kps})
    det = make_detector("rtmpose", model_path=path)
    assert det.multi_person
    people = det.detect(np.zeros((128, 256, 3), dtype=np.uint8))  # letterbox ratio 0.25
    xs = sorted(float(p.keypoints[BODY_25.index("Nose"), 0]) for p in people)
    assert xs == [40.0, 160.0]  # the overlapping second box suppressed; pixels / 0.25


def test_model_errors(tmp_path: Path) -> None:
    with pytest.raises(DetectorUnavailable, match="needs a model file: --model"):
        make_detector("rtmpose")
    with pytest.raises(DetectorUnavailable, match="model file not found"):
        make_detector("rtmpose", model_path=tmp_path / "none.onnx")
    (tmp_path / "bad.onnx").write_bytes(b"not a model")
    with pytest.raises(FormatError, match="not an ONNX model"):
        make_detector("rtmpose", model_path=tmp_path / "bad.onnx")
    path = tmp_path / "three.onnx"
    _constant_model(path, (8, 8), {"a": np.zeros((1, 2)), "b": np.zeros((1, 2)), "c": np.zeros(1)})
    with pytest.raises(FormatError, match="expected RTMPose's SimCC pair"):
        make_detector("rtmpose", model_path=path)


def test_halpe26_keeps_its_own_neck_and_feet() -> None:
    p = np.zeros((26, 3))
    p[:, 0] = np.arange(26)
    p[:, 2] = 0.5
    body = to_body25(p)
    assert body[BODY_25.index("Neck"), 0] == 18  # Halpe's own neck, not a midpoint
    assert body[BODY_25.index("RHeel"), 0] == 25
    with pytest.raises(FormatError, match="17 or 26 keypoints"):
        to_body25(np.zeros((133, 3)))


def test_top_down_model_runs_through_detect_video_on_the_followed_region(tmp_path: Path) -> None:
    import cv2

    from mocapkit.detect.run import detect_video, video_source

    wh = (48, 64)
    pts_in = np.column_stack([np.linspace(14, 34, 17), np.linspace(8, 56, 17)])
    path = tmp_path / "rtmpose.onnx"
    _constant_model(path, (64, 48), _simcc(pts_in, wh))
    folder = tmp_path / "cam"
    folder.mkdir()
    for t in range(4):
        cv2.imwrite(str(folder / f"{t:03d}.png"), np.zeros((240, 320, 3), dtype=np.uint8))
    det = make_detector("rtmpose", model_path=path)
    res = detect_video(video_source(folder), tmp_path / "json", det)
    assert res.found == 4 and res.backend == "rtmpose"
    assert res.roi_calls == 3  # the whole image first, then the followed person's box
    assert len(list((tmp_path / "json").glob("*_keypoints.json"))) == 4
