"""Fit the mono tracker's arm prior (`mocapkit.tracking.mono.arm_prior`) on CMU clips.

    python tools/mono_fit_arm_prior.py                    # writes the shipped table
    python tools/mono_fit_arm_prior.py --out /tmp/t.py --clips 01_01.amc 11_01.amc

Reads each clip of ``../shared/data/mocap`` (the canonical joints as `read_motion` gives
them), takes every fourth frame (30 Hz from 120 Hz), computes both arms' features in
the body frame (`arm_features`, the left arm mirrored) and fits a Gaussian mixture by EM
(seeded). The default clips are the project's tuning set (13_26, 01_09, lambada,
charleston1, zombie): the report set (01_01, 01_12, 11_01, 131_01, 131_03) stays
unseen. The table is written as a Python module
(``src/mocapkit/tracking/mono/arm_prior_table.py`` by default).

The data used here was obtained from mocap.cs.cmu.edu. The database was created with
funding from NSF EIA-0196217.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from mocapkit.io.motion_files import read_motion
from mocapkit.pipelines.demo import find_shared_data
from mocapkit.tracking.mono.arm_prior import ArmPrior, arm_features, fit_arm_prior
from mocapkit.tracking.mono.stick import stick_model

CLIPS = ("13_26.bvh", "01_09.amc", "lambada.amc", "charleston1.amc", "zombie.amc")
TABLE = Path(__file__).resolve().parents[1] / "src/mocapkit/tracking/mono/arm_prior_table.py"
COMPONENTS = 12
REGULARISATION = 0.03
SEED = 0


def clip_features(path: Path, step: int = 4) -> np.ndarray:
    """Both arms' features (2 S, 6) of every ``step``-th frame of a clip."""
    motion = read_motion(str(path))
    model = stick_model()
    names = list(motion.joint_names)
    joints = np.asarray(motion.joints_mm)[::step][:, [names.index(n) for n in model.joint_names]]
    return arm_features(model, joints).reshape(-1, 6)


def fit_on(clips: Sequence[str], mocap: Path) -> tuple[ArmPrior, int]:
    """The prior fitted on these clips and the number of arm samples used."""
    x = np.concatenate([clip_features(mocap / c) for c in clips])
    x = x[np.isfinite(x).all(axis=1)]
    return (
        fit_arm_prior(x, COMPONENTS, np.random.default_rng(SEED), regularisation=REGULARISATION),
        int(x.shape[0]),
    )


def _literal(a: object, indent: int, prefix: int) -> str:
    """A nested list literal laid out as ``ruff format`` lays it out (100 columns)."""
    if np.ndim(a) == 0:
        return f"{float(a):.8g}"
    items = [_literal(x, indent + 4, indent + 4) for x in a]
    flat = "[" + ", ".join(items) + "]"
    if "\n" not in flat and prefix + len(flat) <= 100:
        return flat
    pad = " " * (indent + 4)
    return "[\n" + "".join(f"{pad}{x},\n" for x in items) + " " * indent + "]"


def write_table(prior: ArmPrior, clips: Sequence[str], samples: int, out: Path) -> None:
    def arr(a: np.ndarray, name: str) -> str:
        return _literal(np.asarray(a), 0, len(name) + 3)

    text = f'''"""Shipped parameters of the mono tracker's arm prior (generated; do not edit).

Written by ``tools/mono_fit_arm_prior.py``: a {COMPONENTS}-component Gaussian mixture
(`mocapkit.tracking.mono.arm_prior.fit_arm_prior`, EM, seed {SEED}) over {samples} arm
samples (both arms, every fourth frame) of the CMU clips
{", ".join(clips)} from ``shared/data/mocap``.
These are the project's tuning clips: the report clips stay unseen.

The data used here was obtained from mocap.cs.cmu.edu. The database was created with
funding from NSF EIA-0196217.
"""

WEIGHTS = {arr(prior.weights, "WEIGHTS")}

MEANS = {arr(prior.means, "MEANS")}

COVARIANCES = {arr(prior.covariances, "COVARIANCES")}

CAP = {prior.cap!r}
'''
    out.write_text(text)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clips", nargs="*", default=list(CLIPS))
    ap.add_argument("--mocap", type=Path, help="default: ../shared/data/mocap (as the CLI)")
    ap.add_argument("--out", type=Path, default=TABLE)
    a = ap.parse_args()
    mocap = a.mocap
    if mocap is None:
        data = find_shared_data()
        if data is None:
            raise SystemExit("no --mocap given and ../shared/data/mocap not found")
        mocap = data / "mocap"
    prior, n = fit_on(a.clips, mocap)
    write_table(prior, a.clips, n, a.out)
    print(f"{a.out}: {COMPONENTS} components from {n} arm samples of {', '.join(a.clips)}")


if __name__ == "__main__":
    main()
