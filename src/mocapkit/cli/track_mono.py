"""``mocapkit track mono``: the monocular markerless tracker (Mamania et al. 2004).

Registered by `mocapkit.cli.track` (this module adds a method to ``track``; it has no
``register`` of its own, so it is no top-level command).
"""

from __future__ import annotations

import argparse
import json
from typing import Any

from mocapkit.cli.args import given, output_folder, shows_default

#: The tracker's settings (heavy to import: read by --help only)
MONO = "mocapkit.tracking.mono.tracker:MonoConfig"
#: The mono tracker's edge weights (`MonoConfig.cost`)
COSTS = ("acceleration", "joint_acceleration", "rotation")


def add_mono_parser(methods: Any) -> None:
    """Add ``track mono`` to the ``track`` methods."""
    p = methods.add_parser(
        "mono",
        help="one video's 2-D keypoints, no markers (Mamania et al. 2004)",
        description="Track a session from one camera's 2-D keypoints (keypoints/<camera>.csv, "
        "or --keypoints: a CSV file or a folder of OpenPose JSON, BODY_25 or COCO-18): "
        "flips of every link, pruned by joint limits and collisions, chosen by Viterbi. "
        "Writes motion.npz, joints.csv, motion.bvh and fit.csv to --out.",
    )
    p.add_argument("session", help="session folder")
    p.add_argument("--out", required=True, type=output_folder, help="result folder")
    p.add_argument("--camera", help="camera name (default: the first with keypoints)")
    p.add_argument("--keypoints", help="keypoints CSV file or OpenPose JSON folder")
    shows_default(
        p.add_argument(
            "--camera-model",
            choices=("perspective", "weak", "orthographic"),
            default=None,
            help="perspective, weak perspective, or the paper's orthography (default "
            "%(stated_default)s)",
        ),
        f"{MONO}.camera_model",
    )
    shows_default(
        p.add_argument(
            "--cost",
            choices=COSTS,
            default=None,
            help="edge weight: angular acceleration over pair states (eq. 3, corrected), "
            "joint acceleration (eq. 4-5, corrected), or first-order rotation (default "
            "%(stated_default)s)",
        ),
        f"{MONO}.cost",
    )
    p.add_argument(
        "--lag",
        type=int,
        default=None,
        metavar="FRAMES",
        help="online fixed-lag Viterbi with this lag (latency: the lag plus the smoother's); "
        "default: exact offline",
    )
    p.add_argument(
        "--skin",
        action="store_true",
        help="read the 2-D joints off the video by skin blobs (paper §3.3); the trunk comes "
        "from a waist blob (the paper's golden belt) or, without one, is drawn upright from "
        "the head",
    )
    p.add_argument(
        "--bare-from",
        choices=("elbow", "mid_upper_arm", "shoulder"),
        default=None,
        help="with --skin: where the arms' skin starts (e.g. mid_upper_arm under short "
        "sleeves); the elbow and wrist are then placed on the arm blob by anthropometric "
        "fractions. Default: the paper's rule, the arm ellipse's ends",
    )
    p.add_argument(
        "--costume",
        choices=("paper", "everyday"),
        default=None,
        help="with --skin: the subject's clothing, which sets the skin tracker's rules "
        "(paper: the paper's costume, a dress to the elbows and a skin-like belt, whose "
        "ends give the trunk; everyday: short sleeves, no belt, the trunk drawn from the "
        "head). --bare-from overrides where the arms' skin starts. Default: the paper's "
        "rules as printed (the arm ellipse's ends; the trunk from a belt or the head)",
    )
    p.add_argument("--legs", action="store_true", help="track the legs too")
    p.add_argument(
        "--session-lengths",
        action="store_true",
        help="take link lengths from session.json instead of the video",
    )
    shows_default(
        p.add_argument(
            "--arm-prior-weight",
            type=float,
            default=None,
            help="weight of the data-driven arm prior per nat (default %(stated_default)s; 0: off)",
        ),
        f"{MONO}.arm_prior_weight",
    )
    p.add_argument(
        "--initial-pose",
        metavar="JOINTS_CSV",
        help="the subject's known pose in the first frame (the paper's assumption 3): a "
        "joints.csv (world frame, mm) whose first row is used; the neck is required",
    )
    p.add_argument(
        "--no-floor",
        action="store_true",
        help="place the subject by the depth the link lengths give alone; default: by the "
        "feet where they stand on the world's floor (z = 0, z up) and agree with that "
        "depth (calibrated camera, ankles in the keypoints)",
    )
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=_run_mono)


def _run_mono(args: argparse.Namespace) -> int:
    from mocapkit.pipelines.fit_report import warn_implausible
    from mocapkit.pipelines.mono import (
        SkinOptions,
        costume_skin_options,
        initial_pose_from,
        track_mono,
    )
    from mocapkit.pipelines.run import find_gaps
    from mocapkit.tracking.mono.placement import FloorConfig
    from mocapkit.tracking.mono.stick import stick_model
    from mocapkit.tracking.mono.tracker import MonoConfig

    if not args.skin and (args.costume is not None or args.bare_from is not None):
        from mocapkit.errors import ConfigError

        raise ConfigError(
            "track mono: --costume and --bare-from set the skin tracker; expected them with "
            "--skin, found them without it"
        )
    cfg = MonoConfig(
        legs=args.legs,
        lag=args.lag,
        **given(
            camera_model=args.camera_model, cost=args.cost, arm_prior_weight=args.arm_prior_weight
        ),
    )
    start = None
    if args.initial_pose is not None:
        from mocapkit.io.joints_csv import read_joints_csv

        _, names, joints = read_joints_csv(args.initial_pose)
        start = initial_pose_from(names, joints[0], stick_model(cfg.legs, cfg.limits))
    # the costume's settings, else track_mono's defaults (the paper's printed rules)
    own_arms = {} if args.bare_from is None else {"bare_from": args.bare_from}
    skin_options = (
        costume_skin_options(args.costume, **own_arms)
        if args.costume is not None
        else SkinOptions(bare_from=args.bare_from)
    )
    run = track_mono(
        args.session,
        args.out,
        camera=args.camera,
        keypoints=args.keypoints,
        config=cfg,
        use_session_lengths=args.session_lengths,
        skin=args.skin,
        initial_pose=start,
        skin_options=skin_options,
        placement=FloorConfig(on_floor=False) if args.no_floor else None,
    )
    summary = run.summary()
    if not args.json:  # limbs unseen past the bridge: NaN joints, status in fit.csv
        for gap in find_gaps(run.results):
            print(f"gap: {gap}")
    warn_implausible(args.out)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(
            f"tracked {run.motion.n_frames} frames -> {args.out}: "
            f"{summary['survivors_mean']:.1f} of {summary['candidates_mean']:.1f} poses survive "
            f"pruning on average ({100 * summary['pruned_share_mean']:.0f} % pruned), "
            f"2-D residual {summary['residual_px_mean']:.2f} px; placed by the feet on the "
            f"floor in {100 * summary['on_floor_share']:.0f} % of the frames"
        )
    return 0
