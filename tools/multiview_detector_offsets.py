"""Learn the multi-view fit's detector offsets (writes
``src/mocapkit/tracking/multiview/detector_offsets_table.py``).

For each tuning clip (the project's split: the report clips stay unseen) rendered by
``bench/multiview_peers.py`` with a real detector's keypoints (``<work>/<rig>/<clip>/mp``),
the session is fitted (`track_multiview_session`, shipped settings) and, for every
detected canonical joint, the fitted joint minus the true joint is taken into the frame in
which the fit places its offset (`offset_points`: the segment ending at the joint); the
offset is the mean over all frames and clips, the left and the mirrored right side's
averaged. Each joint's offset is then shrunk towards zero by how well it carries from
clip to clip (`held_out_shrinkage`: leaving each clip out in turn, the factor on the
other clips' mean that best predicts that clip's own, from the fits without offsets).
The fit is run again with the offsets so far and the remaining mean added
(``--rounds``), since offsets move the fit (and the segment lengths, `offset_segments`),
which moves the frames they are measured in.

Usage::

    .venv/bin/python tools/multiview_detector_offsets.py --work /tmp/mvbench --rigs ring
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from mocapkit.io.session import load_session
from mocapkit.pipelines.multiview import track_multiview_session
from mocapkit.skeleton.kinematics import forward_kinematics
from mocapkit.tracking.multiview.detector_offsets import offset_points

ROOT = Path(__file__).resolve().parents[1]
TUNING = ("13_26", "01_09", "lambada", "charleston1", "zombie")
OUT = ROOT / "src" / "mocapkit" / "tracking" / "multiview" / "detector_offsets_table.py"


#: A body-frame vector of one side seen from the other (x is the subject's right).
MIRROR = np.array([-1.0, 1.0, 1.0])


def mirror_name(name: str) -> str:
    """``left_X`` <-> ``right_X``; other names unchanged."""
    for a, b in (("left_", "right_"), ("right_", "left_")):
        if name.startswith(a):
            return b + name[len(a) :]
    return name


def clip_offsets(
    session_dir: Path, offsets: dict[str, tuple[float, float, float]]
) -> tuple[dict[str, list[np.ndarray]], float]:
    """Per joint, the (T, 3) local offsets of the fit with ``offsets`` against the truth,
    and the fit's MPJPE (mm) over those joints."""
    run = track_multiview_session(session_dir, point_offsets_mm=offsets)
    m = run.motion
    truth = load_session(session_dir).truth
    world = forward_kinematics(m.skeleton, m.q)  # (T, J, 4, 4)
    rebuilt = {"neck", "pelvis"}
    out: dict[str, list[np.ndarray]] = {}
    errs = []
    names = [n for n in m.joint_names if n not in rebuilt and n in truth.joint_names]
    frames, _ = offset_points(m.skeleton, names, {n: (0.0, 0.0, 0.0) for n in names})
    for name, j in zip(names, frames, strict=True):
        ti = list(truth.joint_names).index(name)
        true = np.stack(
            [np.interp(m.time_s, truth.time_s, truth.joints_mm[:, ti, a]) for a in range(3)], -1
        )
        fit = m.joints_mm[:, list(m.joint_names).index(name)]
        d = fit - true
        ok = np.all(np.isfinite(d), axis=1)
        rot = world[ok, j, :3, :3]
        local = np.einsum("tba,tb->ta", rot, d[ok])  # R^T d
        out[name] = [local]
        errs.append(np.linalg.norm(d[ok], axis=1).mean())
    return out, float(np.mean(errs))


def held_out_shrinkage(per_clip: list[dict[str, np.ndarray]]) -> dict[str, float]:
    """Per joint, the factor ``s`` in [0, 1] on the mean offset of the other clips that
    best predicts each clip's own mean offset, left out in turn (least squares over the
    clips: ``sum(b . m) / sum(m . m)``, ``b`` the clip's offset, ``m`` the others' mean;
    left and mirrored right pooled): 1 for an offset every clip shares, 0 for one that
    changes from clip to clip as much as it is large."""

    def side_mean(means: dict[str, np.ndarray], k: str) -> np.ndarray:
        other = mirror_name(k)
        return 0.5 * (means[k] + means[other] * MIRROR) if other in means else means[k]

    out = {}
    for k in per_clip[0]:
        num = den = 0.0
        for i, own in enumerate(per_clip):
            rest = np.mean([side_mean(m, k) for j, m in enumerate(per_clip) if j != i], axis=0)
            num += float(side_mean(own, k) @ rest)
            den += float(rest @ rest)
        out[k] = float(np.clip(num / den, 0.0, 1.0)) if den > 0 else 0.0
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", default="/tmp/mvbench")
    ap.add_argument("--rigs", default="ring")
    ap.add_argument("--backend", default="mediapipe")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--dry-run", action="store_true", help="print, do not write the table")
    args = ap.parse_args()
    sessions = [
        Path(args.work) / rig / clip / "mp"
        for rig in args.rigs.split(",")
        for clip in TUNING
        if (Path(args.work) / rig / clip / "mp" / "keypoints").is_dir()
    ]
    offsets: dict[str, tuple[float, float, float]] = {}
    shrink: dict[str, float] | None = None
    for r in range(args.rounds + 1):
        pooled: dict[str, list[np.ndarray]] = {}
        per_clip: list[dict[str, np.ndarray]] = []
        line = []
        for s in sessions:
            per, mpjpe = clip_offsets(s, offsets)
            line.append(f"{s.parent.parent.name}/{s.parent.name} {mpjpe:.1f}")
            per_clip.append({k: np.concatenate(v).mean(axis=0) for k, v in per.items()})
            for k, v in per.items():
                pooled.setdefault(k, []).extend(v)
        print(f"round {r}: " + ", ".join(line), flush=True)
        if r == args.rounds:
            break
        if shrink is None:
            shrink = held_out_shrinkage(per_clip)
            for k, f in sorted(shrink.items()):
                print(f"  {k:16} held-out shrinkage {f:4.2f}")
        means = {k: np.concatenate(v).mean(axis=0) for k, v in pooled.items()}
        for k in pooled:
            mean = means[k]
            other = mirror_name(k)
            if other in means:  # one body: left and mirrored right share their mean
                mean = 0.5 * (mean + means[other] * MIRROR)
            prev = np.array(offsets.get(k, (0.0, 0.0, 0.0)))
            offsets[k] = tuple(float(x) for x in prev + mean)  # type: ignore[assignment]
    assert shrink is not None
    # the learned offsets (those that remove each joint's mean over the tuning clips),
    # shrunk by how well they carry from clip to clip; joints shrunk to nothing left out
    offsets = {
        k: tuple(float(x) * shrink[k] for x in v)  # type: ignore[misc]
        for k, v in offsets.items()
        if shrink[k] > 0.0
    }
    for k, v in sorted(offsets.items()):
        print(f"  {k:16} " + " ".join(f"{x:7.1f}" for x in v))
    if args.dry_run:
        return 0
    clips = ", ".join(f"{s.parent.parent.name}/{s.parent.name}" for s in sessions)
    body = "\n".join(
        f'        "{k}": ({v[0]:.1f}, {v[1]:.1f}, {v[2]:.1f}),' for k, v in sorted(offsets.items())
    )
    OUT.write_text(
        '"""Shipped detector offsets of the multi-view fit (generated; do not edit).\n\n'
        "Written by ``tools/multiview_detector_offsets.py``\n"
        f"(``--rigs {args.rigs} --rounds {args.rounds}``): mm, each shrunk by its\n"
        "held-out factor (`held_out_shrinkage`), in the frame of the segment ending at\n"
        "each joint (`offset_points`), from the fits of the tuning clips' renders\n"
        f"({clips})\nwith the backend's keypoints against the truth.\n"
        '"""\n\n'
        "OFFSETS_MM: dict[str, dict[str, tuple[float, float, float]]] = {\n"
        f'    "{args.backend}": {{\n{body}\n    }},\n}}\n'
    )
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
