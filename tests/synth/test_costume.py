"""The paper's costume (Mamania et al. 2004, §3): skin only on face, neck, forearms, hands
and the golden belt; the belt at the pelvis; the same seeded draws as everyday clothing."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from mocapkit.cues.skin import skin_mask
from mocapkit.errors import ConfigError
from mocapkit.pipelines import mono_accuracy
from mocapkit.synth.builtin_motions import builtin_motion
from mocapkit.synth.render import (
    BELT_BGR,
    BELT_HEIGHT_MM,
    Appearance,
    BodyModel,
    CameraRenderer,
    build_body,
    costume_sleeve,
)
from mocapkit.synth.rigs import make_rig
from mocapkit.synth.session_writer import SynthOptions
from mocapkit.tracking.mono.skin_tracking import SKIN_JOINTS, SkinTracker

BLACK = (35, 35, 35)  # luma below the skin model's floor: never skin


def _scene(costume: str, seed: int = 3):
    """The wave motion's first frame, dressed and seen by the mono rig's camera."""
    motion = builtin_motion("wave", 0.5)
    rng = np.random.default_rng(seed)
    look = Appearance.random(rng, costume=costume)
    body = build_body(motion.skeleton, motion.time_s[:1], np.asarray(motion.q)[:1], look)
    names = motion.joint_names
    pelvis = np.asarray(motion.joints_mm)[0, names.index("pelvis")]
    cam = make_rig("mono", np.zeros(3), np.array([0.0, 1.0, 0.0]), pelvis[2] + 350.0)[0]
    return motion, look, body, cam


def _render(body: BodyModel, cam, recolour: dict | None = None) -> np.ndarray:
    """The body on a mid-grey backdrop; ``recolour`` maps primitive colours to others."""
    r = CameraRenderer(cam)
    w, h = r.canvas_size
    canvas = np.full((h, w, 3), 128, np.uint8)
    prims = [replace(p, colour=(recolour or {}).get(p.colour, p.colour)) for p in body.primitives]
    r.draw_body(canvas, prims, body.points_mm[0])
    return r.warp(canvas)


def test_paper_costume_skin_lies_on_face_forearms_hands_and_belt():
    _, look, body, cam = _scene("paper")
    assert look.sleeve == "elbow" and look.belt == BELT_BGR and look.trousers == look.shirt
    full = skin_mask(_render(body, cam)) > 0
    # the exposed parts (skin colour: face, neck, forearms, hands) and the belt painted
    # black: nothing skin-like is left (dress, hair, shoes, glasses, markers)
    bare = skin_mask(_render(body, cam, {look.skin: BLACK, look.belt: BLACK})) > 0
    assert full.sum() > 1500 and bare.sum() == 0
    # everyday clothing (short sleeves) shows more arm than the paper's dress
    _, _, body_e, _ = _scene("everyday")
    no_belt = skin_mask(_render(body, cam, {look.belt: BLACK})) > 0
    everyday = skin_mask(_render(body_e, cam)) > 0
    assert everyday.sum() > no_belt.sum() + 200


def test_the_belt_is_a_horizontal_band_at_the_pelvis():
    motion, look, body, cam = _scene("paper")
    full = skin_mask(_render(body, cam)) > 0
    no_belt = skin_mask(_render(body, cam, {look.belt: BLACK})) > 0
    ys, xs = np.nonzero(full & ~no_belt)
    names = motion.joint_names
    joints = np.asarray(motion.joints_mm)[0]
    pelvis_px = cam.project(joints[names.index("pelvis")])
    hips_px = cam.project(joints[[names.index("left_hip"), names.index("right_hip")]])
    # the band seen from the camera (above the waist, facing the subject along -y): from
    # its top ring's back edge to its bottom ring's front edge (the ring's depth is the
    # trousers' hull's there, 95-100 mm, plus the stand-off: about 103 mm either side)
    centre = joints[names.index("pelvis")] * [0.0, 0.0, 1.0]
    top_back = cam.project(centre + np.array([0.0, -103.0, 0.5 * BELT_HEIGHT_MM]))
    bottom_front = cam.project(centre + np.array([0.0, 103.0, -0.5 * BELT_HEIGHT_MM]))
    band_px = bottom_front[1] - top_back[1]
    # centred on the pelvis (upright subject), that high (+-2 px: anti-aliasing, the ring's
    # depth), wider than the hips
    assert abs(ys.mean() - pelvis_px[1]) < 2.0
    assert abs(np.median(xs) - pelvis_px[0]) < 2.0
    assert np.ptp(ys) + 1 == pytest.approx(band_px, abs=2.0)
    assert np.ptp(xs) > abs(hips_px[1, 0] - hips_px[0, 0])


def test_skin_tracker_reads_the_trunk_off_the_belt():
    """The paper's labels on the paper's costume: head, forearms and the belt (waist);
    pelvis from the belt's centre, shoulders above its ends at the neck's height."""
    motion, _, body, cam = _scene("paper")
    frame = SkinTracker(trunk_from_head=False).update(_render(body, cam))
    assert set(frame.blobs) == {"head", "left_hand", "right_hand", "waist"}
    names = motion.joint_names
    true_px = cam.project(np.asarray(motion.joints_mm)[0])
    got = dict(zip(SKIN_JOINTS, frame.joints_px))
    assert np.linalg.norm(got["pelvis"] - true_px[names.index("pelvis")]) < 4.0
    waist = frame.blobs["waist"]
    assert got["left_shoulder"][0] == pytest.approx(waist.ends[:, 0].max())
    assert got["left_shoulder"][1] == pytest.approx(got["neck"][1])


def test_costumes_draw_the_same_numbers():
    """Both costumes leave the generator in the same state, so the cameras drawn after the
    appearance (and with them the truth's pixels) are the same."""
    for seed in range(20):
        a, b = np.random.default_rng(seed), np.random.default_rng(seed)
        everyday = Appearance.random(a)
        paper = Appearance.random(b, costume="paper")
        assert a.integers(1 << 30) == b.integers(1 << 30)
        assert paper.skin == everyday.skin and paper.hair == everyday.hair
        # the dress is never skin, at any light the renderer gives it (shading 0.72-1,
        # lighting field 0.75-1.1); the belt always is
        for colour, want in ((paper.shirt, False), (paper.belt, True)):
            assert colour is not None
            img = np.array([[[min(255, int(c * f)) for c in colour]] for f in (0.54, 0.72, 1.1)])
            assert (skin_mask(img.astype(np.uint8)) > 0).ravel().tolist() == [want] * 3


def test_costume_refusals():
    rng = np.random.default_rng(0)
    with pytest.raises(ConfigError, match=r"expected one of everyday, paper, found 'sari'"):
        Appearance.random(rng, costume="sari")
    with pytest.raises(ConfigError, match=r"to the elbow; expected 'elbow'.*found 'long'"):
        Appearance.random(rng, sleeve="long", costume="paper")
    with pytest.raises(ConfigError, match="sleeve: expected one of"):
        costume_sleeve("everyday", "knee")
    with pytest.raises(ConfigError, match="costume: expected"):
        SynthOptions(costume="sari")
    assert costume_sleeve("paper") == "elbow" and costume_sleeve("everyday") == "short"


def test_mono_sessions_are_cached_per_costume_and_seed(tmp_path, monkeypatch):
    rendered: list[tuple[str, int, str]] = []

    def fake(spec, out, opts):
        out.mkdir(parents=True, exist_ok=True)
        (out / "truth.npz").write_bytes(b"")
        info = {"synthetic": {"seed": opts.seed, "costume": opts.costume}}
        (out / "session.json").write_text(json.dumps(info))
        rendered.append((out.name, opts.seed, opts.costume))

    monkeypatch.setattr(mono_accuracy, "synthesize_session", fake)
    for costume, seed in (("paper", 0), ("everyday", 0), ("paper", 0), ("paper", 1)):
        mono_accuracy.mono_session(tmp_path, tmp_path / "w", "zombie.amc", seed, True, costume)
    assert rendered == [
        ("session_paper", 0, "paper"),
        ("session", 0, "everyday"),
        ("session_paper", 1, "paper"),  # another seed: rendered again
    ]
    # an everyday session written before costumes existed (no entry) is reused as everyday
    legacy = tmp_path / "w" / "zombie" / "session" / "session.json"
    legacy.write_text(json.dumps({"synthetic": {"seed": 0}}))
    mono_accuracy.mono_session(tmp_path, tmp_path / "w", "zombie.amc", 0, True, "everyday")
    assert len(rendered) == 3
    with pytest.raises(ConfigError, match="skin tracking only"):
        mono_accuracy.mono_accuracy(tmp_path, tmp_path / "w", costume="paper")


def test_cli_synth_costume(tmp_path, capsys):
    from mocapkit.cli.main import main

    args = ["synth", "builtin:wave", "--seconds", "0.1", "--size", "96x72", "--rig", "mono"]
    assert main([*args, "--out", str(tmp_path / "p"), "--costume", "paper"]) == 0
    info = json.loads((tmp_path / "p" / "session.json").read_text())["synthetic"]
    assert info["costume"] == "paper" and info["sleeve"] == "elbow"
    capsys.readouterr()
    bad = [*args, "--out", str(tmp_path / "q"), "--costume", "paper", "--sleeve", "long"]
    assert main(bad) != 0
    assert "covers the upper arms to the elbow" in capsys.readouterr().err
    assert not (tmp_path / "q").exists()
