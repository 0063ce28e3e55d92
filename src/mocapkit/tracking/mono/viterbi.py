"""Minimum-weight paths through the layered pose graph: plain and pair-state Viterbi.

Mamania et al. (2004, §4.3, Fig. 5): one layer per frame, one node per surviving pose,
edges weighted by the motion between poses; the answer is the minimum-weight path from
the first layer to the last. Eq. 3 couples three frames (errata M3), so the exact method
runs Viterbi over pair states (phi_k, phi_{k+1}), O(T N^3); a first-order weight runs on
plain states, O(T N^2).

`Decoder` runs either form frame by frame in bounded memory. Offline (``lag=None``) it
fixes a frame once the best paths into all current states agree on it (exact; a frame
still open after a window of frames is fixed from the best current path). Online with
``lag=D`` it fixes frame k - D when frame k arrives, by backtracking from the best state
at k: a latency of D frames, and a path that may differ from the offline one where later
frames would have changed an earlier choice.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocapkit.errors import ConfigError, ShapeError

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


class Decoder:
    """Frame-by-frame Viterbi over plain (``order=1``) or pair states (``order=2``).

    Call `push` once per frame, then `flush`; each returns the (frame, state) decisions
    it makes final, in frame order, and over a whole sequence every frame is decided
    once. Costs are non-negative or any real numbers; a state that no path reaches has
    cost ``inf``.

    Memory is bounded: only the back-pointers of frames not yet decided are kept.
    Online (``lag=D``) frame k - D is fixed when frame k arrives. Offline (``lag=None``)
    a frame is fixed as soon as the best paths into every reachable current state pass
    through one state there (they then share all earlier frames too: survivor merging),
    which is the exact offline answer; a frame still open ``window`` frames later is
    fixed from the best current path, as online with that lag.

    Parameters
    ----------
    order : {1, 2}
        1: weights on pairs of consecutive frames. 2: also on triples (pair states).
    lag : int or None
        Frames of delay before a frame's state is fixed (online); None: offline.
    window : int
        Offline: most frames a frame stays open (memory bound); see above.
    """

    def __init__(self, order: int = 1, lag: int | None = None, window: int = 1 << 30) -> None:
        if order not in (1, 2):
            raise ConfigError(f"Decoder order: expected 1 or 2, found {order}")
        if lag is not None and lag < 0:
            raise ConfigError(f"Decoder lag: expected >= 0 frames or None, found {lag}")
        if window < 1:
            raise ConfigError(f"Decoder window: expected >= 1 frame, found {window}")
        self.order = order
        self.lag = lag
        self.window = window
        self._cost: FloatArray | None = None  # (N_k,) or (N_{k-1}, N_k)
        # back-pointers of frames first_back, first_back + 1, ... (order 1: state of k - 1
        # per state of k; order 2: state of k - 2 per pair state (k - 1, k))
        self._back: deque[NDArray[np.integer]] = deque()
        self._first_back = order
        self._sizes: deque[int] = deque(maxlen=2)
        self._n = 0
        self._next = 0  # oldest frame not decided yet
        #: Offline: frames fixed by the ``window`` rule rather than by merging.
        self.n_forced = 0

    @property
    def n_frames(self) -> int:
        """Frames pushed so far."""
        return self._n

    @property
    def first_open(self) -> int:
        """The oldest frame not decided yet."""
        return self._next

    def push(
        self,
        unary: ArrayLike,
        pairwise: ArrayLike | None = None,
        triple: ArrayLike | None = None,
    ) -> list[tuple[int, int]]:
        """Add frame k; returns the (frame, state) decisions this makes final.

        Parameters
        ----------
        unary : (N_k,) float
        pairwise : (N_{k-1}, N_k) float
            Weight of each edge from frame k - 1 (omit for the first frame).
        triple : (N_{k-2}, N_{k-1}, N_k) float
            Order 2 only, from the third frame on: the weight of each triple.
        """
        u = np.asarray(unary, dtype=float)
        if u.ndim != 1 or u.shape[0] == 0:
            raise ShapeError(f"Decoder.push: expected unary (N,) with N >= 1, found {u.shape}")
        k = self.n_frames
        if k == 0:
            if pairwise is not None or triple is not None:
                raise ShapeError("Decoder.push: the first frame takes no pairwise/triple weights")
            self._cost = u.copy()
        else:
            if pairwise is None:
                raise ShapeError(f"Decoder.push: frame {k} needs pairwise weights")
            p = np.asarray(pairwise, dtype=float)
            if p.shape != (self._sizes[-1], u.shape[0]):
                raise ShapeError(
                    f"Decoder.push: frame {k}: expected pairwise {(self._sizes[-1], u.shape[0])}, "
                    f"found {p.shape}"
                )
            assert self._cost is not None
            if self.order == 1:
                tot = self._cost[:, None] + p
                back = np.argmin(tot, axis=0)
                self._cost = tot[back, np.arange(u.shape[0])] + u
                self._store(back)
            elif k == 1:
                self._cost = self._cost[:, None] + p + u[None, :]
            else:
                if triple is None:
                    raise ShapeError(f"Decoder.push: order 2, frame {k} needs triple weights")
                t = np.asarray(triple, dtype=float)
                want = (self._sizes[-2], self._sizes[-1], u.shape[0])
                if t.shape != want:
                    raise ShapeError(
                        f"Decoder.push: frame {k}: expected triple {want}, found {t.shape}"
                    )
                tot = self._cost[:, :, None] + t  # (i, j, m)
                back = np.argmin(tot, axis=0)  # (j, m)
                jj, mm = np.meshgrid(np.arange(t.shape[1]), np.arange(t.shape[2]), indexing="ij")
                self._cost = tot[back, jj, mm] + p + u[None, :]
                self._store(back)
        self._sizes.append(int(u.shape[0]))
        self._n += 1
        return self._decide()

    def pair_costs(self) -> FloatArray:
        """Order 2: best cost of a path ending in each pair state (N_{k-1}, N_k) (a copy)."""
        if self.order != 2 or self._cost is None or self._cost.ndim != 2:
            raise ShapeError("Decoder.pair_costs: needs order 2 and at least two frames pushed")
        return self._cost.copy()

    def push_reduced(
        self, unary: ArrayLike, pairwise: ArrayLike, best: ArrayLike, back: ArrayLike
    ) -> list[tuple[int, int]]:
        """Order 2, from the third frame on: `push` with the triple step done by the caller.

        ``best[j, m]`` = min over i of ``pair_costs()[i, j] + triple[i, j, m]`` and
        ``back[j, m]`` its argmin (e.g. `mocapkit.tracking.mono.motion_cost.acceleration_min`,
        which never builds the (N_{k-2}, N_{k-1}, N_k) array). Same result as `push`.
        """
        u = np.asarray(unary, dtype=float)
        p = np.asarray(pairwise, dtype=float)
        bst = np.asarray(best, dtype=float)
        bk = np.asarray(back, dtype=np.int64)
        if self.order != 2 or self.n_frames < 2 or self._cost is None:
            raise ShapeError("Decoder.push_reduced: needs order 2 and at least two frames pushed")
        want = (self._sizes[-1], u.shape[0])
        if u.ndim != 1 or p.shape != want or bst.shape != want or bk.shape != want:
            raise ShapeError(
                f"Decoder.push_reduced: expected unary ({want[1]},), pairwise, best and back "
                f"{want}; found {u.shape}, {p.shape}, {bst.shape}, {bk.shape}"
            )
        self._cost = bst + p + u[None, :]
        self._store(bk)
        self._sizes.append(int(u.shape[0]))
        self._n += 1
        return self._decide()

    def _store(self, back: NDArray[np.integer]) -> None:
        """Keep a frame's back-pointers in the smallest integer type that holds them."""
        top = int(back.max()) if back.size else 0
        self._back.append(back.astype(np.min_scalar_type(top)))

    def _entry(self, k: int) -> NDArray[np.integer]:
        return self._back[k - self._first_back]

    def _decide(self) -> list[tuple[int, int]]:
        n = self.n_frames
        if self.lag is not None:
            return self._fix_until(n - 1 - self.lag, self._best_path)
        # the merge check walks back over the open frames: run it less often as they
        # grow (every open/8 frames), so its cost per frame stays bounded
        out = []
        if n % max(1, (n - self._next) // 8) == 0:
            out = self._fix_until(self._merged(), self._best_path)
        forced = self._fix_until(n - 1 - self.window, self._best_path)
        self.n_forced += len(forced)
        return out + forced

    def _fix_until(self, last: int, path_from: Callable[[int], IntArray]) -> list[tuple[int, int]]:
        """Decide the open frames up to ``last`` along ``path_from(first open frame)``."""
        if last < self._next:
            return []
        path = path_from(self._next)
        out = [(f, int(path[f - self._next])) for f in range(self._next, last + 1)]
        self._next = last + 1
        # back-pointers of frames <= next (order 1) / next + 1 (order 2) only lead to
        # decided frames
        while self._back and self._first_back <= self._next + self.order - 1:
            self._back.popleft()
            self._first_back += 1
        return out

    def _best_path(self, first: int) -> IntArray:
        """States of frames first .. n - 1 on the best path into the newest frame."""
        assert self._cost is not None
        n = self.n_frames
        path = np.zeros(n - first, dtype=np.int64)
        if self._cost.ndim == 1:
            path[-1] = int(np.argmin(self._cost))
            for k in range(n - 1, first, -1):
                path[k - 1 - first] = self._entry(k)[path[k - first]]
            return path
        j, m = np.unravel_index(int(np.argmin(self._cost)), self._cost.shape)
        path[-1] = int(m)
        if n - first >= 2:
            path[-2] = int(j)
        for k in range(n - 1, first + 1, -1):
            # entry k: the best state of frame k - 2 given (k - 1, k)
            path[k - 2 - first] = self._entry(k)[path[k - 1 - first], path[k - first]]
        return path

    def _merged(self) -> int:
        """Newest frame through which the best paths into every reachable current state
        pass in one state (with the frame before, for pair states); -1 if none open."""
        assert self._cost is not None
        n = self.n_frames
        if self._cost.ndim == 1:
            s = np.flatnonzero(np.isfinite(self._cost))
            k = n - 1
            while s.shape[0] > 1 and k > self._next:
                s = np.unique(self._entry(k)[s])
                k -= 1
            return k if s.shape[0] <= 1 else -1
        jj, mm = np.nonzero(np.isfinite(self._cost))
        k = n - 1
        while jj.shape[0] > 1 and k > self._next + 1:
            older = self._entry(k)[jj, mm].astype(np.int64)
            pairs = np.unique((older << 32) | jj)  # distinct (k - 2, k - 1) pair states
            jj, mm = pairs >> 32, pairs & 0xFFFFFFFF
            k -= 1
        return k if jj.shape[0] <= 1 else -1

    def forward_costs(self) -> FloatArray:
        """Best cost of a path ending in each state of the newest frame (N_k,)."""
        if self._cost is None:
            raise ShapeError("Decoder.forward_costs: no frame pushed yet")
        c = self._cost
        return np.asarray(c if c.ndim == 1 else c.min(axis=0), dtype=float)

    def best_cost(self) -> float:
        """Total weight of the best path so far."""
        assert self._cost is not None
        return float(np.min(self._cost))

    def flush(self) -> list[tuple[int, int]]:
        """End of the sequence: the open frames' decisions, along the best path."""
        if self.n_frames == 0:
            return []
        return self._fix_until(self.n_frames - 1, self._best_path)


def viterbi(unary: Sequence[ArrayLike], pairwise: Sequence[ArrayLike]) -> tuple[IntArray, float]:
    """Exact minimum of ``sum_k unary[k][s_k] + sum_k pairwise[k][s_k, s_{k+1}]``.

    Parameters
    ----------
    unary : T arrays (N_k,)
    pairwise : T - 1 arrays (N_k, N_{k+1})

    Returns
    -------
    path : (T,) int
    cost : float
    """
    if len(pairwise) != max(len(unary) - 1, 0):
        raise ShapeError(
            f"viterbi: expected {len(unary) - 1} pairwise arrays, found {len(pairwise)}"
        )
    dec = Decoder(1)
    decided = []
    for k, u in enumerate(unary):
        decided += dec.push(u, pairwise[k - 1] if k else None)
    decided += dec.flush()
    return np.array([s for _, s in decided], dtype=np.int64), dec.best_cost()


def pair_viterbi(
    unary: Sequence[ArrayLike], pairwise: Sequence[ArrayLike], triple: Sequence[ArrayLike]
) -> tuple[IntArray, float]:
    """Exact minimum of unary + pairwise + ``sum_k triple[k][s_k, s_{k+1}, s_{k+2}]``.

    Parameters
    ----------
    unary : T arrays (N_k,)
    pairwise : T - 1 arrays (N_k, N_{k+1})
    triple : T - 2 arrays (N_k, N_{k+1}, N_{k+2})
    """
    t = len(unary)
    if len(pairwise) != max(t - 1, 0) or len(triple) != max(t - 2, 0):
        raise ShapeError(
            f"pair_viterbi: expected {t - 1} pairwise and {t - 2} triple arrays, found "
            f"{len(pairwise)} and {len(triple)}"
        )
    dec = Decoder(2)
    decided = []
    for k, u in enumerate(unary):
        decided += dec.push(u, pairwise[k - 1] if k else None, triple[k - 2] if k >= 2 else None)
    decided += dec.flush()
    return np.array([s for _, s in decided], dtype=np.int64), dec.best_cost()
