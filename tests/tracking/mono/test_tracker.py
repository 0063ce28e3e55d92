"""The monocular tracker on a smooth synthetic stick motion seen by a calibrated camera."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mocapkit.camera.pinhole import Camera, intrinsics_from_fov, look_at
from mocapkit.errors import ConfigError, ShapeError, UnknownNameError
from mocapkit.eval.metrics import similarity_align
from mocapkit.pipelines.mono import known_lengths_config
from mocapkit.skeleton.kinematics import canonical_positions
from mocapkit.skeleton.presets import load_preset
from mocapkit.tracking.mono.pose_fit import fit_stick_pose
from mocapkit.tracking.mono.stick import stick_model
from mocapkit.tracking.mono.tracker import MonoConfig, MonoTracker

FPS = 30.0


def stick_motion(n_frames: int = 60) -> tuple[np.ndarray, tuple[str, ...], np.ndarray]:
    """World joints (T, 9, 3) of ``upper_stick`` waving both arms, its canonical names, q."""
    sk = load_preset("upper_stick")
    t = np.arange(n_frames) / FPS
    q = np.zeros((n_frames, sk.n_dofs))
    q[:, 2] = 0.0
    q[:, 5] = 0.5 * np.sin(0.8 * t)  # the body turns +-29 deg about the vertical
    for side, sign in (("left", 1.0), ("right", -1.0)):
        from mocapkit.skeleton.limbs import arm

        limb = arm(sk, side)
        ball, hinge = limb.dofs[:3], limb.dofs[3]
        q[:, ball[0]] = 0.9 + 0.6 * np.sin(2.0 * t + (0.0 if sign > 0 else 1.0))  # swing forward
        q[:, ball[1]] = sign * 0.5
        q[:, hinge] = 1.2 + 0.6 * np.sin(3.0 * t)
    names = sk.canonical_names
    return canonical_positions(sk, q, names), names, q


def camera() -> Camera:
    k = intrinsics_from_fov((640, 480), 62.0)
    return Camera("mono", (640, 480), k, np.zeros(5), look_at((0, -3000, 1250), (0, 0, 1250)))


def _recorded(tracker: MonoTracker, layers: dict) -> None:
    """Keep in ``layers`` every layer the tracker's (upper-body) graph builds, by frame
    (the graph itself keeps only the open ones)."""
    graph = tracker._graph
    add = graph.add

    def add_and_keep(*args, **kwargs):  # type: ignore[no-untyped-def]
        out = add(*args, **kwargs)
        newest = max(graph._layers)
        layers[newest] = graph._layers[newest]
        return out

    graph.add = add_and_keep  # type: ignore[method-assign]


def _track(config: MonoConfig, n_frames: int = 60, initial_pose=None, layers=None):  # type: ignore[no-untyped-def]
    joints, names, _ = stick_motion(n_frames)
    model = stick_model(limits=config.limits)
    order = [names.index(n) for n in model.joint_names]
    world = joints[:, order]
    cam = camera()
    px = cam.project(world)
    truth_cam = cam.to_camera(world)
    lengths = np.linalg.norm(model.link_vectors(truth_cam[0]), axis=-1)
    # the true lengths: known, as `track_mono` with the session's lengths (no trunk leans)
    config = known_lengths_config(config)
    tracker = MonoTracker(lengths, cam, 1 / FPS, config, model, initial_pose=initial_pose)
    if layers is not None:
        _recorded(tracker, layers)
    frames = []
    for k in range(n_frames):
        frames += tracker.push(k / FPS, px[k])
    frames += tracker.finish()
    return frames, truth_cam, model


def test_offline_tracking_recovers_the_motion_and_the_flips() -> None:
    frames, truth, model = _track(MonoConfig())
    assert [f.index for f in frames] == list(range(60))
    est = np.stack([f.joints_in_camera for f in frames])
    err = np.array([np.linalg.norm(similarity_align(e, g) - g, axis=1).mean()
                    for e, g in zip(est, truth)])  # fmt: skip
    assert np.median(err) < 20.0
    dz_t = truth[:, model.child, 2] - truth[:, model.parent, 2]
    dz_e = est[:, model.child, 2] - est[:, model.parent, 2]
    counted = np.abs(dz_t) > 0.2 * np.linalg.norm(model.link_vectors(truth), axis=-1)
    right = (np.sign(dz_t) == np.sign(dz_e)) & counted
    assert right.sum() / counted.sum() >= 0.9
    assert all(f.n_survivors <= f.n_candidates for f in frames)
    assert np.nanmean([f.residual_px for f in frames]) < 1.0


def test_online_with_a_long_lag_equals_offline_and_a_short_lag_answers_in_time() -> None:
    off, _, _ = _track(MonoConfig(cost="rotation"), 30)
    on, _, _ = _track(MonoConfig(cost="rotation", lag=40), 30)
    assert [f.code for f in off] == [f.code for f in on]
    cfg = MonoConfig(cost="acceleration", lag=3, smooth_lag=2)
    joints, names, _ = stick_motion(20)
    model = stick_model()
    cam = camera()
    px = cam.project(joints[:, [names.index(n) for n in model.joint_names]])
    lengths = np.linalg.norm(
        model.link_vectors(cam.to_camera(joints[0, [names.index(n) for n in model.joint_names]])),
        axis=-1,
    )
    tracker = MonoTracker(lengths, cam, 1 / FPS, cfg, model)
    for k in range(20):
        out = tracker.push(k / FPS, px[k])
        # frame k - smooth_lag - lag becomes final at frame k
        expect = [k - 5] if k >= 5 else []
        assert [f.index for f in out] == expect
    assert [f.index for f in tracker.finish()] == list(range(15, 20))


def test_pose_fit_reproduces_skeleton_poses() -> None:
    joints, names, _ = stick_motion(10)
    sk = load_preset("upper_stick")
    q2 = fit_stick_pose(sk, names, joints)
    np.testing.assert_allclose(canonical_positions(sk, q2, names), joints, atol=1e-6)


def test_bad_configuration_is_refused() -> None:
    with pytest.raises(ConfigError, match="camera_model"):
        MonoConfig(camera_model="fisheye")
    with pytest.raises(ConfigError, match="short_link_weight: expected \\[0, 1\\], found -0.1"):
        MonoConfig(short_link_weight=-0.1)
    with pytest.raises(ConfigError, match="floor_leg_weight: expected a finite weight >= 0"):
        MonoConfig(floor_leg_weight=-1.0)
    with pytest.raises(ConfigError, match="planted_speed_mm_s: expected a finite speed > 0"):
        MonoConfig(planted_speed_mm_s=0.0)
    with pytest.raises(ConfigError, match="needs a calibrated camera"):
        MonoTracker(np.ones(8), None, 1 / FPS, MonoConfig())
    tr = MonoTracker(np.ones(8), None, 1 / FPS, MonoConfig(camera_model="orthographic"))
    with pytest.raises(ShapeError, match="expected \\(9, 2\\)"):
        tr.push(0.0, np.zeros((3, 2)))


def _track_with_dominant_prior(cfg: MonoConfig, n: int = 12):
    """The stick motion's first ``n`` frames tracked offline with the truth's lengths."""
    joints, names, _ = stick_motion(n)
    model = stick_model()
    cam = camera()
    world = joints[:, [names.index(nm) for nm in model.joint_names]]
    lengths = np.linalg.norm(model.link_vectors(cam.to_camera(world[0])), axis=-1)
    tracker = MonoTracker(lengths, cam, 1 / FPS, cfg, model)
    layers: dict = {}
    _recorded(tracker, layers)
    for k in range(n):
        tracker.push(k / FPS, cam.project(world[k]))
    return model, layers, tracker.finish()


def test_a_dominant_unary_prior_picks_each_frames_cheapest_pose() -> None:
    from mocapkit.tracking.mono.priors import clavicle_forward_cost

    model, layers, frames = _track_with_dominant_prior(
        MonoConfig(clavicle_weight=1e9, arm_prior_weight=0.0, smooth_lag=0, noise_px=0.5)
    )
    varied = 0
    for f in frames:
        layer = layers[f.index]
        costs = clavicle_forward_cost(model, layer.positions[layer.keep])
        chosen = clavicle_forward_cost(model, f.joints_in_camera[None])[0]
        assert chosen == pytest.approx(costs.min(), abs=1e-9)
        varied += int(costs.max() > costs.min() + 1e-3)
    assert varied >= 3  # the prior had a choice to make


def test_a_dominant_arm_prior_picks_each_frames_most_common_arms() -> None:
    from mocapkit.tracking.mono.arm_prior import default_arm_prior

    prior = default_arm_prior()
    model, layers, frames = _track_with_dominant_prior(
        MonoConfig(arm_prior_weight=1e9, clavicle_weight=0.0, smooth_lag=0, noise_px=0.5)
    )
    varied = 0
    for f in frames:
        layer = layers[f.index]
        costs = prior.cost(model, layer.positions[layer.keep])
        assert prior.cost(model, f.joints_in_camera[None])[0] == pytest.approx(costs.min())
        varied += int(costs.max() > costs.min() + 1e-3)
    assert varied >= 3  # the prior had a choice to make


def test_a_known_initial_pose_fixes_the_first_frames_candidate() -> None:
    """The paper's assumption 3: the first frame keeps the survivor nearest to the given
    pose (relative to the neck, so a pose at another depth selects the same one)."""
    cfg = MonoConfig(smooth_lag=0)
    kept: dict = {}
    free, truth, model = _track(cfg, 20, layers=kept)
    layer = kept[0]
    assert layer.codes.shape[0] >= 2  # a choice to make
    # every surviving candidate of the first frame, given as the initial pose 400 mm
    # deeper and 50 mm aside, becomes the first frame's pose
    for i in range(layer.codes.shape[0]):
        start = layer.positions[i] + np.array([50.0, 0.0, 400.0])
        frames, _, _ = _track(cfg, 20, initial_pose=start)
        assert frames[0].code == layer.codes[i]
        np.testing.assert_allclose(frames[0].joints_in_camera, layer.positions[i])
        assert [f.index for f in frames] == list(range(20))
    # the true first pose selects the truth's flips on every link out of the image plane
    frames, _, _ = _track(cfg, 20, initial_pose=truth[0])
    dz = truth[0, model.child, 2] - truth[0, model.parent, 2]
    counted = np.abs(dz) > 0.2 * np.linalg.norm(model.link_vectors(truth[0]), axis=-1)
    bits = (frames[0].code >> np.arange(model.n_links)) & 1
    np.testing.assert_array_equal(bits[counted], (dz[counted] > 0).astype(int))
    # only the first frame is constrained: the free path's later pruning statistics hold
    assert [f.n_survivors for f in frames] == [f.n_survivors for f in free]


def test_a_bad_initial_pose_is_refused() -> None:
    model = stick_model()
    lengths = np.full(model.n_links, 300.0)
    with pytest.raises(ShapeError, match=r"initial pose of shape \(9, 3\)"):
        MonoTracker(lengths, camera(), 1 / FPS, initial_pose=np.zeros((8, 3)))
    no_neck = np.zeros((9, 3))
    no_neck[0] = np.nan
    with pytest.raises(ConfigError, match="needs the neck"):
        MonoTracker(lengths, camera(), 1 / FPS, initial_pose=no_neck)


def test_rebuilt_neck_widens_the_clavicles_band_and_turns_the_girdle_cost_on() -> None:
    """Default (a seen neck): one band for every link, no girdle cost. With the neck and
    pelvis rebuilt (as `mocapkit.pipelines.mono.detector_config` sets for OpenPose
    JSON): the clavicles' band is ``rebuilt_reach_tolerance`` and the girdle cost on."""
    model = stick_model()
    lengths = np.full(model.n_links, 250.0)
    seen = MonoTracker(lengths, camera(), 1 / FPS, MonoConfig(girdle_cosine=-0.7), model)
    np.testing.assert_array_equal(seen._reach, np.full(model.n_links, 0.02))
    assert not seen._girdle  # the neck is seen: no cost, whatever the cosine
    cfg = MonoConfig(rebuilt_joints=("neck", "pelvis"), girdle_cosine=-0.7)
    rebuilt = MonoTracker(lengths, camera(), 1 / FPS, cfg, model)
    expect = np.full(model.n_links, 0.02)
    expect[[model.link_index("left_clavicle"), model.link_index("right_clavicle")]] = 0.1
    np.testing.assert_array_equal(rebuilt._reach, expect)
    assert rebuilt._girdle
    with pytest.raises(UnknownNameError, match="rebuilt_joints joint"):
        MonoTracker(lengths, camera(), 1 / FPS, MonoConfig(rebuilt_joints=("chest",)), model)
    with pytest.raises(ConfigError, match="rebuilt_reach_tolerance: expected"):
        MonoConfig(rebuilt_reach_tolerance=1.0)
    with pytest.raises(ConfigError, match="girdle_weight: expected"):
        MonoConfig(girdle_weight=-1.0)
    with pytest.raises(ConfigError, match=r"window must be >= 1"):
        MonoConfig(window=0)


def test_a_detectors_depth_order_steers_the_flips_softly() -> None:
    """Given the truth's depth order the flips stay right; given its mirror image and a
    large weight, the tracker follows the hint where the limits allow; weight 0 ignores it."""
    joints, names, _ = stick_motion(40)
    model = stick_model()
    cam = camera()
    idx = [names.index(n) for n in model.joint_names]
    px = cam.project(joints[:, idx])
    truth = cam.to_camera(joints[:, idx])
    lengths = np.linalg.norm(model.link_vectors(truth[0]), axis=-1)
    v = model.link_vectors(truth)
    sines = v[..., 2] / np.linalg.norm(v, axis=-1)
    counted = np.abs(sines) > 0.2

    def agree(hint: np.ndarray, weight: float) -> float:
        tracker = MonoTracker(lengths, cam, 1 / FPS, MonoConfig(depth_order_weight=weight), model)
        out = []
        for k in range(px.shape[0]):
            out += tracker.push(k / FPS, px[k], hint[k])
        est = np.stack([f.joints_in_camera for f in out + tracker.finish()])
        dz = est[:, model.child, 2] - est[:, model.parent, 2]
        return float((np.sign(dz) == np.sign(hint))[counted].mean())

    assert agree(sines, 1e4) >= 0.95
    mirrored_free, mirrored_forced = agree(-sines, 0.0), agree(-sines, 1e4)
    assert mirrored_free <= 0.1
    assert mirrored_forced >= mirrored_free + 0.3


def test_trunk_lean_candidates_lie_on_the_pelvis_ray_at_the_given_sines() -> None:
    """Each lean puts the pelvis on its viewing ray, the trunk from the neck at the sine s
    from the plane normal to that ray, both ways, and only where the trunk's length does
    not already lean it as far."""
    model = stick_model()
    cam = camera()
    lengths = np.full(model.n_links, 300.0)
    tracker = MonoTracker(lengths, cam, 1 / FPS, MonoConfig(trunk_lean_sines=(0.25, 0.5)), model)
    obs = np.full((model.n_joints, 2), np.nan)
    obs[0] = (0.01, -0.05)  # the neck's normalised image point
    obs[model.child[0]] = (0.02, 0.05)  # the pelvis's
    neck = 3000.0 * np.array([0.01, -0.05, 1.0])
    ray = np.array([0.02, 0.05, 1.0]) / np.linalg.norm([0.02, 0.05, 1.0])
    pelvises = tracker._lean_pelvises(obs, neck)
    assert len(pelvises) == 4
    sines = []
    for p in pelvises:
        np.testing.assert_allclose(p / p[2], [0.02, 0.05, 1.0], atol=1e-12)  # on the ray
        v = p - neck
        sines.append(float(v @ ray / np.linalg.norm(v)))
    np.testing.assert_allclose(sorted(sines), [-0.5, -0.25, 0.25, 0.5], atol=1e-9)
    # a trunk long enough to lean 0.3 within its length keeps only the 0.5 lean
    d = np.linalg.norm(neck - (neck @ ray) * ray)
    lengths[0] = d / np.sqrt(1 - 0.3**2) / (1 + MonoConfig().reach_tolerance)
    tracker = MonoTracker(lengths, cam, 1 / FPS, MonoConfig(trunk_lean_sines=(0.25, 0.5)), model)
    assert len(tracker._lean_pelvises(obs, neck)) == 2
    off = MonoTracker(lengths, cam, 1 / FPS, MonoConfig(trunk_lean_sines=()), model)
    assert off._lean_pelvises(obs, neck) == []
    with pytest.raises(ConfigError, match=r"trunk_lean_sines: expected sines in \(0, 1\)"):
        MonoConfig(trunk_lean_sines=(1.0,))


def test_trunk_leans_put_a_short_trunks_true_lean_among_the_states() -> None:
    """A camera looking down sees the upright trunk leave the image plane (its pelvis
    farther than its neck). With the trunk's length estimated 10 % short the search alone
    can lean it only as far as that length reaches; the lean candidates add states whose
    trunk is as far out of the plane as the truth's, both ways, and the path stays on a
    consistent lean (the motion cost)."""
    joints, names, _ = stick_motion(40)
    model = stick_model()
    k = intrinsics_from_fov((640, 480), 62.0)
    cam = Camera("mono", (640, 480), k, np.zeros(5), look_at((0, -2500, 2600), (0, 0, 1000)))
    idx = [names.index(n) for n in model.joint_names]
    px = cam.project(joints[:, idx])
    truth = cam.to_camera(joints[:, idx])
    lengths = np.linalg.norm(model.link_vectors(truth[0]), axis=-1)
    lengths[0] *= 0.9
    v = model.link_vectors(truth)[:, 0]
    true_sine = v[:, 2] / np.linalg.norm(v, axis=-1)
    assert true_sine.min() > 0.4

    def track(leans: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
        """Per frame: the nearest state's trunk sine error, and the chosen trunk sine."""
        tracker = MonoTracker(lengths, cam, 1 / FPS, MonoConfig(trunk_lean_sines=leans), model)
        layers: dict = {}
        _recorded(tracker, layers)
        out = []
        for i in range(px.shape[0]):
            out += tracker.push(i / FPS, px[i])
        out += tracker.finish()
        nearest = []
        for f in sorted(layers):
            e = model.link_vectors(layers[f].positions)[:, 0]
            s = e[:, 2] / np.linalg.norm(e, axis=-1)
            nearest.append(np.min(np.abs(s - true_sine[f])))
        chosen = model.link_vectors(np.stack([f.joints_in_camera for f in out]))[:, 0]
        return np.array(nearest), chosen[:, 2] / np.linalg.norm(chosen, axis=-1)

    near_without, _ = track(())
    near_with, chosen = track((0.5,))
    assert np.median(near_without) > 0.2
    assert np.median(near_with) < 0.1
    assert np.all(near_with <= near_without + 1e-9)
    # one lean throughout: the path does not hop between the states' leans
    assert np.all(np.abs(np.diff(chosen)) < 0.05)


def _split_stance_world() -> tuple[np.ndarray, tuple[str, ...]]:
    """World joints (K, 3) of the stick with legs standing in a split stance on the floor
    (z up): the left foot 300 mm towards the camera (at -y), the right 300 mm away."""
    model = stick_model(True)
    at = {
        "neck": (0, 0, 1450), "pelvis": (0, 0, 950), "left_shoulder": (180, 0, 1420),
        "right_shoulder": (-180, 0, 1420), "head": (0, 0, 1650), "left_elbow": (200, 0, 1150),
        "left_wrist": (210, -60, 900), "right_elbow": (-200, 0, 1150),
        "right_wrist": (-210, -60, 900), "left_hip": (90, 0, 900), "right_hip": (-90, 0, 900),
        "left_knee": (90, -160, 500), "left_ankle": (90, -300, 80),
        "right_knee": (-90, 160, 500), "right_ankle": (-90, 300, 80),
    }  # fmt: skip
    return np.array([at[n] for n in model.joint_names], dtype=float), model.joint_names


def test_planted_feet_put_the_legs_depths_where_the_floor_does() -> None:
    """Standing still (eq. 3 costs every flip the same), the floor's depths of the two
    planted feet choose the legs' flips: the ankles' depths as the truth's; feet that slide
    faster than ``planted_speed_mm_s`` count as not planted."""
    world, _ = _split_stance_world()
    model = stick_model(True)
    cam = camera()
    truth = cam.to_camera(world)
    lengths = np.linalg.norm(model.link_vectors(truth), axis=-1)
    ankles = [model.joint_names.index(n) for n in ("left_ankle", "right_ankle")]
    cfg = known_lengths_config(MonoConfig(legs=True, floor_leg_weight=1000.0))
    tracker = MonoTracker(lengths, cam, 1 / FPS, cfg, model, ankle_floor_mm=80.0)
    px = cam.project(world)
    out = []
    for k in range(12):
        out += tracker.push(k / FPS, px)
    est = np.stack([f.joints_in_camera for f in out + tracker.finish()])
    # the tracker's own depth errs a little (its bound); the feet's difference and the
    # legs' flips are the truth's
    gap = est[:, ankles[1], 2] - est[:, ankles[0], 2]
    np.testing.assert_allclose(gap, truth[ankles[1], 2] - truth[ankles[0], 2], atol=10.0)
    legs = [model.link_index(s) for s in ("left_thigh", "left_shank", "right_thigh", "right_shank")]
    dz = est[:, model.child[legs], 2] - est[:, model.parent[legs], 2]
    true_dz = truth[model.child[legs], 2] - truth[model.parent[legs], 2]
    assert (np.sign(dz) == np.sign(true_dz)).all()
    # the floor's depths of both feet, once the previous frame is known; none where they slide
    sliding = MonoTracker(lengths, cam, 1 / FPS, cfg, model, ankle_floor_mm=80.0)
    n = cam.undistort_pixels(px)
    assert np.isnan(sliding._planted(0.0, n)).all()  # no previous frame
    np.testing.assert_allclose(sliding._planted(1 / FPS, n), truth[ankles, 2], rtol=1e-9)
    moved = cam.undistort_pixels(cam.project(world + np.array([20.0, 0.0, 0.0])))  # 600 mm/s
    assert np.isnan(sliding._planted(2 / FPS, moved)).all()
    # no floor given, or the weight 0: no floor depths
    assert MonoTracker(lengths, cam, 1 / FPS, cfg, model)._planted(0.0, n) is None
    off = replace(cfg, floor_leg_weight=0.0)
    assert (
        MonoTracker(lengths, cam, 1 / FPS, off, model, ankle_floor_mm=80.0)._planted(0.0, n) is None
    )
