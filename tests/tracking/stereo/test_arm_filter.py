"""The per-arm particle filter: kinematics, the compiled batch weighting against a brute-force
reference, the 90/60 split and recovery with IK sampling (recipe A, tests A)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from mocapkit.camera.pinhole import Camera, intrinsics_from_fov, look_at
from mocapkit.errors import ConfigError
from mocapkit.geometry.cones import cone_contour_generators
from mocapkit.geometry.rotations import matrix_from_rotvec
from mocapkit.skeleton.kinematics import canonical_positions
from mocapkit.skeleton.limbs import arm
from mocapkit.skeleton.presets import load_preset
from mocapkit.tracking.stereo.arm_filter import (
    ArmFilterConfig,
    ArmModel,
    ArmParticleFilter,
    arm_points_nb,
    arm_weights_nb,
    systematic_resample,
    view_stack,
)
from mocapkit.tracking.stereo.fusion import default_fusion, fused_weight_nb
from mocapkit.tracking.stereo.tracker import yaw_matrix

SIZE = (320, 240)
A, B = 300.0, 270.0
RADII = np.array([50.0, 40.0, 40.0, 30.0])


def _cameras(n=2):
    k = intrinsics_from_fov(SIZE, 62.0)
    cams = []
    for i in range(n):
        ang = math.radians(-15 + 30 * i / max(n - 1, 1))
        eye = np.array([2700 * math.sin(ang) + 45 * (i - 0.5), 2700 * math.cos(ang), 1400.0])
        m = look_at(eye, np.array([0.0, 0.0, 1100.0]))
        cams.append(Camera(f"c{i}", SIZE, k, np.zeros(5), m))
    return cams


def _model(hand, rb=None, sampling=(5.0, 48.0, 0.0)):
    rb = np.eye(3) if rb is None else rb
    return ArmModel(
        rb,
        np.array([-190.0, 0.0, 1410.0]),
        np.array([A, B, 0.0]),
        RADII,
        np.asarray(hand, float),
        np.asarray(sampling, float),
    )


def _points(x, model):
    out = np.empty((4, 3))
    arm_points_nb(np.asarray(x, float), model, out)
    return out


def _outline_lines(pts, cam):
    """The four outline segments (start, end), camera frame: the cones' contour generators."""
    lines = []
    for seg in range(2):
        a, b = cam.to_camera(pts[seg]), cam.to_camera(pts[seg + 1])
        gen = cone_contour_generators(a, b, RADII[2 * seg], RADII[2 * seg + 1])
        lines += [(gen[0, 0], gen[0, 1]), (gen[1, 0], gen[1, 1])]
    return lines


def _render_outlines(pts, cams):
    """Gradient maps with the arm's outlines drawn as 1, blurred a little."""
    maps = []
    for cam in cams:
        img = np.zeros((SIZE[1], SIZE[0]), np.float32)
        for a, b in _outline_lines(pts, cam):
            pa, pb = cam.project_camera_points(np.stack([a, b]))
            cv2.line(img, tuple(np.round(pa).astype(int)), tuple(np.round(pb).astype(int)), 1.0, 2)
        maps.append(np.asarray(cv2.GaussianBlur(img, (0, 0), 1.0), dtype=np.float32) * 1.5)
        np.clip(maps[-1], 0, 1, out=maps[-1])
    return maps


TRUE_X = np.array([0.9, 0.3, -0.2, -1.2, 10.0, -5.0, 8.0])


def test_arm_points_match_the_azad14_preset():
    sk = load_preset("azad14", ["adaptive_shoulder"])
    limb = arm(sk, "left")
    q = sk.zero_pose()
    q[3:6] = (0.0, 0.0, 0.4)
    rb = matrix_from_rotvec(q[3:6])
    q[limb.translation_dofs] = TRUE_X[4:]
    q[limb.dofs] = TRUE_X[:4]
    names = ("left_shoulder", "left_elbow", "left_wrist")
    want = canonical_positions(sk, q, names)
    q0 = q.copy()
    q0[limb.translation_dofs] = 0.0
    base = canonical_positions(sk, q0, names)[0]
    model = ArmModel(
        rb, base, np.array([300.0, 270.0, 40.0]), RADII, np.zeros(3), np.array([5.0, 48.0, 0.0])
    )
    got = _points(TRUE_X, model)
    np.testing.assert_allclose(got[:3], want, atol=1e-9)
    forearm = (want[2] - want[1]) / 270.0
    np.testing.assert_allclose(got[3], want[2] + 40.0 * forearm, atol=1e-9)


def _bilinear(g, u, v):
    if not (0 <= u < SIZE[0] - 1 and 0 <= v < SIZE[1] - 1):
        return 0.0
    c0, r0 = int(u), int(v)
    fx, fy = u - c0, v - r0
    return (1 - fy) * ((1 - fx) * g[r0, c0] + fx * g[r0, c0 + 1]) + fy * (
        (1 - fx) * g[r0 + 1, c0] + fx * g[r0 + 1, c0 + 1]
    )


@pytest.mark.parametrize("oriented", [False, True])
def test_batch_weights_equal_a_brute_force_reference(oriented):
    rng = np.random.default_rng(0)
    cams = _cameras(3)
    maps = [rng.random((SIZE[1], SIZE[0])).astype(np.float32) for _ in cams]
    maps_y = [rng.uniform(-1, 1, (SIZE[1], SIZE[0])).astype(np.float32) for _ in cams]
    views = view_stack(cams, maps, maps_y if oriented else None)
    hand = np.array([-150.0, 250.0, 1000.0])
    model = _model(hand, sampling=(5.0, 48.0, float(oriented)))
    particles = TRUE_X + rng.normal(0, [0.3, 0.3, 0.3, 0.3, 20, 20, 20], size=(25, 7))
    particles[:, 3] = np.clip(particles[:, 3], -math.pi, 0)
    w, eg, d2 = np.empty(25), np.empty(25), np.empty(25)
    fusion = default_fusion()
    arm_weights_nb(particles, model, views, fusion, 2500.0, w, eg, d2)
    for i, x in enumerate(particles):
        pts = _points(x, model)
        errs = []
        for cam, g, gy in zip(cams, maps, maps_y):
            vals = []
            for a, b in _outline_lines(pts, cam):
                pa, pb = cam.project_camera_points(np.stack([a, b]))
                length = np.linalg.norm(pb - pa)
                normal = np.array([-(pb - pa)[1], (pb - pa)[0]]) / length
                n = min(max(math.ceil(length / 5.0) + 1, 2), 48)
                for t in np.linspace(0.0, 1.0, n):
                    u, v = pa + t * (pb - pa)
                    if oriented:
                        vec = np.array([_bilinear(g, u, v), _bilinear(gy, u, v)])
                        vals.append(abs(vec @ normal))
                    else:
                        vals.append(_bilinear(g, u, v))
            errs.append(1.0 - np.mean(vals))
        assert eg[i] == pytest.approx(np.mean(errs), abs=1e-6)
        assert d2[i] == pytest.approx(np.sum((pts[3] - hand) ** 2), rel=1e-12)
        assert w[i] == pytest.approx(fused_weight_nb(eg[i], d2[i], 2500.0, fusion), rel=1e-12)


def test_the_true_pose_has_the_smallest_edge_error_on_its_own_outlines():
    cams = _cameras(2)
    model = _model(np.full(3, np.nan))
    truth = _points(TRUE_X, model)
    views = view_stack(cams, _render_outlines(truth, cams))
    rng = np.random.default_rng(1)
    others = TRUE_X + rng.normal(0, [0.4, 0.4, 0.4, 0.4, 0, 0, 0], size=(40, 7))
    batch = np.vstack([TRUE_X, others])
    w, eg, d2 = np.empty(41), np.empty(41), np.empty(41)
    arm_weights_nb(batch, model, views, default_fusion(), 900.0, w, eg, d2)
    assert np.all(np.isnan(d2))  # no hand measured: distance cue off
    assert eg[0] < 0.2 and eg[0] < eg[1:].min()
    assert w[0] == w.max()


def test_ninety_of_150_particles_come_from_the_ik_in_the_first_run_only():
    cams = _cameras(2)
    model = _model(np.full(3, np.nan))
    views = view_stack(cams, _render_outlines(_points(TRUE_X, model), cams))
    f = ArmParticleFilter("left", ArmFilterConfig(), np.random.default_rng(2))
    f.step(model, views)
    assert f.last_n_ik == 0  # no hand, no IK samples
    hand_model = _model(_points(TRUE_X, model)[3])
    f.step(hand_model, views)
    assert f.last_n_ik == 90 and f.particles.shape == (150, 7)
    f2 = ArmParticleFilter("left", ArmFilterConfig(use_ik=False), np.random.default_rng(2))
    f2.step(hand_model, views)
    assert f2.last_n_ik == 0


def _frames_to_converge(use_ik, seed, n_frames=12):
    cams = _cameras(2)
    model0 = _model(np.zeros(3))
    truth = _points(TRUE_X, model0)
    model = _model(truth[3])
    views = view_stack(cams, _render_outlines(truth, cams))
    cfg = ArmFilterConfig(use_ik=use_ik, n_particles=100)
    f = ArmParticleFilter("left", cfg, np.random.default_rng(seed))
    for k in range(n_frames):
        est = f.step(model, views)
        if np.linalg.norm(est.points_mm[1] - truth[1]) < 40.0:
            return k + 1
    return n_frames + 1


def test_ik_sampling_recovers_from_a_wrong_start_faster_than_plain_sampling():
    """Tests A: the filter starts with the arm hanging; the truth is raised forward."""
    with_ik = [_frames_to_converge(True, s) for s in range(3)]
    without = [_frames_to_converge(False, s) for s in range(3)]
    assert max(with_ik) <= 2
    assert np.mean(without) > np.mean(with_ik)


def test_systematic_resampling_known_values():
    rng = np.random.default_rng(3)
    idx = systematic_resample(np.array([0.0, 1.0, 0.0, 3.0]), rng)
    assert sorted(idx.tolist()) == [1, 3, 3, 3]
    idx = systematic_resample(np.zeros(4), rng)
    assert idx.tolist() == [0, 1, 2, 3]


def test_config_refusals():
    with pytest.raises(ConfigError, match="ik_fraction"):
        ArmFilterConfig(ik_fraction=1.5)
    with pytest.raises(ConfigError, match="side"):
        ArmParticleFilter("middle", ArmFilterConfig(), np.random.default_rng(0))


def test_yaw_matrix_turns_the_right_axis():
    np.testing.assert_allclose(yaw_matrix(math.pi / 2)[:, 0], (0.0, 1.0, 0.0), atol=1e-12)


def _elbow_circle_clusters(how="mode"):
    """A filter whose particles sit in two clusters on one hand's elbow circle, the best
    particle in the first; the model, the views and the two elbows (world)."""
    from mocapkit.ik.arm_analytic import arm_ik, make_problem

    cams = _cameras(2)
    model = _model(np.full(3, np.nan))
    views = view_stack(cams, _render_outlines(_points(TRUE_X, model), cams))
    hand = _points(TRUE_X, model)[3]
    q, elbows = arm_ik(make_problem(np.eye(3), model.shoulder_base_mm, hand, A, B), [-2.5, -0.5])
    f = ArmParticleFilter("left", ArmFilterConfig(estimate=how), np.random.default_rng(0))
    f.particles = np.zeros((150, 7))
    f.particles[:75, :4] = q[0]
    f.particles[75:, :4] = q[1]
    _favour(f, 0)
    return f, model, views, elbows


def test_mode_estimate_stays_on_one_of_two_elbow_modes():
    """Two equally weighted clusters on the elbow circle: the plain mean lies between them,
    the mode estimate on the better one."""
    results = {}
    for how in ("mode", "mean"):
        f, model, views, elbows = _elbow_circle_clusters(how)
        results[how] = f._estimate(model, views).points_mm[1]
    assert np.linalg.norm(results["mode"] - elbows[0]) < 1e-6
    gap = np.linalg.norm(elbows[0] - elbows[1])
    assert np.linalg.norm(results["mean"] - elbows[0]) > 0.2 * gap
    assert np.linalg.norm(results["mean"] - elbows[1]) > 0.2 * gap


def _two_elbow_modes():
    """`_elbow_circle_clusters` with its last estimate in the first mode; the elbows
    relative to the shoulder."""
    f, model, views, elbows = _elbow_circle_clusters()
    f._estimate(model, views)
    return f, model, views, elbows - model.shoulder_base_mm


def _favour(f, mode):
    """The heaviest particle in cluster ``mode`` (0 or 1)."""
    f.weights = np.ones(150)
    f.weights[75 * mode] = 1.5


def test_a_single_frame_elbow_jump_is_held_and_a_lasting_one_drawn_over_from_a_frame_late():
    """The cues favour the other side of the elbow circle (a step of about 300 mm, over
    the 200 mm the elbow may move in a frame): on one frame only, the estimate stays;
    on two running, it turns towards it on the second by the frame's step along the
    circle, and reaches it on the third; without the limit it moves at once."""
    f, model, views, rel = _two_elbow_modes()
    step_mm = float(np.linalg.norm(rel[1] - rel[0]))
    assert step_mm > 250.0
    limit = 200.0

    def elbow():
        return f._estimate(model, views, limit).points_mm[1] - model.shoulder_base_mm

    _favour(f, 1)
    assert np.linalg.norm(elbow() - rel[0]) < 1e-6  # one frame: held
    _favour(f, 0)
    assert np.linalg.norm(elbow() - rel[0]) < 1e-6  # and back: no jump reached the output
    _favour(f, 1)
    assert np.linalg.norm(elbow() - rel[0]) < 1e-6
    _favour(f, 1)
    turned = elbow()  # the second frame running: drawn over by the step, not a jump
    assert 0.8 * limit < np.linalg.norm(turned - rel[0]) <= limit
    assert np.linalg.norm(turned - rel[1]) < step_mm - 0.5 * limit
    _favour(f, 1)
    assert np.linalg.norm(elbow() - rel[1]) < 1e-6  # the third: there
    g, model, views, rel = _two_elbow_modes()
    _favour(g, 1)
    free = g._estimate(model, views).points_mm[1] - model.shoulder_base_mm
    assert np.linalg.norm(free - rel[1]) < 1e-6


def _other_side_poses():
    """Two arm poses with one hand: the elbow on either side of its circle (about 300 mm
    apart), the model with that hand measured, and each pose's outlines as views."""
    from mocapkit.ik.arm_analytic import arm_ik, make_problem

    cams = _cameras(2)
    model0 = _model(np.full(3, np.nan))
    hand = _points(TRUE_X, model0)[3]
    q, elbows = arm_ik(make_problem(np.eye(3), model0.shoulder_base_mm, hand, A, B), [-2.5, -0.5])
    model = _model(hand)
    poses = [np.concatenate([qi, np.zeros(3)]) for qi in q]
    views = [view_stack(cams, _render_outlines(_points(x, model), cams)) for x in poses]
    return model, views, elbows


def _elbow_track(limit_mm, seed):
    """Elbows (T, 3) of a filter that sees the first pose 6 frames, the other side of the
    elbow circle 3 frames, then the first again 4 frames."""
    model, views, elbows = _other_side_poses()
    f = ArmParticleFilter("left", ArmFilterConfig(), np.random.default_rng(seed))
    seen = [0] * 6 + [1] * 3 + [0] * 4
    return np.array([f.step(model, views[k], limit_mm).points_mm[1] for k in seen]), elbows


@pytest.mark.parametrize("seed", [0, 1])
def test_a_cue_that_favours_the_other_side_for_three_frames_draws_the_elbow_over_no_jump(seed):
    """The swivel bound: the elbow moves about the frame's limit along its circle while
    the cues favour the other side, where the unbounded filter jumps there in a frame
    (the bound is on the swivel: the perturbed elbow angle and hand axis add a little,
    hence the 1.25)."""
    limit = 100.0
    free, elbows = _elbow_track(math.inf, seed)
    gap = float(np.linalg.norm(elbows[1] - elbows[0]))
    assert gap > 250.0
    assert np.linalg.norm(free[5] - elbows[0]) < 40.0  # settled on the first pose
    assert np.linalg.norm(np.diff(free, axis=0), axis=1).max() > 0.7 * gap  # a jump
    bounded, _ = _elbow_track(limit, seed)
    assert np.linalg.norm(bounded[5] - elbows[0]) < 40.0
    steps = np.linalg.norm(np.diff(bounded, axis=0), axis=1)
    assert steps.max() <= 1.25 * limit
    assert np.linalg.norm(bounded[8] - elbows[0]) > limit  # drawn over, not held


def test_the_swivel_bound_turns_a_particle_about_its_own_shoulder_hand_axis():
    """Particles beyond the window come back to its edge with the hand point and the
    elbow angle where they were; those within it are untouched."""
    from mocapkit.geometry.rotations import signed_angle_nb
    from mocapkit.tracking.stereo.swivel import bound_swivel_nb

    rng = np.random.default_rng(4)
    model = _model(np.full(3, np.nan))
    x = np.zeros((200, 7))
    x[:, :3] = rng.normal(0.0, 1.0, (200, 3))
    x[:, 3] = rng.uniform(-2.8, -0.3, 200)
    ref = _points(TRUE_X, model)[1] - model.shoulder_base_mm
    before = x.copy()
    window = 0.4
    n_turned = bound_swivel_nb(x, A, B, ref, window)
    assert 50 < n_turned < 200
    np.testing.assert_array_equal(x[:, 3], before[:, 3])
    moved = 0
    for i in range(200):
        p0, p1 = _points(before[i], model), _points(x[i], model)
        np.testing.assert_allclose(p1[3], p0[3], atol=1e-6)  # the hand point stays
        axis = p1[3] - p1[0]
        delta = signed_angle_nb(ref, p1[1] - p1[0], axis)
        delta0 = signed_angle_nb(ref, p0[1] - p0[0], axis)
        if abs(delta0) <= window:
            np.testing.assert_array_equal(x[i], before[i])
        else:
            assert abs(abs(delta) - window) < 1e-6 and delta * delta0 > 0
            moved += 1
    assert moved == n_turned


def test_swivel_window_known_values():
    from mocapkit.tracking.stereo.swivel import swivel_window_rad

    assert swivel_window_rad(100.0, 200.0) == pytest.approx(0.5)
    assert swivel_window_rad(700.0, 200.0) == math.inf  # past half the circle: no bound
    assert swivel_window_rad(100.0, 5.0) == math.inf  # a straight arm: no swivel
    assert swivel_window_rad(math.inf, 200.0) == math.inf
