"""Progress: silent on pipes and logs, frames / fps / ETA on a terminal."""

from __future__ import annotations

import io
import re

from mocapkit.progress import Progress


class FakeTty(io.StringIO):
    """A text stream that claims to be a terminal."""

    def isatty(self) -> bool:
        return True


def test_silent_on_a_non_tty_stream() -> None:
    stream = io.StringIO()
    with Progress(5, "track", stream=stream, min_interval_s=0.0) as prog:
        assert not prog.enabled
        for _ in range(5):
            prog.update()
    assert prog.done == 5
    assert stream.getvalue() == ""


def test_stream_without_isatty_is_silent() -> None:
    class Sink:
        def __init__(self) -> None:
            self.text = ""

        def write(self, s: str) -> int:
            self.text += s
            return len(s)

    sink = Sink()
    with Progress(3, "x", stream=sink, min_interval_s=0.0) as prog:  # type: ignore[arg-type]
        prog.update(3)
    assert not prog.enabled and sink.text == ""


def test_writes_frames_fps_and_eta_to_a_tty() -> None:
    stream = FakeTty()
    with Progress(4, "track hybrid", stream=stream, min_interval_s=0.0) as prog:
        assert prog.enabled
        prog.update()
        first = stream.getvalue()
        assert first.startswith("\rtrack hybrid 1/4 frames, ")
        assert re.search(r"1/4 frames, +\d+\.\d fps, ETA +\d+\.\ds", first), first
        prog.update(3)
    text = stream.getvalue()
    # one redraw per update (interval 0), then the final line ended by a newline
    assert text.count("\r") == 3
    assert "4/4 frames" in text and text.endswith("\033[K\n")
    last = text.rsplit("\r", 1)[1]
    assert re.search(r"ETA +0\.0s", last), last


def test_redraws_are_rate_limited_but_the_last_frame_is_drawn() -> None:
    stream = FakeTty()
    prog = Progress(100, "render", stream=stream, min_interval_s=3600.0)
    for _ in range(100):
        prog.update()
    # redraws wait for the interval (at most the first update may draw, depending on
    # the clock's origin), except the one that completes the total, which always draws
    assert 1 <= stream.getvalue().count("\r") <= 2
    assert stream.getvalue().rsplit("\r", 1)[1].startswith("render 100/100 frames")


def test_eta_unknown_before_any_frame() -> None:
    prog = Progress(10, "wait", stream=FakeTty())
    assert prog.line().endswith("ETA   ?")
    assert "0/10 frames" in prog.line()


def test_units_status_and_rate_scale() -> None:
    prog = Progress(
        12, "batch", stream=FakeTty(), unit="takes", rate_unit="takes/min", rate_scale=60.0
    )
    prog.status = "1 failed, 10 remaining"
    prog.update(2)
    line = prog.line()
    assert line.startswith("batch 2/12 takes, 1 failed, 10 remaining, ")
    assert re.search(r"\d+\.\d takes/min, ETA", line), line


def test_silenced_meters_stay_quiet_on_a_tty_in_this_context_only() -> None:
    import threading

    from mocapkit.progress import silenced

    stream = FakeTty()
    seen: list[bool] = []
    with silenced():
        prog = Progress(2, "inner", stream=stream, min_interval_s=0.0)
        prog.update(2)
        prog.close()
        # a thread started here begins with a fresh context: not silenced
        t = threading.Thread(target=lambda: seen.append(Progress(1, stream=stream).enabled))
        t.start()
        t.join()
    assert not prog.enabled and stream.getvalue() == ""
    assert seen == [True]
    assert Progress(1, stream=stream).enabled
