"""Shared fixtures of the report tests: a small synthetic session and result folders."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from mocapkit.io.motion import Motion
from mocapkit.io.motion_files import write_result_folder
from mocapkit.io.session import load_session
from mocapkit.skeleton.kinematics import canonical_positions
from mocapkit.skeleton.presets import load_preset
from mocapkit.synth.session_writer import SynthOptions, synthesize_session


@pytest.fixture(scope="session")
def small_session(tmp_path_factory) -> Path:
    """One second of the built-in wave, one 160x120 camera (31 frames), markers, truth."""
    out = tmp_path_factory.mktemp("report") / "session"
    synthesize_session(
        "builtin:wave", out, SynthOptions(rig="mono", seconds=1.0, image_size=(160, 120), seed=1)
    )
    return out


@pytest.fixture(scope="session")
def npz_result(small_session, tmp_path_factory) -> Path:
    """A result folder (motion.npz, joints.csv, motion.bvh) on the session's time line: the
    zhang21 model at rest, standing on the truth's pelvis and swaying 100 mm sideways."""
    session = load_session(small_session)
    truth = session.truth
    assert truth is not None
    sk = load_preset("zhang21")
    t = truth.time_s
    q = np.zeros((t.shape[0], sk.n_dofs))
    rest_pelvis = canonical_positions(sk, q[0], ("pelvis",))[0]
    pelvis = truth.joints_mm[:, truth.joint_names.index("pelvis")]
    q[:, :3] = pelvis - rest_pelvis
    q[:, 0] += 100.0 * np.sin(2 * np.pi * t)
    q[5] = np.nan  # one frame without a pose
    out = tmp_path_factory.mktemp("report") / "result"
    write_result_folder(out, Motion.from_q(sk, t, q, source="test motion"))
    return out


@pytest.fixture
def csv_result(npz_result, tmp_path) -> Path:
    """A result folder holding only joints.csv (as a raw-marker or other tracker's result)."""
    out = tmp_path / "csv_result"
    out.mkdir()
    shutil.copy(npz_result / "joints.csv", out / "joints.csv")
    return out
