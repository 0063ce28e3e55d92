"""``mocapkit live METHOD``: track live inputs and publish the joints as an LSL stream.

The input side (streams, cameras, clocks, matching) is `mocapkit.pipelines.live_feed`.
Here: the tracker of each method built from the setup session as the offline pipelines
build it (`mocapkit.pipelines.hybrid.hybrid_setup`, `mocapkit.pipelines.stereo.stereo_tracker`,
`mocapkit.pipelines.mono.online_mono_stream`), each matched sample turned into the
tracker's sample by the same function the offline pipeline uses, the output stream
(`JOINTS_STREAM`, canonical joints in mm, each sample stamped with the LSL time stamp of
the input it answers), and the optional result folder and input recording.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from mocapkit.errors import ConfigError, SessionError
from mocapkit.io.atomic import atomic_folder, remove_stale_temporaries
from mocapkit.io.cameras import write_cameras
from mocapkit.io.lsl import JOINTS_TYPE, local_clock, make_outlet, point_labels
from mocapkit.io.marker_csv import write_markers_csv
from mocapkit.io.session import Session, SessionSample, load_session, write_session_json
from mocapkit.io.session_csv import write_keypoints_csv, write_timestamps_csv
from mocapkit.pipelines.live_feed import LiveConfig, LiveFeed, LiveInputs, LiveStats, rss_mb
from mocapkit.pipelines.run import (
    check_result_folder,
    find_gaps,
    results_motion,
    write_run_folder,
)
from mocapkit.skeleton.model import CANONICAL_JOINTS, CANONICAL_SEGMENTS, Skeleton
from mocapkit.tracking.base import DelayedTracker, FrameResult, Tracker, unobserved_joints

FloatArray = NDArray[np.float64]

#: The trackers that run live.
LIVE_METHODS: tuple[str, ...] = ("hybrid", "stereo", "mono")
#: Default name of the output stream.
JOINTS_STREAM = "mocapkit_joints"


@dataclass
class LiveTracker:
    """A tracker ready for live samples: the tracker, how a matched sample becomes its
    sample, which input drives the time line, and what the result folder needs."""

    tracker: Tracker | DelayedTracker
    to_sample: Callable[[SessionSample], Any]
    driver: str
    skeleton: Skeleton
    joint_names: tuple[str, ...] | None
    source: str


def _hybrid(setup: Session, inputs: LiveInputs) -> Callable[[LiveFeed], LiveTracker]:
    from mocapkit.pipelines.hybrid import hybrid_sample, hybrid_setup, member_markers
    from mocapkit.tracking.hybrid.tracker import MARKER_SETS, HybridTracker

    if inputs.markers is None:
        raise ConfigError("live hybrid: expected a marker stream (--markers NAME)")
    missing = [n for n in MARKER_SETS if n not in setup.marker_sets]
    if missing:
        raise SessionError(
            f"{setup.path}: the hybrid tracker needs marker sets {list(MARKER_SETS)} in "
            f"session.json; missing {missing}"
        )
    if len(inputs.video) > 1:
        raise ConfigError(f"live hybrid: expected one camera, found {sorted(inputs.video)}")
    use_video = bool(inputs.video)
    cam = next(iter(inputs.video), setup.camera_names[0] if setup.cameras else None)
    if cam is None:
        raise SessionError(f"{setup.path}: cameras.json lists no camera (the hybrid needs one)")
    cfg, sk = hybrid_setup(setup, use_video=use_video)
    wanted = member_markers(cfg)

    def build(feed: LiveFeed) -> LiveTracker:
        return LiveTracker(
            HybridTracker(sk, setup.camera(cam), cfg),
            lambda s: hybrid_sample(s, cam, wanted, use_video),
            f"frames:{cam}" if use_video else "markers",
            sk,
            None,
            f"hybrid tracker (live, video={'on' if use_video else 'off'}) on {setup.path}",
        )

    return build


def _stereo(setup: Session, inputs: LiveInputs) -> Callable[[LiveFeed], LiveTracker]:
    from mocapkit.pipelines.stereo import stereo_sample, stereo_tracker
    from mocapkit.tracking.stereo.tracker import StereoConfig

    names = list(inputs.video)
    if len(names) < 2:
        raise ConfigError(f"live stereo: expected two or more cameras (--video), found {names}")
    with_kp = bool(inputs.keypoints)
    if with_kp and sorted(inputs.keypoints) != sorted(names):
        raise ConfigError(
            f"live stereo: expected keypoints of every camera {names} or of none, found "
            f"{sorted(inputs.keypoints)}"
        )
    cfg = StereoConfig(use_keypoints=with_kp)

    def build(feed: LiveFeed) -> LiveTracker:
        kp_names = feed.layouts[f"keypoints:{names[0]}"].points if with_kp else ()
        tracker = stereo_tracker(setup, names, cfg, kp_names)
        mode = "keypoints" if with_kp else "skin blobs"
        return LiveTracker(
            tracker,
            lambda s: stereo_sample(s, names),
            f"frames:{names[0]}",
            tracker.skeleton,
            None,
            f"stereo tracker (live, {mode}) on {setup.path}",
        )

    return build


def _mono(
    setup: Session, inputs: LiveInputs, config: LiveConfig
) -> Callable[[LiveFeed], LiveTracker]:
    from mocapkit.io.session_csv import Keypoints
    from mocapkit.pipelines.mono import MonoSample, online_mono_stream, stick_pixels
    from mocapkit.tracking.mono.tracker import MonoConfig

    if len(inputs.keypoints) != 1:
        raise ConfigError(
            f"live mono: expected the keypoints of one camera (--keypoints CAMERA=STREAM), "
            f"found {sorted(inputs.keypoints)}"
        )
    cam = next(iter(inputs.keypoints))
    cfg = MonoConfig(lag=config.mono_lag)

    def build(feed: LiveFeed) -> LiveTracker:
        layout = feed.layouts[f"keypoints:{cam}"]
        rate = layout.rate_hz or setup.rates.get("video_hz", 30.0)
        stream = online_mono_stream(setup, cam, cfg, 1.0 / rate)
        model = stream.tracker.model
        where = f"LSL stream {layout.name!r}"
        stick_pixels(Keypoints(np.zeros(1), layout.points, np.zeros((1, len(layout.points), 2)),
                               where), model)  # fmt: skip
        idx = [layout.points.index(n) for n in model.joint_names]
        return LiveTracker(
            stream,
            lambda s: MonoSample(s.time_s, np.asarray(s.keypoints_px[cam][idx], dtype=float)),
            f"keypoints:{cam}",
            stream.skeleton,
            stream.joint_names,
            f"mono tracker (live, lag {cfg.lag}, session lengths) on {setup.path}",
        )

    return build


# ====================================================================== output


def joints_outlet(name: str, method: str, rate_hz: float) -> Any:
    """The output stream: the canonical joints (``<joint>_x/_y/_z``, mm, world frame of
    ``cameras.json``: z up), each joint's parent in ``desc/skeleton``."""
    parents = {child: parent for parent, child in CANONICAL_SEGMENTS.values()}
    skeleton = [{"name": j, "parent": parents.get(j, "")} for j in CANONICAL_JOINTS]
    return make_outlet(
        name,
        JOINTS_TYPE,
        point_labels(CANONICAL_JOINTS, 3),
        "mm",
        rate_hz,
        f"{name}@mocapkit-{method}",
        {
            "axes": {"frame": "world of cameras.json", "up": "z", "handedness": "right"},
            "tracker": {"method": method},
        },
        {"skeleton": skeleton},
    )


def published_joints(result: FrameResult) -> list[float]:
    """A result's canonical joints as sent: NaN where a released or missing effector or
    limb leaves them made up (the runner's rule)."""
    joints = np.array(result.joints_mm, dtype=float, copy=True)
    for j in unobserved_joints(result.status):
        joints[CANONICAL_JOINTS.index(j)] = np.nan
    return [float(v) for v in joints.ravel()]


# ====================================================================== recording


class InputRecorder:
    """The live inputs written as a session folder (``--record``): ``session.json`` and
    ``cameras.json`` of the setup, ``markers.csv``, ``keypoints/<camera>.csv`` and each
    tracked frame in ``video/<camera>.mp4`` with its ``timestamps.csv``. Built in a
    temporary folder beside the target and swapped in whole at the end."""

    def __init__(self, setup: Session, folder: Path) -> None:
        self.setup = setup
        self.folder = folder
        self.markers: list[tuple[float, FloatArray]] = []
        self.marker_names: tuple[str, ...] = ()
        self.keypoints: dict[str, list[tuple[float, FloatArray]]] = {}
        self.keypoint_names: dict[str, tuple[str, ...]] = {}
        self.frame_times: dict[str, list[float]] = {}
        self._writers: dict[str, cv2.VideoWriter] = {}
        self.tmp: Path | None = None

    def frame(self, cam: str, t: float, image: NDArray[np.uint8], rate_hz: float) -> None:
        """Append one tracked frame of ``cam``."""
        assert self.tmp is not None
        times = self.frame_times.setdefault(cam, [])
        if times and t <= times[-1]:
            return
        w = self._writers.get(cam)
        if w is None:
            (self.tmp / "video").mkdir(exist_ok=True)
            h, wd = image.shape[:2]
            w = cv2.VideoWriter(
                str(self.tmp / "video" / f"{cam}.mp4"),
                cv2.VideoWriter.fourcc(*"mp4v"),
                rate_hz or 30.0,
                (wd, h),
            )
            self._writers[cam] = w
        w.write(image)
        times.append(t)

    def marker_sample(self, t: float, positions_mm: FloatArray) -> None:
        """Append one received marker sample (mm)."""
        if not self.markers or t > self.markers[-1][0]:
            self.markers.append((t, np.array(positions_mm, dtype=float, copy=True)))

    def keypoints_sample(self, cam: str, t: float, pixels: FloatArray) -> None:
        """Append one received keypoints sample of ``cam`` (px)."""
        rows = self.keypoints.setdefault(cam, [])
        if not rows or t > rows[-1][0]:
            rows.append((t, np.array(pixels, dtype=float, copy=True)))

    def frames(self, s: SessionSample, rate_hz: float) -> None:
        """Append the frames of a tracked sample."""
        for cam, f in s.frames.items():
            self.frame(cam, f.time_s, f.load(), rate_hz)

    def finish(self, keypoint_names: dict[str, tuple[str, ...]], rates: dict[str, float]) -> None:
        """Write the files (the folder is swapped in by the caller)."""
        assert self.tmp is not None
        for w in self._writers.values():
            w.release()
        for cam, times in self.frame_times.items():
            write_timestamps_csv(self.tmp / "video" / f"{cam}.timestamps.csv", times)
        if self.markers:
            write_markers_csv(
                self.tmp / "markers.csv",
                [t for t, _ in self.markers],
                self.marker_names,
                np.stack([p for _, p in self.markers]),
            )
        for cam, rows in self.keypoints.items():
            (self.tmp / "keypoints").mkdir(exist_ok=True)
            write_keypoints_csv(
                self.tmp / "keypoints" / f"{cam}.csv",
                [t for t, _ in rows],
                keypoint_names[cam],
                np.stack([p for _, p in rows]),
            )
        write_cameras(self.tmp / "cameras.json", self.setup.cameras)
        info = {k: v for k, v in self.setup.info.items() if k not in ("format", "units")}
        info["cameras"] = "cameras.json"
        info["rates"] = {**self.setup.rates, **rates}
        write_session_json(self.tmp / "session.json", info)


# ====================================================================== the view


class LiveView:
    """The joints drawn over the driving camera's image in an OpenCV window (streaming
    trackers driven by a camera; the mono tracker's delayed results are not shown)."""

    WINDOW = "mocapkit live"

    def __init__(self, setup: Session, driver: str) -> None:
        kind, _, cam = driver.partition(":")
        if kind != "frames":
            raise ConfigError(f"--view: expected a camera driving the time line, found {driver!r}")
        try:
            cv2.namedWindow(self.WINDOW, cv2.WINDOW_NORMAL)
        except cv2.error:
            raise ConfigError(
                "--view needs OpenCV with a GUI (opencv-python, not opencv-python-headless); "
                "leave --view off in headless use"
            ) from None
        self.cam = cam
        self.camera = setup.camera(cam)

    def show(self, s: SessionSample, result: FrameResult) -> None:
        """Draw ``result`` over the sample's frame and show it."""
        from mocapkit.viz.overlay import draw_sticks

        frame = s.frames.get(self.cam)
        if frame is None:
            return
        joints = np.asarray(published_joints(result)).reshape(-1, 3)
        image = draw_sticks(frame.load().copy(), self.camera, CANONICAL_JOINTS, joints)
        cv2.imshow(self.WINDOW, image)
        cv2.waitKey(1)


# ====================================================================== the run


@dataclass
class LiveReport:
    """What a live run did.

    Attributes
    ----------
    method : str
    stop_reason : str
        What ended the run (``interrupted``, ``lost ...``, ``stopped``).
    stats : LiveStats
        Samples received per input, frames tracked and dropped, latencies (ms).
    n_results : int
        Output samples sent.
    out_dir, record_dir : Path or None
    gaps : list of str
        Released or missing stretches (with ``--out``).
    """

    method: str
    stop_reason: str
    stats: LiveStats
    n_results: int
    out_dir: Path | None = None
    record_dir: Path | None = None
    gaps: list[str] = field(default_factory=list)

    def latency_summary(self) -> dict[str, float]:
        """Median, 99th percentile and max latency (ms) from input time stamp to output."""
        return _summary(self.stats.latency_ms)

    def step_cpu_summary(self) -> dict[str, float]:
        """Median, 99th percentile and max CPU time (ms) of one step (the tracker's
        update and the output): the latency on an idle core, less waiting."""
        return _summary(self.stats.step_cpu_ms)


def _summary(values: list[float]) -> dict[str, float]:
    """Median, 99th percentile and max of ``values`` (ms; NaN when empty)."""
    v = np.asarray(values, dtype=float)
    if v.size == 0:
        return {"median_ms": float("nan"), "p99_ms": float("nan"), "max_ms": float("nan")}
    return {
        "median_ms": float(np.median(v)),
        "p99_ms": float(np.percentile(v, 99)),
        "max_ms": float(v.max()),
    }


@contextlib.contextmanager
def _sigint_stops(feed: LiveFeed) -> Iterator[None]:
    """Ctrl-C ends the feed cleanly (in the main thread; elsewhere nothing changes)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, lambda *_: feed.request_stop("interrupted (Ctrl-C)"))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def track_live(
    method: str,
    setup_dir: str | os.PathLike[str],
    inputs: LiveInputs,
    out_dir: str | os.PathLike[str] | None = None,
    record_dir: str | os.PathLike[str] | None = None,
    stream_name: str = JOINTS_STREAM,
    config: LiveConfig | None = None,
    stop: threading.Event | None = None,
    on_result: Callable[[FrameResult], None] | None = None,
    keep_latency: int = 200_000,
    view: bool = False,
) -> LiveReport:
    """Track live inputs with ``method`` until Ctrl-C, ``stop`` or a lost input.

    Parameters
    ----------
    method : str
        One of `LIVE_METHODS`.
    setup_dir : path
        A session folder giving ``cameras.json`` and ``session.json`` (its recordings, if
        any, are not used).
    inputs : LiveInputs
    out_dir : path, optional
        Result folder (as ``mocapkit track``'s) written at the end.
    record_dir : path, optional
        The inputs as a session folder (`InputRecorder`), written at the end.
    stream_name : str
        Name of the output LSL stream.
    config : LiveConfig, optional
    stop : threading.Event, optional
        Set it to end the run (as Ctrl-C does in the main thread).
    on_result : callable, optional
        Called with each result after it is sent.
    keep_latency : int
        Latencies kept for the report (the newest).
    view : bool
        Show the joints over the first camera's image in a window (`LiveView`; needs
        OpenCV with a GUI); off for headless use.
    """
    if method not in LIVE_METHODS:
        from mocapkit.errors import unknown_name

        raise unknown_name("live method", method, LIVE_METHODS, "mocapkit live")
    cfg = config or LiveConfig()
    if out_dir is not None:
        check_result_folder(out_dir)
    if record_dir is not None:
        rec = Path(record_dir)
        if rec.exists() and (not rec.is_dir() or any(rec.iterdir())):
            raise ConfigError(f"{rec}: --record expects a new or empty folder")
    setup = load_session(setup_dir)
    build = (
        _hybrid(setup, inputs)
        if method == "hybrid"
        else _stereo(setup, inputs)
        if method == "stereo"
        else _mono(setup, inputs, cfg)
    )
    shown = LiveView(setup, _driver(method, inputs)) if view else None  # before connecting
    feed = LiveFeed(setup, inputs, _driver(method, inputs), cfg, stop)
    try:
        live = build(feed)
        return _run(method, setup, feed, live, out_dir, record_dir, stream_name, on_result,
                    keep_latency, shown)  # fmt: skip
    finally:
        feed.close()


def _driver(method: str, inputs: LiveInputs) -> str:
    """The input whose samples set the time line: the first camera's frames (the hybrid
    without a camera: the markers; mono: the keypoints)."""
    if method == "mono":
        return f"keypoints:{next(iter(inputs.keypoints))}"
    return f"frames:{next(iter(inputs.video))}" if inputs.video else "markers"


def _tap(feed: LiveFeed, recorder: InputRecorder) -> None:
    """Every marker and keypoints sample received goes to the recorder."""
    for role, inp in feed.inputs.items():
        kind, _, cam = role.partition(":")
        if kind == "markers":
            recorder.marker_names = feed.marker_names
            inp.tap = recorder.marker_sample
        elif kind == "keypoints":
            inp.tap = lambda t, px, cam=cam: recorder.keypoints_sample(cam, t, px)


def _run(
    method: str,
    setup: Session,
    feed: LiveFeed,
    live: LiveTracker,
    out_dir: str | os.PathLike[str] | None,
    record_dir: str | os.PathLike[str] | None,
    stream_name: str,
    on_result: Callable[[FrameResult], None] | None,
    keep_latency: int,
    view: LiveView | None = None,
) -> LiveReport:
    drv_rate = feed.inputs[live.driver].rate_hz
    outlet = joints_outlet(stream_name, method, drv_rate)
    keep: list[FrameResult] | None = [] if out_dir is not None else None
    latency: deque[float] = deque(maxlen=keep_latency)
    step_cpu: deque[float] = deque(maxlen=keep_latency)
    sent = 0
    recorder = InputRecorder(setup, Path(record_dir)) if record_dir is not None else None
    delayed = live.tracker if isinstance(live.tracker, DelayedTracker) else None
    streaming = live.tracker if isinstance(live.tracker, Tracker) else None

    def publish(results: list[FrameResult], timed: bool = True) -> None:
        nonlocal sent
        for r in results:
            stamp = None
            while feed.pending and feed.pending[0][0] < r.time_s - 1e-9:
                feed.pending.popleft()
            if feed.pending and abs(feed.pending[0][0] - r.time_s) <= 1e-9:
                stamp = feed.pending.popleft()[1]
            outlet.push_sample(published_joints(r), stamp if stamp is not None else 0.0)
            if stamp is not None and timed:
                latency.append(1e3 * (local_clock() - stamp))
            sent += 1
            if sent == 1:
                feed.stats.rss_first_mb = rss_mb()
            if keep is not None:
                keep.append(r)
            if on_result is not None:
                on_result(r)

    with contextlib.ExitStack() as stack:
        if recorder is not None:
            remove_stale_temporaries(recorder.folder.parent, recorder.folder.name)
            recorder.tmp = stack.enter_context(atomic_folder(recorder.folder))
            _tap(feed, recorder)
        stack.enter_context(_sigint_stops(feed))
        video = any(r.startswith("frames:") for r in feed.inputs)
        for s in feed.samples():
            if recorder is not None and video:
                recorder.frames(s, drv_rate)
            c0 = time.thread_time()
            sample = live.to_sample(s)
            if delayed is not None:
                publish(delayed.push(sample))
            elif streaming is not None:
                result = streaming.update(sample)
                publish([result])
                if view is not None:
                    view.show(s, result)
            step_cpu.append(1e3 * (time.thread_time() - c0))
        if delayed is not None:
            # answered when the input ended, not in the stream: sent, but not timed
            publish(sorted(delayed.finish(), key=lambda r: r.time_s), timed=False)
        if recorder is not None:
            names = {r.split(":", 1)[1]: feed.layouts[r].points for r in feed.layouts
                     if r.startswith("keypoints:")}  # fmt: skip
            rates = {"video_hz": drv_rate} if video and drv_rate > 0 else {}
            recorder.finish(names, rates)
    feed.stats.latency_ms = list(latency)
    feed.stats.step_cpu_ms = list(step_cpu)
    feed.stats.results = sent
    feed.stats.rss_last_mb = rss_mb()
    report = LiveReport(
        method,
        feed.stop_reason or "stopped",
        feed.stats,
        sent,
        None,
        Path(record_dir) if record_dir is not None and recorder is not None else None,
    )
    if keep:
        motion = results_motion(keep, live.skeleton, live.source, live.joint_names)
        report.out_dir = write_run_folder(out_dir, motion, keep)  # type: ignore[arg-type]
        report.gaps = [str(g) for g in find_gaps(keep)]
    return report


__all__ = [
    "JOINTS_STREAM",
    "LIVE_METHODS",
    "InputRecorder",
    "LiveReport",
    "LiveTracker",
    "joints_outlet",
    "published_joints",
    "track_live",
]
