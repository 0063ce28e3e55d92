"""What is derived from a skeleton alone, computed once per skeleton object and shared.

A `Skeleton` is frozen, so anything that depends on it alone (the kernels' layout, a
limb's indices, a chain's layout, an arm's checked parts) can be kept and handed to
every caller. `PerSkeleton` keeps such values per skeleton object, held weakly (a process
that fits many subjects does not keep every model alive); `readonly_copy` makes the
arrays it shares read-only, so no caller can change them for the others.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable, Hashable
from typing import Any, Generic, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.skeleton.model import Skeleton

V = TypeVar("V")


def readonly_copy(a: ArrayLike, dtype: Any) -> NDArray[Any]:
    """A C-contiguous read-only copy of ``a`` (a shared layout: one compiled kernel type)."""
    out: NDArray[Any] = np.array(a, dtype=dtype, order="C", copy=True)
    out.setflags(write=False)
    return out


class PerSkeleton(Generic[V]):
    """Values derived from a skeleton, by key, kept per skeleton object (held weakly)."""

    def __init__(self) -> None:
        self._store: weakref.WeakKeyDictionary[Skeleton, dict[Hashable, V]] = (
            weakref.WeakKeyDictionary()
        )

    def __contains__(self, skeleton: object) -> bool:
        """Whether values are kept for ``skeleton``."""
        return skeleton in self._store

    def get(self, skeleton: Skeleton, key: Hashable, build: Callable[..., V], *args: Any) -> V:
        """The value of ``key`` for ``skeleton``; ``build(skeleton, *args)`` the first time
        it is asked. An error raised by ``build`` is raised again on the next ask (nothing
        is kept)."""
        found = self._store.get(skeleton)
        if found is None:
            found = self._store[skeleton] = {}
        value = found.get(key)
        if value is None:
            value = found[key] = build(skeleton, *args)
        return value


__all__ = ["PerSkeleton", "readonly_copy"]
