"""The mono tracker's sensitivity to systematic 2-D offsets of the head and shoulders.

    python examples/mono_offsets.py WORK_DIR VARIANTS [--seed S] [--detail] [--clips CLIP ...]

Sessions are rendered into WORK_DIR as ``mocapkit accuracy mono --work WORK_DIR`` does
(reused when there); default clips: the five of ``mocapkit accuracy mono``. Each clip is
tracked with the shipped defaults from the keypoints that ``mocapkit accuracy mono``
feeds the tracker (the true 2-D keypoints plus 2 px noise; noise seed ``--seed``, 0 by
default, the sessions always seed 0) with one offset added to every frame, in image y
(down positive). VARIANTS, joined by commas:

- ``base``: no offset (reproduces ``mocapkit accuracy mono``);
- ``headN``: the head point moved N px down (``head6``; ``head-6`` up), as the skin
  tracker's head (the hair covers the top of the face) or a detector's rebuilt one;
- ``shN``: both shoulders moved N px down (``sh-6``: up, as the skin tracker's, which
  stand at the neck's level).

One line per clip (Procrustes upper-body mm, flips right, pruned per frame, frames with
every pose pruned; with ``--detail`` also the link lengths over the truth's, flips right
per link and the median out-of-plane sine of the chosen and the true links), then the
mean. docs/mono.md, ninth round.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from mocapkit.eval.metrics import evaluate_result
from mocapkit.pipelines.demo import find_shared_data
from mocapkit.pipelines.mono import track_mono
from mocapkit.pipelines.mono_accuracy import (
    MONO_CLIPS,
    flip_accuracy,
    mono_session,
    noisy_keypoints,
    truth_in_camera,
)
from mocapkit.skeleton.model import UPPER_BODY_JOINTS
from mocapkit.tracking.mono.stick import stick_model
from mocapkit.tracking.mono.tracker import MonoConfig


def offset(pixels: np.ndarray, joints: list[str], variant: str) -> np.ndarray:
    """The stick's pixels (T, K, 2) with the variant's offset in image y (px)."""
    px = pixels.copy()
    if variant == "base":
        return px
    for prefix, moved in (("head", ("head",)), ("sh", ("left_shoulder", "right_shoulder"))):
        if variant.startswith(prefix):
            for j in moved:
                px[:, joints.index(j), 1] += float(variant[len(prefix) :])
            return px
    raise SystemExit(f"unknown variant {variant!r}: base, headN or shN")


def main(work: str, variants: str, *args: str) -> None:
    data = find_shared_data()
    if data is None:
        raise SystemExit("../shared/data/mocap not found")
    rest = list(args)
    detail = "--detail" in rest
    seed = int(rest[rest.index("--seed") + 1]) if "--seed" in rest else 0
    clips = rest[rest.index("--clips") + 1 :] if "--clips" in rest else list(MONO_CLIPS)
    cfg = MonoConfig()
    model = stick_model(cfg.legs, cfg.limits)
    joints = list(model.joint_names)
    out_root = Path(tempfile.mkdtemp(prefix="mono_offsets_"))
    for variant in variants.split(","):
        pa, right = [], []
        for clip in clips:
            session = mono_session(data / "mocap", work, clip)
            s, cam, names, px = noisy_keypoints(session, model, 2.0, seed)
            p = offset(px[:, [names.index(n) for n in joints]], joints, variant)
            out = out_root / f"{variant}_{Path(clip).stem}"
            run = track_mono(session, out, camera=cam, config=cfg, pixels=p)
            rep = evaluate_result(out, session, joints=UPPER_BODY_JOINTS)
            tc = truth_in_camera(s, cam, model)
            flips, per_link = flip_accuracy(run, tc)
            summ = run.summary()
            pa.append(rep.pa_mpjpe_mm)
            right.append(flips)
            line = (
                f"{variant:8s} {Path(clip).stem:12s} PA {rep.pa_mpjpe_mm:6.1f} flips "
                f"{100 * flips:5.1f} pruned {100 * summ['pruned_share_mean']:4.1f} "
                f"allpr {int(summ['all_pruned_frames'])}"
            )
            if detail:
                true_vec = model.link_vectors(tc)
                true_len = np.nanmedian(np.linalg.norm(true_vec, axis=-1), axis=0)
                est_vec = model.link_vectors(np.stack([f.joints_in_camera for f in run.frames]))
                sine = [
                    np.nanmedian(np.abs(v[..., 2]) / np.linalg.norm(v, axis=-1), axis=0)
                    for v in (est_vec, true_vec)
                ]
                line += " | lengths/truth " + " ".join(f"{r:.2f}" for r in run.lengths / true_len)
                line += " | flips/link " + " ".join(f"{100 * f:3.0f}" for f in per_link)
                line += " | sine chosen/true " + " ".join(f"{a:.2f}/{b:.2f}" for a, b in zip(*sine))
            print(line, flush=True)
        print(
            f"== {variant:8s} mean PA {np.mean(pa):6.1f} flips {100 * np.mean(right):5.1f}"
            "  per clip " + " / ".join(f"{a:.1f}" for a in pa),
            flush=True,
        )
    shutil.rmtree(out_root, ignore_errors=True)


if __name__ == "__main__":
    if len(sys.argv) < 3:
        raise SystemExit(__doc__)
    main(*sys.argv[1:])
