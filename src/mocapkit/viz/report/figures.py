"""Plotly figures of a capture report: the animated 3D skeleton, errors and fit quality over time.

Pure functions from arrays to `plotly.graph_objects.Figure`; nothing is read or written here.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import plotly.graph_objects as go
from numpy.typing import NDArray

from mocapkit.errors import ShapeError
from mocapkit.skeleton.model import CANONICAL_SEGMENTS

FloatArray = NDArray[np.float64]

#: Trace colours (CSS): captured, truth, markers.
CAPTURED_COLOUR = "#ff8c1a"
TRUTH_COLOUR = "#2ca02c"
MARKER_COLOUR = "#1f77b4"
#: Line colours of per-joint and per-column plots: 20 distinct colours (Kelly's
#: contrast set without white and black), so that the 15 canonical joints differ.
LINE_COLOURS = (
    "#e6194b", "#3cb44b", "#4363d8", "#f58231", "#911eb4", "#42d4f4", "#f032e6",
    "#9a6324", "#469990", "#800000", "#808000", "#000075", "#bfef45", "#fabed4",
    "#dcbeff", "#ffe119", "#aaffc3", "#ffd8b1", "#a9a9a9", "#000000",
)  # fmt: skip
#: Colours of the tracker statuses in ``fit.csv`` (`mocapkit.tracking.base`): a traffic
#: light; other text columns (e.g. ``worst``, a marker set's name) are plotted apart.
STATUS_COLOURS = {
    "seen": "#2ca02c",
    "bridged": "#f2b701",
    "released": "#d62728",
    "missing": "#7f7f7f",
}
#: Unit suffixes of ``fit.csv`` column names and their axis titles, the first that ends
#: the name wins (a speed before its seconds); a column without one is unitless (a ratio,
#: a count, a flag or an edge cost).
UNIT_SUFFIXES = {
    "_mm_per_s": "mm/s",
    "_deg_per_s": "deg/s",
    "_mm": "mm",
    "_px": "px",
    "_deg": "degrees",
    "_s": "s",
}


@dataclass(frozen=True)
class PointLayer:
    """One set of 3-D points animated over the shared time line.

    Attributes
    ----------
    name : str
        Legend entry (``"captured"``, ``"truth"``, ``"markers"``).
    point_names : tuple of str, length K
        Canonical joint names (for sticks) or marker names.
    points_mm : ndarray, shape (T, K, 3)
        World positions (mm) at each frame of the time line; NaN where unknown.
    colour : str
        CSS colour.
    sticks : bool
        Join canonical joints by the `CANONICAL_SEGMENTS` sticks (False: points only).
    """

    name: str
    point_names: tuple[str, ...]
    points_mm: FloatArray
    colour: str
    sticks: bool = True


def _frame_coords(layer: PointLayer, f: int) -> tuple[list[float | None], ...]:
    """x, y, z lists of one frame: sticks as segments separated by gaps (None)."""
    pts = layer.points_mm[f]
    xs: list[float | None] = []
    ys: list[float | None] = []
    zs: list[float | None] = []

    def add(p: FloatArray) -> None:
        ok = bool(np.all(np.isfinite(p)))
        xs.append(round(float(p[0]), 1) if ok else None)
        ys.append(round(float(p[1]), 1) if ok else None)
        zs.append(round(float(p[2]), 1) if ok else None)

    if layer.sticks:
        index = {n: k for k, n in enumerate(layer.point_names)}
        for a, b in CANONICAL_SEGMENTS.values():
            if a in index and b in index:
                add(pts[index[a]])
                add(pts[index[b]])
                xs.append(None)
                ys.append(None)
                zs.append(None)
        drawn = {n for seg in CANONICAL_SEGMENTS.values() for n in seg}
        for n, k in index.items():  # joints no stick reaches still show as dots
            if n not in drawn:
                add(pts[k])
                xs.append(None)
                ys.append(None)
                zs.append(None)
    else:
        for k in range(pts.shape[0]):
            add(pts[k])
    return xs, ys, zs


def _trace(layer: PointLayer, f: int) -> go.Scatter3d:
    x, y, z = _frame_coords(layer, f)
    return go.Scatter3d(
        x=x,
        y=y,
        z=z,
        name=layer.name,
        mode="lines+markers" if layer.sticks else "markers",
        line={"color": layer.colour, "width": 6},
        marker={"color": layer.colour, "size": 3 if layer.sticks else 4},
        connectgaps=False,
        hoverinfo="name",
    )


def skeleton_animation(
    time_s: FloatArray, layers: Sequence[PointLayer], title: str = "3D view"
) -> go.Figure:
    """Animated 3-D view of skeletons and markers with play, pause and a time slider.

    Parameters
    ----------
    time_s : ndarray, shape (T,)
        Frame times (s) of the animation (T >= 1).
    layers : sequence of PointLayer
        Each with ``points_mm`` of shape (T, K, 3).
    title : str

    Returns
    -------
    plotly.graph_objects.Figure
        One ``Scatter3d`` trace per layer and one animation frame per time (named by its
        index); the axes keep one range over the whole clip and equal scale (mm), Z up.
    """
    t = np.asarray(time_s, dtype=float)
    if t.ndim != 1 or t.shape[0] == 0:
        raise ShapeError(
            f"skeleton_animation: expected time_s of shape (T,), T >= 1, found {t.shape}"
        )
    for layer in layers:
        if layer.points_mm.shape != (t.shape[0], len(layer.point_names), 3):
            raise ShapeError(
                f"skeleton_animation: layer {layer.name!r}: expected points of shape "
                f"({t.shape[0]}, {len(layer.point_names)}, 3), found {layer.points_mm.shape}"
            )
    every = np.concatenate(
        [layer.points_mm.reshape(-1, 3) for layer in layers] or [np.zeros((0, 3))]
    )
    every = every[np.all(np.isfinite(every), axis=1)]
    if every.shape[0] == 0:
        every = np.array([[-1000.0, -1000.0, 0.0], [1000.0, 1000.0, 2000.0]])
    # one range over the whole clip (the view must not jump) with a 100 mm margin, and an
    # aspect ratio equal to the ranges' so that a millimetre is as long on every axis
    lo, hi = every.min(axis=0) - 100.0, every.max(axis=0) + 100.0
    span = hi - lo
    ratio = span / span.max()
    axes = {
        f"{a}axis": {
            "title": {"text": f"{a} (mm)"},
            "range": [float(lo[i]), float(hi[i])],
            "autorange": False,
        }
        for i, a in enumerate("xyz")
    }
    dt_ms = float(np.median(np.diff(t)) * 1000.0) if t.shape[0] > 1 else 100.0
    fig = go.Figure(
        data=[_trace(layer, 0) for layer in layers],
        frames=[
            go.Frame(data=[_trace(layer, f) for layer in layers], name=str(f))
            for f in range(t.shape[0])
        ],
    )
    still = {
        "frame": {"duration": 0, "redraw": True},
        "mode": "immediate",
        "transition": {"duration": 0},
    }
    fig.update_layout(
        title={"text": title},
        height=620,
        margin={"l": 0, "r": 0, "t": 40, "b": 0},
        scene={
            **axes,
            "domain": {"x": [0.0, 1.0], "y": [0.1, 1.0]},  # above the slider
            "aspectmode": "manual",
            "aspectratio": {"x": float(ratio[0]), "y": float(ratio[1]), "z": float(ratio[2])},
            # a view from the front left, a little above (the subject faces +Y, Z up)
            # far enough that the box and its axis titles fit inside the scene
            "camera": {"eye": {"x": -1.3, "y": 1.6, "z": 0.5}, "up": {"x": 0, "y": 0, "z": 1}},
        },
        legend={"x": 0.01, "y": 0.98},
        updatemenus=[
            {
                "type": "buttons",
                "direction": "left",
                "x": 0.01,
                "y": 0.02,
                "xanchor": "left",
                "yanchor": "bottom",
                "showactive": False,
                "buttons": [
                    {
                        "label": "Play",
                        "method": "animate",
                        "args": [
                            None,
                            {
                                "frame": {"duration": dt_ms, "redraw": True},
                                "fromcurrent": True,
                                "transition": {"duration": 0},
                            },
                        ],
                    },
                    {
                        "label": "Pause",
                        "method": "animate",
                        "args": [[None], {**still, "frame": {"duration": 0, "redraw": False}}],
                    },
                ],
            }
        ],
        sliders=[
            {
                "active": 0,
                "x": 0.15,
                "len": 0.85,
                "y": 0.0,
                "currentvalue": {
                    "prefix": "t = ",
                    "suffix": " s",
                    "font": {"color": "#444", "size": 13},
                },
                # one step per frame: their labels would overlap, so only the current
                # value shows the time
                "font": {"color": "rgba(0,0,0,0)"},
                "ticklen": 0,
                "minorticklen": 0,
                "steps": [
                    {"label": f"{t[f]:.2f}", "method": "animate", "args": [[str(f)], still]}
                    for f in range(t.shape[0])
                ],
            }
        ],
    )
    return fig


def animation_options(time_s: FloatArray) -> dict[str, object]:
    """Options for `plotly.io.to_html`'s ``animation_opts``: real-time frames, 3-D redraw."""
    t = np.asarray(time_s, dtype=float)
    dt_ms = float(np.median(np.diff(t)) * 1000.0) if t.shape[0] > 1 else 100.0
    return {
        "frame": {"duration": dt_ms, "redraw": True},
        "transition": {"duration": 0},
        "mode": "immediate",
        "fromcurrent": True,
    }


def error_figure(
    time_s: FloatArray, joint_names: Sequence[str], error_mm: FloatArray, title: str
) -> go.Figure:
    """Per-joint error over time: one line per joint (mm); gaps where a frame has no pose.

    Parameters
    ----------
    time_s : ndarray, shape (T,)
    joint_names : sequence of str, length K
    error_mm : ndarray, shape (T, K)
        Distance between captured and true joint (mm); NaN where unknown.
    title : str
    """
    err = np.asarray(error_mm, dtype=float)
    t = np.asarray(time_s, dtype=float)
    if err.shape != (t.shape[0], len(joint_names)):
        raise ShapeError(
            f"error_figure: expected errors of shape ({t.shape[0]}, {len(joint_names)}), "
            f"found {err.shape}"
        )
    fig = go.Figure()
    for k, name in enumerate(joint_names):
        y = [None if not np.isfinite(v) else round(float(v), 2) for v in err[:, k]]
        colour = LINE_COLOURS[k % len(LINE_COLOURS)]
        fig.add_trace(go.Scatter(x=t, y=y, name=name, mode="lines", line={"color": colour}))
    fig.update_layout(
        title={"text": title},
        xaxis={"title": {"text": "time (s)"}},
        yaxis={"title": {"text": "error (mm)"}, "rangemode": "tozero"},
        height=420,
        margin={"t": 50},
    )
    return fig


def _states_figure(
    t: FloatArray, columns: Mapping[str, Sequence[str]], title: str, colours: Mapping[str, str]
) -> go.Figure:
    """One row per text column, one square per frame coloured by its value (``colours``,
    else the line colours in turn); empty cells left out."""
    fig = go.Figure()
    values = sorted({v for col in columns.values() for v in col if v})
    others = iter(LINE_COLOURS * (1 + len(values) // len(LINE_COLOURS)))
    for value in values:
        xs: list[float] = []
        ys: list[str] = []
        for name, col in columns.items():
            if len(col) != t.shape[0]:
                raise ShapeError(
                    f"fit_figures: column {name!r}: expected {t.shape[0]} values, found {len(col)}"
                )
            hit = [i for i, v in enumerate(col) if v == value]
            xs += [float(t[i]) for i in hit]
            ys += [name] * len(hit)
        colour = colours.get(value) or next(others)
        fig.add_trace(
            go.Scatter(
                x=xs, y=ys, name=value, mode="markers", marker={"symbol": "square", "color": colour}
            )
        )
    fig.update_layout(
        title={"text": title},
        xaxis={"title": {"text": "time (s)"}},
        height=140 + 30 * len(columns),
        margin={"t": 50},
    )
    return fig


def column_unit(name: str) -> str:
    """The unit of a ``fit.csv`` column by its name's suffix (`UNIT_SUFFIXES`); '' if none."""
    return next((u for suffix, u in UNIT_SUFFIXES.items() if name.endswith(suffix)), "")


def fit_figures(
    time_s: FloatArray,
    numeric: Mapping[str, FloatArray],
    text: Mapping[str, Sequence[str]],
    title: str = "Fit quality per frame",
) -> list[go.Figure]:
    """Per-frame fit figures: every numeric column against time, and text columns as states.

    Parameters
    ----------
    time_s : ndarray, shape (T,)
    numeric : mapping column name -> ndarray (T,)
        One line per column (NaN leaves a gap).
    text : mapping column name -> sequence of str (T,)
        Categorical columns (``*_status``: an effector's ``seen``/``bridged``/``missing``
        status; others such as ``worst``): one row per column, one marker colour per
        value; empty cells are left out.
    title : str

    Returns
    -------
    list of Figure
        One figure per unit of the numeric columns (`column_unit`: mm, px, ... and the
        unitless ones apart, each on its labelled axis), then the states figure (when
        there is a ``*_status`` column; statuses in `STATUS_COLOURS`), then one of the
        other text columns (e.g. ``worst``).
    """
    t = np.asarray(time_s, dtype=float)
    out: list[go.Figure] = []
    by_unit: dict[str, dict[str, FloatArray]] = {}
    for name, column in numeric.items():
        v = np.asarray(column, dtype=float)
        if v.shape != t.shape:
            raise ShapeError(
                f"fit_figures: column {name!r}: expected {t.shape[0]} values, found {v.shape}"
            )
        by_unit.setdefault(column_unit(name), {})[name] = v
    for unit, columns in by_unit.items():
        fig = go.Figure()
        for k, (name, v) in enumerate(columns.items()):
            fig.add_trace(
                go.Scatter(
                    x=t,
                    y=[None if not np.isfinite(x) else float(x) for x in v],
                    name=name,
                    mode="lines",
                    line={"color": LINE_COLOURS[k % len(LINE_COLOURS)]},
                )
            )
        fig.update_layout(
            title={"text": f"{title}: {'unitless values' if unit == '' else unit}"},
            xaxis={"title": {"text": "time (s)"}},
            yaxis={"title": {"text": unit or "value (no unit)"}},
            height=380,
            margin={"t": 50},
        )
        out.append(fig)
    status = {n: c for n, c in text.items() if n.endswith("_status")}
    labels = {n: c for n, c in text.items() if not n.endswith("_status")}
    if status:
        out.append(_states_figure(t, status, "Status per frame", STATUS_COLOURS))
    if labels:
        out.append(_states_figure(t, labels, "Labels per frame", {}))
    return out


__all__ = [
    "CAPTURED_COLOUR",
    "LINE_COLOURS",
    "MARKER_COLOUR",
    "STATUS_COLOURS",
    "TRUTH_COLOUR",
    "PointLayer",
    "animation_options",
    "column_unit",
    "error_figure",
    "fit_figures",
    "skeleton_animation",
]
