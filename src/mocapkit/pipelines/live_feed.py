"""The input side of live tracking: LSL streams and cameras matched into session samples.

`mocapkit.pipelines.live.track_live` runs one of the trackers (hybrid, stereo, mono) on
live inputs, frame by frame, through the same ``update``/``push`` a recorded session goes
through. A *setup* session folder gives what does not stream: ``cameras.json`` (calibration) and
``session.json`` (subject, marker sets and their offsets). The inputs:

- markers: an LSL stream of ``<marker>_x/_y/_z`` channels (`mocapkit.io.lsl`), e.g. the
  Vicon, Qualisys or OptiTrack LSL bridge;
- keypoints: per camera an LSL stream of ``<joint>_x/_y`` channels (px);
- video: per camera an OpenCV device index or stream URL (frames stamped with the LSL
  clock when grabbed), or a replay's frame-number stream (`mocapkit.pipelines.replay`),
  whose frames are read from the replayed session's video.

**Clocks.** Each stream keeps its own rate; samples are matched by their LSL time stamps
as `mocapkit.io.session.Session.samples` matches a recording: one step per frame of the
first camera (per keypoints sample for mono; per marker sample for the hybrid without a
camera), with the newest marker sample at or before the frame time and each other
input's nearest sample. A frame waits at most ``match_wait_s`` for a partner sample that
is due (its stream's nominal period has passed) but not yet received; then the newest one
received is used with its own time stamp, so the tracker's age rule
(`mocapkit.tracking.base.BRIDGE_S`) bridges and then releases what is late or missing:
never a stale sample taken as new. A replayed stream is tracked on the session's own
time line (its ``desc/replay``), so a live take of a replay equals ``mocapkit track``.

**Output.** An LSL stream (type ``MocapJoints``) of the 15 canonical joints in mm (NaN
where unobserved, by the runner's rule `mocapkit.pipelines.run.unobserved_to_nan`), each
sample stamped with the LSL time stamp of the input sample it answers; optionally the
result folder (``--out``, for ``mocapkit view``) and the inputs as a session folder
(``--record``), both written atomically at the end.

**Stop.** Ctrl-C, or an input lost (its source closed, or silent for ``lost_after_s``),
ends the run cleanly: what was tracked is written and `LiveReport.stop_reason` says what
ended it.
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import ConfigError, FormatError, UnknownNameError, unknown_name
from mocapkit.io.lsl import (
    FRAMES_TYPE,
    KEYPOINTS_TYPE,
    MARKERS_TYPE,
    StreamLayout,
    find_stream,
    inlet_layout,
    local_clock,
    lost_error,
    lsl_timeout_error,
    open_inlet,
)
from mocapkit.io.marker_sets import set_centre_mm
from mocapkit.io.markers import MarkerData
from mocapkit.io.session import Session, SessionSample, load_session
from mocapkit.io.video import FrameStream, LazyFrame
from mocapkit.pipelines.live_config import LiveConfig
from mocapkit.skeleton.model import CANONICAL_JOINTS

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class LiveInputs:
    """Where the inputs come from.

    Attributes
    ----------
    markers : str or None
        LSL stream name of the markers.
    keypoints : mapping of camera -> LSL stream name
    video : mapping of camera -> source
        ``lsl:<stream>`` (a replay's frame numbers), a device index (``"0"``) or a URL.
    """

    markers: str | None = None
    keypoints: Mapping[str, str] = field(default_factory=dict)
    video: Mapping[str, str] = field(default_factory=dict)


def replay_inputs(setup: Session, prefix: str) -> LiveInputs:
    """The inputs of a replay of ``setup`` (`mocapkit.pipelines.replay.stream_names`)."""
    from mocapkit.pipelines.replay import stream_names

    names = stream_names(setup, prefix)
    return LiveInputs(
        names.get("markers"),
        {k.split(":", 1)[1]: v for k, v in names.items() if k.startswith("keypoints:")},
        {k.split(":", 1)[1]: f"lsl:{v}" for k, v in names.items() if k.startswith("frames:")},
    )


# ====================================================================== input buffers


#: A partner sample is awaited once its stream's newest sample is this fraction of a
#: nominal period older than the step (time-stamp jitter of a quarter period allowed).
DUE_FRACTION = 0.75


class StreamLost(Exception):
    """An input ended; the message says which and why."""


class _Input:
    """Received samples of one input, oldest first: time (tracking time line), LSL stamp
    and values; ``last_rx`` is the wall time of the last sample received."""

    def __init__(self, label: str, rate_hz: float) -> None:
        self.label = label
        self.rate_hz = rate_hz
        self.t: deque[float] = deque()
        self.stamp: deque[float] = deque()
        self.values: deque[Any] = deque()
        self.last_rx = time.monotonic()
        self.n_received = 0
        self.newest_t = -math.inf
        #: Why the input ended (empty while it runs).
        self.lost = ""
        #: Called with (time, values) of every sample received (a recorder).
        self.tap: Callable[[float, Any], None] | None = None

    def poll(self) -> None:
        """Take what has arrived (never blocks); raise `StreamLost` when the source ended."""

    def wait(self, timeout_s: float) -> None:
        """Block up to ``timeout_s`` for a sample (default: sleep)."""
        time.sleep(timeout_s)

    def _add(self, t: float, stamp: float, value: Any) -> None:
        self.t.append(t)
        self.stamp.append(stamp)
        self.values.append(value)
        self.newest_t = max(self.newest_t, t)
        self.n_received += 1
        self.last_rx = time.monotonic()
        if self.tap is not None:
            self.tap(t, value)

    def close(self) -> None:
        """Release the source."""

    def due(self, t: float) -> bool:
        """Whether a sample at or before ``t`` may exist that has not been received: the
        newest one is more than `DUE_FRACTION` of a nominal period before ``t`` (a
        stream comes in order, so a sample after ``t`` ends the wait), or none has come
        yet."""
        if self.lost:
            return False
        if not math.isfinite(self.newest_t):
            return True
        if self.rate_hz <= 0:
            return False
        return self.newest_t + DUE_FRACTION / self.rate_hz <= t + 1e-9

    def newest_at_or_before(self, t: float) -> int:
        """Index of the newest sample at or before ``t`` (-1 when none); older ones are
        forgotten except that one."""
        k = -1
        for i, ti in enumerate(self.t):
            if ti <= t + 1e-9:
                k = i
            else:
                break
        for _ in range(max(k, 0)):
            self.t.popleft()
            self.stamp.popleft()
            self.values.popleft()
        return 0 if k >= 0 else -1

    def nearest(self, t: float) -> int:
        """Index of the sample nearest to ``t`` (-1 when none); older ones forgotten."""
        if not self.t:
            return -1
        k = int(np.argmin(np.abs(np.asarray(self.t) - t)))
        for _ in range(k):
            self.t.popleft()
            self.stamp.popleft()
            self.values.popleft()
        return 0


class _LslInput(_Input):
    """An LSL inlet; time stamps mapped to the tracking time line (`_Clock`)."""

    def __init__(
        self, label: str, layout: StreamLayout, inlet: Any, to_time: Callable[[float], float]
    ) -> None:
        super().__init__(label, layout.rate_hz)
        self.layout = layout
        self.inlet = inlet
        # a live device's clock mapped to this machine's (measured once at connection);
        # a replay's stamps are the replay clock's own (`mocapkit.io.lsl.ReplayClock`)
        offset = 0.0 if layout.replay_clock is not None else float(inlet.time_correction(5.0))
        self.to_time = to_time if offset == 0.0 else (lambda stamp: to_time(stamp + offset))
        self._lost = lost_error()
        self._timeout = lsl_timeout_error()
        self._convert: Callable[[list[float]], Any] = self._identity
        if layout.dims in (2, 3):
            shape, scale = (len(layout.points), layout.dims), layout.scale
            self._convert = lambda row: np.asarray(row, dtype=float).reshape(shape) * scale

    @staticmethod
    def _identity(row: list[float]) -> Any:
        return row

    def poll(self) -> None:
        try:
            data, stamps = self.inlet.pull_chunk(timeout=0.0)
        except self._lost:
            raise StreamLost(f"{self.label}: its source closed the stream") from None
        except self._timeout:  # the inlet is re-connecting: nothing to take now
            return
        for row, stamp in zip(data, stamps):
            self._add(self.to_time(stamp), stamp, self._convert(row))

    def wait(self, timeout_s: float) -> None:
        try:
            row, stamp = self.inlet.pull_sample(timeout=timeout_s)
        except self._lost:
            raise StreamLost(f"{self.label}: its source closed the stream") from None
        except self._timeout:
            return
        if row is not None:
            self._add(self.to_time(stamp), stamp, self._convert(row))

    def close(self) -> None:
        self.inlet.close_stream()


class _CameraInput(_Input):
    """An OpenCV camera (device index or URL) read on a thread; frames stamped with the
    LSL clock when grabbed. At most ``keep`` frames wait; older ones are dropped."""

    def __init__(self, label: str, source: str, keep: int = 8) -> None:
        cap = cv2.VideoCapture(int(source) if source.isdigit() else source)
        if not cap.isOpened():
            raise ConfigError(
                f"{label}: cannot open camera {source!r} (an OpenCV device index or a stream URL)"
            )
        fps = float(cap.get(cv2.CAP_PROP_FPS))
        super().__init__(label, fps if 0 < fps < 1000 else 0.0)
        self._cap = cap
        self._keep = keep
        self._lock = threading.Lock()
        self._incoming: deque[tuple[float, NDArray[np.uint8]]] = deque()
        self._ended = threading.Event()
        self._stop = threading.Event()
        self.overwritten = 0
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            ok, img = self._cap.read()
            stamp = local_clock()
            if not ok:
                self._ended.set()
                return
            with self._lock:
                self._incoming.append((stamp, np.asarray(img, dtype=np.uint8)))
                while len(self._incoming) > self._keep:
                    self._incoming.popleft()
                    self.overwritten += 1

    def poll(self) -> None:
        with self._lock:
            got, self._incoming = list(self._incoming), deque()
        for stamp, img in got:
            self._add(stamp, stamp, img)
        if not got and self._ended.is_set():
            raise StreamLost(f"{self.label}: the camera delivered no more frames")

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._cap.release()


class HeldFrame(LazyFrame):
    """A frame already in memory, handed out as a `LazyFrame`."""

    def __init__(self, image: NDArray[np.uint8], index: int, time_s: float) -> None:
        self._image = image
        self.index = index
        self.time_s = time_s

    def load(self) -> NDArray[np.uint8]:
        return self._image


# ====================================================================== the input side


class _Clock:
    """The tracking time line: a replay's session time, else the LSL clock."""

    def __init__(self) -> None:
        self.replay: Any = None

    def bind(self, layout: StreamLayout) -> Callable[[float], float]:
        clock = layout.replay_clock
        if clock is None:
            if self.replay is not None:
                raise ConfigError(
                    f"LSL stream {layout.name!r} is live but another input is a replay; "
                    "give inputs of one kind"
                )
            return float
        if self.replay is not None and self.replay != clock:
            raise ConfigError(
                f"LSL stream {layout.name!r} is from another replay than the other inputs"
            )
        self.replay = clock
        return clock.to_session


@dataclass
class LiveStats:
    """Counts and latencies of a live run."""

    received: dict[str, int] = field(default_factory=dict)
    frames_tracked: int = 0
    frames_dropped: int = 0
    latency_ms: list[float] = field(default_factory=list)
    step_cpu_ms: list[float] = field(default_factory=list)
    results: int = 0
    #: The process's resident memory (MB) at the first result and at the end.
    rss_first_mb: float = math.nan
    rss_last_mb: float = math.nan


def rss_mb() -> float:
    """This process's resident memory (MB; NaN where /proc is absent)."""
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
    except (OSError, ValueError, IndexError):
        return math.nan
    return pages * os.sysconf("SC_PAGE_SIZE") / 1e6


class LiveFeed:
    """The live inputs of one tracker as a stream of `SessionSample` (see module docstring).

    Parameters
    ----------
    setup : Session
        Calibration and subject.
    inputs : LiveInputs
    driver : str
        Role of the input whose samples set the time line: ``frames:<camera>``,
        ``keypoints:<camera>`` or ``markers``.
    config : LiveConfig
    stop : threading.Event, optional
        Set it to end the stream (as `request_stop`).
    """

    def __init__(
        self,
        setup: Session,
        inputs: LiveInputs,
        driver: str,
        config: LiveConfig,
        stop: threading.Event | None = None,
    ) -> None:
        self.setup = setup
        self.config = config
        self.driver = driver
        self.clock = _Clock()
        self.inputs: dict[str, _Input] = {}
        self.layouts: dict[str, StreamLayout] = {}
        self.video_time: dict[str, FloatArray] = {}
        self._streams: dict[str, FrameStream] = {}
        self.stats = LiveStats()
        self.stop_reason = ""
        self._stop = threading.Event()
        self._external = stop
        self.marker_names: tuple[str, ...] = ()
        self._sets: dict[str, list[int]] = {}
        self._last_full: dict[str, FloatArray] = {}
        self.pending: deque[tuple[float, float]] = deque()  # (time, stamp) of steps taken
        try:
            self._connect(inputs)
        except BaseException:
            self.close()
            raise
        if driver not in self.inputs:
            raise ConfigError(f"live: no input {driver!r}; inputs: {sorted(self.inputs)}")

    # ------------------------------------------------------------------ connecting

    def _lsl(self, label: str, name: str, expected: str) -> tuple[StreamLayout, Any]:
        info = find_stream(name, self.config.connect_timeout_s)
        inlet = open_inlet(info, timeout_s=self.config.connect_timeout_s)
        layout = inlet_layout(inlet)
        if layout.type != expected:
            inlet.close_stream()
            raise FormatError(
                f"{label}: LSL stream {name!r} has type {layout.type!r}, expected {expected!r}"
            )
        return layout, inlet

    def _connect(self, inputs: LiveInputs) -> None:
        setup = self.setup
        if inputs.markers is not None:
            layout, inlet = self._lsl("markers", inputs.markers, MARKERS_TYPE)
            self._add_lsl("markers", layout, inlet)
            self._bind_marker_sets(layout)
        for cam, name in inputs.keypoints.items():
            if cam not in setup.camera_names:
                raise unknown_name("camera", cam, setup.camera_names, "--keypoints")
            layout, inlet = self._lsl(f"keypoints of {cam}", name, KEYPOINTS_TYPE)
            unknown = [p for p in layout.points if p not in CANONICAL_JOINTS]
            if unknown:
                inlet.close_stream()
                raise FormatError(
                    f"LSL stream {name!r}: joint {unknown[0]!r} is not a canonical joint; "
                    f"expected names among {', '.join(CANONICAL_JOINTS)}"
                )
            self._add_lsl(f"keypoints:{cam}", layout, inlet)
        for cam, source in inputs.video.items():
            if cam not in setup.camera_names:
                raise unknown_name("camera", cam, setup.camera_names, "--video")
            if source.startswith("lsl:"):
                layout, inlet = self._lsl(f"video of {cam}", source[4:], FRAMES_TYPE)
                self._add_lsl(f"frames:{cam}", layout, inlet)
                self._open_replayed_video(cam, layout)
            else:
                if self.clock.replay is not None:
                    raise ConfigError(
                        f"--video {cam}={source}: a camera runs on the LSL clock, the other "
                        "inputs on a replay's session clock; give a replay's frames "
                        "(lsl:STREAM) or live streams"
                    )
                self.inputs[f"frames:{cam}"] = _CameraInput(f"camera {cam} ({source})", source)

    def _add_lsl(self, role: str, layout: StreamLayout, inlet: Any) -> None:
        to_time = self.clock.bind(layout)
        label = f"{role.split(':')[0]} stream {layout.name!r}"
        self.inputs[role] = _LslInput(label, layout, inlet, to_time)
        self.layouts[role] = layout

    def _bind_marker_sets(self, layout: StreamLayout) -> None:
        """Members of the setup's marker sets, found among the stream's markers."""
        self.marker_names = layout.points
        probe = MarkerData(
            np.zeros(1), layout.points, np.zeros((1, len(layout.points), 3)), 1.0,
            f"LSL stream {layout.name!r}",
        )  # fmt: skip
        for set_name, members in self.setup.marker_sets.items():
            try:
                self._sets[set_name] = probe.indices(members)
            except UnknownNameError as exc:
                raise FormatError(
                    f"{self.setup.path}: marker set {set_name!r}: {exc}; the stream's "
                    f"channels name markers {list(layout.points)}"
                ) from None

    def _open_replayed_video(self, cam: str, layout: StreamLayout) -> None:
        from mocapkit.pipelines.replay import session_path_of

        where = session_path_of(layout.meta) or self.setup.path
        if layout.replay_clock is None:
            raise ConfigError(
                f"LSL stream {layout.name!r} sends frame numbers but is no replay (no "
                "desc/replay): give a camera index or URL for live video"
            )
        session = self.setup if Path(where) == self.setup.path else load_session(where)
        video = session.video(cam)
        self.video_time[cam] = video.time_s
        self._streams[cam] = video.open()

    # ------------------------------------------------------------------ running

    def request_stop(self, reason: str) -> None:
        """End the stream at the next step (from a signal handler or another thread)."""
        if not self.stop_reason:
            self.stop_reason = reason
        self._stop.set()

    def _poll(self, inp: _Input, wait_s: float = 0.0) -> None:
        """Take what ``inp`` has received; a lost input is marked (`_Input.lost`)."""
        if inp.lost:
            return
        try:
            inp.wait(wait_s) if wait_s > 0 else inp.poll()
        except StreamLost as exc:
            inp.lost = f"lost {exc}"
            return
        silent = time.monotonic() - inp.last_rx
        # before its first sample an input has connect_timeout_s to start sending
        limit = self.config.lost_after_s if inp.n_received else self.config.connect_timeout_s
        if silent > limit:
            inp.lost = f"lost {inp.label}: no sample for {silent:.1f} s (lost after {limit:g} s)"

    def samples(self) -> Iterator[SessionSample]:
        """The matched samples, until a stop or a lost input (`stop_reason` says which).

        When an input is lost, the samples of the driving input already received are
        still tracked (a lost partner's last sample then ages out by the tracker's
        rule); then the stream ends.
        """
        drv = self.inputs[self.driver]
        index = 0
        start = time.monotonic()
        for inp in self.inputs.values():  # silence is counted from now, not from connecting
            inp.last_rx = start
        while not self._stop.is_set():
            if self._external is not None and self._external.is_set():
                self.request_stop("stopped")
                break
            for role, inp in self.inputs.items():
                self._poll(inp)
                self.stats.received[role] = inp.n_received
            lost = [i.lost for i in self.inputs.values() if i.lost]
            if not drv.t:
                if lost:
                    self.request_stop("; ".join(lost))
                    break
                self._poll(drv, 0.002)
                continue
            t, stamp, value = drv.t.popleft(), drv.stamp.popleft(), drv.values.popleft()
            if (
                drv.t
                and math.isfinite(self.config.max_behind_s)
                and local_clock() - stamp > self.config.max_behind_s
            ):
                self.stats.frames_dropped += 1
                continue
            sample = self._sample(index, t, stamp, value)
            if sample is None:  # a camera without any frame yet
                self.stats.frames_dropped += 1
                continue
            yield sample
            index += 1
            self.stats.frames_tracked += 1

    def _missing(self, role: str, inp: _Input, t: float) -> bool:
        """Whether partner ``inp`` still lacks its sample for step time ``t``: the markers
        one that is due (`_Input.due`), another input one at or after ``t``."""
        if role == "markers":
            return inp.due(t)
        return not inp.lost and inp.newest_t < t - 1e-9

    def _wait_partners(self, t: float) -> None:
        deadline = time.monotonic() + self.config.match_wait_s
        waiting = [
            (r, i) for r, i in self.inputs.items() if r != self.driver and self._missing(r, i, t)
        ]
        while waiting and time.monotonic() < deadline:
            for _, inp in waiting:
                self._poll(inp)
            waiting = [(r, i) for r, i in waiting if self._missing(r, i, t)]
            if waiting:
                time.sleep(0.0005)

    def _frame(self, cam: str, inp: _Input, t: float, value: Any, index: int) -> LazyFrame:
        stream = self._streams.get(cam)
        if stream is None:
            return HeldFrame(value, index, t)
        j = int(value[0])
        stream.advance_to(max(j, stream.index))
        return LazyFrame(stream, stream.index, float(self.video_time[cam][stream.index]))

    def _sample(self, index: int, t: float, stamp: float, value: Any) -> SessionSample | None:
        role, _, cam = self.driver.partition(":")
        if role == "frames":
            frame = self._frame(cam, self.inputs[self.driver], t, value, index)
            t = frame.time_s  # a replayed video's own frame time
        self._wait_partners(t)
        self.pending.append((t, stamp))
        frames: dict[str, LazyFrame] = {}
        if role == "frames":
            frames[cam] = frame
        keypoints: dict[str, FloatArray] = {}
        if role == "keypoints":
            keypoints[cam] = value
        for r, inp in self.inputs.items():
            kind, _, other = r.partition(":")
            if r == self.driver or kind == "markers":
                continue
            k = inp.nearest(t)
            if k < 0:
                if kind == "frames":
                    self.pending.pop()
                    return None
                continue
            if kind == "frames":
                frames[other] = self._frame(other, inp, inp.t[0], inp.values[0], index)
            else:
                keypoints[other] = inp.values[0]
        markers = self.inputs.get("markers")
        if role == "markers":
            return self._with_markers(index, t, t, value, frames, keypoints)
        if markers is not None and markers.newest_at_or_before(t) >= 0:
            return self._with_markers(index, t, markers.t[0], markers.values[0], frames, keypoints)
        return SessionSample(index, t, frames, keypoints_px=keypoints)

    def _with_markers(
        self,
        index: int,
        t: float,
        t_m: float,
        positions: FloatArray,
        frames: dict[str, LazyFrame],
        keypoints: dict[str, FloatArray],
    ) -> SessionSample:
        sets = {}
        for name, idx in self._sets.items():
            members = positions[idx]
            seen = np.isfinite(members).all(axis=1)
            if seen.all():
                self._last_full[name] = members
            rows = [members] if name not in self._last_full else [self._last_full[name], members]
            sets[name] = set_centre_mm(np.stack(rows))[-1]
        return SessionSample(
            index, t, frames, 0, t_m, t - t_m, positions, self.marker_names, sets, keypoints
        )

    def close(self) -> None:
        """Close every input."""
        for inp in self.inputs.values():
            inp.close()
        for st in self._streams.values():
            st.close()
