"""The options of a synthetic session that the command line offers, light to import.

Names, ranges and defaults stated once here; `mocapkit.synth.render`, `.rigs`,
`.realism` and `.session_writer` use them, and ``mocapkit synth --help`` shows them
without importing the renderer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from mocapkit.errors import ConfigError

#: Rig names accepted by `mocapkit.synth.rigs.make_rig`.
RIG_NAMES: tuple[str, ...] = ("mono", "stereo", "all", "multi", "ring")
SLEEVES = ("short", "long", "none", "elbow")
#: Clothing of the rendered subject. ``everyday``: a shirt (sleeves per ``sleeve``) and
#: trousers of independent colours. ``paper``: the costume of Mamania et al. (2004, §3):
#: "covers her entire body except the face, forearms, and the feet", with "the golden
#: belt [...] around the waist region" that their skin model "categorised as skin region":
#: one dress colour over trunk, upper arms (sleeves to the elbow) and legs, bare
#: forearms and hands, and a skin-like gold belt (`BELT_BGR`). The neck stays bare and
#: the feet shod (the paper's feet are bare; below the upper body its tracker ignores).
COSTUMES = ("everyday", "paper")

#: Accepted video rates (frames per second), marker rates (Hz) and image sides (px).
FPS_RANGE: tuple[float, float] = (1.0, 1000.0)
MARKER_RATE_RANGE_HZ: tuple[float, float] = (1.0, 2000.0)
IMAGE_SIDE_RANGE_PX: tuple[int, int] = (32, 8192)

BACKGROUNDS = ("textured", "plain")


#: Accepted range (inclusive) of each numeric `RealismOptions` field.
REALISM_RANGES: dict[str, tuple[float, float]] = {
    "noise": (0.0, 100.0),
    "blur": (0.0, 1.0),
    "marker_noise_mm": (0.0, 200.0),
    "dropout": (0.0, 1.0),
    "dropout_s": (0.0, 60.0),
    "video_jitter_s": (0.0, 0.1),
    "marker_jitter_s": (0.0, 0.1),
}


@dataclass(frozen=True)
class RealismOptions:
    """Realism knobs of `synthesize_session` (defaults give a plausible indoor recording).

    Attributes
    ----------
    noise : float
        Sensor noise standard deviation in grey levels (0-255).
    blur : float
        Shutter time as a fraction of the frame interval; the body is rendered at two
        instants within it and averaged (0 disables motion blur).
    background : {"textured", "plain"}
    marker_noise_mm : float
        Standard deviation of marker position noise per axis (mm).
    dropout : float
        Probability per marker and frame that a drop-out run starts.
    dropout_s : float
        Mean length of a drop-out run (s).
    video_jitter_s : float
        Standard deviation of video frame time stamps around the nominal grid (s).
    marker_jitter_s : float
        Standard deviation of marker time stamps (s).
    """

    noise: float = 2.5
    blur: float = 0.5
    background: str = "textured"
    marker_noise_mm: float = 1.0
    dropout: float = 0.002
    dropout_s: float = 0.1
    video_jitter_s: float = 0.002
    marker_jitter_s: float = 0.0002

    def __post_init__(self) -> None:
        for name, (lo, hi) in REALISM_RANGES.items():
            v = getattr(self, name)
            if not (math.isfinite(v) and lo <= v <= hi):
                raise ConfigError(
                    f"--{name.replace('_', '-')}: expected a value in [{lo}, {hi}], found {v}"
                )
        if self.background not in BACKGROUNDS:
            raise ConfigError(
                f"--background: expected one of {', '.join(BACKGROUNDS)}, found {self.background!r}"
            )
