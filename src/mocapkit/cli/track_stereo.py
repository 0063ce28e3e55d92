"""``mocapkit track stereo``: the stereo / multi-view markerless tracker (Azad et al. 2008).

Registered under ``track`` by `mocapkit.cli.track` (one line), so that each method's
options live in their own module.
"""

from __future__ import annotations

import argparse
import json
from typing import Any

from mocapkit.cli.args import output_folder


def register_method(methods: Any) -> None:
    """Add ``stereo`` to the ``track`` methods."""
    p = methods.add_parser(
        "stereo",
        help="two or more cameras, no markers (Azad, Asfour, Dillmann 2008)",
        description="Track the upper body of a session folder with two or more calibrated "
        "cameras: skin-blob (or keypoint) head and hands in 3-D, one particle filter per "
        "arm on the edge and distance cues. Writes motion.npz, joints.csv, motion.bvh and fit.csv "
        "to --out; with a truth.npz in the session, prints the arm joints' errors too.",
    )
    p.add_argument("session", help="session folder")
    p.add_argument("--out", required=True, type=output_folder, help="result folder")
    p.add_argument(
        "--cameras",
        default=None,
        metavar="A,B[,C...]",
        help="cameras to use (default: every camera with a video); the cues average over them",
    )
    p.add_argument(
        "--keypoints",
        action="store_true",
        help="head and hands from keypoints/<camera>.csv instead of skin blobs",
    )
    p.add_argument(
        "--particles", type=int, default=None, help="particles per arm and run (default 150)"
    )
    p.add_argument(
        "--torso",
        choices=("shoulders", "keypoints"),
        default="shoulders",
        help="torso orientation from the adaptive shoulders (default, the paper's inputs) or "
        "from the shoulder/neck/pelvis keypoints (with --keypoints)",
    )
    p.add_argument(
        "--torso-anchor",
        choices=("neck", "shoulders"),
        default="neck",
        help="with --torso keypoints: hang the arms from the neck keypoint (default; give "
        "the subject's segment_vectors_mm in session.json) or centre the shoulders on the "
        "shoulder keypoints (real detections without the subject's measurements)",
    )
    p.add_argument(
        "--fixed-shoulders",
        action="store_true",
        help="4 DoF per arm: no adaptive shoulder offsets (best with --torso keypoints)",
    )
    p.add_argument("--json", action="store_true", help="print the evaluation as JSON")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from dataclasses import replace
    from pathlib import Path

    from mocapkit.errors import ConfigError
    from mocapkit.pipelines.run import find_gaps
    from mocapkit.pipelines.stereo import evaluate_stereo, track_stereo_session
    from mocapkit.tracking.stereo.tracker import StereoConfig

    if args.torso == "keypoints" and not args.keypoints:
        raise ConfigError("--torso keypoints needs --keypoints")
    if args.particles is not None and args.particles < 2:
        raise ConfigError(f"--particles: expected at least 2, found {args.particles}")
    if args.torso_anchor != "neck" and args.torso != "keypoints":
        raise ConfigError("--torso-anchor needs --torso keypoints")
    cfg = StereoConfig(
        use_keypoints=args.keypoints, torso=args.torso, torso_anchor=args.torso_anchor
    )
    if args.fixed_shoulders:
        cfg = replace(cfg, arm=replace(cfg.arm, adaptive_shoulder=False))
    run = track_stereo_session(
        args.session,
        args.out,
        cameras=args.cameras,
        use_keypoints=args.keypoints,
        n_particles=args.particles,
        config=cfg,
    )
    # frames where the head or a hand was not measured past the bridge have no joints of
    # its limb (NaN in joints.csv, the status in fit.csv): say where, as track hybrid does
    for gap in find_gaps(run.results):
        print(f"gap: {gap}")
    fps = run.motion.n_frames / max(run.seconds, 1e-9)
    print(f"tracked {run.motion.n_frames} frames in {run.seconds:.1f} s ({fps:.1f} frames/s)")
    print(f"wrote {args.out}")
    if (Path(args.session) / "truth.npz").is_file():
        ev = evaluate_stereo(run, args.session)
        if args.json:
            print(json.dumps(ev, indent=2))
        else:
            for k, v in ev["per_joint_mm"].items():
                print(f"  {k:<16}{v:8.1f} mm")
            print(f"  {'arm mean':<16}{ev['arm_mean_mm']:8.1f} mm")
            print(f"  {'torso yaw':<16}{ev['torso_yaw_error_deg']:8.1f} deg")
    return 0
