"""Why the mono tracker's path keeps a link's wrong flip: the cost terms along the paths.

    python examples/mono_path_costs.py WORK_DIR [CLIP [LINK [SETTINGS]]]
    python examples/mono_path_costs.py /tmp/mono_acc charleston1.amc left_upper_arm
    python examples/mono_path_costs.py /tmp/mono_acc charleston1.amc left_upper_arm \\
        '{"arm_prior_weight": 0, "limits": {"elbow_min_included_deg": 20,
          "shoulder_max_extension_deg": 60}}'

Sessions are rendered into WORK_DIR as ``mocapkit accuracy mono --work WORK_DIR`` does
(reused when there); the clip is tracked from its true 2-D keypoints plus 2 px noise
(seed 0) with `MonoConfig` defaults, or with SETTINGS (a JSON object of `MonoConfig`
fields, ``limits`` a JSON object of `LimitConfig` fields). Printed:

1. ``wrong``: the frames where LINK leaves the image plane by at least the flip figure's
   12 deg and the chosen pose has its flip wrong; for each, the candidate with the chosen
   flips but LINK's turned (the last pass's own lengths, depth and observation) is looked
   up in the unpruned set: ``pruned_by`` counts the constraints it breaks (``()`` when it
   survives), ``absent`` the frames without it.
2. The cost terms, summed over the clip, along four joint sequences: ``free`` (the
   chosen path), ``link_true`` (the same path with LINK's flip set to the truth's in the
   wrong frames, taken from the unpruned set), ``initial`` (the path of a second run
   given the true first pose, the paper's assumption 3; ``track_mono(initial_pose=...)``)
   and ``truth`` (the true joints): eq. 3 per link (rad/s^2, errata M1-M3), the clavicle
   prior and each arm's prior in the units of the decoder (times their weights, which
   are those of the settings' last pass), and the flips right per link.
3. ``perspective cue``: with the true joints (true lengths, true depth), LINK's child
   moved to the other point of its viewing ray at LINK's length from its parent (the
   mirror the enumeration makes) and, for each link hanging from that child, whether it
   can still reach its own child's ray: the frames where it cannot are the only ones
   where the image residual could tell the mirror from the truth, even with a perfect
   camera distance.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from mono_truth_pruning import _enumerate, _enumerate_both, _process_noting_frame, _record

import mocapkit.tracking.mono.tracker as tracker_module
from mocapkit.pipelines.demo import find_shared_data
from mocapkit.pipelines.mono import MonoRun, initial_pose_from, track_mono
from mocapkit.pipelines.mono_accuracy import (
    FLIP_MIN_SINE,
    flip_accuracy,
    mono_session,
    noisy_keypoints,
    truth_in_camera,
)
from mocapkit.tracking.mono.arm_prior import arm_features, default_arm_prior
from mocapkit.tracking.mono.flips import _fails
from mocapkit.tracking.mono.motion_cost import pair_omegas
from mocapkit.tracking.mono.priors import clavicle_forward_cost
from mocapkit.tracking.mono.stick import LimitConfig, StickModel, stick_model
from mocapkit.tracking.mono.tracker import MonoConfig


def config_from(settings: dict) -> MonoConfig:
    kw = dict(settings)
    lim = kw.pop("limits", None)
    if lim:
        lim = {k: tuple(v) if isinstance(v, list) else v for k, v in lim.items()}
        kw["limits"] = LimitConfig(**lim)
    return MonoConfig(**kw)


def cost_terms(model: StickModel, cfg: MonoConfig, pos: np.ndarray, dt: float) -> dict:
    """Sums over the clip of eq. 3 per link and the weighted priors of joints (T, K, 3)."""
    v = model.link_vectors(pos)
    w = np.stack([pair_omegas(v[k][None], v[k + 1][None], dt)[0, 0] for k in range(len(v) - 1)])
    alpha = np.linalg.norm(w[1:] - w[:-1], axis=-1) / dt  # (T - 2, L) rad/s^2
    arm = (cfg.arm_prior or default_arm_prior()).arm_cost(arm_features(model, pos))
    out = {f"eq3 {s}": float(alpha[:, i].sum()) for i, s in enumerate(model.segments)}
    out["eq3 total"] = float(alpha.sum())
    out["clavicle prior"] = float(cfg.clavicle_weight * clavicle_forward_cost(model, pos).sum())
    out["arm prior left"] = float(cfg.arm_prior_weight * arm[:, 0].sum())
    out["arm prior right"] = float(cfg.arm_prior_weight * arm[:, 1].sum())
    out["all terms"] = out["eq3 total"] + sum(
        out[k] for k in ("clavicle prior", "arm prior left", "arm prior right")
    )
    return out


def perspective_cue(
    model: StickModel, true_cam: np.ndarray, li: int, counted: np.ndarray, focal_px: float
) -> dict:
    """Frames (of the counted ones) where the mirror of link ``li`` leaves a link hanging
    from its child unable to reach its child's ray, and by how much (px at that depth)."""
    parent, child = true_cam[:, model.parent[li]], true_cam[:, model.child[li]]
    ray = child / np.linalg.norm(child, axis=1, keepdims=True)
    mirror = 2 * (parent * ray).sum(axis=1, keepdims=True) * ray - child  # ray-sphere
    out = {}
    for lj in np.flatnonzero(model.parent == model.child[li]):
        end = true_cam[:, model.child[lj]]
        length = np.linalg.norm(end - child, axis=1)
        c = end / np.linalg.norm(end, axis=1, keepdims=True)
        gap = np.linalg.norm(mirror - (mirror * c).sum(axis=1, keepdims=True) * c, axis=1) - length
        short = counted & (gap > 0)
        px = np.where(short, gap, 0.0) / np.linalg.norm(end, axis=1) * focal_px
        out[model.segments[lj]] = {"frames": int(short.sum()), "px_max": round(float(px.max()), 1)}
    return out


def main(work: str, clip: str = "charleston1.amc", link: str = "left_upper_arm",
         settings: str = "{}") -> None:  # fmt: skip
    data = find_shared_data()
    if data is None:
        raise SystemExit("../shared/data/mocap not found")
    session = mono_session(data / "mocap", work, clip)  # rendered unless already there
    cfg = config_from(json.loads(settings))
    model = stick_model(cfg.legs, cfg.limits)
    s, cam, names, px = noisy_keypoints(session, model, 2.0, 0)
    px = px[:, [names.index(n) for n in model.joint_names]]
    true_cam = truth_in_camera(s, cam, model)
    truth = s.truth
    assert truth is not None  # truth_in_camera has refused a session without one
    tracker_module.MonoTracker._process = _process_noting_frame  # type: ignore[method-assign]
    tracker_module.enumerate_poses = _enumerate_both  # type: ignore[assignment]
    run: MonoRun = track_mono(session, None, camera=cam, config=cfg, pixels=px)
    start = initial_pose_from(truth.joint_names, truth.joints_mm[0], model)
    tracker_module.enumerate_poses = _enumerate  # the initial-pose run needs no record
    initial: MonoRun = track_mono(session, None, camera=cam, config=cfg, pixels=px,
                                  initial_pose=start)  # fmt: skip
    li = model.link_index(link)
    vec = model.link_vectors(true_cam)
    counted = np.abs(vec[..., 2]) >= FLIP_MIN_SINE * np.linalg.norm(vec, axis=-1)
    want = vec[..., 2] > 0
    checks = [
        f"{int(k)}:{model.segments[a]}/{model.segments[b]}"
        for k, (a, b, *_) in zip(model.checks.kind, model.checks.links)
    ]
    free = np.stack([f.joints_in_camera for f in run.frames])
    link_true = free.copy()
    pruned_by: dict[str, int] = {}
    wrong = absent = 0
    for k, f in enumerate(run.frames):
        if not counted[k, li] or bool((f.code >> li) & 1) == want[k, li]:
            continue
        wrong += 1
        _, full, lengths = _record[k]
        hit = np.flatnonzero(full.codes == (f.code ^ (1 << li)))
        if not hit.size:
            absent += 1
            continue
        pos = np.ascontiguousarray(full.positions[hit[0]])
        link_true[k] = pos
        stick = model.arrays(lengths)
        broken = str(tuple(c for i, c in enumerate(checks)
                           if _fails(pos, stick, model.checks, i)))  # fmt: skip
        pruned_by[broken] = pruned_by.get(broken, 0) + 1
    print(json.dumps({"clip": clip, "link": link, "settings": json.loads(settings),
                      "counted": int(counted[:, li].sum()), "wrong": wrong, "absent": absent,
                      "pruned_by (kind 0 angle, 1 backward, 3 capsule, 4 elbow plane)":
                      pruned_by}))  # fmt: skip
    print(json.dumps({"perspective cue (true depth and lengths)":
                      perspective_cue(model, true_cam, li, counted[:, li],
                                      float(s.camera(cam).K[0, 0]))}))  # fmt: skip
    dt = float(np.median(np.diff([f.time_s for f in run.frames])))
    paths = {
        "free": free,
        "link_true": link_true,
        "initial": np.stack([f.joints_in_camera for f in initial.frames]),
        "truth": true_cam,
    }
    terms = {name: cost_terms(model, cfg, p, dt) for name, p in paths.items()}
    print(f"{'term':24s}" + "".join(f"{n:>11s}" for n in paths))
    for t in terms["free"]:
        print(f"{t:24s}" + "".join(f"{terms[n][t]:11.0f}" for n in paths))
    for name, r in (("free", run), ("initial", initial)):
        total, per_link = flip_accuracy(r, true_cam)
        links = " ".join(f"{s} {100 * p:.0f}" for s, p in zip(model.segments, per_link))
        print(f"flips right, {name}: {100 * total:.1f} %; per link {links}")


if __name__ == "__main__":
    main(*sys.argv[1:5])
