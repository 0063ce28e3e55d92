"""Pops in a result folder: the largest joint speed and bone roll per frame, against the
inputs' own largest marker speed, and pictures of the frames that pop.

Joint speeds are those of the pose (forward kinematics of ``motion.npz``'s ``q``: what the
BVH shows, including held parts); bone rolls are measured on the tracker's pose and on the
written ``motion.bvh``. A pop is a joint faster than the fastest input marker (and than
``--factor`` times it), or a roll faster than 1200 deg/s.

Usage::

    .venv/bin/python examples/pops.py RESULT_DIR [--markers FILE] [--names A,B,...]
        [--pictures OUT_DIR] [--label TEXT]

``--markers`` is the marker file the result was tracked from (a session's ``markers.csv``
or a raw C3D); ``--names`` restricts the input speeds to the markers the tracker used.
``--session`` is the session folder the result was tracked from (markerless input): per
canonical joint of ``joints.csv``, its peak speed against the truth's (``truth.npz``, a
synthetic session) and the frames on which it moves faster than the cameras' 2-D
keypoints show (the rule of fit.csv's plausibility columns,
`mocapkit.eval.plausibility`). With a ``fit.csv`` holding those columns, its spans of
implausible motion are listed as ``mocapkit track`` warns of them.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from mocapkit.eval.continuity import peak, roll_steps_deg, speeds_mm_s
from mocapkit.io.bvh import read_bvh
from mocapkit.io.joints_csv import read_joints_csv
from mocapkit.io.marker_files import read_markers
from mocapkit.io.motion_npz import load_motion_npz
from mocapkit.pipelines.fit_report import implausible_spans_in_folder, implausible_warnings
from mocapkit.pipelines.input_speeds import keypoint_input_speeds
from mocapkit.pipelines.run import FIT_FILE, check_run_motion, read_fit_csv
from mocapkit.skeleton.kinematics import forward_kinematics

#: Bones of a leg (after the side prefix, ``l_`` or ``r_``).
LEG_BONES = ("hip", "femur", "tibia", "foot", "foot_end")


def _picture(path: Path, joints: np.ndarray, parents: np.ndarray, frame: int, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(9, 4.5))
    for k, (view, (elev, azim)) in enumerate((("front", (10, -90)), ("side", (10, 0)))):
        ax = fig.add_subplot(1, 2, k + 1, projection="3d")
        for f, colour in ((frame - 1, "tab:blue"), (frame, "tab:red")):
            p = joints[f]
            for j, par in enumerate(parents):
                if par >= 0:
                    ax.plot(*zip(p[par], p[j]), color=colour, lw=2)
        centre = joints[frame].mean(axis=0)
        for a, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre):
            a(c - 1000, c + 1000)
        ax.view_init(elev, azim)
        ax.set_title(f"{view}: frame {frame - 1} blue, {frame} red", fontsize=8)
    fig.suptitle(title, fontsize=9)
    fig.savefig(path, dpi=80)
    plt.close(fig)


def _peaks(values: np.ndarray) -> np.ndarray:
    """Per column, the largest finite value (NaN where a column has none)."""
    v = np.where(np.isfinite(values), values, -np.inf)
    out = v.max(axis=0)
    return np.where(np.isfinite(out), out, np.nan)


def _per_joint(result: Path, session_dir: Path, factor: float) -> None:
    """Per canonical joint: the result's peak speed against the truth's (frames faster
    than ``factor`` times the truth's peak + 0.3 m/s counted), and the frames whose step
    no camera's keypoints show."""
    from mocapkit.io.session import load_session

    t, names, joints = read_joints_csv(result / "joints.csv")
    out_speed = speeds_mm_s(t, joints)
    out_peak = _peaks(out_speed)
    session = load_session(session_dir)
    truth = session.truth
    if truth is not None:
        cols = [truth.joint_names.index(n) if n in truth.joint_names else -1 for n in names]
        tr = speeds_mm_s(truth.time_s, truth.joints_mm)
        tr_peak = np.array([_peaks(tr)[c] if c >= 0 else np.nan for c in cols])
        print(
            "  per joint, peak speed (m/s): result / truth, frames over "
            f"{factor:g} x the truth's peak + 0.3 m/s"
        )
        for k, n in enumerate(names):
            if not np.isfinite(out_peak[k]):
                continue
            pops = int(np.sum(out_speed[:, k] > factor * tr_peak[k] + 300.0))
            i = int(np.nanargmax(out_speed[:, k]))
            print(
                f"    {n:16s} {out_peak[k] / 1000:6.2f} at {t[i + 1]:5.2f} s / "
                f"{tr_peak[k] / 1000:5.2f}   {pops:3d}"
            )
    evidence = keypoint_input_speeds(session, sorted(session.keypoints))
    if evidence is None:
        return
    # the runner's rule: faster than the bound on what every camera's keypoints show
    motion = load_motion_npz(result / "motion.npz")  # the joints of joints.csv, with q
    check = check_run_motion(motion, evidence)
    t, names = motion.time_s, motion.joint_names
    flags, step_mm = check.joint_flags, check.speed_mm_s * np.gradient(t)[:, None]
    print("  per joint, frames faster than the cameras' keypoints show (fit.csv's rule):")
    for k, n in enumerate(names):
        if flags[:, k].any():
            i = np.flatnonzero(flags[:, k])
            worst = i[int(np.argmax(step_mm[i, k]))]
            print(
                f"    {n:16s} {i.size:3d} frames, largest {step_mm[worst, k]:.0f} mm "
                f"({check.speed_mm_s[worst, k] / 1000:.2f} m/s, keypoints "
                f"{check.input_mm_s[worst, k] / 1000:.2f} m/s) at {t[worst]:.2f} s"
            )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("result", type=Path)
    ap.add_argument("--markers", type=Path)
    ap.add_argument("--names", default="")
    ap.add_argument("--session", type=Path)
    ap.add_argument("--factor", type=float, default=1.5)
    ap.add_argument("--pictures", type=Path)
    ap.add_argument("--label", default="")
    args = ap.parse_args()
    motion = load_motion_npz(args.result / "motion.npz")
    sk, t = motion.skeleton, motion.time_s
    world = forward_kinematics(sk, motion.q)
    pos = world[..., :3, 3]
    names = sk.joint_names
    speed = speeds_mm_s(t, pos)
    fast = peak(speed, names)
    bones, roll = roll_steps_deg(sk, motion.q)
    r_q = peak(roll, bones)
    bvh = read_bvh(args.result / "motion.bvh", unit_mm=1000.0)
    b_bones, b_roll = roll_steps_deg(bvh.skeleton, bvh.q)
    r_bvh = peak(b_roll, b_bones)
    label = args.label or args.result.name
    print(f"{label}: {motion.n_frames} frames at {1 / np.median(np.diff(t)):.0f} Hz")
    if args.markers is not None:
        m = read_markers(args.markers)
        wanted = [n for n in args.names.split(",") if n]
        # a Vicon "Subject:" prefix is matched as in --marker-set
        keep = [k for k, n in enumerate(m.names) if n.split(":")[-1] in wanted]
        keep = keep or list(range(len(m.names)))
        m_speed = speeds_mm_s(m.time_s, m.positions_mm[:, keep])
        inp = peak(m_speed, tuple(m.names[k] for k in keep))
        print(
            f"  inputs' largest marker speed {inp.value / 1000:.2f} m/s "
            f"({inp.name} at {m.time_s[inp.frame]:.2f} s)"
        )
    print(
        f"  largest joint speed {fast.value / 1000:.2f} m/s ({fast.name} at {t[fast.frame]:.2f} s, "
        f"{np.linalg.norm(pos[fast.frame] - pos[fast.frame - 1], axis=1).max():.0f} mm in a frame)"
    )
    legs = [j for j, nm in enumerate(names) if nm == "root" or nm[2:] in LEG_BONES]
    low = peak(speed[:, legs], tuple(names[j] for j in legs))
    print(f"  pelvis and legs: {low.value / 1000:.2f} m/s ({low.name} at {t[low.frame]:.2f} s)")
    for what, r in (("pose", r_q), ("BVH", r_bvh)):
        print(
            f"  largest bone roll a frame, {what}: {r.value:.1f} deg ({r.name}, {t[r.frame]:.2f} s)"
        )
    if args.session is not None:
        _per_joint(args.result, args.session, args.factor)
    over = np.nanmax(speed, axis=1) > 5000.0
    print(f"  frames with a joint faster than 5 m/s: {int(over.sum())}")
    fit = args.result / FIT_FILE
    if fit.is_file():
        for line in implausible_warnings(implausible_spans_in_folder(args.result), 5):
            print(f"  {line}")
        _, columns = read_fit_csv(fit)
        if "flips" in columns:  # the mono tracker's chosen flip code per frame
            code = columns["flips"][columns["flips"] >= 0]
            print(f"  flip-set changes: {int(np.sum(code[1:] != code[:-1]))} in {code.size} frames")
    if args.pictures is not None:
        args.pictures.mkdir(parents=True, exist_ok=True)
        out = args.pictures / f"{label}_frame{fast.frame}.png"
        _picture(
            out,
            pos,
            sk.parents,
            fast.frame,
            f"{label}: {fast.name} {fast.value / 1000:.1f} m/s at {t[fast.frame]:.2f} s",
        )
        print(f"  picture: {out}")


if __name__ == "__main__":
    main()
