"""Lab Streaming Layer (LSL) streams: channel layouts, metadata, outlets and inlets.

LSL is how labs connect live devices (Vicon, Qualisys, OptiTrack, cameras, EEG); its
Python binding ``pylsl`` carries ``liblsl`` in its wheel and is the optional extra
``mocapkit[live]``. A stream is a name, a type, a channel count, a nominal rate and an
XML description; every sample carries a time stamp on the LSL clock
(``pylsl.local_clock``, s). mocapkit's streams:

- **markers** (type ``Mocap``): three channels per marker, labelled ``<marker>_x``,
  ``_y``, ``_z`` in ``desc/channels/channel/label`` with their ``unit`` (``mm`` or
  ``millimeters``; ``m``/``meters`` are scaled to mm), NaN where occluded;
- **keypoints** (type ``Keypoints``), one stream per camera: ``<joint>_x``, ``<joint>_y``
  in px, the camera named in ``desc/camera``;
- **frames** (type ``VideoFrames``), one per camera: one channel, the frame number of a
  video that the consumer reads itself (`mocapkit.pipelines.replay`);
- **joints** (type ``MocapJoints``): the tracker's canonical joints, ``<joint>_x/_y/_z`` in
  mm, with the skeleton (each joint's parent) and the world axes in ``desc``.

A replayed stream (`mocapkit.pipelines.replay`) also holds ``desc/replay`` with the
session clock it was replayed from (`ReplayClock`), so that a consumer tracks it on the
session's own time line at any replay speed.

liblsl reads its settings from ``lsl_api.cfg`` or the file named by ``LSLAPICFG``
(`LOOPBACK_CONFIG` keeps discovery on this machine, as the tests do). Where the user
has no such file, mocapkit gives liblsl `QUIET_CONFIG` (its defaults, with its log at
warnings), so that its start-up INFO lines do not fill the terminal.
"""

from __future__ import annotations

import math
import os
import re
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

from mocapkit.errors import ConfigError, FormatError

#: Stream types of mocapkit's streams.
MARKERS_TYPE = "Mocap"
KEYPOINTS_TYPE = "Keypoints"
FRAMES_TYPE = "VideoFrames"
JOINTS_TYPE = "MocapJoints"

#: An ``lsl_api.cfg`` that keeps LSL on this machine (discovery and data on loopback).
LOOPBACK_CONFIG = """[ports]
IPv6 = disable
[multicast]
ResolveScope = machine
[lab]
KnownPeers = {127.0.0.1}
[log]
level = -3
"""

#: liblsl's defaults with its log at warnings and above: used only where the user has no
#: ``lsl_api.cfg`` of their own (`user_config_files`).
QUIET_CONFIG = """[log]
level = -1
"""

#: Channel units accepted for positions, and their scale to mm.
LENGTH_UNITS: dict[str, float] = {
    "mm": 1.0,
    "millimeters": 1.0,
    "millimetres": 1.0,
    "m": 1000.0,
    "meters": 1000.0,
    "metres": 1000.0,
}

_AXIS_LABEL = re.compile(r"^(?P<name>.+?)[_ .:-]?(?P<axis>[xyzXYZ])$")


def user_config_files() -> list[Path]:
    """The ``lsl_api.cfg`` files liblsl would read, in its order of search, that exist:
    the file named by ``LSLAPICFG``, then ``lsl_api.cfg`` in the working directory, in
    ``~/lsl_api/`` and in ``/etc/lsl_api/``."""
    named = os.environ.get("LSLAPICFG")
    candidates = [Path(named)] if named else []
    candidates += [
        Path("lsl_api.cfg"),
        Path.home() / "lsl_api" / "lsl_api.cfg",
        Path("/etc/lsl_api/lsl_api.cfg"),
    ]
    return [path for path in candidates if path.is_file()]


_quiet_config_set = False


def pylsl() -> ModuleType:
    """The ``pylsl`` module, or a `ConfigError` saying how to install it.

    On its first load, where the user has no ``lsl_api.cfg`` (`user_config_files`),
    liblsl is given `QUIET_CONFIG` before any stream exists."""
    global _quiet_config_set
    try:
        import pylsl as module
    except ImportError as exc:
        raise ConfigError(
            "live capture needs pylsl (Lab Streaming Layer); install it with "
            f"pip install 'mocapkit[live]' ({exc})"
        ) from None
    if not _quiet_config_set:
        _quiet_config_set = True
        set_content = getattr(module.lib.lib, "lsl_set_config_content", None)
        if set_content is not None and not user_config_files():
            set_content(QUIET_CONFIG.encode())
    return module


def _pylsl_error(name: str) -> type[Exception]:
    import importlib

    found = getattr(pylsl(), name, None)
    if found is None:
        found = getattr(importlib.import_module("pylsl.util"), name)
    return found


def lost_error() -> type[Exception]:
    """The exception an inlet raises when its stream's source has closed."""
    return _pylsl_error("LostError")


def lsl_timeout_error() -> type[Exception]:
    """The exception an inlet raises when an operation timed out."""
    return _pylsl_error("TimeoutError")


def local_clock() -> float:
    """The LSL clock (s), the time line of every stream's time stamps."""
    return float(pylsl().local_clock())


@dataclass(frozen=True)
class ReplayClock:
    """How a replay maps session time to LSL time: ``lsl = lsl_start_s + (t - session_start_s)
    / speed``; `to_session` inverts it."""

    lsl_start_s: float
    session_start_s: float
    speed: float

    def to_lsl(self, time_s: float) -> float:
        """LSL time stamp of session time ``time_s``."""
        return self.lsl_start_s + (time_s - self.session_start_s) / self.speed

    def to_session(self, stamp_s: float) -> float:
        """Session time of LSL time stamp ``stamp_s``."""
        return self.session_start_s + (stamp_s - self.lsl_start_s) * self.speed


@dataclass(frozen=True)
class StreamLayout:
    """What a stream holds, parsed from its metadata.

    Attributes
    ----------
    name, type, source_id : str
    rate_hz : float
        Nominal rate (0: irregular).
    points : tuple of str
        Marker or joint names, in channel order (one per 3 or 2 channels).
    dims : int
        3 (x, y, z) or 2 (x, y); 1 for a frame-number stream.
    scale : float
        Factor from the channel unit to mm (px: 1).
    meta : dict of str to dict of str to str
        Attributes of the ``desc`` children other than ``channels`` (``camera``,
        ``replay``, ``video``, ...).
    """

    name: str
    type: str
    source_id: str
    rate_hz: float
    points: tuple[str, ...]
    dims: int
    scale: float
    meta: dict[str, dict[str, str]]

    @property
    def replay_clock(self) -> ReplayClock | None:
        """The replay's clock (`ReplayClock`) when the stream is a mocapkit replay."""
        r = self.meta.get("replay")
        if r is None:
            return None
        try:
            return ReplayClock(
                float(r["lsl_start_s"]), float(r["session_start_s"]), float(r["speed"])
            )
        except (KeyError, ValueError):
            raise FormatError(
                f"LSL stream {self.name!r}: desc/replay: expected lsl_start_s, "
                f"session_start_s and speed, found {r}"
            ) from None


def point_labels(points: Sequence[str], dims: int) -> list[str]:
    """Channel labels ``<point>_x, <point>_y[, <point>_z]`` per point."""
    return [f"{p}_{a}" for p in points for a in "xyz"[:dims]]


def make_outlet(
    name: str,
    stream_type: str,
    labels: Sequence[str],
    unit: str,
    rate_hz: float,
    source_id: str,
    meta: Mapping[str, Mapping[str, str]] | None = None,
    children: Mapping[str, Sequence[Mapping[str, str]]] | None = None,
    channel_format: str = "double64",
    chunk_size: int = 1,
) -> Any:
    """An LSL outlet with channel labels and units in its XML description.

    Parameters
    ----------
    name, stream_type : str
    labels : sequence of str
        One per channel.
    unit : str
        Every channel's unit (``mm``, ``px``, ``frame``).
    rate_hz : float
        Nominal rate (0: irregular).
    source_id : str
        Unique id of the source (lets a consumer re-connect to the same stream).
    meta : mapping, optional
        ``desc`` children with attributes as child elements: ``{"camera": {"name": "cam0"}}``.
    children : mapping, optional
        ``desc`` children holding a list of elements: ``{"skeleton": [{"name": "neck",
        "parent": "pelvis"}, ...]}`` gives ``<skeleton><joint>...</joint>...``.
    channel_format : str
        ``double64`` (default: positions pass exactly), ``float32`` or ``int32``.
    """
    lsl = pylsl()
    fmt = {"double64": lsl.cf_double64, "float32": lsl.cf_float32, "int32": lsl.cf_int32}
    info = lsl.StreamInfo(name, stream_type, len(labels), rate_hz, fmt[channel_format], source_id)
    desc = info.desc()
    chans = desc.append_child("channels")
    for label in labels:
        ch = chans.append_child("channel")
        ch.append_child_value("label", label)
        ch.append_child_value("unit", unit)
    for key, attrs in (meta or {}).items():
        el = desc.append_child(key)
        for k, v in attrs.items():
            el.append_child_value(k, str(v))
    for key, items in (children or {}).items():
        el = desc.append_child(key)
        for attrs in items:
            item = el.append_child("joint")
            for k, v in attrs.items():
                item.append_child_value(k, str(v))
    return lsl.StreamOutlet(info, chunk_size)


def find_stream(name: str, timeout_s: float = 5.0) -> Any:
    """The ``StreamInfo`` of the stream called ``name`` (resolved on the network).

    Raises
    ------
    ConfigError
        No stream of that name within ``timeout_s``; the message lists the streams seen.
    """
    lsl = pylsl()
    found = lsl.resolve_byprop("name", name, 1, timeout_s)
    if found:
        return found[0]
    seen = lsl.resolve_streams(min(1.0, timeout_s))
    shown = ", ".join(sorted(f"{s.name()} ({s.type()})" for s in seen)) or "none"
    raise ConfigError(
        f"LSL stream {name!r}: not found within {timeout_s:g} s; streams seen: {shown}"
    )


def open_inlet(info: Any, max_buffer_s: float = 60.0, timeout_s: float = 5.0) -> Any:
    """An inlet on a resolved stream, opened. Time stamps come as sent (no processing;
    `mocapkit.pipelines.live_feed` maps a device's clock to this machine's). The inlet
    re-connects to a source that comes back; samples received before a source closed
    stay readable (a consumer notices the loss by the silence)."""
    lsl = pylsl()
    inlet = lsl.StreamInlet(info, max_buflen=max(1, math.ceil(max_buffer_s)))
    inlet.open_stream(timeout_s)
    return inlet


def inlet_layout(inlet: Any, timeout_s: float = 5.0) -> StreamLayout:
    """The full metadata of an inlet's stream, parsed (`parse_layout`)."""
    return parse_layout(inlet.info(timeout_s).as_xml())


def parse_layout(xml: str) -> StreamLayout:
    """Parse a stream's XML header: channel labels to points, unit to a scale to mm.

    Raises
    ------
    FormatError
        Labels missing or not ``<name>_<axis>`` in x, y[, z] order, a channel count not a
        whole number of points, or a length unit not in `LENGTH_UNITS`; the message names
        the stream, the channel, what was expected and what was found.
    """
    root = ET.fromstring(xml)
    name = root.findtext("name", "")
    stype = root.findtext("type", "")
    n = int(root.findtext("channel_count", "0"))
    rate = float(root.findtext("nominal_srate", "0"))
    source_id = root.findtext("source_id", "")
    desc = root.find("desc")
    meta: dict[str, dict[str, str]] = {}
    labels: list[str] = []
    units: list[str] = []
    if desc is not None:
        for child in desc:
            if child.tag == "channels":
                for ch in child.findall("channel"):
                    labels.append(ch.findtext("label", "").strip())
                    units.append(ch.findtext("unit", "").strip().lower())
            elif len(child) and all(len(c) == 0 for c in child):
                meta[child.tag] = {c.tag: (c.text or "") for c in child}
    where = f"LSL stream {name!r} ({stype})"
    if stype == FRAMES_TYPE:
        if n != 1:
            raise FormatError(f"{where}: expected 1 channel (the frame number), found {n}")
        return StreamLayout(name, stype, source_id, rate, ("frame",), 1, 1.0, meta)
    if len(labels) != n or not all(labels):
        raise FormatError(
            f"{where}: expected a label for each of its {n} channels in "
            f"desc/channels/channel/label, found {len(labels)} labels ({labels[:6]})"
        )
    dims = 2 if stype == KEYPOINTS_TYPE else 3
    if n % dims:
        raise FormatError(
            f"{where}: expected {dims} channels per point ({'x, y' if dims == 2 else 'x, y, z'}), "
            f"found {n} channels"
        )
    points: list[str] = []
    for k in range(0, n, dims):
        parsed = [_AXIS_LABEL.match(lab) for lab in labels[k : k + dims]]
        names = {m.group("name") for m in parsed if m}
        axes = "".join(m.group("axis").lower() for m in parsed if m)
        if len(names) != 1 or axes != "xyz"[:dims]:
            raise FormatError(
                f"{where}: channels {k}-{k + dims - 1}: expected labels "
                f"<name>_{', <name>_'.join('xyz'[:dims])} of one point, found "
                f"{labels[k : k + dims]}"
            )
        points.append(names.pop())
    if len(set(points)) != len(points):
        dup = next(p for p in points if points.count(p) > 1)
        raise FormatError(f"{where}: point {dup!r} has more than one set of channels")
    scale = 1.0
    if dims == 3:
        unit_set = set(units)
        if len(unit_set) != 1 or next(iter(unit_set)) not in LENGTH_UNITS:
            raise FormatError(
                f"{where}: expected one length unit for every channel (one of "
                f"{', '.join(LENGTH_UNITS)}), found {sorted(unit_set)}"
            )
        scale = LENGTH_UNITS[units[0]]
    return StreamLayout(name, stype, source_id, rate, tuple(points), dims, scale, meta)


__all__ = [
    "FRAMES_TYPE",
    "JOINTS_TYPE",
    "KEYPOINTS_TYPE",
    "LENGTH_UNITS",
    "LOOPBACK_CONFIG",
    "MARKERS_TYPE",
    "QUIET_CONFIG",
    "ReplayClock",
    "StreamLayout",
    "find_stream",
    "inlet_layout",
    "local_clock",
    "lost_error",
    "lsl_timeout_error",
    "make_outlet",
    "open_inlet",
    "parse_layout",
    "point_labels",
    "pylsl",
    "user_config_files",
]
