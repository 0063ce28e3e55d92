"""A run's per-frame results as compact columns: what a long recording's run keeps.

`ResultTable` holds what each `mocapkit.tracking.base.FrameResult` of a run says
(time, ``q``, ``joints_mm``, status per effector or limb, fit figures, ``worst``,
``held_dofs``) in numpy columns, about 0.7 kB a frame for the mono tracker against 2.7 kB
for the objects with their dicts. It is a sequence of `FrameResult`: indexing it builds that frame's
result (a plain `FrameResult`, without a tracker's own fields), so `write_fit_csv` and
the rest of `mocapkit.pipelines.run` read it as a list; a figure or a status over all
frames is read as one column (`ResultTable.fit_column`, `ResultTable.status_column`).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from typing import overload

import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import ShapeError, unknown_name
from mocapkit.tracking.base import FrameResult

FloatArray = NDArray[np.float64]


class ResultTable(Sequence[FrameResult]):
    """Per-frame results in columns (see the module docstring).

    Parameters
    ----------
    capacity : int
        Expected frame count (the columns are sized for it; they grow past it).
    """

    def __init__(self, capacity: int = 0) -> None:
        self._n = 0
        self._capacity = max(int(capacity), 1)
        self._time = np.empty(self._capacity)
        self._q: FloatArray | None = None
        self._joints: FloatArray | None = None
        self._held: NDArray[np.bool_] | None = None  # (capacity, D): each frame's held_dofs
        self.status_names: list[str] = []  # effectors or limbs, in order of appearance
        self._status_values: list[str] = []  # code k + 1 is _status_values[k]; 0: absent
        self._status = np.zeros((self._capacity, 0), dtype=np.int8)
        self.fit_names: list[str] = []
        self._fit = np.zeros((self._capacity, 0))
        self._has_fit = np.zeros((self._capacity, 0), dtype=bool)
        self._worst_names: list[str] = []
        self._worst = np.zeros(self._capacity, dtype=np.int32)

    # ------------------------------------------------------------------ building
    def append(self, r: FrameResult) -> None:
        """Add one frame's result (its ``q`` and ``joints_mm`` shaped as the first's)."""
        q = np.asarray(r.q, dtype=float)
        joints = np.asarray(r.joints_mm, dtype=float)
        if self._q is None or self._joints is None:
            self._q = np.empty((self._capacity, *q.shape))
            self._joints = np.empty((self._capacity, *joints.shape))
            self._held = np.zeros((self._capacity, q.size), dtype=bool)
        if q.shape != self._q.shape[1:] or joints.shape != self._joints.shape[1:]:
            raise ShapeError(
                f"result at {r.time_s} s: expected q {self._q.shape[1:]} and joints_mm "
                f"{self._joints.shape[1:]} as the first frame's, found {q.shape} and "
                f"{joints.shape}"
            )
        if self._n == self._capacity:
            self._grow(self._capacity + max(self._capacity // 2, 16))
        i = self._n
        self._time[i] = r.time_s
        self._q[i] = q
        self._joints[i] = joints
        assert self._held is not None
        self._held[i] = False
        self._held[i, np.asarray(r.held_dofs, dtype=np.int64)] = True
        for name, st in r.status.items():
            k = self._column(self.status_names, name, "_status")  # may widen the column
            self._status[i, k] = self._code(st)
        for name, v in r.fit.items():
            k = self._column(self.fit_names, name, "_fit")
            self._fit[i, k] = v
            self._has_fit[i, k] = True
        if r.worst not in self._worst_names:
            self._worst_names.append(r.worst)
        self._worst[i] = self._worst_names.index(r.worst)
        self._n += 1

    def extend(self, results: Iterable[FrameResult]) -> None:
        """`append` each of ``results``."""
        for r in results:
            self.append(r)

    def sort_by_time(self) -> None:
        """Put the frames in time order (stable: equal times keep their order)."""
        order = np.argsort(self._time[: self._n], kind="stable")
        if np.array_equal(order, np.arange(self._n)):
            return
        for name in ("_time", "_q", "_joints", "_held", "_status", "_fit", "_has_fit", "_worst"):
            col = getattr(self, name)
            if col is not None:
                col[: self._n] = col[order]

    def trim(self) -> None:
        """Free the room reserved beyond the frames held."""
        if self._capacity > self._n:
            self._grow(self._n)

    def _grow(self, capacity: int) -> None:
        keep = min(self._n, capacity)
        for name in ("_time", "_q", "_joints", "_held", "_status", "_fit", "_has_fit", "_worst"):
            col = getattr(self, name)
            if col is None:
                continue
            new = np.zeros((capacity, *col.shape[1:]), dtype=col.dtype)
            new[:keep] = col[:keep]
            setattr(self, name, new)
        self._capacity = capacity

    def _column(self, names: list[str], name: str, kind: str) -> int:
        if name in names:
            return names.index(name)
        names.append(name)
        pad = ((0, 0), (0, 1))
        if kind == "_status":
            self._status = np.pad(self._status, pad)
        else:
            self._fit = np.pad(self._fit, pad)
            self._has_fit = np.pad(self._has_fit, pad)
        return len(names) - 1

    def _code(self, status: str) -> int:
        if status not in self._status_values:
            self._status_values.append(status)
        return self._status_values.index(status) + 1

    # ------------------------------------------------------------------ reading
    @property
    def time_s(self) -> FloatArray:
        """(T,) s."""
        return self._time[: self._n]

    @property
    def q(self) -> FloatArray:
        """(T, D): each frame's ``q``."""
        if self._q is None:
            return np.zeros((0, 0))
        return self._q[: self._n]

    @property
    def joints_mm(self) -> FloatArray:
        """(T, K, 3): each frame's ``joints_mm``."""
        if self._joints is None:
            return np.zeros((0, 0, 3))
        return self._joints[: self._n]

    def fit_column(self, name: str) -> FloatArray:
        """(T,): each frame's fit figure ``name`` (NaN in frames without it).

        Raises
        ------
        UnknownNameError
            No frame has a figure of that name (lists those there are).
        """
        k = _index("fit figure", name, self.fit_names)
        return np.where(self._has_fit[: self._n, k], self._fit[: self._n, k], np.nan)

    def status_column(self, name: str) -> list[str | None]:
        """Each frame's status of the effector or limb ``name`` (None in frames without it).

        Raises
        ------
        UnknownNameError
            No frame has a status of that name (lists those there are).
        """
        k = _index("status", name, self.status_names)
        values: list[str | None] = [None, *self._status_values]
        return [values[c] for c in self._status[: self._n, k].tolist()]

    def __len__(self) -> int:
        return self._n

    @overload
    def __getitem__(self, index: int) -> FrameResult: ...

    @overload
    def __getitem__(self, index: slice) -> list[FrameResult]: ...

    def __getitem__(self, index: int | slice) -> FrameResult | list[FrameResult]:
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(self._n))]
        i = int(index)
        if i < 0:
            i += self._n
        if not 0 <= i < self._n:
            raise IndexError(f"result {index} of {self._n}")
        assert self._q is not None and self._joints is not None
        status = {
            n: self._status_values[c - 1]
            for n, c in zip(self.status_names, self._status[i].tolist())
            if c
        }
        fit = {
            n: v
            for n, v, has in zip(self.fit_names, self._fit[i].tolist(), self._has_fit[i])
            if has
        }
        assert self._held is not None
        return FrameResult(
            float(self._time[i]),
            self._q[i].copy(),
            self._joints[i].copy(),
            status,
            fit,
            self._worst_names[int(self._worst[i])],
            np.flatnonzero(self._held[i]),
        )

    def __iter__(self) -> Iterator[FrameResult]:
        for i in range(self._n):
            yield self[i]


def _index(kind: str, name: str, names: list[str]) -> int:
    """The column of ``name`` among ``names``; `UnknownNameError` (listing them) if absent."""
    if name not in names:
        raise unknown_name(kind, name, names, "the run's results")
    return names.index(name)


__all__ = ["ResultTable"]
