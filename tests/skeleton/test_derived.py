"""Values derived from a skeleton alone: built once per skeleton and key, held weakly,
shared read-only."""

from __future__ import annotations

import gc
import weakref

import numpy as np
import pytest

from mocapkit.errors import UnknownNameError
from mocapkit.skeleton import load_preset
from mocapkit.skeleton.derived import PerSkeleton, readonly_copy
from mocapkit.skeleton.limbs import limb


def test_built_once_per_skeleton_and_key() -> None:
    cache: PerSkeleton[list[str]] = PerSkeleton()
    a, b = load_preset("upper_stick"), load_preset("upper_stick")
    calls: list[str] = []

    def build(skeleton: object, tag: str) -> list[str]:
        assert skeleton is a or skeleton is b
        calls.append(tag)
        return [tag]

    first = cache.get(a, "k", build, "a")
    assert cache.get(a, "k", build, "again") is first
    assert cache.get(a, "other", build, "a2") == ["a2"]
    assert cache.get(b, "k", build, "b") == ["b"]  # another object, its own value
    assert calls == ["a", "a2", "b"]
    assert a in cache and b in cache


def test_held_weakly() -> None:
    cache: PerSkeleton[int] = PerSkeleton()
    sk = load_preset("upper_stick")
    cache.get(sk, None, lambda skeleton: 1)
    alive = weakref.ref(sk)
    del sk
    gc.collect()
    assert alive() is None


def test_a_failed_build_is_not_kept() -> None:
    sk = load_preset("upper_stick")
    with pytest.raises(UnknownNameError, match="left_leg"):
        limb(sk, "left_leg")  # upper_stick has no legs
    with pytest.raises(UnknownNameError, match="left_leg"):
        limb(sk, "left_leg")
    assert limb(sk, "left_arm") is limb(sk, "left_arm")


def test_readonly_copy() -> None:
    src = np.arange(12, dtype=np.int32).reshape(3, 4).T  # not C-contiguous
    out = readonly_copy(src, np.int64)
    assert out.dtype == np.int64 and out.flags.c_contiguous and not out.flags.writeable
    np.testing.assert_array_equal(out, src)
    src[0, 0] = 99
    assert out[0, 0] == 0  # a copy
    with pytest.raises(ValueError, match="read-only"):
        out[0, 0] = 1
