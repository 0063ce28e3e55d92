"""Micro-benchmark of the SDLS IK alone (`mocapkit bench ik`)."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import ConfigError
from mocapkit.ik.config import IKConfig
from mocapkit.ik.sdls import SDLSSolver
from mocapkit.skeleton.limbs import arm, head_joint, spine_dofs
from mocapkit.skeleton.model import PRISMATIC
from mocapkit.skeleton.presets import load_preset

if TYPE_CHECKING:
    pass

FloatArray = NDArray[np.float64]


def bench_ik(n_frames: int = 2000, repeats: int = 5, rate_hz: float = 50.0) -> dict[str, float]:
    """Warm-started IK solves per second on a synthetic arm-waving sequence (one core).

    Targets come from forward kinematics of a smooth upper-body motion sampled at
    ``rate_hz``; each frame starts from the previous solution (Alg. 1 with the default
    `IKConfig`). The first pass compiles and is not timed.

    Returns
    -------
    dict
        ``solves_per_s`` (median over repeats), ``solves_per_s_min``, ``mean_iterations``,
        ``max_residual_mm``, ``converged_fraction``, ``n_frames``.
    """
    if n_frames < 1 or repeats < 1:
        raise ConfigError(
            f"bench_ik: expected n_frames >= 1 and repeats >= 1, found {n_frames}, {repeats}"
        )
    sk = load_preset("zhang21")
    solver = SDLSSolver(sk, config=IKConfig())
    t = np.arange(n_frames) / rate_hz
    q = np.tile(solver.secondary.omega, (n_frames, 1))
    arms = np.concatenate([arm(sk, side).dofs for side in ("left", "right")])
    # the neck: rotations of the joints from the canonical neck down to the head joint
    neck_joint = sk.joint_index(sk.canonical["neck"][0])
    neck_chain = [head_joint(sk)]
    while neck_chain[-1] != neck_joint and neck_chain[-1] >= 0:
        neck_chain.append(int(sk.parents[neck_chain[-1]]))
    neck = np.flatnonzero(np.isin(sk.dof_joint, neck_chain) & (sk.dof_kind != PRISMATIC))
    for d in arms:
        q[:, d] += 0.5 * np.sin(2 * np.pi * 0.5 * t + d) + 0.4
    for d in spine_dofs(sk):
        q[:, d] += 0.1 * np.sin(2 * np.pi * 0.3 * t + d)
    for d in neck:
        q[:, d] += 0.2 * np.sin(2 * np.pi * 0.4 * t + d)
    q = np.clip(q, sk.lower, sk.upper)
    targets = np.stack([solver.effector_positions(qq) for qq in q])
    solver.solve(q[0], targets[0])  # compile
    rates, iters, resid, conv = [], 0.0, 0.0, 0.0
    for _ in range(repeats):
        qc = q[0].copy()
        n_it = 0
        worst = 0.0
        ok = 0
        start = time.perf_counter()
        for i in range(n_frames):
            res = solver.solve(qc, targets[i])
            qc = res.q
            n_it += res.iterations
            worst = max(worst, float(np.nanmax(res.residual_mm)))
            ok += res.converged
        rates.append(n_frames / (time.perf_counter() - start))
        iters, resid, conv = n_it / n_frames, worst, ok / n_frames
    return {
        "solves_per_s": float(np.median(rates)),
        "solves_per_s_min": float(np.min(rates)),
        "mean_iterations": float(iters),
        "max_residual_mm": float(resid),
        "converged_fraction": float(conv),
        "n_frames": float(n_frames),
    }
