"""``mocapkit track stereo``: the stereo / multi-view markerless tracker (Azad et al. 2008).

Registered under ``track`` by `mocapkit.cli.track` (one line), so that each method's
options live in their own module.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, NamedTuple

from mocapkit.cli.args import given, output_folder, shows_default
from mocapkit.tracking.multiview.config import SMOOTHING, STEREO_METHODS, MultiviewRunConfig

if TYPE_CHECKING:
    from mocapkit.io.session import Session
    from mocapkit.timing import CompileTime

#: The stereo tracker's settings (the paper's tracker: heavy to import, read by --help only)
_STEREO = "mocapkit.tracking.stereo.tracker:StereoConfig"
#: The multi-view fit's settings (light to import: the arguments' own defaults)
_FIT = "mocapkit.tracking.multiview.config:MultiviewRunConfig"


def register_method(methods: Any) -> None:
    """Add ``stereo`` to the ``track`` methods."""
    p = methods.add_parser(
        "stereo",
        help="two or more cameras, no markers: the full body fitted to every view's 2-D "
        "keypoints; on a narrow pair or without keypoints the paper's arm filters (Azad, "
        "Asfour, Dillmann 2008)",
        description="Track a session folder with two or more calibrated cameras. With 2-D "
        "keypoints for every camera (default --method auto): the full body fitted to every "
        "view's detections (robust, left/right swaps per view, the subject's segment lengths "
        "from the take). Without keypoints, or with --method skin|filter: the paper's upper "
        "body, skin-blob (or keypoint) head and hands in 3-D and one particle filter per arm on "
        "the edge and distance cues. Writes motion.npz, joints.csv, motion.bvh and fit.csv "
        "to --out; with a truth.npz in the session, prints the joints' errors too.",
    )
    p.add_argument("session", help="session folder")
    p.add_argument("--out", required=True, type=output_folder, help="result folder")
    p.add_argument(
        "--cameras",
        default=None,
        metavar="A,B[,C...]",
        help="cameras to use (default: every camera with a video); the cues average over them",
    )
    shows_default(
        p.add_argument(
            "--method",
            choices=STEREO_METHODS,
            default=None,
            help="fit: the full-body model fitted to the keypoints; filter: the paper's arm "
            "particle filters with head and hands from the keypoints; skin: the paper's skin "
            "blobs; auto: with keypoints for every camera the fit, or filter on a narrow "
            "pair; without them skin (default %(stated_default)s)",
        ),
        "mocapkit.pipelines.multiview:resolve_stereo_method.method",
    )
    shows_default(
        p.add_argument(
            "--smooth",
            choices=SMOOTHING,
            default=MultiviewRunConfig().smoothing,
            help="with the fit: smoothing of the poses: none; one-euro (online, a few frames "
            "of lag on fast motion); butterworth (offline, zero lag, 4th order, as Pose2Sim) "
            "(default %(stated_default)s)",
        ),
        f"{_FIT}.smoothing",
    )
    shows_default(
        p.add_argument(
            "--cutoff-hz",
            type=float,
            default=MultiviewRunConfig().cutoff_hz,
            help="with --smooth: cut-off (default %(stated_default)s Hz)",
        ),
        f"{_FIT}.cutoff_hz",
    )
    p.add_argument(
        "--keypoints",
        action="store_true",
        help="same as --method filter: head and hands from keypoints/<camera>.csv instead of "
        "skin blobs, arms by the particle filters",
    )
    shows_default(
        p.add_argument(
            "--particles",
            type=int,
            default=None,
            help="particles per arm and run (default %(stated_default)s)",
        ),
        "mocapkit.tracking.stereo.arm_filter:ArmFilterConfig.n_particles",
    )
    shows_default(
        p.add_argument(
            "--torso",
            choices=("shoulders", "keypoints"),
            default=None,
            help="torso orientation from the adaptive shoulders (the paper's inputs) or "
            "from the shoulder/neck/pelvis keypoints (with --keypoints; default "
            "%(stated_default)s)",
        ),
        f"{_STEREO}.torso",
    )
    shows_default(
        p.add_argument(
            "--torso-anchor",
            choices=("neck", "shoulders"),
            default=None,
            help="with --torso keypoints: hang the arms from the neck keypoint (give the "
            "subject's segment_vectors_mm in session.json) or centre the shoulders on the "
            "shoulder keypoints (real detections without the subject's measurements; "
            "default %(stated_default)s)",
        ),
        f"{_STEREO}.torso_anchor",
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
    from mocapkit.io.session import load_session
    from mocapkit.pipelines.fit_report import warn_implausible
    from mocapkit.pipelines.multiview import resolve_stereo_method
    from mocapkit.pipelines.run import find_gaps
    from mocapkit.pipelines.stereo import (
        elbow_jump_warnings,
        evaluate_stereo,
        track_stereo_session,
    )
    from mocapkit.tracking.stereo.tracker import StereoConfig

    if args.keypoints:
        if args.method not in (None, "auto", "filter"):
            raise ConfigError(f"--keypoints is --method filter; found --method {args.method}")
        args.method = "filter"
    if args.method is None:
        args.method = "auto"
    paper_options = (
        args.particles is not None
        or args.torso is not None
        or args.torso_anchor is not None
        or args.fixed_shoulders
    )
    if args.method == "auto" and paper_options:
        args.method = "skin"  # the paper's tracker's options: the paper's tracker
    session = load_session(args.session)  # read once, for the choice and the tracker
    method = resolve_stereo_method(session, args.method, args.cameras)
    if method == "fit":
        return _run_fit(args, session)
    if method == "filter" and args.method == "auto":
        print(
            "the views are a narrow pair (optical axes less than 20 deg apart): the paper's "
            "tracker on the keypoints (--method fit forces the full-body fit). From a "
            "detector's keypoints expect arm errors near 200 mm (MediaPipe on rendered pairs "
            "with a 90 mm baseline: 195 mm, 29 mm from exact 2-D; docs/stereo.md): a narrow "
            "baseline turns the views' 1-2 px disagreement into depth; three or more cameras "
            "or a wide pair are far better"
        )
    if method == "skin" and args.method == "auto":
        print(
            "no keypoints/<camera>.csv for every camera: tracking by skin colour (the paper's "
            "cues; they fail on most real video). Give 2-D keypoints for the full-body fit.",
        )
    args.keypoints = method == "filter"
    if args.torso == "keypoints" and not args.keypoints:
        raise ConfigError("--torso keypoints needs --keypoints")
    if args.particles is not None and args.particles < 2:
        raise ConfigError(f"--particles: expected at least 2, found {args.particles}")
    if args.torso_anchor is not None and args.torso != "keypoints":
        raise ConfigError("--torso-anchor needs --torso keypoints")
    cfg = StereoConfig(
        use_keypoints=args.keypoints, **given(torso=args.torso, torso_anchor=args.torso_anchor)
    )
    if args.fixed_shoulders:
        cfg = replace(cfg, arm=replace(cfg.arm, adaptive_shoulder=False))
    run = track_stereo_session(
        session,
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
    for line in elbow_jump_warnings(run.jumps):
        print(line)
    warn_implausible(args.out)
    fps = run.motion.n_frames / max(run.seconds, 1e-9)
    print(
        f"tracked {run.motion.n_frames} frames in {run.seconds:.1f} s ({fps:.1f} frames/s"
        f"{first_run(run.compiled)})"
    )
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


class _FarSpan(NamedTuple):
    joint: str
    start_s: float
    end_s: float
    n_frames: int

    def __str__(self) -> str:
        from mocapkit.pipelines.fit_report import span_when

        return f"{self.joint} {span_when(self.start_s, self.end_s, self.n_frames)}"


def far_warnings(spans: Sequence[tuple[str, float, float, int]], warn_px: float) -> list[str]:
    """The warning about the fit's far spans (joint, first s, last s, frames;
    `mocapkit.pipelines.multiview.far_spans`): a count, the longest few, then how many
    more, as the other end-of-run warnings list their spans."""
    from mocapkit.pipelines.fit_report import worst_spans_lines

    far = [_FarSpan(*s) for s in spans]
    n_frames = sum(s.n_frames for s in far)
    header = (
        f"warning: a joint is more than {warn_px:g} px from its detections in most views in "
        f"{len(far)} span{'s' if len(far) != 1 else ''} ({n_frames} frames); see fit.csv"
    )
    return worst_spans_lines(header, [far], lambda s: s.n_frames)


def first_run(compiled: CompileTime) -> str:
    """The speed line's note when the run compiled Numba kernels (a first run after
    installing: later runs load them from their cache); empty otherwise."""
    if not compiled.kernels:
        return ""
    kernels = f"{compiled.kernels} kernel{'s' if compiled.kernels != 1 else ''}"
    return (
        f"; first run: includes compiling {kernels}, {compiled.seconds:.1f} s; later runs "
        "load them from the cache"
    )


def _run_fit(args: argparse.Namespace, session: Session) -> int:
    """``--method fit``: the full-body model fitted to the keypoints."""
    from dataclasses import replace
    from pathlib import Path

    from mocapkit.errors import ConfigError
    from mocapkit.pipelines.accuracy import evaluate_result
    from mocapkit.pipelines.fit_report import warn_implausible
    from mocapkit.pipelines.multiview import track_multiview_session
    from mocapkit.pipelines.run import find_gaps

    for flag, value, default in (
        ("--particles", args.particles, None),
        ("--torso", args.torso, None),
        ("--torso-anchor", args.torso_anchor, None),
        ("--fixed-shoulders", args.fixed_shoulders, False),
    ):
        if value != default:
            raise ConfigError(f"{flag} belongs to --method filter or skin, not to the fit")
    cfg = replace(MultiviewRunConfig(), smoothing=args.smooth, cutoff_hz=args.cutoff_hz)
    run = track_multiview_session(session, args.out, cameras=args.cameras, config=cfg)
    for gap in find_gaps(run.results):
        print(f"gap: {gap}")
    for line in far_warnings(run.far, cfg.fit.warn_px):
        print(line)
    fps = run.motion.n_frames / max(run.seconds, 1e-9)
    print(
        f"fitted {run.motion.n_frames} frames in {run.seconds:.2f} s CPU ({fps:.1f} frames/s"
        f"{first_run(run.compiled)}), smoothing {cfg.smoothing}"
    )
    print(f"wrote {args.out}")
    warn_implausible(args.out)
    if (Path(args.session) / "truth.npz").is_file():
        rep = evaluate_result(args.out, args.session)
        if args.json:
            print(rep.to_json())
        else:
            for k, v in rep.per_joint_mm.items():
                print(f"  {k:<16}{v:8.1f} mm")
            print(f"  {'MPJPE':<16}{rep.mpjpe_mm:8.1f} mm")
    return 0
