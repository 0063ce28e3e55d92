"""The report in headless Chromium: loads without errors, the 3D view renders and animates,
the plots and the video are there. Skipped where no Chromium is installed."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from mocapkit.pipelines.report import build_report

from .chromium import Chromium, find_chromium

CHROMIUM = find_chromium()
pytestmark = pytest.mark.skipif(
    CHROMIUM is None,
    reason="no chromium on PATH (Debian: apt-get install -y chromium); make test installs it "
    "where it may (tools/install-test-browser)",
)

_RECT = (
    "(function (id) { var r = document.getElementById(id).getBoundingClientRect();"
    " return {x: r.left + window.scrollX, y: r.top + window.scrollY,"
    " width: r.width, height: r.height}; })"
)


def _image(png: bytes) -> np.ndarray:
    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    assert img is not None
    return img


@pytest.fixture(scope="module")
def report_page(npz_result, small_session, tmp_path_factory):
    out = tmp_path_factory.mktemp("browser") / "report"
    return build_report(npz_result, truth_session=small_session, out_dir=out)


def test_report_in_chromium(report_page):
    assert CHROMIUM is not None
    with Chromium(CHROMIUM, 1280, 900) as browser:
        browser.open(report_page.as_uri(), settle_s=1.0)
        browser.wait_for(
            "document.querySelectorAll('.js-plotly-plot .main-svg').length >= 2 &&"
            " Array.from(document.querySelectorAll('video')).every(function (v) {"
            " return v.dataset.state; })"
        )
        # every plotly figure drew: the 3D view (WebGL canvas) and the error plot (SVG)
        plots = browser.evaluate(
            "Array.from(document.querySelectorAll('.js-plotly-plot')).map(function (d) {"
            " return [d.id, d.querySelectorAll('.gl-container canvas').length,"
            " d.querySelectorAll('.main-svg .trace').length]; })"
        )
        assert len(plots) == 2
        assert plots[0][0] == "figure0" and plots[0][1] >= 1  # 3D scene on a canvas
        assert plots[1][2] >= 15  # one error line per canonical joint
        # the overlay video decoded (the page marks it) and lasts one second
        videos = browser.evaluate(
            "Array.from(document.querySelectorAll('video')).map(function (v) {"
            " return [v.dataset.state, v.readyState, v.duration, v.videoWidth]; })"
        )
        assert len(videos) == 1
        state, _ready, duration, width = videos[0]
        assert state == "loaded" and width == 160  # (readyState drops while it loops)
        assert duration == pytest.approx(31 / 30.0, abs=0.1)

        # the 3D view: scrub to the first frame, then press Play and look again later
        rect = browser.evaluate(f"{_RECT}('figure0')")
        browser.evaluate(
            "Plotly.animate('figure0', ['0'], {frame: {duration: 0, redraw: true},"
            " transition: {duration: 0}, mode: 'immediate'})"
        )
        browser.pump(1.0)
        first = _image(browser.screenshot(rect))
        assert first.std() > 5.0  # the scene drew something, not a blank box
        browser.evaluate(
            "document.querySelector('#figure0 .updatemenu-button').dispatchEvent("
            "new MouseEvent('click', {bubbles: true}))"
        )
        # software WebGL on a busy machine may draw a frame in a second: wait for the
        # slider to leave the first frame (the state, not a time, decides)
        active = "document.getElementById('figure0').layout.sliders[0].active"
        assert browser.wait_for(f"{active} > 1"), "Play did not move the animation"
        later = _image(browser.screenshot(rect))
        assert first.shape == later.shape
        changed = np.any(first != later, axis=2).mean()
        assert changed > 0.001, "the 3D view looks the same at a later frame"
        assert browser.errors() == []
