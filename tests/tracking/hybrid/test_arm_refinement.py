"""Per-arm video refinement: Nelder-Mead = SciPy on the arm cost, cost minimum, swivel recovery."""

from __future__ import annotations

import math
from dataclasses import replace

import cv2
import numpy as np
import pytest
from scipy.optimize import Bounds, minimize

from mocapkit.camera.pinhole import Camera, intrinsics_from_fov, look_at
from mocapkit.cues.edges import EdgeConfig
from mocapkit.errors import ConfigError, ShapeError, UnknownNameError
from mocapkit.ik.nelder_mead import initial_simplex
from mocapkit.ik.swivel import swivel_arm
from mocapkit.skeleton import forward_kinematics, joint_positions, load_preset
from mocapkit.skeleton.limbs import arm
from mocapkit.tracking.hybrid.arm_refinement import (
    SIDES,
    ArmDiagnostics,
    RefineConfig,
    arm_cost_nb,
    arm_problem,
    arm_roi,
    nelder_mead_arm_nb,
    refine_arms,
    swivel_x_nb,
)
from mocapkit.viz.overlay import draw_body

SKEL = load_preset("zhang21")
POSE_DEG = {
    "l_shoulder_abduction": 35,
    "l_shoulder_flexion": 20,
    "l_elbow_flexion": 70,
    "l_shoulder_rotation": 30,
    "r_shoulder_abduction": 45,
    "r_shoulder_flexion": 10,
    "r_elbow_flexion": 60,
    "r_shoulder_rotation": -20,
}


def _pose() -> np.ndarray:
    q = SKEL.zero_pose()
    for name, deg in POSE_DEG.items():
        q[SKEL.dof_index(name)] = math.radians(deg)
    return q


def _joint(side: str, k: int, sk=SKEL) -> int:
    """Shoulder (0), elbow (1) or wrist (2) joint of an arm, by canonical names."""
    return arm(sk, side).joints[k]


CAMERA = Camera(
    "front",
    (640, 480),
    intrinsics_from_fov((640, 480), 60),
    np.zeros(5),
    look_at((300, 3200, 1300), (0, 0, 1250)),
)


def _render(q: np.ndarray) -> np.ndarray:
    rng = np.random.default_rng(7)
    bg = (rng.normal(0, 1, (480, 640, 3)) * 12 + 170).clip(0, 255).astype(np.uint8)
    bg = np.asarray(cv2.GaussianBlur(bg, (0, 0), 2), dtype=np.uint8)  # light texture
    colours = {n: (40, 60, 200) for n in ("l_humerus", "l_radius", "l_hand")}
    colours.update({n: (200, 80, 40) for n in ("r_humerus", "r_radius", "r_hand")})
    return draw_body(bg, SKEL, CAMERA, q, colours, default_colour=(90, 120, 90))


@pytest.fixture(scope="module")
def scene():
    q = _pose()
    world = joint_positions(SKEL, q)
    targets = {s: world[_joint(s, 2)] for s in SIDES}
    return q, _render(q), targets


def _swivel_deg(q_ref: np.ndarray, q_est: np.ndarray, side: str, sk=SKEL) -> float:
    """Angle between the two elbows about the reference shoulder->wrist axis."""
    ref, est = joint_positions(sk, q_ref), joint_positions(sk, q_est)
    s, h = ref[_joint(side, 0, sk)], ref[_joint(side, 2, sk)]
    axis = (h - s) / np.linalg.norm(h - s)
    vecs = []
    for w in (ref, est):
        v = w[_joint(side, 1, sk)] - s
        vecs.append(v - (v @ axis) * axis)
    c = np.cross(vecs[0], vecs[1]) @ axis
    return math.degrees(math.atan2(c, vecs[0] @ vecs[1]))


@pytest.mark.parametrize("side", SIDES)
def test_nelder_mead_arm_nb_reproduces_scipy_on_the_arm_cost(scene, side):
    """The cached production search (cost bound as a global) = SciPy on the same cost,
    iterate for iterate: same result, value and evaluation count."""
    q, img, targets = scene
    start = swivel_arm(SKEL, q, side, math.radians(12.0))
    p = arm_problem(SKEL, CAMERA, start, side, img, targets[side])
    dmap = p.maps
    sim = initial_simplex(p.x0, 0.1)
    res = minimize(
        lambda x: arm_cost_nb(x, p.model, dmap),
        p.x0,
        method="Nelder-Mead",
        bounds=Bounds(p.lower, p.upper),
        options={"initial_simplex": sim, "xatol": 1e-3, "fatol": 1e-4, "maxfev": 300},
    )
    x, fx, nfev, _nit, converged = nelder_mead_arm_nb(
        p.model, dmap, sim, p.lower, p.upper, 1e-3, 1e-4, 300
    )
    np.testing.assert_array_equal(x, res.x)
    assert fx == res.fun
    assert nfev == res.nfev
    assert converged == (res.status == 0)


def test_swivel_keeps_hand_and_matches_compiled_swivel(scene):
    q, img, targets = scene
    for side in SIDES:
        p = arm_problem(SKEL, CAMERA, q, side, img, targets[side])
        out = np.empty(4)
        for deg in (-25.0, 10.0, 33.0):
            q2 = swivel_arm(SKEL, q, side, math.radians(deg))
            assert swivel_x_nb(p.x0, math.radians(deg), p.model, out)
            np.testing.assert_allclose(out, q2[p.dofs], atol=1e-12)
            hand = p.joints_mm(out)[3]
            np.testing.assert_allclose(hand, targets[side], atol=1e-9)
            assert _swivel_deg(q, q2, side) == pytest.approx(deg, abs=1e-6)


def test_cost_is_lowest_at_the_true_pose(scene):
    q, img, targets = scene
    for side in SIDES:
        p = arm_problem(SKEL, CAMERA, q, side, img, targets[side])
        true_cost = p.cost(p.x0)
        image_term, hand = p.cost_terms(p.x0)
        # the hand term vanishes (up to rounding: the chain's FK is carried by its parent's)
        assert hand == pytest.approx(0.0, abs=1e-9)
        assert true_cost == pytest.approx(image_term, abs=2.0 * 1e-9)
        for deg in (-20, -10, -5, 5, 10, 20):
            q2 = swivel_arm(SKEL, q, side, math.radians(deg))
            assert p.cost(q2[p.dofs]) > true_cost
        for k in range(4):
            for step in (-0.1, 0.1):
                x = p.x0.copy()
                x[k] += step
                assert p.cost(x) > true_cost


def test_oriented_cost_reads_each_outline_line_in_the_map_of_its_direction(scene):
    q, img, targets = scene
    p = arm_problem(SKEL, CAMERA, q, "left", img, targets["left"], RefineConfig(edges=EdgeConfig()))
    assert p.maps.maps.shape[0] == 1  # the paper's plain chamfer: one map
    rng = np.random.default_rng(3)
    xs = p.x0 + rng.normal(0.0, 0.2, (20, 4))
    # K copies of the plain map: the same cost whatever bin each line reads
    same = replace(p, maps=p.maps._replace(maps=np.repeat(p.maps.maps, 8, axis=0)))
    for x in xs:
        assert same.cost(x) == pytest.approx(p.cost(x), rel=1e-12)
    # an arm hanging straight down, seen from the front: every outline line runs
    # vertically in the image (90 deg: bin 4 of 8), so with map k constant k the mean is 4
    hang = SKEL.zero_pose()
    world = joint_positions(SKEL, hang)
    wrist = world[_joint("left", 2)]
    down = arm_problem(SKEL, CAMERA, hang, "left", img, wrist, RefineConfig())
    assert down.maps.maps.shape[0] == 8
    k_maps = np.ascontiguousarray(
        np.broadcast_to(np.arange(8, dtype=np.float32)[:, None, None], down.maps.maps.shape)
    )
    image_term, hand = replace(down, maps=down.maps._replace(maps=k_maps)).cost_terms(down.x0)
    assert hand == pytest.approx(0.0, abs=1e-9)
    assert image_term == pytest.approx(4.0, abs=1e-12)


@pytest.mark.parametrize("deg", [-20.0, -15.0, 15.0, 20.0])
def test_refinement_recovers_a_perturbed_swivel(scene, deg):
    q, img, targets = scene
    for side in SIDES:
        start = swivel_arm(SKEL, q, side, math.radians(deg))
        diag: dict[str, ArmDiagnostics] = {}
        refined = refine_arms(SKEL, CAMERA, start, img, targets, RefineConfig(), diagnostics=diag)
        assert abs(_swivel_deg(q, refined, side)) < 2.0
        d = diag[side]
        assert d.refined and d.cost_after < d.cost_before
        assert d.hand_offset_after_mm < 2.0  # the hand penalty holds the hand on its marker
        assert d.n_evaluations <= RefineConfig().maxfev + RefineConfig().swivel_scan_steps


def test_plain_paper_search_and_scipy_solver(scene):
    """Without the swivel scan (paper: simplex from the IK pose) a 10 deg swivel is
    inside the basin; SciPy's Nelder-Mead on the same cost recovers it too."""
    q, img, targets = scene
    start = swivel_arm(SKEL, q, "right", math.radians(10.0))
    plain = RefineConfig(swivel_scan_rad=0.0)
    for cfg in (plain, RefineConfig(swivel_scan_rad=0.0, solver="scipy")):
        diag: dict[str, ArmDiagnostics] = {}
        refined = refine_arms(
            SKEL, CAMERA, start, img, {"right": targets["right"]}, cfg, diagnostics=diag
        )
        assert abs(_swivel_deg(q, refined, "right")) < 2.0
        assert diag["left"].reason == "no hand target" and not diag["left"].refined
        np.testing.assert_array_equal(
            refined[SKEL.dofs_of_joint("l_humerus")], start[SKEL.dofs_of_joint("l_humerus")]
        )


def test_literal_sum_counts_silhouette_pixels(scene):
    q, img, targets = scene
    p = arm_problem(
        SKEL,
        CAMERA,
        q,
        "left",
        img,
        targets["left"],
        RefineConfig(literal_sum=True, include_hand=False),
    )
    ones = type(p.distance)(np.ones_like(p.distance.distance_px), p.distance.origin_px, 25.0)
    p1 = type(p)(p.side, p.dofs, p.model, ones, p.lower, p.upper, p.x0, ones.chamfer_maps(False))
    mask = np.zeros((480, 640), np.uint8)
    draw_body(np.zeros((480, 640, 3), np.uint8), SKEL, CAMERA, q)  # exercise the renderer
    from mocapkit.viz.overlay import segment_silhouettes

    for _name, quad, _discs, _d in segment_silhouettes(SKEL, CAMERA, q, ["l_humerus", "l_radius"]):
        cv2.fillConvexPoly(mask, np.round(quad).astype(np.int32), 1)
    x0, y0, x1, y1 = p.distance.roi
    area = mask[y0 : y1 - 1, x0 : x1 - 1].sum()
    # same silhouette, rasterised by OpenCV vs pixel-centre test: boundary pixels differ
    assert abs(p1.cost_terms(p1.x0)[0] - area) < 0.1 * area


def test_bad_inputs_raise(scene):
    q, img, targets = scene
    with pytest.raises(UnknownNameError, match="unknown arm side 'middle'"):
        refine_arms(SKEL, CAMERA, q, img, {"middle": targets["left"]})
    with pytest.raises(ShapeError, match=r"hand_targets_mm\['left'\]: expected 3 finite"):
        refine_arms(SKEL, CAMERA, q, img, {"left": np.zeros(2)})
    with pytest.raises(ShapeError, match=r"expected size \(640, 480\)"):
        refine_arms(SKEL, CAMERA, q, img[:100], targets)
    with pytest.raises(ShapeError, match="expected joint parameters of shape"):
        refine_arms(SKEL, CAMERA, q[:5], img, targets)
    with pytest.raises(ConfigError, match="RefineConfig.maxfev"):
        RefineConfig(maxfev=2)


@pytest.mark.parametrize("side", SIDES)
def test_roi_covers_every_scanned_elbow(side):
    q = _pose()
    world = forward_kinematics(SKEL, q)
    cfg = RefineConfig()
    x0, y0, x1, y1 = arm_roi(SKEL, CAMERA, world, side, 0.0, cfg.swivel_scan_rad)
    elbow = _joint(side, 1)
    for angle in np.linspace(-cfg.swivel_scan_rad, cfg.swivel_scan_rad, 73):
        px = CAMERA.project(joint_positions(SKEL, swivel_arm(SKEL, q, side, angle))[elbow])
        assert x0 - 1 <= px[0] <= x1 + 1 and y0 - 1 <= px[1] <= y1 + 1, math.degrees(angle)
    # without a scan the box only holds the current arm
    small = arm_roi(SKEL, CAMERA, world, side, 0.0, 0.0)
    assert (small[2] - small[0]) * (small[3] - small[1]) < (x1 - x0) * (y1 - y0)


def test_elbow_jump_penalty_is_a_hinge_on_the_elbow_distance(scene):
    q, img, targets = scene
    world = joint_positions(SKEL, q)
    elbow = world[_joint("left", 1)]

    def left(config, **kw):
        return arm_problem(SKEL, CAMERA, q, "left", img, targets["left"], config, **kw)

    off = left(RefineConfig())
    cfg = RefineConfig(elbow_jump_weight_per_mm=0.2)
    direction = np.array([0.6, 0.0, 0.8])
    for dist_mm, free_mm, expected in ((50.0, 80.0, 0.0), (150.0, 80.0, 0.2 * 70.0)):
        p = left(cfg, previous_elbow_mm=elbow + dist_mm * direction, elbow_free_mm=free_mm)
        assert p.cost(p.x0) - off.cost(off.x0) == pytest.approx(expected, abs=1e-9)
    # no previous elbow, a non-finite one, or a weight of 0: no penalty
    for config, kw in (
        (cfg, {}),
        (cfg, {"previous_elbow_mm": np.full(3, np.nan)}),
        (RefineConfig(elbow_jump_weight_per_mm=0.0), {"previous_elbow_mm": elbow + 500.0}),
    ):
        p = left(config, **kw)
        assert p.cost(p.x0) == pytest.approx(off.cost(off.x0), abs=1e-12)


def test_elbow_jump_penalty_settles_an_ambiguous_swivel_near_the_previous_elbow(scene):
    """A frame with no edges leaves every swivel equally good; the penalty picks the one
    whose elbow is nearest the previous frame's, wherever that is."""
    q, _img, targets = scene
    blank = np.full((480, 640, 3), 128, np.uint8)
    cfg = RefineConfig(elbow_jump_weight_per_mm=0.1, elbow_speed_mm_per_s=300.0)
    elbow = _joint("right", 1)
    for previous_deg, start_deg in ((0.0, 70.0), (70.0, 0.0), (-40.0, 30.0)):
        previous_q = swivel_arm(SKEL, q, "right", math.radians(previous_deg))
        assert np.all((previous_q >= SKEL.lower) & (previous_q <= SKEL.upper))  # reachable
        start = swivel_arm(SKEL, q, "right", math.radians(start_deg))
        refined = refine_arms(
            SKEL,
            CAMERA,
            start,
            blank,
            {"right": targets["right"]},
            cfg,
            previous_elbows_mm={"right": joint_positions(SKEL, previous_q)[elbow]},
            elapsed_s=0.02,  # 6 mm free
        )
        assert abs(_swivel_deg(previous_q, refined, "right")) < 3.0, (previous_deg, start_deg)


def test_elbow_jump_settings_checked():
    with pytest.raises(ConfigError, match="RefineConfig.elbow_jump_weight_per_mm"):
        RefineConfig(elbow_jump_weight_per_mm=-1.0)
    with pytest.raises(ConfigError, match="RefineConfig.elbow_speed_mm_per_s"):
        RefineConfig(elbow_speed_mm_per_s=-5.0)


def test_limb_at_the_camera_plane_costs_the_cap(scene):
    """A forearm just in front of a distorting lens and far off its axis projects to
    outline lines about 1e9 px long. Every sample is off the map, so the image term is the
    cap, and the sample count is bounded by the map's size rather than that length (a
    131_03 hop once spent a minute on one evaluation)."""
    q, img, targets = scene
    world = joint_positions(SKEL, q)
    elbow = world[_joint("left", 1)]
    wrist = world[_joint("left", 2)]
    along = (wrist - elbow) / np.linalg.norm(wrist - elbow)
    lateral = np.cross(along, [0.0, 0.0, 1.0])
    lateral /= np.linalg.norm(lateral)
    # looking along the forearm from 50 mm behind the elbow and 2 m beside it
    eye = elbow - 50.0 * along + 2000.0 * lateral
    barrel = np.array([-0.10, 0.03, 0.0, 0.0, 0.0])
    near = Camera(
        "near", (640, 480), intrinsics_from_fov((640, 480), 60), barrel, look_at(eye, eye + along)
    )
    p = arm_problem(SKEL, near, q, "left", img, targets["left"])
    u = near.project(np.stack([elbow, wrist]))[:, 0]
    assert np.all(np.isfinite(u)) and np.abs(u[0] - u[1]) > 1e6  # the projection blows up
    image_term, _hand = p.cost_terms(p.x0)
    assert image_term == pytest.approx(RefineConfig().edges.cap_px)


def _small_scene(preset: str) -> tuple[object, Camera, np.ndarray, np.ndarray]:
    """A 320x240 render of ``preset`` with both elbows bent where a swivel shows."""
    from scipy.spatial.transform import Rotation

    sk = load_preset(preset)
    if preset == "zhang21":
        q = _pose()
    else:  # azad14's ball shoulders: raised sideways and forwards, turned about the arm
        q = sk.zero_pose()
        for side, sgn in (("left", 1.0), ("right", -1.0)):
            limb = arm(sk, side)
            rot = Rotation.from_euler("YXZ", [sgn * 40, -35, sgn * 70], degrees=True)
            q[limb.dofs[:3]] = rot.as_rotvec()
            q[limb.dofs[3]] = math.radians(-80)
    size = (320, 240)
    pose = look_at((300, 2400, 1300), (0, 0, 1250))
    cam = Camera("small", size, intrinsics_from_fov(size, 50), np.zeros(5), pose)
    rng = np.random.default_rng(7)
    bg = (rng.normal(0, 1, (240, 320, 3)) * 12 + 170).clip(0, 255).astype(np.uint8)
    bg = np.asarray(cv2.GaussianBlur(bg, (0, 0), 2), dtype=np.uint8)
    colours = {}
    for side, colour in (("left", (40, 60, 200)), ("right", (200, 80, 40))):
        colours.update({sk.joint_names[j]: colour for j in arm(sk, side).chain})
    return sk, cam, q, draw_body(bg, sk, cam, q, colours, default_colour=(90, 120, 90))


@pytest.mark.parametrize("preset", ["zhang21", "azad14"])
def test_refinement_recovers_a_perturbed_swivel_on_either_model(preset):
    """Limbs come from canonical names: revolute (zhang21) and ball (azad14) shoulders."""
    sk, cam, q, img = _small_scene(preset)
    world = joint_positions(sk, q)
    targets = {s: world[arm(sk, s).end] for s in SIDES}
    for deg in (-40.0, 60.0):
        start = q.copy()
        for side in SIDES:
            start = swivel_arm(sk, start, side, math.radians(deg))
        assert abs(_swivel_deg(q, start, "left", sk)) > 30.0
        diag: dict[str, ArmDiagnostics] = {}
        refined = refine_arms(sk, cam, start, img, targets, RefineConfig(), diagnostics=diag)
        for side in SIDES:
            assert abs(_swivel_deg(q, refined, side, sk)) < 2.0, (side, deg)
            assert diag[side].hand_offset_after_mm < 2.0


def test_arm_shape_scores_a_hand_only_where_it_has_a_bone():
    from mocapkit.tracking.hybrid.arm_refinement import arm_shape

    zhang, azad = SKEL, load_preset("azad14")
    assert arm_shape(zhang, "left", (0.0, 0.0, 0.0)).n_segments == 3
    assert arm_shape(zhang, "left", (0.0, 0.0, 0.0), include_hand=False).n_segments == 2
    assert arm_shape(azad, "right", (0.0, 0.0, 0.0)).n_segments == 2  # azad14's hand is a point
    with pytest.raises(UnknownNameError, match="unknown arm side 'up'"):
        arm_shape(zhang, "up", (0.0, 0.0, 0.0))


def test_arms_that_the_refinement_cannot_take_raise():
    from mocapkit.skeleton.serialize import skeleton_from_dict, skeleton_to_dict
    from mocapkit.tracking.hybrid.arm_refinement import arm_limb

    def moved(**canonical: str):
        data = skeleton_to_dict(SKEL)
        for name, joint in canonical.items():
            data["canonical"][name] = {"joint": joint, "point_mm": [0.0, 0.0, 0.0]}
        return skeleton_from_dict(data)

    with pytest.raises(ShapeError, match="without joints between"):
        arm_limb(moved(left_wrist="l_hand_end"), "left")
    shifted = moved(left_shoulder="l_radius", left_elbow="l_hand", left_wrist="l_hand_end")
    with pytest.raises(ShapeError, match=r"3 rotational DoFs at 'l_radius'.*found \[1, 0, 0\]"):
        arm_limb(shifted, "left")
