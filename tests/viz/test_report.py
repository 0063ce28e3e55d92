"""The report builder: local files only, the expected traces, optional truth/video/fit, refusals."""

from __future__ import annotations

import re
import shutil
from html.parser import HTMLParser
from pathlib import Path

import cv2
import numpy as np
import plotly.offline
import pytest

from mocapkit.cli.main import main
from mocapkit.errors import ConfigError, FormatError, SessionError, ShapeError
from mocapkit.io.joints_csv import read_joints_csv
from mocapkit.io.marker_files import read_markers
from mocapkit.io.session import load_session
from mocapkit.pipelines.report import build_report, read_fit_table
from mocapkit.skeleton.model import CANONICAL_JOINTS
from mocapkit.viz.report.figures import (
    STATUS_COLOURS,
    PointLayer,
    column_unit,
    error_figure,
    fit_figures,
    skeleton_animation,
)
from mocapkit.viz.web_video import JPEG_SEQUENCE, WebVideoWriter, web_codec


class _Refs(HTMLParser):
    """Every src and href of a page."""

    def __init__(self) -> None:
        super().__init__()
        self.refs: list[tuple[str, str]] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        for key, value in attrs:
            if key in ("src", "href") and value is not None:
                self.refs.append((tag, value))


def page_refs(page: Path) -> list[tuple[str, str]]:
    parser = _Refs()
    parser.feed(page.read_text(encoding="utf-8"))
    return parser.refs


def trace_names(page: Path) -> set[str]:
    """Names of the plotly traces the page holds (from the embedded figure JSON)."""
    return set(re.findall(r'"name":"([^"]+)"', page.read_text(encoding="utf-8")))


def test_report_with_truth_video_and_markers(npz_result, small_session, tmp_path):
    out = tmp_path / "rep"
    page = build_report(npz_result, truth_session=small_session, out_dir=out)
    assert page == out / "index.html"
    refs = page_refs(page)
    # only local files, and each exists beside the page
    assert refs, "the page references its script, video and files"
    for tag, ref in refs:
        assert not re.match(r"^[a-z]+://|^//", ref), f"{tag} refers to {ref}"
        assert (out / ref).exists(), f"{tag} refers to missing {ref}"
    text = page.read_text(encoding="utf-8")
    assert "cdn" not in " ".join(r for _, r in refs).lower()
    # plotly.js once, beside the page, as the installed package ships it
    assert text.count('src="plotly.min.js"') == 1
    assert (out / "plotly.min.js").read_text(encoding="utf-8") == plotly.offline.get_plotlyjs()
    names = trace_names(page)
    session = load_session(small_session)
    assert {"captured", "truth", "markers"} <= names
    assert set(session.truth.joint_names) <= names  # one error line per joint
    # the overlay video: one frame per video frame, decodable
    video_ref = next(r for t, r in refs if t == "video")
    assert video_ref.startswith("overlay_mono")
    cap = cv2.VideoCapture(str(out / video_ref))
    n = 0
    while cap.read()[0]:
        n += 1
    cap.release()
    assert n == session.video("mono").n_frames
    # links to the result's BVH and CSV and the report's TRC
    hrefs = {r for t, r in refs if t == "a"}
    linked = {Path(r).name for r in hrefs}
    assert {"motion.bvh", "joints.csv", "motion.npz", "joints.trc"} <= linked
    trc = read_markers(out / "joints.trc")
    _, jn, joints = read_joints_csv(npz_result / "joints.csv")
    assert trc.names == jn
    np.testing.assert_allclose(trc.positions_mm, joints, atol=1e-5)
    # the accuracy table holds the evaluation's figures, each column naming its joints
    assert "MPJPE (mm)" in text and "Error per joint" in text
    assert "upper body (9 joints)" in text and "all 15 joints" in text


def test_report_without_truth_or_video(csv_result, tmp_path):
    page = build_report(csv_result)
    assert page == csv_result / "report" / "index.html"
    names = trace_names(page)
    assert "captured" in names
    assert not {"truth", "markers", "left_elbow"} & names
    text = page.read_text(encoding="utf-8")
    assert "<video" not in text and "Accuracy" not in text
    # built again: the old report is replaced whole
    (csv_result / "report" / "stale.txt").write_text("old")
    build_report(csv_result)
    assert not (csv_result / "report" / "stale.txt").exists()


def test_raw_marker_result_shows_given_markers(csv_result, small_session, tmp_path):
    session = load_session(small_session)
    page = build_report(csv_result, out_dir=tmp_path / "r", markers=session.markers.source)
    assert {"captured", "markers"} <= trace_names(page)
    assert "<video" not in page.read_text(encoding="utf-8")


def test_fit_csv_every_column_plotted(csv_result, tmp_path):
    t, _, _ = read_joints_csv(csv_result / "joints.csv")
    rows = ["time_s,head_status,ik_residual_mm,outline_px,worst"]
    for i, ti in enumerate(t):
        status = "seen" if i % 4 else "bridged"
        resid = "" if i == 3 else f"{0.5 * i:.3f}"
        rows.append(f"{ti:.9f},{status},{resid},{i % 7},{'head' if i % 2 else ''}")
    (csv_result / "fit.csv").write_text("\n".join(rows) + "\n")
    fit = read_fit_table(csv_result / "fit.csv")
    assert set(fit.numeric) == {"ik_residual_mm", "outline_px"}
    assert set(fit.text) == {"head_status", "worst"}
    assert np.isnan(fit.numeric["ik_residual_mm"][3])
    np.testing.assert_allclose(fit.time_s, t, atol=1e-9)
    page = build_report(csv_result, out_dir=tmp_path / "r")
    names = trace_names(page)
    assert {"ik_residual_mm", "outline_px", "seen", "bridged", "head"} <= names
    assert any(Path(r).name == "fit.csv" for _, r in page_refs(page))


def test_fit_csv_without_time_refused(tmp_path):
    (tmp_path / "fit.csv").write_text("frame,residual\n0,1.0\n")
    with pytest.raises(FormatError, match=r"fit.csv: line 1: expected a header with a 'time_s'"):
        read_fit_table(tmp_path / "fit.csv")


def test_refuses_folders_that_are_not_results(npz_result, small_session, tmp_path):
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(SessionError, match=r"not a result folder: expected motion.npz or joints"):
        build_report(tmp_path)
    with pytest.raises(SessionError, match="this is a session folder: give the result folder"):
        build_report(small_session)
    with pytest.raises(SessionError, match="result folder not found"):
        build_report(tmp_path / "missing")
    with pytest.raises(SessionError, match="expected a result folder .* found a file"):
        build_report(tmp_path / "notes.txt")
    with pytest.raises(ConfigError, match="would replace"):
        build_report(npz_result, out_dir=npz_result)
    with pytest.raises(ConfigError, match="would replace"):
        build_report(npz_result, out_dir=npz_result.parent)
    with pytest.raises(ConfigError, match="would replace"):
        build_report(npz_result, truth_session=small_session, out_dir=small_session)
    # a session without truth.npz given as --truth
    no_truth = tmp_path / "no_truth"
    shutil.copytree(small_session, no_truth)
    (no_truth / "truth.npz").unlink()
    with pytest.raises(SessionError, match=r"session lacks truth.npz"):
        build_report(npz_result, truth_session=no_truth, out_dir=tmp_path / "r")


def test_cli_view(csv_result, tmp_path, capsys):
    out = tmp_path / "v"
    assert main(["view", str(csv_result), "--out", str(out)]) == 0
    assert capsys.readouterr().out.strip() == str(out / "index.html")
    assert main(["view", str(tmp_path / "v")]) == 2
    assert "not a result folder" in capsys.readouterr().err


def test_skeleton_animation_frames_and_fixed_axes():
    rng = np.random.default_rng(4)
    t = np.arange(6) / 30.0
    names = ("neck", "head", "pelvis", "left_hip")
    pts = rng.normal(0.0, 300.0, (6, 4, 3)) + np.array([0.0, 0.0, 1000.0])
    pts[2, 1] = np.nan
    fig = skeleton_animation(t, [PointLayer("captured", names, pts, "#f80")])
    assert len(fig.frames) == 6
    assert [list(s["args"][0]) for s in fig.layout.sliders[0].steps] == [[str(f)] for f in range(6)]
    x = fig.frames[2].data[0].x
    # sticks neck-head, pelvis-neck (trunk), pelvis-left_hip, each two points and a gap
    assert len(x) == 9
    assert x[3] is not None and x[4] is None  # neck drawn, the missing head a gap
    rng_x = fig.layout.scene.xaxis.range
    assert rng_x[0] <= np.nanmin(pts[..., 0]) - 99 and rng_x[1] >= np.nanmax(pts[..., 0]) + 99
    with pytest.raises(ShapeError, match="expected points of shape"):
        skeleton_animation(t[:3], [PointLayer("captured", names, pts, "#f80")])


def test_fit_figures_one_trace_per_column_and_state():
    t = np.arange(4) / 10.0
    figs = fit_figures(
        t, {"a_mm": np.array([1.0, np.nan, 2.0, 3.0])}, {"x_status": ["seen", "", "lost", "seen"]}
    )
    assert [tr.name for tr in figs[0].data] == ["a_mm"]
    assert figs[0].data[0].y == (1.0, None, 2.0, 3.0)
    states = {tr.name: (list(tr.x), list(tr.y)) for tr in figs[1].data}
    assert states == {"lost": ([0.2], ["x_status"]), "seen": ([0.0, 0.3], ["x_status"] * 2)}
    assert fit_figures(t, {}, {}) == []


def test_column_unit_by_suffix_a_speed_before_its_seconds():
    assert column_unit("right_elbow_speed_mm_per_s") == "mm/s"
    assert column_unit("rms_mm") == "mm"
    assert column_unit("lag_s") == "s"
    assert column_unit("right_elbow_jump") == ""


def test_fit_figures_units_on_labelled_axes_and_status_colours():
    """mm, px and unitless columns on separate labelled axes; statuses in their own
    colours, apart from other text columns (a marker set's name)."""
    t = np.arange(3) / 10.0
    ones = np.ones(3)
    figs = fit_figures(
        t,
        {"rms_mm": ones, "residual_px": ones, "head_mm": ones, "candidates": ones},
        {"head_status": ["seen", "bridged", "released"], "worst": ["head", "seen", "head"]},
    )
    axes = [f.layout.yaxis.title.text for f in figs[:3]]
    assert axes == ["mm", "px", "value (no unit)"]
    assert [tr.name for tr in figs[0].data] == ["rms_mm", "head_mm"]
    status = {tr.name: tr.marker.color for tr in figs[3].data}
    assert status == {n: STATUS_COLOURS[n] for n in ("bridged", "released", "seen")}
    labels = {tr.name: tr.marker.color for tr in figs[4].data}
    assert set(labels) == {"head", "seen"}  # 'seen' as a label is not a status colour
    assert not set(labels.values()) & set(STATUS_COLOURS.values())


def test_error_lines_of_every_canonical_joint_differ_in_colour():
    t = np.arange(3) / 10.0
    names = list(CANONICAL_JOINTS)
    fig = error_figure(t, names, np.zeros((3, len(names))), "e")
    colours = [tr.line.color for tr in fig.data]
    assert len(set(colours)) == len(names) == 15


def test_web_video_round_trip_and_interruption(tmp_path):
    rng = np.random.default_rng(2)
    base = rng.integers(0, 255, (48, 64, 3), dtype=np.uint8)
    base = cv2.GaussianBlur(base, (9, 9), 3)  # smooth content the lossy codec keeps
    with WebVideoWriter(tmp_path, "clip", 25.0, (64, 48)) as w:
        for i in range(6):
            w.write(np.roll(base, i, axis=1))
    video = w.result()
    assert video.n_frames == 6 and video.path.exists()
    if web_codec() is None:
        assert video.codec == JPEG_SEQUENCE
        frames = [cv2.imread(str(p)) for p in sorted(video.path.iterdir())]
    else:
        assert video.path.suffix == ".webm" and video.mime.startswith("video/webm")
        cap = cv2.VideoCapture(str(video.path))
        frames = []
        while True:
            ok, img = cap.read()
            if not ok:
                break
            frames.append(img)
        cap.release()
    assert len(frames) == 6
    err = np.abs(frames[3].astype(float) - np.roll(base, 3, axis=1)).mean()
    assert err < 12.0
    with pytest.raises(ShapeError, match=r"expected uint8 frames of shape \(48, 64, 3\)"):
        with WebVideoWriter(tmp_path, "broken", 25.0, (64, 48)) as w2:
            w2.write(base)
            w2.write(np.zeros((10, 10, 3), np.uint8))
    assert sorted(p.name for p in tmp_path.iterdir()) == [video.path.name]


def test_jpeg_fallback_without_web_codec(npz_result, small_session, tmp_path, monkeypatch):
    import mocapkit.viz.web_video as web_video

    monkeypatch.setattr(web_video, "web_codec", lambda: None)
    page = build_report(npz_result, session=small_session, out_dir=tmp_path / "r")
    text = page.read_text(encoding="utf-8")
    assert "<video" not in text and "no web video codec" in text
    img = next(r for t, r in page_refs(page) if t == "img")
    frames = sorted((page.parent / img).parent.glob("*.jpg"))
    assert img == "overlay_mono/000000.jpg"
    assert len(frames) == load_session(small_session).video("mono").n_frames
    assert "truth" not in trace_names(page)  # --session alone brings no truth


# ---------------------------------------------------------------- bad input (issue 30)


def test_view_refuses_a_folder_it_did_not_write_before_any_work(csv_result, tmp_path, capsys):
    """`mocapkit view R --out DIR` deleted whatever DIR held (notes.txt, a thesis/
    folder): a folder that is not a report folder is refused, its files kept."""
    mine = tmp_path / "mine"
    (mine / "thesis").mkdir(parents=True)
    (mine / "notes.txt").write_text("keep me")
    (mine / "thesis" / "ch1.tex").write_text("keep me too")
    with pytest.raises(
        ConfigError,
        match=r"mine: mocapkit view replaces its report folder "
        r"whole, but this folder is not a report folder \(no index.html; it "
        r"holds notes.txt, thesis\)",
    ):
        build_report(csv_result, out_dir=mine)
    assert main(["view", str(csv_result), "--out", str(mine)]) == 2
    assert "not a report folder" in capsys.readouterr().err
    assert (mine / "notes.txt").read_text() == "keep me"
    assert (mine / "thesis" / "ch1.tex").read_text() == "keep me too"
    assert sorted(p.name for p in mine.iterdir()) == ["notes.txt", "thesis"]
    # its own earlier report is replaced
    page = build_report(csv_result, out_dir=tmp_path / "rep")
    assert build_report(csv_result, out_dir=tmp_path / "rep") == page


def test_view_clears_what_a_killed_view_left(csv_result, tmp_path):
    """A kill mid-build left `.report.new-*` beside the report: the next view removes it."""
    stale = csv_result / ".report.new-abc123"
    stale.mkdir()
    (stale / "index.html").write_text("half")
    build_report(csv_result)
    assert sorted(p.name for p in csv_result.iterdir()) == ["joints.csv", "report"]


def test_view_says_when_a_folder_mixes_two_runs(npz_result, tmp_path, capsys):
    """`view` showed a folder mixing two runs without a word."""
    mixed = tmp_path / "mixed"
    shutil.copytree(npz_result, mixed)
    lines = (mixed / "joints.csv").read_text().splitlines(keepends=True)
    (mixed / "joints.csv").write_text("".join(lines[:11]))  # another, shorter run's
    (mixed / "fit.csv").write_text(
        "time_s,head_status\n" + "".join(f"{i / 30:.9f},seen\n" for i in range(5))
    )
    assert main(["view", str(mixed), "--out", str(tmp_path / "r")]) == 0
    err = capsys.readouterr().err
    assert re.search(
        r"warning: .*joints.csv and motion.npz are not from the same run "
        r"\(10 vs 31 frames",
        err,
    ), err
    assert re.search(r"warning: .*fit.csv: not from the same run as the result \(5 frames", err)
    assert "not from the same run" in (tmp_path / "r" / "index.html").read_text(encoding="utf-8")
    # one run's folder: no warning
    assert main(["view", str(npz_result), "--out", str(tmp_path / "r2")]) == 0
    assert "warning" not in capsys.readouterr().err


def test_view_truth_on_a_session_without_truth_says_so(npz_result, small_session, tmp_path, capsys):
    no_truth = tmp_path / "no_truth"
    shutil.copytree(small_session, no_truth)
    (no_truth / "truth.npz").unlink()
    code = main(["view", str(npz_result), "--truth", str(no_truth), "--out", str(tmp_path / "r")])
    assert code == 2
    assert re.search(r"mocapkit view: error: .*no_truth.*truth.npz", capsys.readouterr().err)
    assert not (tmp_path / "r").exists()


def test_report_lists_the_spans_of_implausible_motion(npz_result, tmp_path):
    from mocapkit.eval.plausibility import SpeedBound, check_motion
    from mocapkit.io.motion_npz import load_motion_npz
    from mocapkit.pipelines.run import write_fit_csv
    from mocapkit.tracking.base import FrameResult

    result = tmp_path / "result"
    shutil.copytree(npz_result, result)
    motion = load_motion_npz(result / "motion.npz")
    # the inputs keep still: the sway (up to 0.6 m/s) is allowed, a 2 m/s step is not
    joints = np.array(motion.joints_mm, copy=True)
    joints[20:, motion.joint_names.index("head")] += [
        0.0,
        0.0,
        2000.0 * (motion.time_s[20] - motion.time_s[19]),
    ]
    still = np.zeros(joints.shape[:2])
    check = check_motion(
        motion.time_s, motion.joint_names, joints, still, SpeedBound(1.5, 1000.0), 1200.0
    )
    results = [
        FrameResult(float(t), np.zeros(1), np.zeros((1, 3)), {}, {}, "") for t in motion.time_s
    ]
    write_fit_csv(result / "fit.csv", results, check.columns())
    page = build_report(result, out_dir=tmp_path / "rep")
    text = page.read_text(encoding="utf-8")
    assert "WARNING: implausible motion in 1 span (1 frame)" in text
    assert f"head moves 2.0 m/s at {motion.time_s[20]:.2f} s" in text
    assert column_unit("worst_roll_deg_per_s") == "deg/s"
