"""Shared fixtures. Real third-party data is reached only through `shared_data`."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest


def _find_shared_data() -> Path | None:
    env = os.environ.get("MOCAPKIT_SHARED_DATA")
    if env:
        return Path(env) if Path(env).is_dir() else None
    here = Path(__file__).resolve()
    for parent in here.parents:
        candidate = parent / "shared" / "data"
        if candidate.is_dir():
            return candidate
        sibling = parent.parent / "shared" / "data"
        if sibling.is_dir():
            return sibling
    return None


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The ``../shared/data`` folder of real recordings; skips the test when absent."""
    found = _find_shared_data()
    if found is None:
        pytest.skip(
            "real data folder ../shared/data not found (set MOCAPKIT_SHARED_DATA to its path); "
            "real-data tests are skipped"
        )
    return found


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator; tests never touch global random state."""
    return np.random.default_rng(20261121)
