"""Synthetic sessions: every real clip renders into a consistent session; builtins need no data."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from mocapkit.cli.main import main
from mocapkit.errors import ConfigError, SessionError, UnknownNameError
from mocapkit.io.session import Session, load_session
from mocapkit.synth.realism import RealismOptions
from mocapkit.synth.render import parse_colour
from mocapkit.synth.rigs import make_rig
from mocapkit.synth.session_writer import (
    MIN_CAMERA_DEPTH_MM,
    SynthOptions,
    keep_cameras_away,
    synthesize_session,
)

CLIPS = (
    "13_26.bvh",
    "01_01.bvh",
    "131_01.bvh",
    "131_03.bvh",
    "01_01.amc",
    "01_09.amc",
    "01_12.amc",
    "11_01.amc",
    "lambada.amc",
    "charleston1.amc",
    "zombie.amc",
)
# every clip finds its skeleton by the look-up rule (charleston1.amc -> charleston.asf)
ASF: dict[str, str] = {}


def check_consistent(s: Session) -> None:
    """Keypoints reproject the truth; markers sit near their joints; counts agree."""
    truth = s.truth
    assert truth is not None and s.markers is not None
    names = truth.joint_names
    for cam in s.cameras:
        assert s.video(cam.name).n_frames == len(truth.time_s)
        kp = s.keypoints[cam.name]
        np.testing.assert_allclose(kp.time_s, truth.time_s)
        proj = cam.project(truth.joints_mm)
        seen = np.isfinite(kp.pixels[..., 0])
        assert seen[0].sum() >= 12, "subject in view at the start"
        np.testing.assert_allclose(kp.pixels[seen], proj[seen], atol=2e-3)
        assert np.all(cam.in_image(kp.pixels[seen]))
    clean = dict(zip(truth.marker_names, np.moveaxis(truth.markers_mm, 1, 0)))
    joint = dict(zip(names, np.moveaxis(truth.joints_mm, 1, 0)))

    def dist(a: str, b: str) -> np.ndarray:
        return np.linalg.norm(clean[a] - joint[b], axis=-1)

    # head marker on glasses 100 mm in front of the head centre
    np.testing.assert_allclose(dist("head", "head"), 100.0, atol=1.0)
    for side in ("left", "right"):
        d = dist(f"{side}_hand", f"{side}_wrist")
        assert np.all((d > 60) & (d < 110)), d
        e = dist(f"{side}_elbow_ref", f"{side}_elbow")
        np.testing.assert_allclose(e, 45.0, atol=1.0)
    # noisy markers at their own rate follow the clean ones
    est = s.markers.positions_mm
    ref = np.stack(
        [
            np.stack(
                [np.interp(s.markers.time_s, truth.time_s, clean[n][:, a]) for a in range(3)], -1
            )
            for n in s.markers.names
        ],
        1,
    )
    err = np.linalg.norm(est - ref, axis=-1)
    assert np.nanmedian(err) < 25.0
    # the floor is z = 0: ankles above it, pelvis at the origin at the start
    assert np.all(joint["left_ankle"][:, 2] > 0) and np.all(joint["right_ankle"][:, 2] > 0)
    assert np.linalg.norm(joint["pelvis"][0, :2]) < 60.0


@pytest.mark.parametrize("clip", CLIPS)
def test_every_clip_renders_a_consistent_session(clip, shared_data, tmp_path):
    path = shared_data / "mocap" / clip
    asf = str(shared_data / "mocap" / ASF[clip]) if clip in ASF else None
    out = tmp_path / "s"
    summary = synthesize_session(
        str(path),
        out,
        SynthOptions(rig="all", seconds=0.25, start_s=0.5, image_size=(128, 96), asf=asf),
    )
    assert summary.cameras == ("mono", "stereo_left", "stereo_right")
    s = load_session(out)
    check_consistent(s)
    assert s.info["synthetic"]["motion"] == str(path)


@pytest.mark.parametrize("name", ["table-tennis", "squat", "wave"])
def test_builtins_render_without_data(name, tmp_path):
    out = tmp_path / name
    synthesize_session(
        f"builtin:{name}", out, SynthOptions(rig="stereo", seconds=0.3, image_size=(128, 96))
    )
    s = load_session(out)
    assert s.camera_names == ("stereo_left", "stereo_right")
    check_consistent(s)


def test_rendered_pixels_show_the_body_where_keypoints_say(tmp_path):
    """Rendering and Camera.project agree (incl. distortion): the shirt is where the chest is."""
    out = tmp_path / "s"
    synthesize_session(
        "builtin:squat",
        out,
        SynthOptions(
            rig="mono",
            seconds=0.1,
            image_size=(320, 240),
            shirt_colour="#ff0000",
            video_format="png",
            realism=RealismOptions(noise=0.0, blur=0.0, background="plain"),
        ),
    )
    s = load_session(out)
    image = next(iter(s.samples())).image().astype(float)
    kp = s.keypoints["mono"].pixels[0]
    names = s.keypoints["mono"].joint_names
    neck, pelvis = kp[names.index("neck")], kp[names.index("pelvis")]
    chest = neck + 0.35 * (pelvis - neck)
    x, y = np.round(chest).astype(int)
    patch = image[y - 2 : y + 3, x - 2 : x + 3].reshape(-1, 3)
    b, g, r = patch.mean(axis=0)
    assert r > 120 and r > 3 * g and r > 3 * b  # red shirt (BGR)
    # the plain background far to the side is grey
    side = image[5:15, 5:15].reshape(-1, 3).mean(axis=0)
    assert np.ptp(side) < 10


def test_same_seed_same_session(tmp_path):
    opts = SynthOptions(rig="mono", seconds=0.1, image_size=(96, 72), video_format="png", seed=7)
    synthesize_session("builtin:wave", tmp_path / "a", opts)
    synthesize_session("builtin:wave", tmp_path / "b", opts)
    for f in ("markers.csv", "keypoints/mono.csv", "video/mono/000001.png"):
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes()


def test_height_scaling(tmp_path):
    synthesize_session(
        "builtin:wave",
        tmp_path / "s",
        SynthOptions(seconds=0.1, image_size=(96, 72), height_mm=1500.0),
    )
    s = load_session(tmp_path / "s")
    assert s.height_mm == pytest.approx(1500.0, abs=1.0)


def test_refusals(tmp_path):
    opts = SynthOptions(seconds=0.1, image_size=(96, 72))
    synthesize_session("builtin:wave", tmp_path / "s", opts)
    with pytest.raises(SessionError, match="not empty"):
        synthesize_session("builtin:wave", tmp_path / "s", opts)
    with pytest.raises(UnknownNameError, match="unknown built-in motion 'dance'"):
        synthesize_session("builtin:dance", tmp_path / "t", opts)
    with pytest.raises(ConfigError, match="--fps"):
        SynthOptions(fps=0.0)
    with pytest.raises(ConfigError, match="--blur"):
        RealismOptions(blur=2.0)
    with pytest.raises(ConfigError, match="#RRGGBB"):
        parse_colour("mauve-ish")
    with pytest.raises(UnknownNameError, match="unknown rig 'trinocular'"):
        make_rig("trinocular", np.zeros(3), np.array([0, 1.0, 0]), 1300.0)


def test_rigs_face_the_subject():
    cams = make_rig("all", np.zeros(3), np.array([0.0, 1.0, 0.0]), 1300.0)
    assert [c.name for c in cams] == ["mono", "stereo_left", "stereo_right"]
    chest = np.array([0.0, 0.0, 1300.0])
    for c in cams:
        assert 2400 < np.linalg.norm(c.center_in_world - chest) < 3200
        assert c.in_image(c.project(chest))
    base = np.linalg.norm(cams[1].center_in_world - cams[2].center_in_world)
    assert base == pytest.approx(90.0)
    assert cams[0].center_in_world[1] > 2900  # in front: the subject faces +y


def test_multi_rig_adds_a_side_camera():
    cams = make_rig("multi", np.zeros(3), np.array([0.0, 1.0, 0.0]), 1300.0)
    assert [c.name for c in cams] == ["mono", "stereo_left", "stereo_right", "side"]
    chest = np.array([0.0, 0.0, 1300.0])
    side = cams[3]
    assert side.in_image(side.project(chest))
    assert np.linalg.norm(side.center_in_world - chest) == pytest.approx(3000.0, abs=1.0)
    # 45 degrees around the subject from the mono camera, on the stereo head's far side
    to_mono = cams[0].center_in_world[:2] / np.linalg.norm(cams[0].center_in_world[:2])
    to_side = side.center_in_world[:2] / np.linalg.norm(side.center_in_world[:2])
    assert float(to_mono @ to_side) == pytest.approx(np.cos(np.radians(45.0)), abs=1e-6)
    to_stereo = cams[1].center_in_world[:2]

    def turn(u, v):  # z of the 2-D cross product
        return u[0] * v[1] - u[1] * v[0]

    assert turn(to_mono, to_side) * turn(to_mono, to_stereo) < 0


def test_cli_synth(tmp_path, capsys):
    out = tmp_path / "cli"
    rc = main(
        [
            "synth",
            "builtin:table-tennis",
            "--out",
            str(out),
            "--seconds",
            "0.2",
            "--size",
            "96x72",
            "--rig",
            "mono",
            "--sleeve",
            "long",
            "--shirt-colour",
            "green",
            "--background",
            "plain",
            "--dropout",
            "0.05",
            "--marker-noise-mm",
            "2",
        ]
    )
    assert rc == 0
    assert "session written to" in capsys.readouterr().out
    s = load_session(out)
    assert s.markers is not None and np.isnan(s.markers.positions_mm).any()
    with pytest.raises(SystemExit) as exc:
        main(["synth", "builtin:wave", "--out", str(tmp_path / "x"), "--size", "big"])
    assert exc.value.code == 2
    assert "argument --size: expected WIDTHxHEIGHT" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_mp4_reads_back(tmp_path):
    synthesize_session(
        "builtin:wave", tmp_path / "s", SynthOptions(seconds=0.3, image_size=(96, 72))
    )
    cap = cv2.VideoCapture(str(Path(tmp_path / "s" / "video" / "mono.mp4")))
    n = 0
    while cap.read()[0]:
        n += 1
    cap.release()
    assert n == 10


def test_session_montage(tmp_path):
    from mocapkit.io.session import write_session_json
    from mocapkit.synth.montage import session_montage

    synthesize_session(
        "builtin:wave", tmp_path / "s", SynthOptions(rig="all", seconds=0.2, image_size=(160, 120))
    )
    image = session_montage(tmp_path / "s", 0.1, panel_width=80)
    assert image.shape == (60, 240, 3)
    empty = tmp_path / "empty"
    empty.mkdir()
    write_session_json(empty / "session.json", {})
    with pytest.raises(SessionError, match="a video under video/"):
        session_montage(empty, 0.0)


def test_cameras_step_back_from_a_subject_who_comes_close():
    cams = make_rig("all", np.zeros(3), np.array([0.0, 1.0, 0.0]), 1300.0)
    far = np.array([[[0.0, 0.0, 1300.0], [100.0, 200.0, 900.0]]])
    same, moved = keep_cameras_away(cams, far)
    assert moved == 0.0 and same is cams
    # the subject walks 2.5 m towards the cameras: a joint ends 300 mm in front of the mono lens
    near = np.concatenate([far, far + np.array([0.0, 2500.0, 0.0])])
    depth_before = min(
        float(np.min(near.reshape(-1, 3) @ c.camera_from_world[2, :3] + c.camera_from_world[2, 3]))
        for c in cams
    )
    moved_cams, moved = keep_cameras_away(cams, near)
    assert moved == pytest.approx(MIN_CAMERA_DEPTH_MM - depth_before)
    for before, after in zip(cams, moved_cams, strict=True):
        depth = near.reshape(-1, 3) @ after.camera_from_world[2, :3] + after.camera_from_world[2, 3]
        assert depth.min() >= MIN_CAMERA_DEPTH_MM - 1e-6
        # straight back along the optical axis: same orientation, centre moved by `moved`
        np.testing.assert_allclose(
            after.camera_from_world[:3, :3], before.camera_from_world[:3, :3]
        )
        step = before.center_in_world - after.center_in_world
        np.testing.assert_allclose(step, moved * before.camera_from_world[2, :3], atol=1e-9)
    baseline = moved_cams[1].center_in_world - moved_cams[2].center_in_world
    np.testing.assert_allclose(
        baseline, cams[1].center_in_world - cams[2].center_in_world, atol=1e-9
    )


def test_walking_clip_never_reaches_the_lens(shared_data, tmp_path):
    """CMU 131_03 walks about 3 m towards where the camera stands at its start."""
    out = tmp_path / "s"
    summary = synthesize_session(
        str(shared_data / "mocap" / "131_03.bvh"),
        out,
        SynthOptions(rig="mono", seconds=8.0, fps=5.0, image_size=(64, 48)),
    )
    assert any("moved back" in n for n in summary.notes), summary.notes
    s = load_session(out)
    cam = s.camera("mono")
    depth = s.truth.joints_mm @ cam.camera_from_world[2, :3] + cam.camera_from_world[2, 3]
    assert np.nanmin(depth) >= MIN_CAMERA_DEPTH_MM - 1e-6
    check_consistent(s)


def test_start_beyond_a_clip_is_refused(shared_data, tmp_path):
    with pytest.raises(ConfigError, match="--start-s 900"):
        synthesize_session(
            str(shared_data / "mocap" / "13_26.bvh"),
            tmp_path / "t",
            SynthOptions(start_s=900.0, seconds=0.1, image_size=(96, 72)),
        )
    assert not (tmp_path / "t").exists()


def test_builtin_motion_lasts_as_long_as_asked(tmp_path):
    """A built-in motion is procedural: --seconds 30 gives 30 s, not the default 20 s."""
    opts = SynthOptions(seconds=30.0, fps=2.0, marker_rate_hz=10.0, image_size=(96, 72))
    summary = synthesize_session("builtin:wave", tmp_path / "s", opts)
    assert summary.duration_s == pytest.approx(30.0)
    assert not summary.notes
    truth = load_session(tmp_path / "s").truth
    assert truth is not None and truth.time_s[-1] > 29.0


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def test_interrupted_synth_leaves_old_session_whole(tmp_path, monkeypatch):
    """Ctrl-C mid-render: no new session appears, and --overwrite keeps the old one intact."""
    from mocapkit.synth import session_writer

    opts = SynthOptions(seconds=0.3, image_size=(96, 72))
    synthesize_session("builtin:wave", tmp_path / "s", opts)
    before = _snapshot(tmp_path / "s")
    original = session_writer._VideoOut.write
    calls = {"n": 0}

    def interrupted(self, image):
        calls["n"] += 1
        if calls["n"] > 3:
            raise KeyboardInterrupt
        original(self, image)

    monkeypatch.setattr(session_writer._VideoOut, "write", interrupted)
    with pytest.raises(KeyboardInterrupt):
        synthesize_session("builtin:squat", tmp_path / "s", replace(opts, overwrite=True))
    assert _snapshot(tmp_path / "s") == before
    calls["n"] = 0
    with pytest.raises(KeyboardInterrupt):
        synthesize_session("builtin:squat", tmp_path / "new", opts)
    assert not (tmp_path / "new").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s"]  # no temporaries left
    monkeypatch.undo()
    synthesize_session("builtin:squat", tmp_path / "s", replace(opts, overwrite=True))
    assert _snapshot(tmp_path / "s") != before
