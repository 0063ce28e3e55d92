"""``mocapkit replay SESSION --lsl``: publish a recorded session as live LSL streams."""

from __future__ import annotations

import argparse
import sys

from mocapkit.cli.args import given, number, shows_default

_RUN = "mocapkit.pipelines.replay:replay_session"

HELP = "publish a session's markers, keypoints and video frames as LSL streams"


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``replay`` subcommand."""
    from mocapkit.pipelines.live_config import STREAM_PREFIX

    p = subparsers.add_parser(
        "replay",
        help=HELP,
        description="Replay a session folder as Lab Streaming Layer streams, in real time or "
        "faster: the markers (<marker>_x/_y/_z, mm), each camera's 2-D keypoints and each "
        "camera's frame numbers (the consumer reads the frames from the session's video). "
        "Stream names: PREFIXmarkers, PREFIXkeypoints_<camera>, PREFIXframes_<camera>. "
        "Track them with mocapkit live METHOD SESSION --from-replay. Needs mocapkit[live].",
    )
    p.add_argument("session", help="session folder")
    p.add_argument("--lsl", action="store_true", required=True, help="publish over LSL")
    shows_default(
        p.add_argument(
            "--speed",
            type=number(above=0.0, at_most=100.0),
            default=None,
            help="replay speed: 1 real time, 4 four times faster (default %(stated_default)s)",
        ),
        f"{_RUN}.speed",
    )
    shows_default(
        p.add_argument(
            "--prefix",
            default=STREAM_PREFIX,
            help="stream name prefix (default %(stated_default)s)",
        ),
        f"{_RUN}.prefix",
    )
    shows_default(
        p.add_argument(
            "--lead-s",
            type=number(at_least=0.0),
            default=None,
            help="seconds between the streams appearing and the first sample (default "
            "%(stated_default)s)",
        ),
        f"{_RUN}.lead_s",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Replay until the end of the session (or Ctrl-C); print what was sent."""
    from mocapkit.pipelines.replay import replay_session

    def ready(names: dict[str, str]) -> None:
        print("publishing " + ", ".join(names.values()), file=sys.stderr, flush=True)

    stats = replay_session(
        args.session,
        prefix=args.prefix,
        on_ready=ready,
        **given(speed=args.speed, lead_s=args.lead_s),
    )
    sent = ", ".join(f"{n}: {k}" for n, k in stats.samples.items())
    print(f"replayed {stats.start_s:.3f}-{stats.end_s:.3f} s ({sent})")
    return 0
