"""Settings the accuracy and speed harnesses share, light to import (the CLI help shows them)."""

from __future__ import annotations

#: Half-width (mm) of the uniform marker jitter of
#: `mocapkit.pipelines.accuracy.hybrid_accuracy_repeats`: far below the rendered marker
#: noise (about 1 mm) and the 1 mm the comparisons resolve, far above double round-off at
#: 1-2 m (2e-13 mm).
JITTER_MM = 1e-6
