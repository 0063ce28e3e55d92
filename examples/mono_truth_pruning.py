"""How often the mono tracker's pruning removes the true pose, and which links carry wrong flips.

    python examples/mono_truth_pruning.py WORK_DIR [CLIP ...]

Sessions are rendered into WORK_DIR as ``mocapkit accuracy mono --work WORK_DIR`` does
(reused when there); default clips: the five of ``mocapkit accuracy mono`` and the four
held-out ones (01_12, 11_01, 131_01, 131_03). Each is tracked with the shipped defaults
from the true 2-D keypoints plus 2 px noise (seed 0). During the last pass every frame's
candidate set is recorded twice, with and without pruning (the tracker's own
observation, neck depth and estimated lengths), by wrapping the enumeration the tracker
calls. A candidate "matches the truth" when every link that leaves the image plane by
at least ``FLIP_MIN_SINE`` (the flip figure's threshold) has the truth's flip. Per clip,
one JSON line:

- ``pruned_pct``: frames where a matching candidate exists but pruning removed all of
  them; ``pruned_by``: for those frames, the constraints that the least-violating
  matching candidate breaks (frame counts);
- ``absent_pct``: frames where no candidate matches even unpruned (a link estimated
  shorter than its projection collapses to one configuration, errata M5, or the depth
  is off); ``absent_links``: in those frames, the counted links whose true flip no
  candidate has (frame counts);
- ``truth_breaks_pct``: the true pose with the true lengths, per constraint broken
  (share of frames);
- ``flips_by_link``: flips right per link (%) and the counted link-frames;
- ``length_ratio``: estimated over true link length.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

import mocapkit.tracking.mono.tracker as tracker_module
from mocapkit.pipelines.demo import find_shared_data
from mocapkit.pipelines.mono import session_lengths, track_mono
from mocapkit.pipelines.mono_accuracy import (
    FLIP_MIN_SINE,
    MONO_CLIPS,
    flip_accuracy,
    mono_session,
    noisy_keypoints,
    truth_in_camera,
)
from mocapkit.tracking.mono.flips import _fails
from mocapkit.tracking.mono.stick import (
    ANGLE,
    BACKWARD,
    CAPSULE,
    ELBOW_PLANE,
    HINGE_SIGN,
    stick_model,
)
from mocapkit.tracking.mono.tracker import MonoConfig

HELD_OUT = ("01_12.amc", "11_01.amc", "131_01.bvh", "131_03.bvh")
KIND = {ANGLE: "angle", BACKWARD: "backward", HINGE_SIGN: "hinge", CAPSULE: "capsule",
        ELBOW_PLANE: "elbow_plane"}  # fmt: skip

_record: dict[int, tuple] = {}
_current = {"frame": -1}
_process = tracker_module.MonoTracker._process
_enumerate = tracker_module.enumerate_poses


def _process_noting_frame(self, k):  # type: ignore[no-untyped-def]
    _current["frame"] = k
    return _process(self, k)


def _enumerate_both(model, lengths, obs, root, prune=True, **kw):  # type: ignore[no-untyped-def]
    """`enumerate_poses` as the tracker calls it, recording per frame the pruned and the
    unpruned candidates and the lengths (the last pass overwrites); `mono_path_costs.py`
    records through it too."""
    fp = _enumerate(model, lengths, obs, root, prune=prune, **kw)
    full = _enumerate(model, lengths, obs, root, prune=False, **kw)
    _record[_current["frame"]] = (fp, full, np.asarray(lengths))
    return fp


def check_names(model) -> list[str]:  # type: ignore[no-untyped-def]
    segs = model.segments
    return [
        f"{KIND[int(k)]}:{segs[lk[0]]}/{segs[lk[1]]}"
        for k, lk in zip(model.checks.kind, model.checks.links)
    ]


def clip_report(work: Path, clip: str) -> dict:
    cfg = MonoConfig()
    session = work / Path(clip).stem / "session"
    model = stick_model(cfg.legs, cfg.limits)
    s, cam, names, px = noisy_keypoints(session, model, 2.0, 0)
    _record.clear()
    run = track_mono(session, None, camera=cam, config=cfg,
                     pixels=px[:, [names.index(n) for n in model.joint_names]])  # fmt: skip
    true_cam = truth_in_camera(s, cam, model)
    flips, per_link = flip_accuracy(run, true_cam)
    true_len = session_lengths(s, model)
    vec = model.link_vectors(true_cam)
    counted = np.abs(vec[..., 2]) >= FLIP_MIN_SINE * np.linalg.norm(vec, axis=-1)
    names_c = check_names(model)
    n_checks = len(names_c)
    true_stick = model.arrays(true_len)
    breaks: dict[str, int] = {}
    for k in range(true_cam.shape[0]):
        pose = np.ascontiguousarray(true_cam[k])
        for c in range(n_checks):
            if _fails(pose, true_stick, model.checks, c):
                breaks[names_c[c]] = breaks.get(names_c[c], 0) + 1
    pruned = absent = frames = 0
    pruned_by: dict[str, int] = {}
    absent_links: dict[str, int] = {}
    bits = np.arange(model.n_links)
    for k, (fp, full, lengths) in _record.items():
        codes, all_codes, all_pos = fp.codes, full.codes, full.positions
        if k >= true_cam.shape[0]:
            continue
        frames += 1
        want = (vec[k, :, 2] > 0).astype(np.int64)

        def matching(cs: np.ndarray) -> np.ndarray:
            return (((cs[:, None] >> bits) & 1 == want) | ~counted[k]).all(axis=1)  # noqa: B023

        if matching(codes).any():
            continue
        m = matching(all_codes)
        if not m.any():
            absent += 1
            have = ((all_codes[:, None] >> bits) & 1 == want).any(axis=0)
            for li in np.flatnonzero(counted[k] & ~have):
                absent_links[model.segments[li]] = absent_links.get(model.segments[li], 0) + 1
            continue
        pruned += 1
        stick = model.arrays(lengths)
        broken = min(
            (
                [names_c[c] for c in range(n_checks)
                 if _fails(np.ascontiguousarray(all_pos[i]), stick, model.checks, c)]
                for i in np.flatnonzero(m)
            ),
            key=len,
        )  # fmt: skip
        for b in broken:
            pruned_by[b] = pruned_by.get(b, 0) + 1
    n_t = true_cam.shape[0]
    return {
        "clip": clip,
        "flips_pct": round(100 * flips, 1),
        "frames": frames,
        "pruned_pct": round(100 * pruned / max(frames, 1), 1),
        "pruned_by": pruned_by,
        "absent_pct": round(100 * absent / max(frames, 1), 1),
        "absent_links": absent_links,
        "truth_breaks_pct": {k: round(100 * v / n_t, 1) for k, v in breaks.items()},
        "flips_by_link": {
            s_: (round(100 * p), int(c))
            for s_, p, c in zip(model.segments, per_link, counted.sum(0))
        },
        "length_ratio": {
            s_: round(float(a / b), 3) for s_, a, b in zip(model.segments, run.lengths, true_len)
        },
    }


def main(work: str, *clips: str) -> None:
    data = find_shared_data()
    if data is None:
        raise SystemExit("../shared/data/mocap not found")
    chosen = clips or (*MONO_CLIPS, *HELD_OUT)
    for clip in chosen:
        mono_session(data / "mocap", work, clip)  # rendered unless already there
    tracker_module.MonoTracker._process = _process_noting_frame  # type: ignore[method-assign]
    tracker_module.enumerate_poses = _enumerate_both  # type: ignore[assignment]
    for clip in chosen:
        print(json.dumps(clip_report(Path(work), clip)), flush=True)


if __name__ == "__main__":
    main(*sys.argv[1:])
