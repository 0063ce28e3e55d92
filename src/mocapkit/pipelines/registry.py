"""The tracking methods a batch can run: method name -> the function tracking a session.

Every entry is a library function ``f(session_dir, out_dir)`` that tracks one session
folder and writes its result folder (``motion.npz``, ``joints.csv``, ``motion.bvh``),
such as `mocapkit.pipelines.hybrid.track_hybrid_session`; what it returns (a Motion, a
run record) is not used: the batch reads the folder. Entries are
``"module:function"`` paths resolved on first use, so a method whose module is not part
of this installation yet (stereo and mono are being built) is listed but not available,
and a Dask worker resolves the same function by importing it. A tracker added later
registers with one line in `TRACKERS` (or `register_tracker` at run time, e.g. from a
notebook).

``auto`` chooses by what a session holds (`choose_method`): markers and video -> hybrid
(Zhang 2011); two or more cameras with video and no markers -> stereo (the model-based
multi-view fit when every camera has 2-D keypoints, else Azad 2008's skin colour); one
camera -> mono (Mamania 2004). When the preferred method is not available, the next one
that can use the session is taken (a stereo pair can be tracked by mono from its first
camera); when none is, the error names the missing method and the ones available.
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Callable
from typing import Any, cast

from mocapkit.errors import ConfigError, SessionError, unknown_name

#: A tracker: ``f(session_dir, out_dir)`` writing the result folder ``out_dir``.
SessionTracker = Callable[[str | os.PathLike[str], str | os.PathLike[str]], Any]

#: Method name -> ``"module:function"`` (or a function registered at run time).
TRACKERS: dict[str, str | SessionTracker] = {
    "hybrid": "mocapkit.pipelines.hybrid:track_hybrid_session",
    "stereo": "mocapkit.pipelines.multiview:track_stereo_auto",
    "mono": "mocapkit.pipelines.mono:track_mono",
}

#: The choice that picks a method per session (`choose_method`).
AUTO = "auto"


def register_tracker(name: str, tracker: str | SessionTracker) -> None:
    """Add or replace the tracker of method ``name`` (a ``"module:function"`` path or a
    function ``f(session_dir, out_dir)`` writing the result folder)."""
    if not name or name == AUTO or not name.isidentifier():
        raise ConfigError(
            f"register_tracker: expected a method name (a Python identifier, not {AUTO!r}), "
            f"found {name!r}"
        )
    if isinstance(tracker, str) and tracker.count(":") != 1:
        raise ConfigError(
            f"register_tracker: expected 'module:function' for method {name!r}, found {tracker!r}"
        )
    TRACKERS[name] = tracker


def _resolve(name: str) -> SessionTracker | str:
    """The tracker of ``name``, or the reason it is not available."""
    entry = TRACKERS[name]
    if not isinstance(entry, str):
        return entry
    module_name, func_name = entry.split(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name is not None and module_name.startswith(exc.name):
            return f"{module_name} is not part of this installation"
        raise  # the module exists but one of its own imports is missing: a real bug
    func = getattr(module, func_name, None)
    if not callable(func):
        return f"{module_name} has no function {func_name}"
    return cast(SessionTracker, func)


def available_methods() -> tuple[str, ...]:
    """Names of the methods whose tracker can be loaded here."""
    return tuple(n for n in TRACKERS if not isinstance(_resolve(n), str))


def session_tracker(name: str) -> SessionTracker:
    """The tracker function of method ``name``.

    Raises
    ------
    UnknownNameError
        ``name`` is no method.
    ConfigError
        The method is known but its tracker is not available in this installation.
    """
    if name not in TRACKERS:
        raise unknown_name("tracking method", name, (*TRACKERS, AUTO), "--method")
    found = _resolve(name)
    if isinstance(found, str):
        raise ConfigError(
            f"--method {name}: the {name} tracker is not available ({found}); "
            f"available: {', '.join(available_methods()) or 'none'}"
        )
    return found


def candidate_methods(session_dir: str | os.PathLike[str]) -> tuple[tuple[str, ...], str]:
    """Methods able to track a session, preferred first, and what the session holds.

    Markers and video -> hybrid first; two or more cameras with video -> stereo, then
    mono; one camera with video -> mono. A session with markers keeps the camera
    methods as fall-backs (they ignore the markers).
    """
    from mocapkit.io.session import load_session

    session = load_session(session_dir)
    n_video = len(session.video_cameras)
    has_markers = session.markers is not None
    holds = (
        f"{n_video} camera{'s' if n_video != 1 else ''} with video, "
        f"{'markers' if has_markers else 'no markers'}"
    )
    methods: list[str] = []
    if has_markers and n_video >= 1:
        methods.append("hybrid")
    if n_video >= 2:
        methods.append("stereo")
    if n_video >= 1:
        methods.append("mono")
    if not methods:
        raise SessionError(
            f"{session.path}: no tracking method fits this session ({holds}); every method "
            "needs at least one camera with a video"
        )
    return tuple(methods), holds


def choose_method(session_dir: str | os.PathLike[str]) -> str:
    """The ``auto`` method for a session: the first of `candidate_methods` available.

    Raises
    ------
    ConfigError
        None of the methods that fit the session is available here.
    """
    methods, holds = candidate_methods(session_dir)
    available = available_methods()
    for m in methods:
        if m in available:
            return m
    raise ConfigError(
        f"{session_dir}: --method auto chose {methods[0]} ({holds}), but no tracker that fits "
        f"this session ({', '.join(methods)}) is available; available: "
        f"{', '.join(available) or 'none'}"
    )
