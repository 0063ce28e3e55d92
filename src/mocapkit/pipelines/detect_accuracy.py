"""A 2-D detector against the true keypoints of synthetic sessions (``accuracy detect``).

For every camera of every session, the detector's canonical keypoints
(`mocapkit.detect.run.detect_session`, read back as every tracker reads them) are compared
with the session's true ones (``keypoints/<camera>.csv`` of a rendered session):

- per joint, the median and 90th percentile of the image distance (px) over the frames
  where both are there;
- the share of frames where the view swaps left and right: the whole body (the sum of the
  left/right pairs' distances is smaller with every pair exchanged) and any one limb pair
  (elbows, wrists, knees or ankles, exchanged, nearer the truth by at least
  ``SWAP_MARGIN_PX``);
- the share of frames with no person (no detected shoulder or hip) among the frames where
  the subject is in view (both true shoulders and hips inside the image; a subject who
  walks out of the picture is not a miss).

The detector's neck and pelvis are rebuilt from its shoulders and hips
(`mocapkit.io.openpose`) and its head is the middle of the ears: the errors of those three
include the mapping's, not only the detector's.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mocapkit.detect.backend import Detector
from mocapkit.detect.run import detect_session
from mocapkit.io.session import load_session
from mocapkit.io.session_csv import read_keypoints_csv
from mocapkit.skeleton.model import CANONICAL_JOINTS

#: Left/right pairs whose exchange counts as a swap (canonical names without the side).
PAIRS: tuple[str, ...] = ("shoulder", "elbow", "wrist", "hip", "knee", "ankle")
LIMB_PAIRS: tuple[str, ...] = ("elbow", "wrist", "knee", "ankle")
#: A limb pair counts as swapped when the exchange is nearer the truth by this much (px).
SWAP_MARGIN_PX = 5.0


@dataclass
class DetectErrors:
    """Errors of one detector over a set of views (frames pooled)."""

    joint_names: tuple[str, ...]
    errors_px: list[np.ndarray]  # per joint, the distances of every frame with both
    frames: int = 0
    in_view: int = 0
    no_person: int = 0
    body_swaps: int = 0
    limb_swaps: int = 0

    def rows(self) -> list[dict[str, object]]:
        """Per joint: name, median and 90th percentile (px), frames compared."""
        return [
            {
                "joint": n,
                "median_px": float(np.median(e)) if e.size else float("nan"),
                "p90_px": float(np.percentile(e, 90)) if e.size else float("nan"),
                "frames": int(e.size),
            }
            for n, e in zip(self.joint_names, self.errors_px)
        ]

    def shares(self) -> dict[str, float]:
        """Shares of frames: no person (of the frames with the subject in view), body
        swapped, a limb pair swapped."""
        n = max(self.frames, 1)
        return {
            "no_person": self.no_person / max(self.in_view, 1),
            "body_swapped": self.body_swaps / n,
            "limb_pair_swapped": self.limb_swaps / n,
        }


def _side(pixels: np.ndarray, names: Sequence[str], side: str, part: str) -> np.ndarray:
    return pixels[:, list(names).index(f"{side}_{part}")]


def compare(
    det: np.ndarray,
    truth: np.ndarray,
    names: Sequence[str],
    acc: DetectErrors,
    image_size: tuple[int, int],
) -> None:
    """Add one view's frames (T, K, 2 each; NaN where missing) to ``acc``; ``image_size``
    (W, H) tells when the subject is in view."""
    for k, n in enumerate(acc.joint_names):
        j = list(names).index(n)
        d = np.linalg.norm(det[:, j] - truth[:, j], axis=-1)
        acc.errors_px[k] = np.concatenate([acc.errors_px[k], d[np.isfinite(d)]])
    acc.frames += det.shape[0]
    trunk = [list(names).index(f"{s}_{p}") for s in ("left", "right") for p in ("shoulder", "hip")]
    tt = truth[:, trunk]
    w, h = image_size
    with np.errstate(invalid="ignore"):
        inside = (tt[..., 0] >= 0) & (tt[..., 0] < w) & (tt[..., 1] >= 0) & (tt[..., 1] < h)
    in_view = np.all(inside, axis=1)
    acc.in_view += int(np.count_nonzero(in_view))
    nobody = ~np.isfinite(det[:, trunk]).any(axis=(1, 2))
    acc.no_person += int(np.count_nonzero(nobody & in_view))
    straight = np.zeros(det.shape[0])
    crossed = np.zeros(det.shape[0])
    limb = np.zeros(det.shape[0], dtype=bool)
    for part in PAIRS:
        dl, dr = _side(det, names, "left", part), _side(det, names, "right", part)
        tl, tr = _side(truth, names, "left", part), _side(truth, names, "right", part)
        s = np.linalg.norm(dl - tl, axis=-1) + np.linalg.norm(dr - tr, axis=-1)
        c = np.linalg.norm(dl - tr, axis=-1) + np.linalg.norm(dr - tl, axis=-1)
        ok = np.isfinite(s) & np.isfinite(c)
        straight += np.where(ok, s, 0.0)
        crossed += np.where(ok, c, 0.0)
        if part in LIMB_PAIRS:
            limb |= ok & (c + SWAP_MARGIN_PX < s)
    acc.body_swaps += int(np.count_nonzero(crossed < straight))
    acc.limb_swaps += int(np.count_nonzero(limb))


def detect_accuracy(
    sessions: Sequence[str | os.PathLike[str]],
    detector: Detector | str | None,
    work: str | os.PathLike[str],
    overwrite: bool = False,
) -> DetectErrors:
    """Run the detector on every camera of the (synthetic) sessions and pool its errors.

    The detections go to ``work/<session name>/`` (kept: a second call reuses them
    unless ``overwrite``); the sessions are not written to.
    """
    names = CANONICAL_JOINTS
    acc: DetectErrors | None = None
    for s in sessions:
        session = load_session(s)
        out = Path(work) / session.path.name
        detect_session(session.path, detector, out_dir=out, overwrite=overwrite)
        for cam in session.video_cameras:
            truth = session.keypoints[cam]
            det = read_keypoints_csv(out / "keypoints" / f"{cam}.csv")
            common = tuple(n for n in names if n in det.joint_names and n in truth.joint_names)
            if acc is None:
                acc = DetectErrors(common, [np.zeros(0) for _ in common])
            idx_d = [det.joint_names.index(n) for n in acc.joint_names]
            idx_t = [truth.joint_names.index(n) for n in acc.joint_names]
            compare(det.pixels[:, idx_d], truth.pixels[:, idx_t], acc.joint_names, acc,
                    session.camera(cam).image_size)  # fmt: skip
    if acc is None:
        raise ValueError("detect_accuracy: expected at least one session")
    return acc


def format_table(acc: DetectErrors, label: str) -> str:
    """A Markdown table of `DetectErrors.rows` and the shares."""
    lines = [f"| joint ({label}) | median px | p90 px | frames |", "|---|---:|---:|---:|"]
    for r in acc.rows():
        lines.append(f"| {r['joint']} | {r['median_px']:.1f} | {r['p90_px']:.1f} | {r['frames']} |")
    sh = acc.shares()
    lines.append("")
    lines.append(
        f"frames {acc.frames} ({acc.in_view} with the subject in view): no person "
        f"{100 * sh['no_person']:.1f} % of those in view, body swapped "
        f"left/right {100 * sh['body_swapped']:.1f} %, a limb pair swapped "
        f"{100 * sh['limb_pair_swapped']:.1f} %"
    )
    return "\n".join(lines)
