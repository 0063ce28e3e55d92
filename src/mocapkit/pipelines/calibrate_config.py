"""Defaults of `mocapkit calibrate`, light to import (the CLI help shows them)."""

from __future__ import annotations

#: Fewest images (pairs) with a detected board.
DEFAULT_MIN_BOARDS = 5
#: Largest accepted RMS reprojection error (px), per camera and for the stereo fit. Good
#: chessboard calibrations give well under 1 px (OpenCV's own stereo set: 0.45 px); a pair
#: whose right images are shifted by one gives about 50 px.
DEFAULT_MAX_RMS_PX = 2.0
