"""Screenshots of a report page for the docs: ``python -m tests.viz.screenshots PAGE OUT_DIR``.

Shows the overlay video paused at ``--time-s`` and the 3D view at the same time, then
writes ``report_screenshot.png`` (top of the page: facts, video, 3D view) and
``report_accuracy.png`` (the error plot and the accuracy tables), each scaled to 900 px
wide and stored with an adaptive 256-colour palette to stay small.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

from .chromium import Chromium, find_chromium

_SECTION_RECT = (
    "(function (title) { var hs = Array.from(document.querySelectorAll('h2'));"
    " var h = hs.find(function (e) { return e.textContent === title; });"
    " var s = h.parentNode.getBoundingClientRect();"
    " return {x: 0, y: s.top + window.scrollY - 10, width: 1280, height: s.height + 20}; })"
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
    args = parser.parse_args(argv)
    exe = find_chromium()
    if exe is None:
        print("no chromium on PATH", file=sys.stderr)
        return 1
    args.out.mkdir(parents=True, exist_ok=True)
    with Chromium(exe, 1280, 1400) as browser:
        browser.open(args.page.resolve().as_uri(), settle_s=2.0)
        t = args.time_s
        frame = browser.evaluate(
            "(function (t) { var s = document.getElementById('figure0').layout.sliders[0];"
            " var best = 0; s.steps.forEach(function (st, i) {"
            " if (Math.abs(parseFloat(st.label) - t) < Math.abs(parseFloat(s.steps[best].label)"
            " - t)) { best = i; } }); return best; })" + f"({t})"
        )
        browser.evaluate(
            f"Plotly.animate('figure0', ['{frame}'], {{frame: {{duration: 0, redraw: true}},"
            " transition: {duration: 0}, mode: 'immediate'}).catch(function () {}); 0"
        )
        browser.evaluate(
            "Promise.all(Array.from(document.querySelectorAll('video')).map(function (v) {"
            " v.pause(); return new Promise(function (done) {"
            " v.addEventListener('seeked', done, {once: true});"
            f" v.currentTime = {t}; }}); }})).then(function () {{ return 0; }})"
        )
        browser.pump(3.0)
        top = browser.evaluate(
            "(function () { var r = document.getElementById('figure0').getBoundingClientRect();"
            " return r.bottom + window.scrollY + 10; })()"
        )
        _save(
            browser.screenshot({"x": 0, "y": 0, "width": 1280, "height": top}),
            args.out / "report_screenshot.png",
        )
        rect = browser.evaluate(f"{_SECTION_RECT}('Accuracy against the truth')")
        _save(browser.screenshot(rect), args.out / "report_accuracy.png")
        errors = browser.errors()
    if errors:
        print("page errors:", *errors, sep="\n  ", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
