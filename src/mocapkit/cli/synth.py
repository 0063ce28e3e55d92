"""``mocapkit synth``: render a synthetic session (video, markers, keypoints, truth)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any

from mocapkit.cli.args import checked_by, given, imported, number, output_folder, shows_default

#: The session's settings (heavy to import: read by --help only)
_SYNTH = "mocapkit.synth.session_writer:SynthOptions"
#: The realism settings (light to import: the arguments' own defaults)
_REALISM = "mocapkit.synth.options:RealismOptions"

# the line of `mocapkit --help` (shown without importing this module's pipeline)
HELP = "render a synthetic session from a motion file or a built-in motion"


_EPILOG = """\
MOTION is a BVH or AMC file (an AMC takes its skeleton from --asf, else from an .asf
beside it: same stem, the subject prefix before '_', or the only .asf in the folder),
or a built-in procedural motion: builtin:table-tennis, builtin:squat, builtin:wave.
The subject is recentred so that the pelvis is at the world origin at the start of the
excerpt and the floor is z = 0; cameras face the subject's initial facing direction.
"""


def _size(text: str) -> tuple[int, int]:
    """``--size``: ``WIDTHxHEIGHT`` in pixels, each side within `IMAGE_SIDE_RANGE_PX`."""
    from mocapkit.synth.options import IMAGE_SIDE_RANGE_PX

    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected WIDTHxHEIGHT such as 640x480, found {text!r}"
        ) from None
    lo, hi = IMAGE_SIDE_RANGE_PX
    if not (lo <= w <= hi and lo <= h <= hi):
        raise argparse.ArgumentTypeError(
            f"expected WIDTHxHEIGHT with sides between {lo} and {hi} px, found {text!r}"
        )
    return (w, h)


def _blackout(text: str) -> tuple[float, float]:
    parts = text.split(",")
    try:
        if len(parts) != 2:
            raise ValueError
        return (float(parts[0]), float(parts[1]))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected START,DURATION in seconds (e.g. 2.0,0.5), found {text!r}"
        ) from None


def _realism(name: str) -> Callable[[str], float]:
    """The ``type=`` of a realism option: a number in its `REALISM_RANGES` range."""
    from mocapkit.synth.options import REALISM_RANGES

    lo, hi = REALISM_RANGES[name]
    return number(at_least=lo, at_most=hi)


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``synth`` subcommand."""
    from mocapkit.synth.options import (
        BACKGROUNDS,
        COSTUMES,
        FPS_RANGE,
        MARKER_RATE_RANGE_HZ,
        RIG_NAMES,
        SLEEVES,
        RealismOptions,
    )

    p = subparsers.add_parser(
        "synth",
        help=HELP,
        description="Render a session folder (cameras.json, video, markers.csv, keypoints, "
        "truth.npz) from real or procedural motion.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    d = RealismOptions()
    p.add_argument("motion", metavar="MOTION", help="BVH/AMC file or builtin:NAME")
    p.add_argument("--out", required=True, type=output_folder, help="session folder to create")
    stated: dict[str, dict[str, Any]] = {
        "--rig": dict(choices=RIG_NAMES, help="cameras (default %(stated_default)s)"),
        "--start-s": dict(
            type=number(at_least=0.0),
            help="excerpt start in the clip (default %(stated_default)s s)",
        ),
        "--seconds": dict(
            type=number(above=0.0), help="excerpt length (default %(stated_default)s s)"
        ),
        "--seed": dict(type=int, help="random seed (default %(stated_default)s)"),
    }
    for flag, kwargs in stated.items():
        field = flag[2:].replace("-", "_")
        shows_default(p.add_argument(flag, default=None, **kwargs), f"{_SYNTH}.{field}")
    p.add_argument(
        "--height-mm",
        type=float,
        default=None,
        help="scale the skeleton to this stature (default: the motion's own)",
    )
    p.add_argument("--asf", default=None, help="ASF skeleton of an AMC motion")
    stated = {
        "fps": dict(
            type=number(at_least=FPS_RANGE[0], at_most=FPS_RANGE[1]),
            help="video rate (default %(stated_default)s Hz)",
        ),
        "marker_rate_hz": dict(
            flag="--marker-rate",
            type=number(at_least=MARKER_RATE_RANGE_HZ[0], at_most=MARKER_RATE_RANGE_HZ[1]),
            help="marker rate (default %(stated_default)s Hz)",
        ),
        "image_size": dict(
            flag="--size", type=_size, help="image size WxH (default %(stated_default)s)"
        ),
    }
    for field, kwargs in stated.items():
        flag = kwargs.pop("flag", "--" + field.replace("_", "-"))
        shows_default(p.add_argument(flag, default=None, **kwargs), f"{_SYNTH}.{field}")
    realism = {
        "noise": "sensor noise sigma, grey levels (default %(stated_default)s)",
        "blur": "motion blur: shutter / frame interval (default %(stated_default)s; 0 = off)",
        "background": "scene (default %(stated_default)s)",
        "marker_noise_mm": "marker noise sigma per axis (default %(stated_default)s mm)",
        "dropout": "probability per marker sample that a drop-out starts (default "
        "%(stated_default)s)",
        "dropout_s": "mean drop-out length (default %(stated_default)s s)",
        "video_jitter_s": "video time stamp jitter sigma (default %(stated_default)s s; 0 = even)",
    }
    for field, text in realism.items():
        kind = {"choices": BACKGROUNDS} if field == "background" else {"type": _realism(field)}
        shows_default(
            p.add_argument(
                "--" + field.replace("_", "-"), default=getattr(d, field), help=text, **kind
            ),
            f"{_REALISM}.{field}",
        )
    p.add_argument(
        "--sleeve",
        choices=SLEEVES,
        default=None,
        help="shirt sleeves (default: the costume's, short for everyday, elbow for paper)",
    )
    shows_default(
        p.add_argument(
            "--costume",
            choices=COSTUMES,
            default=None,
            help="clothing: everyday (shirt and trousers) or paper (Mamania et al.'s dance "
            "costume, one dress to the elbows, bare forearms, a skin-like gold belt; default "
            "%(stated_default)s)",
        ),
        f"{_SYNTH}.costume",
    )
    p.add_argument(
        "--shirt-colour",
        type=checked_by(imported("mocapkit.synth.render:parse_colour"), "colour"),
        default=None,
        help="shirt colour name or #RRGGBB (default: seeded)",
    )
    p.add_argument(
        "--blackout-s",
        type=_blackout,
        default=None,
        metavar="START,DURATION",
        help="blank every view (black frames, no keypoints) from START for DURATION s",
    )
    p.add_argument("--png", action="store_true", help="write PNG image folders instead of mp4")
    p.add_argument("--overwrite", action="store_true", help="replace an existing session folder")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Render the session and print a summary."""
    from mocapkit.synth.options import RealismOptions
    from mocapkit.synth.session_writer import SynthOptions, synthesize_session

    realism = RealismOptions(
        noise=args.noise,
        blur=args.blur,
        background=args.background,
        marker_noise_mm=args.marker_noise_mm,
        dropout=args.dropout,
        dropout_s=args.dropout_s,
        video_jitter_s=args.video_jitter_s,
    )
    options = SynthOptions(
        height_mm=args.height_mm,
        asf=args.asf,
        sleeve=args.sleeve,
        shirt_colour=args.shirt_colour,
        video_format="png" if args.png else "mp4",
        overwrite=args.overwrite,
        realism=realism,
        blackout_s=args.blackout_s,
        **given(
            rig=args.rig,
            start_s=args.start_s,
            seconds=args.seconds,
            seed=args.seed,
            fps=args.fps,
            marker_rate_hz=args.marker_rate,
            image_size=args.size,
            costume=args.costume,
        ),
    )
    summary = synthesize_session(args.motion, args.out, options)
    print(summary.text())
    return 0
