"""``mocapkit accuracy mono``: the monocular tracker on synthetic mono sessions.

Registered by `mocapkit.cli.accuracy` (no ``register`` here: not a top-level command).
"""

from __future__ import annotations

import argparse
from typing import Any

from mocapkit.cli.args import MOCAP_HELP, add_clip_options, chosen_clips, given, shows_default
from mocapkit.cli.track_mono import COSTS, MONO

_RUN = "mocapkit.pipelines.mono_accuracy:mono_accuracy"


def add_mono_accuracy_parser(methods: Any) -> None:
    """Add ``accuracy mono`` to the ``accuracy`` methods."""
    m = methods.add_parser(
        "mono",
        help="upper-body error (Procrustes), flip share and pruning of the mono tracker",
        description="Render a mono session from each clip, add noise to its true 2-D "
        "keypoints, track (from the keypoints or from OpenPose JSON with a bystander) "
        "and report the upper-body error after similarity alignment, the share of "
        "link-frames with the right flip and the poses pruned per frame.",
    )
    m.add_argument("--mocap", help=MOCAP_HELP)
    add_clip_options(m)
    m.add_argument(
        "--work", default="accuracy-output/mono", help="sessions and results (default %(default)s)"
    )
    shows_default(
        m.add_argument("--seed", type=int, default=None, help="seed (default %(stated_default)s)"),
        f"{_RUN}.seed",
    )
    shows_default(
        m.add_argument(
            "--noise-px",
            type=float,
            default=None,
            help="2-D noise sigma (default %(stated_default)s px)",
        ),
        f"{_RUN}.noise_px",
    )
    src = m.add_mutually_exclusive_group()
    src.add_argument("--openpose", action="store_true", help="track from OpenPose JSON")
    src.add_argument(
        "--skin",
        action="store_true",
        help="track from the rendered video by skin blobs",
    )
    src.add_argument(
        "--detector",
        choices=("mediapipe", "rtmpose"),
        help="track from this 2-D detector run on the rendered video (kept in WORK and "
        "reused); its own 3-D, where it gives one, is measured beside the tracker",
    )
    m.add_argument(
        "--costume",
        choices=("paper", "everyday"),
        default=None,
        help="with --skin: the subject's clothing (default paper: the paper's costume, "
        "bare forearms and a skin-like belt, tracked by the paper's rules; everyday: short "
        "sleeves and no belt, the elbow and wrist placed on the arm blob and the trunk "
        "drawn from the head)",
    )
    shows_default(
        m.add_argument(
            "--bare-from",
            choices=("costume", "paper", "elbow", "mid_upper_arm", "shoulder"),
            default=None,
            help="with --skin: where the arms' skin starts (costume: the costume's, paper for "
            "the paper's costume, mid_upper_arm for everyday; paper: the arm ellipse's ends "
            "as elbow and wrist; default %(stated_default)s)",
        ),
        f"{_RUN}.skin_bare_from",
    )
    m.add_argument(
        "--legs",
        action="store_true",
        help="track the legs too (track mono --legs) and measure the whole body instead of "
        "the upper body",
    )
    m.add_argument(
        "--lag", type=int, default=None, help="online fixed lag (frames; default: offline, exact)"
    )
    shows_default(
        m.add_argument("--cost", choices=COSTS, help="edge weight (default %(stated_default)s)"),
        f"{MONO}.cost",
    )
    shows_default(
        m.add_argument(
            "--arm-prior-weight",
            type=float,
            default=None,
            help="weight of the data-driven arm prior per nat (default %(stated_default)s; 0: off)",
        ),
        f"{MONO}.arm_prior_weight",
    )
    m.add_argument(
        "--initial-pose",
        action="store_true",
        help="give the tracker the true pose of the first frame (the paper's assumption 3); "
        "report these figures apart",
    )
    m.add_argument(
        "--no-floor",
        action="store_true",
        help="place the subject by the link lengths alone (track mono --no-floor)",
    )
    m.add_argument("--json", action="store_true", help="print JSON instead of a table")
    m.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    import numpy as np

    from mocapkit.cli.args import mocap_folder
    from mocapkit.pipelines.mono_accuracy import format_rows, mono_accuracy, to_json
    from mocapkit.tracking.mono.placement import FloorConfig
    from mocapkit.tracking.mono.tracker import MonoConfig

    mocap = mocap_folder(args.mocap)
    # "paper": the arm ellipse's ends (the library's None); not given: the library's default
    bare: dict[str, Any] = {}
    if args.bare_from is not None:
        bare["skin_bare_from"] = None if args.bare_from == "paper" else args.bare_from
    if not args.json:
        print(format_rows([]))
    rows = mono_accuracy(
        mocap,
        args.work,
        chosen_clips(args),
        openpose=args.openpose,
        skin=args.skin,
        costume=args.costume,
        initial_pose=args.initial_pose,
        placement=FloorConfig(on_floor=False) if args.no_floor else None,
        detector=args.detector,
        config=MonoConfig(
            lag=args.lag,
            legs=args.legs,
            **given(cost=args.cost, arm_prior_weight=args.arm_prior_weight),
        ),
        say=(lambda _line: None) if args.json else print,
        **given(seed=args.seed, noise_px=args.noise_px),
        **bare,
    )
    if args.json:
        print(to_json(rows))
    else:
        body = "whole-body" if args.legs else "upper-body"
        print(
            f"mean: Procrustes {body} error {np.mean([r.pa_mpjpe_mm for r in rows]):.1f} mm, "
            f"flips right {100 * np.mean([r.flips_right for r in rows]):.1f} %, pruned "
            f"{100 * np.mean([r.pruned_share_mean for r in rows]):.1f} % of the poses per frame"
        )
        if args.detector:
            print(
                f"mean: arm {np.mean([r.arm_pa_mpjpe_mm for r in rows]):.1f} mm; the "
                f"detector's own 3-D: {body} "
                f"{np.mean([r.detector3d_pa_mpjpe_mm for r in rows]):.1f}, arm "
                f"{np.mean([r.detector3d_arm_pa_mm for r in rows]):.1f} mm; world MPJPE "
                f"{np.mean([r.mpjpe_mm for r in rows]):.1f} mm "
                f"({np.mean([r.mpjpe_at_true_depth_mm for r in rows]):.1f} at the true neck "
                f"depth); arms swapped in the input on "
                f"{sum(r.swapped_frames for r in rows)} frames, right in the answer on "
                f"{sum(r.swaps_handled for r in rows)}"
            )
        if args.skin:
            for r in rows:
                per = ", ".join(f"{n} {v:.1f}" for n, v in r.input_px_by_joint.items())
                print(f"{r.clip} 2-D input error per joint (median px): {per}")
    return 0
