"""Where the OpenPose path of the mono tracker loses against the keypoint path.

    python examples/mono_openpose_substitute.py WORK_DIR VARIANT [CLIP ...]

Sessions are rendered into WORK_DIR as ``mocapkit accuracy mono --work WORK_DIR`` does
(reused when there); default clips: the five of ``mocapkit accuracy mono`` and the four
held-out ones. Each clip is tracked with the shipped defaults from the OpenPose BODY_25
JSON that ``mocapkit accuracy mono --openpose`` writes (the true 2-D keypoints plus 2 px
noise, seed 0, with a bystander), read and followed by `mocapkit.io.openpose`, with one
piece replaced at a time. VARIANT, pieces joined by ``+``:

- ``keypoints``: the keypoint path itself (no JSON; ``mocapkit accuracy mono``);
- ``op``: the OpenPose path as shipped;
- ``fixed`` / ``oracle``: the neck and pelvis at the fixed fractions 0.81 / 0.25, or at the
  median fractions of the true 2-D neck and pelvis along the hip-to-shoulder line of
  that clip, instead of the take's estimate (`mocapkit.io.openpose.trunk_fractions`);
- a joint of the stick (``neck``, ``pelvis``, ``head``, ...): that joint taken from the
  keypoint path's input (the noisy truth);
- ``online``: the neck and pelvis at the truth's own fraction in every frame, on the line
  (the spine's bending kept, the offset across the line dropped);
- ``across``: the rebuilt neck and pelvis moved by the truth's offset across the line;
- ``noise``: 2 px of independent noise added to the rebuilt neck and pelvis (seed 5).

One line per clip (Procrustes upper-body mm, flips right, estimated over true link
lengths, flips right per link), then the mean of the five and of the held-out clips.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np

from mocapkit.eval.metrics import evaluate_result
from mocapkit.io.openpose import read_openpose_folder
from mocapkit.pipelines.demo import find_shared_data
from mocapkit.pipelines.mono import detector_config, stick_pixels, track_mono
from mocapkit.pipelines.mono_accuracy import (
    MONO_CLIPS,
    flip_accuracy,
    mono_session,
    noisy_keypoints,
    truth_in_camera,
    write_openpose_with_bystander,
)
from mocapkit.skeleton.model import UPPER_BODY_JOINTS
from mocapkit.tracking.mono.stick import stick_model
from mocapkit.tracking.mono.tracker import MonoConfig

HELD_OUT = ("01_12.amc", "11_01.amc", "131_01.bvh", "131_03.bvh")
FLAGS = ("op", "fixed", "oracle", "online", "across", "noise")


def _line(px: np.ndarray, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Hip midpoint (T, 2) and hip-to-shoulder midpoint vector (T, 2)."""
    j = names.index
    m_h = 0.5 * (px[:, j("left_hip")] + px[:, j("right_hip")])
    m_s = 0.5 * (px[:, j("left_shoulder")] + px[:, j("right_shoulder")])
    return m_h, m_s - m_h


def clip_input(base: Path, variant: str) -> tuple:
    """The stick's 2-D input (T, K, 2) of one clip under ``variant``."""
    model = stick_model(False)
    session = base / "session"
    s, cam, names, px = noisy_keypoints(session, model, 2.0, 0)
    kpx = px[:, [names.index(n) for n in model.joint_names]]
    parts = variant.split("+")
    if parts == ["keypoints"]:
        return s, cam, kpx
    folder = base / "openpose_json"
    write_openpose_with_bystander(folder, names, px, 0)
    fractions = None
    if "fixed" in parts:
        fractions = (0.81, 0.25)
    if "oracle" in parts:  # the truth's own place along the line, median over the clip
        true_px = s.keypoints[cam].pixels
        m_h, u = _line(true_px, list(names))
        uu = (u * u).sum(-1)
        fractions = tuple(
            float(np.nanmedian(((true_px[:, names.index(j)] - m_h) * u).sum(-1) / uu))
            for j in ("neck", "pelvis")
        )
    kp = read_openpose_folder(folder, s.keypoints[cam].time_s, fractions=fractions)
    use = stick_pixels(kp, model).copy()
    trunk = [model.joint_names.index("neck"), model.joint_names.index("pelvis")]
    if "online" in parts or "across" in parts:
        m_h, u = _line(px, list(names))  # the noisy truth's hips and shoulders
        uu = (u * u).sum(-1, keepdims=True)
        for k in trunk:
            d = kpx[:, k] - m_h
            along = (d * u).sum(-1, keepdims=True) / uu * u
            use[:, k] = m_h + along if "online" in parts else use[:, k] + (d - along)
    if "noise" in parts:
        rng = np.random.default_rng(5)
        use[:, trunk] += rng.normal(scale=2.0, size=use[:, trunk].shape)
    for joint in (p for p in parts if p not in FLAGS):
        k = model.joint_names.index(joint)
        use[:, k] = kpx[:, k]
    return s, cam, use


def main(work: str, variant: str, *clips: str) -> None:
    data = find_shared_data()
    if data is None:
        raise SystemExit("../shared/data/mocap not found")
    chosen = clips or (*MONO_CLIPS, *HELD_OUT)
    for clip in chosen:
        mono_session(data / "mocap", work, clip)  # rendered unless already there
    model = stick_model(False)
    rows = []
    for clip in chosen:
        base = Path(work) / Path(clip).stem
        s, cam, use = clip_input(base, variant)
        out = base / ("substitute_" + variant.replace("+", "_"))
        shutil.rmtree(out, ignore_errors=True)
        # a rebuilt neck tracks as `track_mono` tracks an OpenPose folder
        rebuilt = variant != "keypoints" and "neck" not in variant.split("+")
        cfg = detector_config(MonoConfig()) if rebuilt else MonoConfig()
        run = track_mono(base / "session", out, camera=cam, config=cfg, pixels=use)
        rep = evaluate_result(out, base / "session", joints=UPPER_BODY_JOINTS)
        flips, per_link = flip_accuracy(run, truth_in_camera(s, cam, model))
        ratio = run.lengths / np.array([s.bone_lengths_mm[x] for x in model.segments])
        rows.append((clip, rep.pa_mpjpe_mm, flips))
        print(
            f"{variant:20s} {Path(clip).stem:12s} PA {rep.pa_mpjpe_mm:6.1f} flips "
            f"{100 * flips:5.1f} %  length/true "
            + " ".join(f"{x:.2f}" for x in ratio)
            + "  flips per link "
            + " ".join(f"{100 * x:.0f}" for x in per_link),
            flush=True,
        )
    for name, group in (("five", MONO_CLIPS), ("held-out", HELD_OUT)):
        sel = [r for r in rows if r[0] in group]
        if sel:
            print(
                f"{variant:20s} {name}: PA {np.mean([r[1] for r in sel]):.1f} mm, flips "
                f"{100 * np.mean([r[2] for r in sel]):.1f} %, per clip "
                + " / ".join(f"{r[1]:.1f}" for r in sel)
            )


if __name__ == "__main__":
    main(*sys.argv[1:])
