"""The report page: one offline HTML file with plotly figures, videos, tables and links.

Plotly's own offline writer (`plotly.io.to_html`) renders every figure; the plotly.js
bundle is written once beside the page (``plotly.min.js``, taken from the installed
plotly package, ``include_plotlyjs="directory"``), so the page fetches nothing from the
network. A few lines of page script only mark each video as loaded or failed (and say so
on the page) and flip through JPEG frames when no video codec was available.
"""

from __future__ import annotations

import html
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import plotly.graph_objects as go
import plotly.io as pio
import plotly.offline

from mocapkit.io.atomic import atomic_write
from mocapkit.viz.web_video import JPEG_SEQUENCE, WebVideo

PAGE_NAME = "index.html"
PLOTLY_JS = "plotly.min.js"


@dataclass(frozen=True)
class Table:
    """A small table of text cells (already formatted)."""

    title: str
    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]


@dataclass(frozen=True)
class Section:
    """A titled part of the page holding figures, videos, tables and notes, in that order.

    Attributes
    ----------
    title : str
    figures : sequence of Figure
    videos : sequence of (label, WebVideo)
        Videos written inside the page's folder.
    tables : sequence of Table
    notes : sequence of str
        Plain sentences shown under the title.
    animation_opts : dict, optional
        When given, the section's first figure starts its animation on load with these
        options (`Plotly.animate`'s).
    """

    title: str
    figures: Sequence[go.Figure] = ()
    videos: Sequence[tuple[str, WebVideo]] = ()
    tables: Sequence[Table] = ()
    notes: Sequence[str] = ()
    animation_opts: dict[str, object] | None = None


@dataclass(frozen=True)
class ReportPage:
    """Everything the page shows.

    Attributes
    ----------
    title : str
    facts : sequence of (label, value)
        Shown at the top (result folder, source, frames, ...).
    sections : sequence of Section
    links : sequence of (label, href)
        Files to download, hrefs relative to the page.
    """

    title: str
    facts: Sequence[tuple[str, str]] = ()
    sections: Sequence[Section] = ()
    links: Sequence[tuple[str, str]] = field(default_factory=tuple)


_STYLE = """
body { font-family: system-ui, sans-serif; margin: 1.5em auto; max-width: 1200px;
       color: #222; padding: 0 1em; }
h1 { font-size: 1.6em; } h2 { font-size: 1.25em; margin-top: 1.6em;
       border-bottom: 1px solid #ddd; }
table { border-collapse: collapse; margin: 0.5em 0 1em; }
td, th { border: 1px solid #ccc; padding: 0.2em 0.7em; text-align: right; }
td:first-child, th:first-child { text-align: left; }
dl.facts { display: grid; grid-template-columns: max-content auto; gap: 0.2em 1em; }
dl.facts dt { font-weight: 600; } dl.facts dd { margin: 0; }
.videos { display: flex; flex-wrap: wrap; gap: 1em; }
.videos figure { margin: 0; } .videos video, .videos img { max-width: 100%; }
.note { color: #555; } .video-error { color: #b00; }
"""

# Marks every <video> with data-state="loaded" or "error" (and says so under the video),
# flips through JPEG frames for the fallback without a video codec, and keeps plotly's
# interrupted animations out of the console.
_HEAD_SCRIPT = """
// Plotly.animate rejects its promise without a reason when a newer animation interrupts
// it (Pause, the slider, Play again); that is how plotly.js stops an animation, not an
// error, so such rejections are not reported. Any other rejection still is.
window.addEventListener('unhandledrejection', function (event) {
  if (event.reason === undefined) { event.preventDefault(); }
});
"""

_SCRIPT = """document.querySelectorAll('video').forEach(function (v) {
  function loaded() { v.dataset.state = 'loaded'; }
  function failed() {
    v.dataset.state = 'error';
    var p = document.createElement('p');
    p.className = 'video-error';
    p.textContent = 'This browser cannot play ' + v.getAttribute('src') + '.';
    v.parentNode.appendChild(p);
  }
  if (v.error) { failed(); } else if (v.readyState >= 2) { loaded(); }
  v.addEventListener('loadeddata', loaded);
  v.addEventListener('error', failed);
});
document.querySelectorAll('img[data-frames]').forEach(function (img) {
  var n = parseInt(img.dataset.count, 10), i = 0;
  setInterval(function () {
    i = (i + 1) % n;
    img.src = img.dataset.frames + '/' + String(i).padStart(6, '0') + '.jpg';
  }, 1000 / parseFloat(img.dataset.fps));
});
"""


def _autoplay_script(options: dict[str, object] | None) -> str:
    """Start the figure's animation once it is drawn; an interrupted animation (Pause, the
    slider) rejects its promise, which is how plotly.js stops one, so it is caught."""
    return (
        f"return Plotly.animate('{{plot_id}}', null, {json.dumps(options)})"
        ".catch(function () {});"
    )


def _video_html(label: str, video: WebVideo, folder: Path) -> str:
    rel = html.escape(os.path.relpath(video.path, folder).replace(os.sep, "/"))
    w, h = video.size
    cap = html.escape(f"{label}: {video.n_frames} frames, {video.fps:.3g} Hz")
    if video.codec == JPEG_SEQUENCE:
        body = (
            f'<img src="{rel}/000000.jpg" width="{w}" height="{h}" data-frames="{rel}" '
            f'data-count="{video.n_frames}" data-fps="{video.fps:.6g}" alt="{cap}">'
        )
        cap += " (JPEG frames: no web video codec in this OpenCV)"
    else:
        body = (
            f'<video src="{rel}" width="{w}" height="{h}" controls loop muted autoplay '
            f'playsinline preload="auto" data-codec="{html.escape(video.codec)}" '
            f'data-fps="{video.fps:.6g}"></video>'
        )
    return f"<figure>{body}<figcaption>{cap}</figcaption></figure>"


def _table_html(table: Table) -> str:
    head = "".join(f"<th>{html.escape(c)}</th>" for c in table.header)
    rows = "".join(
        "<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>" for row in table.rows
    )
    return f"<h3>{html.escape(table.title)}</h3><table><tr>{head}</tr>{rows}</table>"


def write_report_page(folder: str | os.PathLike[str], page: ReportPage) -> Path:
    """Write ``index.html`` and ``plotly.min.js`` into ``folder`` (each atomically).

    Videos named by the sections must already lie inside ``folder``.

    Returns
    -------
    Path
        The page.
    """
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    parts: list[str] = []
    plotly_included = False
    n_fig = 0
    for section in page.sections:
        parts.append(f"<section><h2>{html.escape(section.title)}</h2>")
        parts += [f'<p class="note">{html.escape(n)}</p>' for n in section.notes]
        for i, fig in enumerate(section.figures):
            animate = section.animation_opts is not None and i == 0
            parts.append(
                pio.to_html(
                    fig,
                    include_plotlyjs=False if plotly_included else "directory",
                    full_html=False,
                    # plotly's own auto_play leaves the animation's promise unhandled, so
                    # stopping it (Pause, the slider) reports an error; start it here instead
                    auto_play=False,
                    post_script=_autoplay_script(section.animation_opts) if animate else None,
                    div_id=f"figure{n_fig}",
                    config={"displaylogo": False, "responsive": True},
                )
            )
            plotly_included = True
            n_fig += 1
        if section.videos:
            parts.append('<div class="videos">')
            parts += [_video_html(label, v, out) for label, v in section.videos]
            parts.append("</div>")
        parts += [_table_html(t) for t in section.tables]
        parts.append("</section>")
    if page.links:
        parts.append("<section><h2>Files</h2><ul>")
        parts += [
            f'<li><a href="{html.escape(href)}">{html.escape(label)}</a></li>'
            for label, href in page.links
        ]
        parts.append("</ul></section>")
    facts = "".join(f"<dt>{html.escape(k)}</dt><dd>{html.escape(v)}</dd>" for k, v in page.facts)
    doc = (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>{html.escape(page.title)}</title><style>{_STYLE}</style>"
        f"<script>{_HEAD_SCRIPT}</script></head><body>"
        f'<h1>{html.escape(page.title)}</h1><dl class="facts">{facts}</dl>'
        + "\n".join(parts)
        + f"<script>{_SCRIPT}</script></body></html>\n"
    )
    if plotly_included:
        with atomic_write(out / PLOTLY_JS, "w") as fh:
            fh.write(plotly.offline.get_plotlyjs())
    path = out / PAGE_NAME
    with atomic_write(path, "w") as fh:
        fh.write(doc)
    return path


__all__ = ["PAGE_NAME", "PLOTLY_JS", "ReportPage", "Section", "Table", "write_report_page"]
