"""Live capture over LSL, on loopback only: replay a session, track it live, compare with
the offline trackers; a stalled stream; wrong channel layouts refused."""

from __future__ import annotations

import os
import shutil
import threading
import time
import uuid
from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("pylsl")

from mocapkit.errors import FormatError
from mocapkit.io.lsl import (
    LOOPBACK_CONFIG,
    MARKERS_TYPE,
    make_outlet,
    parse_layout,
    point_labels,
)
from mocapkit.io.motion_npz import load_motion_npz
from mocapkit.io.session import load_session
from mocapkit.pipelines.live import track_live
from mocapkit.pipelines.live_feed import LiveConfig, LiveInputs, replay_inputs
from mocapkit.pipelines.replay import replay_session
from mocapkit.pipelines.run import read_fit_csv

#: Generous for a loaded 2-core machine: the replay starts this long after its streams
#: appear, and an input silent this long ends a run (more than the 1 s stall).
LEAD_S = 4.0
LOST_S = 2.5


@pytest.fixture(scope="module", autouse=True)
def loopback(tmp_path_factory):
    """liblsl on this machine only (read once, when the library is first used)."""
    cfg = tmp_path_factory.mktemp("lsl") / "lsl_api.cfg"
    cfg.write_text(LOOPBACK_CONFIG)
    old = os.environ.get("LSLAPICFG")
    os.environ["LSLAPICFG"] = str(cfg)
    yield
    if old is None:
        os.environ.pop("LSLAPICFG", None)
    else:
        os.environ["LSLAPICFG"] = old


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """0.8 s of the wave seen by the mono camera and the stereo pair, markers at 60 Hz,
    video without time-stamp jitter (so the mono tracker's frame interval is the nominal
    one that a live stream declares), no marker drop-outs (a set missing a member is
    compensated from the frames before it live, from those on both sides offline)."""
    from mocapkit.synth.realism import RealismOptions
    from mocapkit.synth.session_writer import SynthOptions, synthesize_session

    folder = tmp_path_factory.mktemp("live") / "wave"
    synthesize_session(
        "builtin:wave",
        folder,
        SynthOptions(
            rig="all",
            start_s=0.5,
            seconds=0.8,
            image_size=(320, 240),
            marker_rate_hz=60.0,
            overwrite=True,
            realism=RealismOptions(video_jitter_s=0.0, dropout=0.0),
        ),
    )
    return folder


def _live(method, folder, inputs_of, speed, tmp_path, match_wait_s=1.0, **kwargs):
    """Track a replay of ``folder`` live; returns the report, the result folder and the
    joints stream as a consumer received it (samples, stamps, its metadata). A step waits
    up to ``match_wait_s`` for a due partner sample: long, so that a loaded machine's
    late delivery cannot change the pairing (the wait ends when the sample comes)."""
    from mocapkit.io.lsl import find_stream, inlet_layout, open_inlet

    prefix = f"t{uuid.uuid4().hex[:8]}_"
    out = tmp_path / f"live_{method}"
    setup = load_session(folder)
    inputs = inputs_of(replay_inputs(setup, prefix))
    joints_name = f"{prefix}joints"
    got: dict = {"rows": [], "stamps": []}
    done = threading.Event()

    def consume():
        inlet = open_inlet(find_stream(joints_name, 30.0))
        got["layout"] = inlet_layout(inlet)
        while not done.is_set():
            rows, stamps = inlet.pull_chunk(timeout=0.05)
            got["rows"] += rows
            got["stamps"] += stamps
        rows, stamps = inlet.pull_chunk(timeout=0.5)
        got["rows"] += rows
        got["stamps"] += stamps

    sent = {}

    def replay():
        time.sleep(0.5)  # the live side waits for the streams (LiveConfig.connect_timeout_s)
        sent["stats"] = replay_session(folder, speed, prefix, lead_s=LEAD_S)

    threads = [threading.Thread(target=replay), threading.Thread(target=consume)]
    for th in threads:
        th.start()
    try:
        report = track_live(
            method,
            folder,
            inputs,
            out,
            stream_name=joints_name,
            config=LiveConfig(
                match_wait_s=match_wait_s,
                lost_after_s=LOST_S,
                connect_timeout_s=30.0,
                max_behind_s=np.inf,
            ),
            **kwargs,
        )
    finally:
        time.sleep(0.3)
        done.set()
        for th in threads:
            th.join(timeout=60)
    return report, out, got, sent["stats"]


def _same_joints(live_dir, offline, atol):
    live = load_motion_npz(live_dir / "motion.npz")
    assert live.n_frames == offline.n_frames
    np.testing.assert_allclose(live.time_s, offline.time_s, rtol=0, atol=1e-9)
    assert live.joint_names == offline.joint_names
    np.testing.assert_array_equal(np.isnan(live.joints_mm), np.isnan(offline.joints_mm))
    np.testing.assert_allclose(live.joints_mm, offline.joints_mm, rtol=0, atol=atol, equal_nan=True)
    return live


def _first_camera(inputs):
    return LiveInputs(inputs.markers, {}, dict(list(inputs.video.items())[:1]))


def test_live_hybrid_equals_track_and_publishes_joints(session, tmp_path):
    from mocapkit.pipelines.hybrid import track_hybrid_session
    from mocapkit.skeleton.model import CANONICAL_JOINTS

    offline = track_hybrid_session(session, tmp_path / "offline")  # compiled, warm
    record = tmp_path / "take"
    report, out, got, sent = _live(
        "hybrid", session, _first_camera, 4.0, tmp_path, record_dir=record
    )
    assert "lost" in report.stop_reason and "stream" in report.stop_reason
    assert report.stats.frames_dropped == 0
    n = load_session(session).video("mono").n_frames
    assert report.stats.frames_tracked == report.n_results == n
    # the hybrid is deterministic: the live take equals the offline one exactly
    _same_joints(out, offline, atol=0.0)
    rows, _ = read_fit_csv(out / "fit.csv")
    assert len(rows) == n
    # the output stream: labelled canonical joints in mm, stamped with the frames' stamps
    layout = got["layout"]
    assert layout.points == CANONICAL_JOINTS and layout.scale == 1.0
    assert layout.type == "MocapJoints"
    assert len(got["rows"]) == n
    assert layout.replay_clock is None  # the output is on the LSL clock
    video_t = load_session(session).video("mono").time_s
    np.testing.assert_allclose(
        got["stamps"], [sent.clock.to_lsl(t) for t in video_t], rtol=0, atol=1e-6
    )
    sent_joints = np.array(got["rows"]).reshape(n, 15, 3)
    np.testing.assert_allclose(sent_joints, offline.joints_mm, rtol=0, atol=1e-9)
    # the recording is a readable session with every marker sample and tracked frame
    rec = load_session(record)
    assert rec.markers is not None
    assert rec.markers.n_frames == load_session(session).markers.n_frames
    assert rec.video("mono").n_frames == n
    np.testing.assert_allclose(rec.video("mono").time_s, video_t, rtol=0, atol=1e-9)


def test_live_mono_and_stereo_equal_track(session, tmp_path):
    from mocapkit.pipelines.mono import track_mono
    from mocapkit.pipelines.stereo import track_stereo_session
    from mocapkit.tracking.mono.tracker import MonoConfig

    # offline first: the trackers are compiled and warm before the live runs start
    offline = track_mono(
        session, None, "mono", config=MonoConfig(lag=LiveConfig().mono_lag),
        use_session_lengths=True,
    )  # fmt: skip
    stereo = ("stereo_left", "stereo_right")
    run = track_stereo_session(session, None, cameras=list(stereo), use_keypoints=True)
    report, out, _, _ = _live(
        "mono",
        session,
        lambda i: LiveInputs(None, {"mono": i.keypoints["mono"]}, {}),
        4.0,
        tmp_path,
    )
    assert report.stats.frames_dropped == 0
    # the same online decoder on the same samples; time stamps pass the replay clock
    # (about 1e-13 s off), the only difference; placed by the feet on the floor alike
    assert offline.summary()["on_floor_share"] > 0.5
    _same_joints(out, offline.motion, atol=1e-6)

    report, out, _, _ = _live(
        "stereo",
        session,
        lambda i: LiveInputs(
            None, {c: i.keypoints[c] for c in stereo}, {c: i.video[c] for c in stereo}
        ),
        4.0,
        tmp_path,
    )
    assert report.stats.frames_dropped == 0
    _same_joints(out, run.motion, atol=0.0)


def test_stalled_marker_stream_bridged_released_and_back(session, tmp_path):
    """The marker stream stalls for 1 s (real time) and comes back: the hybrid bridges,
    then releases the sets, and tracks them again, exactly as offline on the same data."""
    from mocapkit.io.marker_csv import read_markers_csv, write_markers_csv
    from mocapkit.pipelines.hybrid import track_hybrid_session
    from mocapkit.tracking.base import BRIDGE_S

    folder = tmp_path / "stall"
    shutil.copytree(session, folder)
    m = read_markers_csv(folder / "markers.csv")
    gap = (m.time_s >= 0.1) & (m.time_s < 0.1 + 1.0 * 0.5)  # 0.5 s of session at speed 0.5
    write_markers_csv(folder / "markers.csv", m.time_s[~gap], m.names, m.positions_mm[~gap])
    offline = track_hybrid_session(folder, tmp_path / "offline")
    # a frame waits 0.2 s at most for a due marker sample: during the stall none comes
    report, out, _, _ = _live("hybrid", folder, _first_camera, 0.5, tmp_path, 0.2)
    assert report.stats.frames_dropped == 0
    live = _same_joints(out, offline, atol=0.0)
    rows, _ = read_fit_csv(out / "fit.csv")
    status = [r["head_status"] for r in rows]
    t = live.time_s
    last_seen, back = m.time_s[gap][0] - 1 / 60, m.time_s[gap][-1] + 1 / 60
    assert {"released", "seen"} <= set(status)
    for ti, st in zip(t, status):
        if last_seen + BRIDGE_S + 0.02 < ti < back:
            assert st == "released"  # too old to be an observation of this frame
        elif ti > back + 0.02:
            assert st == "seen"
    head = live.joint_names.index("head")
    released = np.array(status) == "released"
    assert np.isnan(live.joints_mm[released, head]).all()  # never a stale sample as new


def test_wrong_channel_layouts_refused():
    xml = (
        "<info><name>vicon</name><type>Mocap</type><channel_count>{n}</channel_count>"
        "<nominal_srate>100</nominal_srate><desc><channels>{ch}</channels></desc></info>"
    )

    def doc(labels, unit="mm"):
        ch = "".join(
            f"<channel><label>{lab}</label><unit>{unit}</unit></channel>" for lab in labels
        )
        return xml.format(n=len(labels), ch=ch)

    ok = parse_layout(doc(["LFHD_x", "LFHD_y", "LFHD_z", "RFHD X", "RFHD Y", "RFHD Z"], "m"))
    assert ok.points == ("LFHD", "RFHD") and ok.scale == 1000.0
    with pytest.raises(FormatError, match=r"'vicon'.*expected 3 channels per point.*found 4"):
        parse_layout(doc(["A_x", "A_y", "A_z", "B_x"]))
    with pytest.raises(
        FormatError, match=r"channels 0-2: expected labels.*found \['A_x', 'A_y', 'B_z'\]"
    ):
        parse_layout(doc(["A_x", "A_y", "B_z"]))
    with pytest.raises(FormatError, match=r"expected one length unit.*found \['inches'\]"):
        parse_layout(doc(["A_x", "A_y", "A_z"], "inches"))
    with pytest.raises(FormatError, match=r"expected a label for each of its 3 channels"):
        parse_layout(xml.format(n=3, ch=""))


def test_live_refuses_stream_without_the_marker_sets(session, tmp_path):
    """A marker stream whose channels lack a marker set's members is refused by name."""
    name = f"t{uuid.uuid4().hex[:8]}_markers"
    outlet = make_outlet(name, MARKERS_TYPE, point_labels(["LFHD", "RFHD"], 3), "mm", 60.0, name)
    try:
        with pytest.raises(FormatError, match=r"marker set 'head'.*the stream's channels name "
                           r"markers \['LFHD', 'RFHD'\]"):  # fmt: skip
            track_live(
                "hybrid",
                session,
                LiveInputs(name, {}, {}),
                config=replace(LiveConfig(), connect_timeout_s=20.0),
            )
    finally:
        del outlet


def test_cli_live_and_replay_refuse_bad_use(session, capsys):
    from mocapkit.cli.main import main
    from mocapkit.pipelines.live import JOINTS_STREAM

    assert main(["live", "hybrid", str(session)]) == 2
    err = capsys.readouterr().err
    assert "live hybrid: expected a marker stream (--markers NAME)" in err
    assert f"live hybrid: publishing {JOINTS_STREAM}; Ctrl-C stops" in err
    assert main(["live", "hybrid", str(session), "--stream", "lab_joints"]) == 2
    assert "live hybrid: publishing lab_joints; Ctrl-C stops" in capsys.readouterr().err
    assert main(["live", "stereo", str(session), "--video", "mono=0"]) == 2
    assert "expected two or more cameras (--video), found ['mono']" in capsys.readouterr().err
    try:
        import cv2

        cv2.namedWindow("probe")
        gui = True
    except cv2.error:
        gui = False
    if not gui:  # headless OpenCV: --view is refused before connecting to anything
        args = ["live", "hybrid", str(session), "--markers", "m", "--video", "mono=lsl:f"]
        assert main([*args, "--view"]) == 2
        assert "--view needs OpenCV with a GUI" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["replay", str(session), "--lsl", "--speed", "0"])
    assert "--speed" in capsys.readouterr().err
