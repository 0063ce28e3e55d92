"""Constants of the session builder that ``mocapkit session --help`` shows, light to import.

`mocapkit.io.calib_toml` and `mocapkit.io.video` use them.
"""

from __future__ import annotations

#: mm per unit of a Calib.toml's translation, by the unit's name.
UNITS_MM: dict[str, float] = {"m": 1000.0, "mm": 1.0}
#: Video encoders pad frames to whole 16 x 16 macroblocks; a calibration made on the
#: padded frames is larger than the video that a player shows.
PAD_MULTIPLE_PX = 16
