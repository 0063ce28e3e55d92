"""RTMPose (top-down) and RTMO (one-stage, several people) ONNX models on onnxruntime.

The models are the ones Pose2Sim and Sports2D run (through ``rtmlib``); mocapkit ships no
weights. Download an ONNX export from OpenMMLab's model zoo (docs/detect.md lists the
files) and give its path: ``mocapkit detect SOURCE --detector rtmpose --model FILE.onnx``.
The kind of model is read off its outputs:

- **RTMPose** (two outputs, SimCC ``(1, K, Lx)`` and ``(1, K, Ly)``): one person in a box.
  The box (the followed person's last box grown by ``BOX_PADDING``, or the whole image
  when there is none yet) is widened to the model's aspect ratio and warped onto the input
  (an affine crop, no rotation); each keypoint is where its x and y classification vectors
  peak, divided by the SimCC split ratio (the vectors' length over the input side) and
  mapped back through the crop; its confidence the lower of the two peaks.
- **RTMO** (outputs ``(1, N, 5)`` boxes with scores and ``(1, N, K, 3)`` keypoints): every
  person at once, on the image letterboxed onto the input (grey 114 padding, no
  normalisation), boxes of score at least ``RTMO_MIN_SCORE`` kept by non-maximum
  suppression (IoU ``RTMO_NMS_IOU``).

K = 17 (COCO) or 26 (Halpe26, "body with feet") keypoints map onto BODY_25 (`COCO_TO_BODY_25`,
`HALPE26_TO_BODY_25`); with COCO, "Neck" and "MidHip" are the midpoints of the shoulders
and of the hips, with the lower confidence, and the feet stay empty. RTMPose input: RGB,
normalised by the ImageNet mean and standard deviation (as the models were trained).
"""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from mocapkit.detect.backend import (
    N_BODY_25,
    DetectorUnavailable,
    FloatArray,
    ImageArray,
    PersonPose,
)
from mocapkit.errors import FormatError
from mocapkit.io.openpose import BODY_25

#: A person box is grown by this factor about its centre before the crop (RTMPose's own).
BOX_PADDING = 1.25
#: ImageNet statistics (RGB, 0-255) the RTMPose models are normalised with.
MEAN_RGB = np.array([123.675, 116.28, 103.53])
STD_RGB = np.array([58.395, 57.12, 57.375])
RTMO_MIN_SCORE = 0.5
RTMO_NMS_IOU = 0.45

_COCO = ("Nose", "LEye", "REye", "LEar", "REar", "LShoulder", "RShoulder", "LElbow", "RElbow",
         "LWrist", "RWrist", "LHip", "RHip", "LKnee", "RKnee", "LAnkle", "RAnkle")  # fmt: skip
_HALPE_EXTRA = ("Head", "Neck", "MidHip", "LBigToe", "RBigToe", "LSmallToe", "RSmallToe",
                "LHeel", "RHeel")  # fmt: skip
#: Model keypoint index -> BODY_25 index (-1: none in BODY_25).
COCO_TO_BODY_25: tuple[int, ...] = tuple(BODY_25.index(n) for n in _COCO)
HALPE26_TO_BODY_25: tuple[int, ...] = COCO_TO_BODY_25 + tuple(
    BODY_25.index(n) if n in BODY_25 else -1 for n in _HALPE_EXTRA
)


def available() -> bool:
    """Whether onnxruntime is importable here."""
    return importlib.util.find_spec("onnxruntime") is not None


def to_body25(points: FloatArray) -> FloatArray:
    """BODY_25 (..., 25, 3) from COCO-17 or Halpe-26 keypoints (..., K, 3) (x, y, score)."""
    p = np.asarray(points, dtype=float)
    k = p.shape[-2]
    table = {17: COCO_TO_BODY_25, 26: HALPE26_TO_BODY_25}.get(k)
    if table is None:
        raise FormatError(f"RTMPose/RTMO model: expected 17 or 26 keypoints, found {k}")
    out = np.zeros((*p.shape[:-2], N_BODY_25, 3))
    for i, j in enumerate(table):
        if j >= 0:
            out[..., j, :] = p[..., i, :]
    if k == 17:
        for mid, (a, b) in {"Neck": ("LShoulder", "RShoulder"),
                            "MidHip": ("LHip", "RHip")}.items():  # fmt: skip
            ia, ib = BODY_25.index(a), BODY_25.index(b)
            m = BODY_25.index(mid)
            out[..., m, :2] = 0.5 * (out[..., ia, :2] + out[..., ib, :2])
            out[..., m, 2] = np.minimum(out[..., ia, 2], out[..., ib, 2])
    return out


def box_to_input(box: tuple[float, float, float, float], input_wh: tuple[int, int]) -> FloatArray:
    """The 2x3 affine map from image pixels to the model input for one person box: the box
    grown by `BOX_PADDING`, widened to the input's aspect ratio, its centre on the input's
    centre."""
    x0, y0, x1, y1 = box
    w_in, h_in = input_wh
    cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    bw, bh = BOX_PADDING * (x1 - x0), BOX_PADDING * (y1 - y0)
    aspect = w_in / h_in
    if bw > bh * aspect:
        bh = bw / aspect
    else:
        bw = bh * aspect
    s = w_in / bw  # = h_in / bh
    return np.array([[s, 0.0, 0.5 * w_in - s * cx], [0.0, s, 0.5 * h_in - s * cy]])


def decode_simcc(simcc_x: FloatArray, simcc_y: FloatArray, input_wh: tuple[int, int]) -> FloatArray:
    """Keypoints (K, 3) in input pixels from SimCC vectors (K, Lx), (K, Ly): the peak of each
    vector over the split ratio (Lx / input width), confidence the lower peak value."""
    sx, sy = np.asarray(simcc_x, dtype=float), np.asarray(simcc_y, dtype=float)
    ratio = sx.shape[-1] / input_wh[0]
    ix, iy = sx.argmax(axis=-1), sy.argmax(axis=-1)
    conf = np.minimum(sx.max(axis=-1), sy.max(axis=-1))
    out = np.stack([ix / ratio, iy / ratio, np.clip(conf, 0.0, 1.0)], axis=-1)
    out[conf <= 0] = 0.0
    return out


class RTMPose:
    """RTMPose or RTMO from an ONNX file (`mocapkit.detect.backend.Detector`).

    Parameters
    ----------
    model_path : path-like
        The ``.onnx`` file (docs/detect.md says where to get one).
    threads : int
        onnxruntime's intra-op threads (0: its default).
    """

    name = "rtmpose"
    roi_first = True

    def __init__(self, model_path: str | os.PathLike[str] | None = None, threads: int = 0) -> None:
        if model_path is None:
            raise DetectorUnavailable(
                "detector 'rtmpose' needs a model file: --model FILE.onnx (an RTMPose or RTMO "
                "ONNX export; docs/detect.md says where to download one)"
            )
        path = Path(model_path)
        if not path.is_file():
            raise DetectorUnavailable(f"{path}: RTMPose/RTMO model file not found")
        import onnxruntime as ort

        opts = ort.SessionOptions()
        opts.intra_op_num_threads = threads
        try:
            self._session = ort.InferenceSession(str(path), opts,
                                                 providers=["CPUExecutionProvider"])  # fmt: skip
        except Exception as exc:  # onnxruntime raises its own exception types
            raise FormatError(f"{path}: not an ONNX model onnxruntime can load ({exc})") from None
        inp = self._session.get_inputs()[0]
        shape = inp.shape
        if len(shape) != 4 or not all(isinstance(v, int) for v in shape[2:]):
            raise FormatError(
                f"{path}: input {inp.name!r}: expected a fixed (1, 3, H, W) image input, "
                f"found {shape}"
            )
        self._input = inp.name
        self.input_wh = (int(shape[3]), int(shape[2]))
        outs = [o.shape for o in self._session.get_outputs()]
        if len(outs) == 2 and len(outs[0]) == 3 and len(outs[1]) == 3:
            self.kind = "rtmpose"
        elif len(outs) == 2 and len(outs[0]) == 3 and len(outs[1]) == 4:
            self.kind = "rtmo"
        else:
            raise FormatError(
                f"{path}: outputs {outs}: expected RTMPose's SimCC pair (1, K, Lx), (1, K, Ly) "
                "or RTMO's boxes (1, N, 5) and keypoints (1, N, K, 3)"
            )
        self.multi_person = self.kind == "rtmo"

    def _run(self, blob: FloatArray) -> list[Any]:
        out: list[Any] = self._session.run(None, {self._input: blob.astype(np.float32)})
        return out

    def detect(
        self, image: ImageArray, roi: tuple[float, float, float, float] | None = None
    ) -> list[PersonPose]:
        """The people in the image (RTMO) or the person in ``roi`` / the image (RTMPose)."""
        if self.kind == "rtmo":
            return self._detect_rtmo(image)
        h, w = image.shape[:2]
        box = roi if roi is not None else (0.0, 0.0, float(w), float(h))
        m = box_to_input(box, self.input_wh)
        crop = cv2.warpAffine(image, m, self.input_wh, flags=cv2.INTER_LINEAR)
        rgb = crop[:, :, ::-1].astype(float)
        blob = ((rgb - MEAN_RGB) / STD_RGB).transpose(2, 0, 1)[None]
        sx, sy = self._run(blob)
        kp = decode_simcc(sx[0], sy[0], self.input_wh)
        # back to the image: x = (u - t) / s
        s = m[0, 0]
        kp[:, 0] = np.where(kp[:, 2] > 0, (kp[:, 0] - m[0, 2]) / s, 0.0)
        kp[:, 1] = np.where(kp[:, 2] > 0, (kp[:, 1] - m[1, 2]) / s, 0.0)
        return [PersonPose(to_body25(kp))]

    def _detect_rtmo(self, image: ImageArray) -> list[PersonPose]:
        w_in, h_in = self.input_wh
        h, w = image.shape[:2]
        r = min(w_in / w, h_in / h)
        canvas = np.full((h_in, w_in, 3), 114, dtype=np.uint8)
        small = cv2.resize(image, (max(int(w * r), 1), max(int(h * r), 1)))
        canvas[: small.shape[0], : small.shape[1]] = small
        dets, kps = self._run(canvas.astype(float).transpose(2, 0, 1)[None])
        boxes, scores = dets[0, :, :4] / r, dets[0, :, 4]
        keep = scores >= RTMO_MIN_SCORE
        if not keep.any():
            return []
        idx = np.flatnonzero(keep)
        xywh = [[float(b[0]), float(b[1]), float(b[2] - b[0]), float(b[3] - b[1])]
                for b in boxes[idx]]  # fmt: skip
        chosen = cv2.dnn.NMSBoxes(xywh, [float(v) for v in scores[idx]], RTMO_MIN_SCORE,
                                  RTMO_NMS_IOU)  # fmt: skip
        out = []
        for i in np.asarray(chosen, dtype=int).reshape(-1):
            p = np.array(kps[0, idx[i]], dtype=float)
            p[:, :2] /= r
            p[:, 2] = np.clip(p[:, 2], 0.0, 1.0)
            out.append(PersonPose(to_body25(p)))
        return out

    def close(self) -> None:
        """Nothing to release (onnxruntime frees the session with the object)."""


__all__ = [
    "BOX_PADDING",
    "COCO_TO_BODY_25",
    "HALPE26_TO_BODY_25",
    "RTMPose",
    "available",
    "box_to_input",
    "decode_simcc",
    "to_body25",
]
