"""``mocapkit live METHOD SETUP``: track live LSL streams and cameras, joints out over LSL."""

from __future__ import annotations

import argparse
import json
import sys

from mocapkit.cli.args import number, output_folder, shows_default

_CONFIG = "mocapkit.pipelines.live_config:LiveConfig"

HELP = "track live LSL streams and cameras; joints out as an LSL stream"


def _pair(text: str) -> tuple[str, str]:
    cam, sep, value = text.partition("=")
    if not sep or not cam or not value:
        raise argparse.ArgumentTypeError(f"expected CAMERA=SOURCE, found {text!r}")
    return cam, value


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``live`` subcommand."""
    from mocapkit.pipelines.live_config import STREAM_PREFIX, LiveConfig

    _DEFAULTS = LiveConfig()
    p = subparsers.add_parser(
        "live",
        help=HELP,
        description="Track as it happens: markers and 2-D keypoints from Lab Streaming Layer "
        "streams, video from cameras (OpenCV device index or URL), calibration and subject "
        "from the SETUP session folder (cameras.json, session.json). The canonical joints go "
        "out as the LSL stream --stream (mm, z up, stamped with the input's time stamp). "
        "Ctrl-C or a lost input stops cleanly; --out and --record are then written. "
        "Needs mocapkit[live]. See docs/live.md.",
    )
    p.add_argument("method", choices=("hybrid", "stereo", "mono"), help="tracker")
    p.add_argument("setup", help="session folder with cameras.json and session.json")
    p.add_argument("--markers", metavar="STREAM", help="LSL marker stream (hybrid)")
    p.add_argument(
        "--keypoints",
        metavar="CAMERA=STREAM",
        type=_pair,
        action="append",
        default=[],
        help="LSL keypoints stream of a camera (mono: one; stereo: every camera or none)",
    )
    p.add_argument(
        "--video",
        metavar="CAMERA=SOURCE",
        type=_pair,
        action="append",
        default=[],
        help="a camera's video: OpenCV device index (0), stream URL, or lsl:STREAM (a "
        "replay's frame numbers); the first camera sets the time line",
    )
    p.add_argument(
        "--from-replay",
        nargs="?",
        const=STREAM_PREFIX,
        metavar="PREFIX",
        help="take every input from `mocapkit replay SETUP --lsl` (its stream prefix, "
        "default %(const)s); hybrid uses the first camera, mono its keypoints",
    )
    shows_default(
        p.add_argument(
            "--stream", default=None, help="output LSL stream name (default %(stated_default)s)"
        ),
        "mocapkit.pipelines.live:JOINTS_STREAM",
    )
    p.add_argument("--out", type=output_folder, help="result folder written at the end")
    p.add_argument("--record", type=output_folder, help="record the inputs as a session folder")
    shows_default(
        p.add_argument(
            "--lag",
            type=number(int, at_least=1),
            default=_DEFAULTS.mono_lag,
            help="mono: online Viterbi lag in frames (default %(stated_default)s)",
        ),
        f"{_CONFIG}.mono_lag",
    )
    shows_default(
        p.add_argument(
            "--lost-after-s",
            type=number(above=0.0),
            default=_DEFAULTS.lost_after_s,
            help="stop when an input is silent this long (default %(stated_default)s s)",
        ),
        f"{_CONFIG}.lost_after_s",
    )
    p.add_argument(
        "--view",
        action="store_true",
        help="show the joints over the first camera's image in a window (needs OpenCV "
        "with a GUI; off by default, for headless use)",
    )
    p.add_argument("--json", action="store_true", help="print the run's report as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Track until Ctrl-C or a lost input; print what happened."""
    from dataclasses import replace

    from mocapkit.io.session import load_session
    from mocapkit.pipelines.live import JOINTS_STREAM, track_live
    from mocapkit.pipelines.live_feed import LiveConfig, LiveInputs, replay_inputs

    inputs = LiveInputs(args.markers, dict(args.keypoints), dict(args.video))
    if args.from_replay is not None:
        r = replay_inputs(load_session(args.setup), args.from_replay)
        video = dict(args.video) or r.video
        keypoints = dict(args.keypoints) or dict(r.keypoints)
        if args.method == "hybrid":
            video = dict(list(video.items())[:1])
            keypoints = dict(args.keypoints)
        if args.method == "mono":
            keypoints = dict(list(keypoints.items())[:1])
            video = {}
        inputs = LiveInputs(args.markers or r.markers, keypoints, video)
    if args.method != "hybrid":
        inputs = replace(inputs, markers=None)
    config = LiveConfig(lost_after_s=args.lost_after_s, mono_lag=args.lag)
    stream = args.stream or JOINTS_STREAM
    print(f"live {args.method}: publishing {stream}; Ctrl-C stops", file=sys.stderr)
    report = track_live(
        args.method,
        args.setup,
        inputs,
        args.out,
        args.record,
        config=config,
        view=args.view,
        stream_name=stream,
    )
    summary = {
        "method": report.method,
        "stopped": report.stop_reason,
        "frames_tracked": report.stats.frames_tracked,
        "frames_dropped": report.stats.frames_dropped,
        "results_sent": report.n_results,
        "received": report.stats.received,
        "latency": report.latency_summary(),
        "step_cpu": report.step_cpu_summary(),
        "rss_mb": {"first_result": report.stats.rss_first_mb, "end": report.stats.rss_last_mb},
        "out": str(report.out_dir) if report.out_dir else None,
        "record": str(report.record_dir) if report.record_dir else None,
    }
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        lat = report.latency_summary()
        print(f"live {args.method}: stopped: {report.stop_reason}", file=sys.stderr)
        print(
            f"{report.stats.frames_tracked} frames tracked, {report.stats.frames_dropped} "
            f"dropped, {report.n_results} results sent; latency median {lat['median_ms']:.1f} "
            f"ms, p99 {lat['p99_ms']:.1f} ms"
        )
        for gap in report.gaps:
            print(f"  gap: {gap}")
        for path in (report.out_dir, report.record_dir):
            if path is not None:
                print(path)
    return 0
