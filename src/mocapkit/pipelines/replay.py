"""Replay a recorded session as live LSL streams (``mocapkit replay SESSION --lsl``).

Every input of the session becomes a stream (`mocapkit.io.lsl`): its markers (type
``Mocap``, ``<marker>_x/_y/_z`` in mm), each camera's 2-D keypoints (type ``Keypoints``)
and each camera's video as a stream of frame numbers (type ``VideoFrames``) whose
consumer reads the frames from the session's video itself (named in ``desc/video``).
Samples are pushed in time order, each stamped with its session time on the LSL clock
(`mocapkit.io.lsl.ReplayClock`, also in every stream's ``desc/replay``), at real time or
``speed`` times faster, so that a live tracker on this machine (`mocapkit.pipelines.live`)
sees what a lab's devices would send, on the session's own time line.
"""

from __future__ import annotations

import heapq
import os
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.errors import ConfigError, SessionError
from mocapkit.io.lsl import (
    FRAMES_TYPE,
    KEYPOINTS_TYPE,
    MARKERS_TYPE,
    ReplayClock,
    local_clock,
    make_outlet,
    point_labels,
)
from mocapkit.io.session import Session, load_session
from mocapkit.pipelines.live_config import STREAM_PREFIX


def stream_names(session: Session, prefix: str = STREAM_PREFIX) -> dict[str, str]:
    """The streams a replay of ``session`` publishes: role -> stream name (``markers``,
    ``keypoints:<camera>``, ``frames:<camera>``)."""
    names: dict[str, str] = {}
    if session.markers is not None:
        names["markers"] = f"{prefix}markers"
    for cam in session.keypoints:
        names[f"keypoints:{cam}"] = f"{prefix}keypoints_{cam}"
    for cam in session.video_cameras:
        names[f"frames:{cam}"] = f"{prefix}frames_{cam}"
    return names


@dataclass
class ReplayStats:
    """What a replay sent: samples per stream name, the session span (s), its clock and
    whether it was stopped early."""

    samples: dict[str, int]
    start_s: float
    end_s: float
    clock: ReplayClock
    stopped: bool = False


#: Seconds the outlets stay open after the last sample of a replay that ran to its end
#: (LSL has no delivery receipt; an inlet whose source has closed reports it lost, and
#: the last samples still in flight would never be pulled).
CLOSE_LINGER_S = 0.5


def replay_session(
    session_dir: str | os.PathLike[str],
    speed: float = 1.0,
    prefix: str = STREAM_PREFIX,
    lead_s: float = 2.0,
    stop: threading.Event | None = None,
    on_ready: Callable[[dict[str, str]], None] | None = None,
) -> ReplayStats:
    """Publish a session's markers, keypoints and frame numbers as LSL streams.

    Parameters
    ----------
    session_dir : path
    speed : float
        1: real time; 4: four times faster (time stamps compressed likewise; the stream
        metadata says so, so a consumer maps them back to session time).
    prefix : str
        Stream names are ``<prefix>markers``, ``<prefix>keypoints_<camera>``,
        ``<prefix>frames_<camera>`` (`stream_names`).
    lead_s : float
        The first sample goes out this long after the streams appear, which gives
        consumers time to connect (a consumer that comes later misses the beginning, as
        with a live device).
    stop : threading.Event, optional
        Set it to end the replay early (the streams then close, as a lost device would).
    on_ready : callable, optional
        Called with `stream_names` once the outlets exist.

    Raises
    ------
    ConfigError
        ``speed`` not positive and finite.
    SessionError
        A session with nothing to replay.
    """
    if not (np.isfinite(speed) and speed > 0):
        raise ConfigError(f"--speed: expected a positive factor (1: real time), found {speed}")
    session = load_session(session_dir)
    names = stream_names(session, prefix)
    if not names:
        raise SessionError(f"{session.path}: nothing to replay (no markers, keypoints or video)")
    starts = []
    if session.markers is not None:
        starts.append(float(session.markers.time_s[0]))
    starts += [float(k.time_s[0]) for k in session.keypoints.values() if k.time_s.size]
    starts += [float(session.video(c).time_s[0]) for c in session.video_cameras]
    t0 = min(starts)
    if not (np.isfinite(lead_s) and lead_s >= 0):
        raise ConfigError(f"lead_s: expected a delay >= 0 s, found {lead_s}")
    # the clock is in every stream's metadata, so it is fixed before the outlets exist
    lsl_start = local_clock() + lead_s
    clock = ReplayClock(lsl_start, t0, float(speed))
    replay_meta = {
        "replay": {
            "lsl_start_s": repr(clock.lsl_start_s),
            "session_start_s": repr(clock.session_start_s),
            "speed": repr(clock.speed),
            "session": str(session.path.resolve()),
        }
    }
    outlets: dict[str, Any] = {}
    sources: list[Iterator[tuple[float, int, str, list[float]]]] = []
    if session.markers is not None:
        m = session.markers
        rate = float(session.rates.get("markers_hz", m.rate_hz))
        outlets["markers"] = make_outlet(
            names["markers"],
            MARKERS_TYPE,
            point_labels(m.names, 3),
            "mm",
            rate,
            f"{names['markers']}@{session.path.resolve()}",
            replay_meta,
        )
        sources.append(_rows("markers", 0, m.time_s, m.positions_mm.reshape(m.n_frames, -1)))
    for cam, kp in session.keypoints.items():
        role = f"keypoints:{cam}"
        outlets[role] = make_outlet(
            names[role],
            KEYPOINTS_TYPE,
            point_labels(kp.joint_names, 2),
            "px",
            float(session.rates.get("video_hz", 0.0)),
            f"{names[role]}@{session.path.resolve()}",
            {**replay_meta, "camera": {"name": cam}},
        )
        sources.append(_rows(role, 1, kp.time_s, kp.pixels.reshape(kp.pixels.shape[0], -1)))
    for cam in session.video_cameras:
        role = f"frames:{cam}"
        v = session.video(cam)
        outlets[role] = make_outlet(
            names[role],
            FRAMES_TYPE,
            ["frame"],
            "frame",
            float(session.rates.get("video_hz", 0.0)),
            f"{names[role]}@{session.path.resolve()}",
            {**replay_meta, "camera": {"name": cam}, "video": {"session": str(session.path)}},
        )
        idx = np.arange(v.n_frames, dtype=float)[:, None]
        sources.append(_rows(role, 2, v.time_s, idx))
    if on_ready is not None:
        on_ready(names)
    counts = dict.fromkeys(names.values(), 0)
    end = t0
    stopped = False
    for t, _, role, values in heapq.merge(*sources):
        if stop is not None and stop.is_set():
            stopped = True
            break
        stamp = clock.to_lsl(t)
        delay = stamp - local_clock()
        if delay > 0:
            if stop is not None:
                if stop.wait(delay):
                    stopped = True
                    break
            else:
                time.sleep(delay)
        outlets[role].push_sample(values, stamp)
        counts[names[role]] += 1
        end = t
    if not stopped:
        # a consumer that sees a closed source stops pulling: keep the streams open
        # a moment so that the last samples reach it before they end
        if stop is not None:
            stop.wait(CLOSE_LINGER_S)
        else:
            time.sleep(CLOSE_LINGER_S)
    outlets.clear()  # closing the outlets ends the streams
    return ReplayStats(counts, t0, end, clock, stopped)


def _rows(
    role: str, order: int, time_s: np.ndarray, values: np.ndarray
) -> Iterator[tuple[float, int, str, list[float]]]:
    """``(time, order, role, row)`` per sample; at equal times markers go first, then
    keypoints, then frames (a frame's partners are sent before it)."""
    for t, row in zip(time_s.tolist(), values):
        yield t, order, role, row.tolist()


def session_path_of(meta: dict[str, dict[str, str]]) -> Path | None:
    """The replayed session's folder named in a stream's ``desc/replay`` (None if absent)."""
    r = meta.get("replay", {})
    return Path(r["session"]) if "session" in r else None


__all__ = ["STREAM_PREFIX", "ReplayStats", "replay_session", "session_path_of", "stream_names"]
