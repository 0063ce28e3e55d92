"""Screenshots of a report page for the docs: ``python -m tests.viz.screenshots PAGE OUT_DIR``.

Works on every page mocapkit writes: a tracker's report (with or without truth, with or
without videos) and the demo's top page. Where the page has the animated 3D view, it is
moved to the animation frame nearest ``--time-s`` and every overlay video is paused on
that same frame's time. Writes ``<name>_screenshot.png`` (the top of the page: facts,
videos, 3D view; the first 1400 px of a page without one) and, where the page has the
section, ``<name>_accuracy.png`` (the error plot and the accuracy tables) or else
``<name>_fit.png`` (the fit-quality plots), each scaled to 900 px wide and stored with an
adaptive 256-colour palette to stay small. ``--name`` defaults to ``report``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

from .chromium import Chromium, find_chromium

WIDTH_PX, HEIGHT_PX = 1280, 1400

_SECTION_RECT = (
    "(function (title) { var hs = Array.from(document.querySelectorAll('h2'));"
    " var h = hs.find(function (e) { return e.textContent === title; });"
    " if (!h) { return null; }"
    " var s = h.parentNode.getBoundingClientRect();"
    f" return {{x: 0, y: s.top + window.scrollY - 10, width: {WIDTH_PX},"
    " height: s.height + 20}; })"
)
# the id of the animated 3D figure (the one with a time slider), or null
_ANIMATED = (
    "(function () { var f = Array.from(document.querySelectorAll('.js-plotly-plot'))"
    ".find(function (e) { return e.layout && e.layout.sliders && e.layout.sliders.length; });"
    " return f ? f.id : null; })()"
)
# the step of the slider nearest t: [frame name, its time (s)]
_NEAREST_STEP = (
    "(function (id, t) { var s = document.getElementById(id).layout.sliders[0];"
    " var best = s.steps[0]; s.steps.forEach(function (st) {"
    " if (Math.abs(parseFloat(st.label) - t) < Math.abs(parseFloat(best.label) - t)) {"
    " best = st; } }); return [best.args[0][0], parseFloat(best.label)]; })"
)
# pause every video on the frame shown at time t (s), the middle of that frame, and wait
# until that frame is presented (at most 3 s: a seek onto the frame shown presents none)
_SEEK_VIDEOS = (
    "(function (t) { return Promise.all(Array.from(document.querySelectorAll('video'))"
    ".map(function (v) { v.pause(); var fps = parseFloat(v.dataset.fps) || 30;"
    " return new Promise(function (done) {"
    " v.addEventListener('seeked', function () { setTimeout(done, 3000);"
    " if (v.requestVideoFrameCallback) { v.requestVideoFrameCallback(function () { done(); });"
    " } else { done(); } }, {once: true});"
    " v.currentTime = Math.round(t * fps) / fps + 0.5 / fps; }); }))"
    ".then(function () { return 0; }); })"
)


def _save(png: bytes, path: Path, width: int = 900) -> None:
    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    h = round(img.shape[0] * width / img.shape[1])
    small = cv2.resize(img, (width, h), interpolation=cv2.INTER_AREA)
    try:
        from PIL import Image

        rgb = Image.fromarray(cv2.cvtColor(small, cv2.COLOR_BGR2RGB))
        rgb.quantize(256, method=Image.Quantize.MEDIANCUT).save(path, optimize=True)
    except ImportError:  # no Pillow: a plain PNG
        cv2.imwrite(str(path), small, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    print(f"{path}: {path.stat().st_size // 1024} KiB, {width}x{h}")


def main(argv: list[str] | None = None) -> int:
    """Take the screenshots."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("page", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--time-s", type=float, default=1.5)
    parser.add_argument("--name", default="report", help="file name prefix (default report)")
    args = parser.parse_args(argv)
    exe = find_chromium()
    if exe is None:
        print("no chromium on PATH", file=sys.stderr)
        return 1
    args.out.mkdir(parents=True, exist_ok=True)
    with Chromium(exe, WIDTH_PX, HEIGHT_PX, timeout_s=300) as browser:
        browser.open(args.page.resolve().as_uri(), settle_s=2.0)
        figure = browser.evaluate(_ANIMATED)
        t = args.time_s
        if figure is not None:
            frame, t = browser.evaluate(f"{_NEAREST_STEP}('{figure}', {t})")
            browser.evaluate(
                f"Plotly.animate('{figure}', ['{frame}'], {{frame: {{duration: 0, redraw: true}},"
                " transition: {duration: 0}, mode: 'immediate'}).catch(function () {}); 0"
            )
        browser.evaluate(f"{_SEEK_VIDEOS}({t})")
        browser.pump(3.0)
        if figure is not None:
            top = browser.evaluate(
                f"(function () {{ var r = document.getElementById('{figure}')"
                ".getBoundingClientRect(); return r.bottom + window.scrollY + 10; })()"
            )
        else:
            top = min(HEIGHT_PX, browser.evaluate("document.documentElement.scrollHeight"))
        _save(
            browser.screenshot({"x": 0, "y": 0, "width": WIDTH_PX, "height": top}),
            args.out / f"{args.name}_screenshot.png",
        )
        for title, suffix in (("Accuracy against the truth", "accuracy"), ("Fit quality", "fit")):
            rect = browser.evaluate(f"{_SECTION_RECT}('{title}')")
            if rect is not None:
                _save(browser.screenshot(rect), args.out / f"{args.name}_{suffix}.png")
                break
        errors = browser.errors()
    if errors:
        print("page errors:", *errors, sep="\n  ", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
