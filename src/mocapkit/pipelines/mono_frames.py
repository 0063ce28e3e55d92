"""The mono tracker's per-frame answers of a run as compact columns.

`MonoFrames` keeps what each `mocapkit.tracking.mono.tracker.MonoFrame` of a run says
in numpy columns (about 0.4 kB a frame), for what reads a whole run afterwards: the
run's summary (`mocapkit.pipelines.mono.MonoRun.summary`), the refined link lengths and
the accuracy harness's flips (`mocapkit.pipelines.mono_accuracy`). It is a sequence of
`MonoFrame` (indexing builds the frame's object) with the columns as attributes.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from typing import overload

import numpy as np
from numpy.typing import NDArray

from mocapkit.tracking.mono.tracker import MonoFrame

FloatArray = NDArray[np.float64]


class MonoFrames(Sequence[MonoFrame]):
    """A run's `MonoFrame` answers in columns, in the order given (`sort` by index).

    Attributes
    ----------
    frame_index, code, n_candidates, n_survivors : (T,) int
        ``frame_index``: each frame's ``MonoFrame.index``.
    time_s, residual_px, depth_mm : (T,) float
    pruned_all : (T,) bool
    joints_in_camera : (T, K, 3) float
    """

    def __init__(self, frames: Iterable[MonoFrame] = ()) -> None:
        # the latest frames wait as tuples and arrays, up to _BLOCK of them, then join
        # a block of columns; reading a column joins the blocks into one
        self._rows: list[tuple[int, float, int, int, int, bool, float, float]] = []
        self._joints: list[FloatArray] = []
        self._blocks: list[dict[str, NDArray[np.generic]]] = []
        self.extend(frames)

    def append(self, f: MonoFrame) -> None:
        """Add one frame (its fields are kept, not the object)."""
        self._rows.append(
            (
                f.index,
                f.time_s,
                f.code,
                f.n_candidates,
                f.n_survivors,
                f.pruned_all,
                f.residual_px,
                f.depth_mm,
            )
        )
        self._joints.append(np.asarray(f.joints_in_camera, dtype=float))
        if len(self._rows) >= _BLOCK:
            self._close()

    def extend(self, frames: Iterable[MonoFrame]) -> None:
        """`append` each of ``frames``."""
        for f in frames:
            self.append(f)

    def sort(self) -> None:
        """Put the frames in index order (stable)."""
        cols = self._columns()
        order = np.argsort(cols["index"], kind="stable")
        self._blocks = [{k: v[order] for k, v in cols.items()}]

    def _close(self) -> None:
        rows = self._rows
        if not rows:
            return
        block: dict[str, NDArray[np.generic]] = {
            name: np.array([r[i] for r in rows], dtype=dtype)
            for i, (name, dtype) in enumerate(_SCALARS)
        }
        block["joints_in_camera"] = np.stack(self._joints)
        self._blocks.append(block)
        self._rows, self._joints = [], []

    def _columns(self) -> dict[str, NDArray[np.generic]]:
        self._close()
        if not self._blocks:
            empty: dict[str, NDArray[np.generic]] = {
                name: np.zeros(0, dtype=dtype) for name, dtype in _SCALARS
            }
            return {**empty, "joints_in_camera": np.zeros((0, 0, 3))}
        if len(self._blocks) > 1:
            keys = self._blocks[0]
            self._blocks = [{k: np.concatenate([b[k] for b in self._blocks]) for k in keys}]
        return self._blocks[0]

    @property
    def frame_index(self) -> NDArray[np.int64]:
        return np.asarray(self._columns()["index"], dtype=np.int64)

    @property
    def time_s(self) -> FloatArray:
        return np.asarray(self._columns()["time_s"], dtype=float)

    @property
    def code(self) -> NDArray[np.int64]:
        return np.asarray(self._columns()["code"], dtype=np.int64)

    @property
    def n_candidates(self) -> NDArray[np.int64]:
        return np.asarray(self._columns()["n_candidates"], dtype=np.int64)

    @property
    def n_survivors(self) -> NDArray[np.int64]:
        return np.asarray(self._columns()["n_survivors"], dtype=np.int64)

    @property
    def pruned_all(self) -> NDArray[np.bool_]:
        return np.asarray(self._columns()["pruned_all"], dtype=bool)

    @property
    def residual_px(self) -> FloatArray:
        return np.asarray(self._columns()["residual_px"], dtype=float)

    @property
    def depth_mm(self) -> FloatArray:
        return np.asarray(self._columns()["depth_mm"], dtype=float)

    @property
    def joints_in_camera(self) -> FloatArray:
        return np.asarray(self._columns()["joints_in_camera"], dtype=float)

    def __len__(self) -> int:
        return len(self._rows) + sum(len(b["index"]) for b in self._blocks)

    @overload
    def __getitem__(self, i: int) -> MonoFrame: ...

    @overload
    def __getitem__(self, i: slice) -> list[MonoFrame]: ...

    def __getitem__(self, i: int | slice) -> MonoFrame | list[MonoFrame]:
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(len(self)))]
        c = self._columns()
        k = int(i)
        return MonoFrame(
            index=int(c["index"][k]),
            time_s=float(c["time_s"][k]),
            joints_in_camera=np.array(c["joints_in_camera"][k], dtype=float),
            code=int(c["code"][k]),
            n_candidates=int(c["n_candidates"][k]),
            n_survivors=int(c["n_survivors"][k]),
            pruned_all=bool(c["pruned_all"][k]),
            residual_px=float(c["residual_px"][k]),
            depth_mm=float(c["depth_mm"][k]),
        )

    def __iter__(self) -> Iterator[MonoFrame]:
        for k in range(len(self)):
            yield self[k]


#: Frames held as tuples before they join a block of columns.
_BLOCK = 256
#: The scalar columns, in `MonoFrame`'s order, with their types.
_SCALARS: tuple[tuple[str, type], ...] = (
    ("index", np.int64),
    ("time_s", np.float64),
    ("code", np.int64),
    ("n_candidates", np.int64),
    ("n_survivors", np.int64),
    ("pruned_all", np.bool_),
    ("residual_px", np.float64),
    ("depth_mm", np.float64),
)


def camera_joints(frames: Sequence[MonoFrame]) -> FloatArray:
    """The frames' stick joints (T, K, 3) in the camera frame (mm)."""
    if isinstance(frames, MonoFrames):
        return frames.joints_in_camera
    return np.stack([f.joints_in_camera for f in frames])


__all__ = ["MonoFrames", "camera_joints"]
