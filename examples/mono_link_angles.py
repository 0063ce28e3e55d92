"""Per-link out-of-plane angles of the mono tracker against the truth, per clip and frame.

    python examples/mono_link_angles.py WORK_DIR VARIANT CLIPS [FIELD=VALUE,...]

WORK_DIR and VARIANT as `examples/mono_openpose_substitute.py` (``op``: the OpenPose path
as shipped, ``keypoints``: the keypoint path, ...); CLIPS comma-separated stems
(``zombie,01_09``); the optional last argument overrides `MonoConfig` fields of the
variant's configuration (``rebuilt_in_plane_from=0.95,girdle_weight=150``; values are
Python literals, ``inf`` allowed). Sessions must already be rendered in WORK_DIR (run
`mocapkit accuracy mono --work WORK_DIR` or the substitution example once).

Per clip: PA upper-body mm and flips right (overall, per link), then per link the median
out-of-plane angle (deg, the link's component along its parent's viewing ray) of the
truth and of the estimate, the median and 90th-percentile difference, the share of
frames of the same sign, and D / L: the parent's distance to the child's ray over the
link's length (10th / 50th / 90th percentiles; above 1 the link looks longer than
itself), and the share of frames where the band's in-plane candidate was chosen. With
``--frames`` after the clips, the clavicles' D / L and angles every 20th frame.
"""

from __future__ import annotations

import ast
import math
import shutil
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from mono_openpose_substitute import clip_input

from mocapkit.eval.metrics import evaluate_result
from mocapkit.pipelines.mono import detector_config, track_mono
from mocapkit.pipelines.mono_accuracy import flip_accuracy, truth_in_camera
from mocapkit.skeleton.model import UPPER_BODY_JOINTS
from mocapkit.tracking.mono.stick import StickModel, stick_model
from mocapkit.tracking.mono.tracker import MonoConfig


def _overrides(text: str) -> dict[str, object]:
    out: dict[str, object] = {}
    for item in filter(None, text.split(",")):
        key, value = item.split("=")
        out[key] = math.inf if value == "inf" else ast.literal_eval(value)
    return out


def _angles(model: StickModel, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Out-of-plane angle (T, L) in degrees and the parent's distance to the child's
    viewing ray (T, L) in mm (what `mocapkit.tracking.mono.flips` compares with the
    length), for joints (T, K, 3) in the camera frame."""
    par, kid = pos[:, model.parent], pos[:, model.child]
    v = kid - par
    ray = par / np.linalg.norm(par, axis=-1, keepdims=True)
    along = (v * ray).sum(-1)
    norm = np.linalg.norm(v, axis=-1)
    kid_ray = kid / np.linalg.norm(kid, axis=-1, keepdims=True)
    dist = np.linalg.norm(np.cross(par, kid_ray), axis=-1)
    return np.degrees(np.arcsin(np.clip(along / norm, -1.0, 1.0))), dist


def main(work: str, variant: str, clips: str, *rest: str) -> None:
    frames = "--frames" in rest
    extra = _overrides(next((r for r in rest if r != "--frames"), ""))
    model = stick_model(False)
    for clip in clips.split(","):
        base = Path(work) / clip
        s, cam, use = clip_input(base, variant)
        out = base / ("angles_" + variant.replace("+", "_"))
        shutil.rmtree(out, ignore_errors=True)
        rebuilt = variant != "keypoints" and "neck" not in variant.split("+")
        cfg = replace(detector_config(MonoConfig()) if rebuilt else MonoConfig(), **extra)
        run = track_mono(base / "session", out, camera=cam, config=cfg, pixels=use)
        rep = evaluate_result(out, base / "session", joints=UPPER_BODY_JOINTS)
        tj = truth_in_camera(s, cam, model)
        flips, per_link = flip_accuracy(run, tj)
        est = np.stack([f.joints_in_camera for f in run.frames])
        codes = np.array([f.code for f in run.frames])
        a_t, _ = _angles(model, tj)
        a_e, d_e = _angles(model, est)
        ratio = d_e / run.lengths
        print(
            f"{clip} {variant} {extra} PA {rep.pa_mpjpe_mm:.1f} flips {100 * flips:.1f} % "
            "per link " + " ".join(f"{100 * x:.0f}" for x in per_link)
        )
        for li, name in enumerate(model.segments):
            ok = np.isfinite(a_t[:, li]) & np.isfinite(a_e[:, li])
            err = np.abs(a_t[ok, li] - a_e[ok, li])
            q = np.percentile(ratio[ok, li], [10, 50, 90])
            plane = np.mean((codes[ok] >= 0) & ((codes[ok] >> (model.n_links + li)) & 1 == 1))
            print(
                f"   {name:16s} |true| {np.median(np.abs(a_t[ok, li])):5.1f}  |est| "
                f"{np.median(np.abs(a_e[ok, li])):5.1f}  |diff| {np.median(err):5.1f} "
                f"(p90 {np.percentile(err, 90):5.1f})  same sign "
                f"{100 * np.mean(np.sign(a_t[ok, li]) == np.sign(a_e[ok, li])):3.0f} %  "
                f"D/L {q[0]:.3f} / {q[1]:.3f} / {q[2]:.3f}  in plane {100 * plane:3.0f} %"
            )
        if frames:
            for name in ("left_clavicle", "right_clavicle"):
                li = model.link_index(name)
                print(f"   {name}, frames 0, 20, 40, ...")
                print("     D/L   " + " ".join(f"{x:5.2f}" for x in ratio[::20, li]))
                print("     est   " + " ".join(f"{x:5.0f}" for x in a_e[::20, li]))
                print("     true  " + " ".join(f"{x:5.0f}" for x in a_t[::20, li]))


if __name__ == "__main__":
    main(*sys.argv[1:])
