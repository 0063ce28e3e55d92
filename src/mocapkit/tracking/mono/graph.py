"""The layered pose graph of one chain, decoded as it streams, in bounded memory.

Mamania et al. (2004, §4.3): one layer per frame, one node per surviving pose, edges
weighted by the links' motion. `PoseGraph` takes a frame's candidate poses and unary
costs, builds the edge weights (eq. 3's angular acceleration over pair states, errata
M1-M3, ``cost="acceleration"``; eq. 4-5's joint accelerations, ``"joint_acceleration"``;
the first-order rotation, ``"rotation"``) and runs `mocapkit.tracking.mono.viterbi.Decoder`.

Pair-state decoding is O(N^3) per frame; where a frame has more than ``max_pair_states``
poses, the ones with the lowest first-order forward cost are kept (a beam; exact below
the cap). A layer is kept only until its frame is decided, and once the next two frames
no longer read it only with its beam's poses, so memory does not grow with the
recording (the decoder's window bounds the open frames offline, its lag online).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mocapkit.tracking.mono.motion_cost import (
    acceleration_min,
    joint_acceleration_cost,
    pair_omegas_and_rotation,
)
from mocapkit.tracking.mono.stick import StickModel
from mocapkit.tracking.mono.viterbi import Decoder

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass
class Layer:
    """One frame's poses in the graph.

    Attributes
    ----------
    index : int
        Frame index (the graph's layers are consecutive frames).
    time_s : float
    codes : (N,) int
        Flip code of each pose (`mocapkit.tracking.mono.flips.FramePoses`).
    positions : (N, K, 3) float
        The poses (camera frame).
    vectors : (N, L, 3) float
        Their link vectors.
    unary : (N,) float
        Soft cost of each pose.
    keep : (M,) int
        The poses the pair-state decoder keeps (the beam; all of them under the cap).
    info : object
        What the caller attaches to the frame (returned with the decision).
    """

    index: int
    time_s: float
    codes: IntArray
    positions: FloatArray
    vectors: FloatArray
    unary: FloatArray
    keep: IntArray
    info: Any


class PoseGraph:
    """Streaming minimum-weight path through the pose graph of one chain.

    Parameters
    ----------
    model : StickModel
    cost : {"acceleration", "joint_acceleration", "rotation"}
    dt_s : float
        Frame interval used where two frames share a time stamp.
    lag : int or None
        Online fixed lag (frames); None: offline (`Decoder`).
    window : int
        Offline: most frames a frame stays undecided (`Decoder`'s ``window``).
    max_pair_states : int
        Beam cap of pair-state decoding.
    """

    def __init__(
        self,
        model: StickModel,
        cost: str,
        dt_s: float,
        lag: int | None,
        window: int,
        max_pair_states: int,
    ) -> None:
        self.model = model
        self.cost = cost
        self.dt_s = float(dt_s)
        self.max_pair_states = max_pair_states
        self.decoder = Decoder(1 if cost == "rotation" else 2, lag, window)
        self._beam = Decoder(1, lag=0)  # first-order forward costs for the beam
        self._layers: dict[int, Layer] = {}
        self._n = 0
        self._last_w = np.zeros((0, 0, 0, 3))

    def add(
        self,
        time_s: float,
        codes: IntArray,
        positions: FloatArray,
        unary: FloatArray,
        info: Any = None,
        only: int | None = None,
    ) -> list[tuple[Layer, int]]:
        """Add the next frame's poses; returns the (layer, pose index) decisions this makes
        final, in frame order. ``only``: keep just that pose (a known start)."""
        k = self._n
        vectors = self.model.link_vectors(positions)
        prev = self._layers.get(k - 1)
        w_full = r_full = None
        if prev is not None:
            w_full, r_full = pair_omegas_and_rotation(
                prev.vectors, vectors, self._dt(prev.time_s, time_s)
            )
        keep = self._beam_select(unary, r_full)
        if only is not None:
            keep = np.array([only], dtype=np.int64)
        layer = Layer(k, float(time_s), codes, positions, vectors, unary, keep, info)
        self._layers[k] = layer
        self._n += 1
        decided = self._push(layer, w_full, r_full)
        self._compact(k - 2)
        return self._answer(decided)

    def finish(self) -> list[tuple[Layer, int]]:
        """End of the recording: every decision still pending."""
        return self._answer(self.decoder.flush())

    def _answer(self, decided: list[tuple[int, int]]) -> list[tuple[Layer, int]]:
        out = [(self._layers[f], int(self._layers[f].keep[s])) for f, s in decided]
        # a layer is read by the next two frames' weights and until it is decided
        oldest = min(self._n - 2, self.decoder.first_open)
        for f in [f for f in self._layers if f < oldest]:
            del self._layers[f]
        return out

    def _compact(self, k: int) -> None:
        """Layer ``k`` is no longer read by any weight: keep only its beam's poses (what
        a decision can pick), without their link vectors."""
        old = self._layers.get(k)
        if old is None:
            return
        sel = old.keep
        self._layers[k] = Layer(
            old.index,
            old.time_s,
            old.codes[sel],
            old.positions[sel],
            np.zeros((0, 0, 3)),
            old.unary[sel],
            np.arange(sel.shape[0]),
            old.info,
        )

    def _dt(self, t0: float, t1: float) -> float:
        d = t1 - t0
        return d if d > 0 else self.dt_s

    def _beam_select(self, unary: FloatArray, rotation: FloatArray | None) -> IntArray:
        """Poses of this layer the pair-state decoder keeps (all of them under the cap).

        The beam runs a first-order (rotation) forward pass over the full layers and keeps
        the ``max_pair_states`` poses of lowest forward cost.
        """
        n = unary.shape[0]
        if self.decoder.order == 1:
            return np.arange(n)
        if rotation is None:
            self._beam.push(unary)
        else:
            self._beam.push(unary, rotation)
        if n <= self.max_pair_states:
            return np.arange(n)
        cost = self._beam.forward_costs()
        return np.sort(np.argsort(cost, kind="stable")[: self.max_pair_states])

    def _push(
        self, layer: Layer, w_full: FloatArray | None, r_full: FloatArray | None
    ) -> list[tuple[int, int]]:
        sel = layer.keep
        u = layer.unary[sel]
        if w_full is None or r_full is None:
            return self.decoder.push(u)
        prev = self._layers[layer.index - 1]
        pick = np.ix_(prev.keep, sel)
        pair = np.zeros((prev.keep.shape[0], sel.shape[0]))
        if self.cost == "rotation":
            return self.decoder.push(u, r_full[pick])
        w_b = w_full[pick]
        older = self._layers.get(layer.index - 2)
        if older is None:
            self._last_w = w_b
            return self.decoder.push(u, pair)
        dt_mid = 0.5 * self._dt(older.time_s, layer.time_s)
        if self.cost == "acceleration":
            best, back = acceleration_min(self.decoder.pair_costs(), self._last_w, w_b, dt_mid)
            self._last_w = w_b
            return self.decoder.push_reduced(u, pair, best, back)
        triple = joint_acceleration_cost(
            older.positions[older.keep], prev.positions[prev.keep], layer.positions[sel], dt_mid
        )
        self._last_w = w_b
        return self.decoder.push(u, pair, triple)
