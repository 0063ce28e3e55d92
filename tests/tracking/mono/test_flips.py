"""Flip enumeration and pruning (Mamania et al. 2004 §4.2; errata M5; tests M)."""

import numpy as np
import pytest

from mocapkit.errors import ConfigError, ShapeError
from mocapkit.tracking.mono.flips import count_candidates, enumerate_poses, violates
from mocapkit.tracking.mono.stick import LimitConfig, stick_model
from mocapkit.tracking.mono.tracker import MonoConfig
from tests.tracking.mono.conftest import random_pose


def _orthographic(pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Image-plane positions and the root with z measured from the neck."""
    root = pos[0].copy()
    root[2] = 0.0
    return pos[:, :2], root


def _observed(pos: np.ndarray, perspective: bool) -> tuple[np.ndarray, np.ndarray]:
    """What the enumeration sees of ``pos``: normalised image points and the root under
    perspective, else `_orthographic`'s."""
    if perspective:
        return pos[:, :2] / pos[:, 2:], pos[0]
    return _orthographic(pos)


def _relative(pos: np.ndarray) -> np.ndarray:
    out = pos.copy()
    out[..., 2] -= pos[..., :1, 2]
    return out


@pytest.mark.parametrize("legs", [False, True])
def test_exactly_two_to_the_links_poses_with_equal_projections(legs: bool) -> None:
    rng = np.random.default_rng(10)
    model = stick_model(legs=legs)
    pos, lengths = random_pose(rng, model, 40.0)
    obs, root = _orthographic(pos)
    fp = enumerate_poses(model, lengths, obs, root, prune=False)
    n = 1 << model.n_links
    assert fp.codes.shape == (n,) and len(set(fp.codes.tolist())) == n
    assert fp.n_candidates == n
    flat = fp.positions.reshape(n, -1)
    assert len({tuple(np.round(r, 6)) for r in flat}) == n  # distinct poses
    np.testing.assert_allclose(fp.positions[:, :, :2], np.broadcast_to(obs, (n, *obs.shape)))
    np.testing.assert_allclose(
        np.linalg.norm(model.link_vectors(fp.positions), axis=-1),
        np.broadcast_to(lengths, (n, model.n_links)),
    )
    err = np.abs(fp.positions - _relative(pos)).max(axis=(1, 2))
    assert err.min() < 1e-9


def test_a_link_parallel_to_the_image_halves_the_count() -> None:
    """Errata M5: one link with dz = 0 gives 2^(L-1) distinct poses, not duplicates."""
    rng = np.random.default_rng(11)
    model = stick_model()
    pos, lengths = random_pose(rng, model, 40.0)
    i = model.link_index("left_upper_arm")
    p, c = model.parent[i], model.child[i]
    shift = pos[p, 2] - pos[c, 2]
    below = [c] + [int(model.child[j]) for j in range(model.n_links) if model.parent[j] == c]
    pos[below, 2] += shift  # the upper arm now lies in a plane parallel to the image
    lengths = lengths.copy()
    lengths[i] = np.linalg.norm(pos[c, :2] - pos[p, :2])
    obs, root = _orthographic(pos)
    fp = enumerate_poses(model, lengths, obs, root, prune=False)
    half = 1 << (model.n_links - 1)
    assert fp.codes.shape == (half,) and fp.n_candidates == half
    assert not np.any(fp.codes & (1 << i))
    assert len({tuple(np.round(r, 6)) for r in fp.positions.reshape(half, -1)}) == half
    assert np.abs(fp.positions - _relative(pos)).max(axis=(1, 2)).min() < 1e-6


def _ray_distance(pos: np.ndarray, p: int, c: int, perspective: bool) -> float:
    """Distance from joint p to joint c's viewing ray (perspective) or projection line."""
    if not perspective:
        return float(np.linalg.norm(pos[c, :2] - pos[p, :2]))
    ray = pos[c] / np.linalg.norm(pos[c])
    return float(np.linalg.norm(np.cross(pos[p], ray)))


def _shortened_link(rng: np.random.Generator, model, name: str, ratio: float, perspective: bool):  # type: ignore[no-untyped-def]
    """A random pose with link ``name`` in a plane parallel to the image and every other
    link 30 deg out of it (towards or away at random), the link's length set to ``ratio``
    times its parent's distance to the child's ray."""
    pos, lengths = random_pose(rng, model, 30.0)
    i = model.link_index(name)
    for j in range(model.n_links):  # links are ordered parents first
        p, c = model.parent[j], model.child[j]
        d = pos[c, :2] - pos[p, :2]
        d /= np.linalg.norm(d)
        sine = 0.0 if j == i else 0.5 * rng.choice([-1.0, 1.0])
        step = lengths[j] * np.array([*(np.sqrt(1.0 - sine**2) * d), sine])
        below = [c] + [int(model.child[k]) for k in range(j + 1, model.n_links)
                       if model.parent[k] == c]  # fmt: skip
        pos[below] += pos[p] + step - pos[c]  # the subtree moves with the child
    lengths = lengths.copy()
    lengths[i] = ratio * _ray_distance(pos, model.parent[i], model.child[i], perspective)
    return pos, lengths, i


@pytest.mark.parametrize("perspective", [False, True])
def test_reach_tolerance_keeps_both_flips_of_a_link_just_too_short(perspective: bool) -> None:
    """A link 3 % shorter than its parent's distance D to its child's ray: errata M5 gives
    it one configuration; with ``reach_tolerance`` 0.05 it keeps two, the child on its ray
    at the band's length L + (D - 0.95 L) / 2 = 1.04 L from its parent, the other links
    (30 deg out of the image plane, outside the band) unchanged. Beyond the band
    (tolerance 0.02) M5 holds. Orthographic: 2^(L-1) poses become 2^L."""
    rng = np.random.default_rng(17)
    model = stick_model()
    pos, lengths, i = _shortened_link(rng, model, "left_upper_arm", 1.0 / 1.03, perspective)
    p, c = model.parent[i], model.child[i]
    obs, root = _observed(pos, perspective)
    parent_true = pos[p] if perspective else _relative(pos)[p]
    kw = {"perspective": perspective, "prune": False}
    bit = 1 << i
    m5 = enumerate_poses(model, lengths, obs, root, **kw)
    narrow = enumerate_poses(model, lengths, obs, root, reach_tolerance=0.02, **kw)
    fp = enumerate_poses(model, lengths, obs, root, reach_tolerance=0.05, **kw)
    np.testing.assert_array_equal(narrow.codes, m5.codes)
    np.testing.assert_array_equal(narrow.positions, m5.positions)
    at = [np.abs(f.positions[:, p] - parent_true).max(axis=1) < 1e-6 for f in (m5, fp)]
    # where the link's parent is the truth's (its clavicle's true flip): one flip, then two
    assert not np.any(m5.codes[at[0]] & bit)
    assert at[1].sum() == 2 * at[0].sum() > 0
    assert (fp.codes[at[1]] & bit != 0).sum() == at[0].sum()
    if not perspective:
        n = 1 << model.n_links
        assert m5.codes.shape == (n // 2,) and m5.n_candidates == n // 2
        assert fp.codes.shape == (n,) and fp.n_candidates == n
        assert len(set(fp.codes.tolist())) == n
        np.testing.assert_allclose(fp.positions[:, c, :2], np.broadcast_to(obs[c], (n, 2)))
    else:  # the child lies on its ray
        ray = np.append(obs[c], 1.0) / np.linalg.norm(np.append(obs[c], 1.0))
        np.testing.assert_allclose(np.cross(fp.positions[at[1], c], ray), 0.0, atol=1e-6)
    vec = model.link_vectors(fp.positions[at[1]])
    np.testing.assert_allclose(np.linalg.norm(vec[:, i], axis=-1), 1.04 * lengths[i], rtol=1e-9)
    others = [j for j in range(model.n_links) if j != i]
    np.testing.assert_allclose(
        np.linalg.norm(vec[:, others], axis=-1),
        np.broadcast_to(lengths[others], (vec.shape[0], len(others))),
        rtol=1e-9,
    )
    # bit set: the far configuration (the child deeper than with the bit clear)
    sub = fp.codes[at[1]]
    z = fp.positions[at[1], c, 2]
    order_near = np.argsort(sub & ~bit, kind="stable")
    near = z[order_near][~(sub[order_near] & bit).astype(bool)]
    far = z[order_near][(sub[order_near] & bit).astype(bool)]
    assert near.shape == far.shape and np.all(near < far)


def test_reach_tolerance_is_refused_outside_its_range() -> None:
    with pytest.raises(ConfigError, match="reach_tolerance: expected"):
        MonoConfig(reach_tolerance=-0.01)
    with pytest.raises(ConfigError, match="reach_tolerance: expected"):
        MonoConfig(reach_tolerance=1.0)


def test_perspective_candidates_share_the_rays_and_include_the_truth() -> None:
    rng = np.random.default_rng(12)
    model = stick_model()
    pos, lengths = random_pose(rng, model, 40.0)
    rays = pos[:, :2] / pos[:, 2:]
    fp = enumerate_poses(model, lengths, rays, pos[0], perspective=True, prune=False)
    assert 1 <= fp.codes.shape[0] <= 1 << model.n_links
    two = np.abs(fp.positions - pos).max(axis=(1, 2))
    assert two.min() < 1e-6
    np.testing.assert_allclose(
        np.linalg.norm(model.link_vectors(fp.positions), axis=-1),
        np.broadcast_to(lengths, (fp.codes.shape[0], model.n_links)),
    )
    # every joint whose link has two solutions lies on its own viewing ray
    truth_like = fp.positions[np.argmin(two)]
    np.testing.assert_allclose(truth_like[:, :2] / truth_like[:, 2:], rays, atol=1e-9)


@pytest.mark.parametrize("reach", [0.0, 0.08])
@pytest.mark.parametrize("legs", [False, True])
@pytest.mark.parametrize("perspective", [False, True])
def test_pruning_during_the_search_equals_pruning_after_it(
    legs: bool, perspective: bool, reach: float
) -> None:
    """Also with a reach tolerance, the lengths then 4 % short so that some links use it."""
    rng = np.random.default_rng(13)
    model = stick_model(legs=legs)
    kept_some = pruned_some = 0
    for _ in range(30):
        pos, lengths = random_pose(rng, model, 35.0)
        if reach > 0:
            lengths = 0.96 * lengths
        obs, root = _observed(pos, perspective)
        kw = {"perspective": perspective, "reach_tolerance": reach}
        full = enumerate_poses(model, lengths, obs, root, prune=False, **kw)
        during = enumerate_poses(model, lengths, obs, root, prune=True, **kw)
        ok = ~violates(model, lengths, full.positions)
        if not ok.any():
            assert during.pruned_all
            continue
        assert not during.pruned_all
        assert sorted(during.codes.tolist()) == sorted(full.codes[ok].tolist())
        order = np.argsort(during.codes)
        np.testing.assert_array_equal(
            during.positions[order], full.positions[ok][np.argsort(full.codes[ok])]
        )
        kept_some += 1
        pruned_some += int((~ok).sum() > 0)
    assert kept_some >= 10 and pruned_some >= 5


def test_joint_limits_known_values() -> None:
    """An elbow folded to 20 deg is pruned; at 40 deg it is kept (limit 30 deg)."""
    model = stick_model(limits=LimitConfig(collisions=False))
    rng = np.random.default_rng(14)
    pos, lengths = random_pose(rng, model, 0.0)
    i_up, i_fo = model.link_index("left_upper_arm"), model.link_index("left_forearm")
    elbow, wrist = model.child[i_up], model.child[i_fo]
    up = pos[elbow] - pos[model.parent[i_up]]
    up /= np.linalg.norm(up)
    side = np.cross(up, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    for included_deg, bad in ((20.0, True), (40.0, False)):
        a = np.radians(180.0 - included_deg)  # angle between upper arm and forearm
        fore = np.cos(a) * up + np.sin(a) * side
        p = pos.copy()
        p[wrist] = p[elbow] + lengths[i_fo] * fore
        assert violates(model, lengths, p[None])[0] == bad


def test_capsules_prune_a_forearm_through_the_trunk() -> None:
    model = stick_model()
    rng = np.random.default_rng(15)
    pos, lengths = random_pose(rng, model, 0.0)
    assert not violates(model, lengths, pos[None])[0]
    i_fo = model.link_index("left_forearm")
    p = pos.copy()
    mid = 0.5 * (pos[0] + pos[model.child[model.link_index("trunk")]])
    d = mid - p[model.parent[i_fo]]
    p[model.child[i_fo]] = p[model.parent[i_fo]] + lengths[i_fo] * d / np.linalg.norm(d)
    if np.linalg.norm(d) <= lengths[i_fo]:
        assert violates(model, lengths, p[None])[0]


def test_a_missing_joint_drops_its_subtree() -> None:
    rng = np.random.default_rng(16)
    model = stick_model()
    pos, lengths = random_pose(rng, model, 30.0)
    obs, root = _orthographic(pos)
    obs = obs.copy()
    elbow = model.joint_names.index("right_elbow")
    obs[elbow] = np.nan
    fp = enumerate_poses(model, lengths, obs, root, prune=False)
    assert fp.codes.shape == (1 << (model.n_links - 2),)
    wrist = model.joint_names.index("right_wrist")
    assert np.isnan(fp.positions[:, [elbow, wrist]]).all()
    assert count_candidates(model, lengths, obs, root) == fp.codes.shape[0]


def test_bad_inputs_are_refused() -> None:
    model = stick_model()
    with pytest.raises(ShapeError, match="positive lengths"):
        enumerate_poses(model, np.ones(3), np.zeros((model.n_joints, 2)), np.zeros(3))
    with pytest.raises(ShapeError, match="observed"):
        enumerate_poses(model, np.ones(model.n_links), np.zeros((4, 2)), np.zeros(3))


def test_reach_tolerance_per_link_widens_only_its_links() -> None:
    """A band per link (L,): the shortened link keeps both flips only where its own entry
    covers it; the same share for every link equals the scalar; a wrong length is refused."""
    rng = np.random.default_rng(23)
    model = stick_model()
    pos, lengths, i = _shortened_link(rng, model, "left_upper_arm", 1.0 / 1.03, False)
    obs, root = _orthographic(pos)
    kw = {"perspective": False, "prune": False}
    n = 1 << model.n_links
    scalar = enumerate_poses(model, lengths, obs, root, reach_tolerance=0.05, **kw)
    same = enumerate_poses(model, lengths, obs, root, reach_tolerance=np.full(8, 0.05), **kw)
    np.testing.assert_array_equal(same.codes, scalar.codes)
    np.testing.assert_array_equal(same.positions, scalar.positions)
    only = np.zeros(model.n_links)
    only[i] = 0.05
    fp = enumerate_poses(model, lengths, obs, root, reach_tolerance=only, **kw)
    assert fp.codes.shape == (n,) and fp.n_candidates == n
    other = np.full(model.n_links, 0.05)
    other[i] = 0.0
    m5 = enumerate_poses(model, lengths, obs, root, reach_tolerance=other, **kw)
    assert m5.codes.shape == (n // 2,) and m5.n_candidates == n // 2
    with pytest.raises(ShapeError, match=r"reach_tolerance: expected a number or \(8,\)"):
        enumerate_poses(model, lengths, obs, root, reach_tolerance=np.zeros(3), **kw)


@pytest.mark.parametrize("perspective", [False, True])
def test_fixed_joints_give_the_full_searchs_poses_with_that_upper_body(perspective: bool) -> None:
    """The legs enumerated below a fixed upper-body pose are exactly the poses of the full
    search (all 14 links, pruned) that have that upper body; the capacity is 2^6."""
    rng = np.random.default_rng(31)
    model = stick_model(legs=True)
    upper = stick_model()
    tested = 0
    for _ in range(20):
        pos, lengths = random_pose(rng, model, 35.0)
        obs, root = _observed(pos, perspective)
        kw = {"perspective": perspective}
        full = enumerate_poses(model, lengths, obs, root, **kw)
        if full.pruned_all:
            continue
        mask = (1 << upper.n_links) - 1
        pick = full.codes[int(rng.integers(full.codes.shape[0]))] & mask
        fixed = np.full((model.n_joints, 3), np.nan)
        fixed[: upper.n_joints] = full.positions[np.flatnonzero((full.codes & mask) == pick)[0]][
            : upper.n_joints
        ]
        legs = enumerate_poses(model, lengths, obs, root, fixed=fixed, **kw)
        same = (full.codes & mask) == pick
        assert not legs.pruned_all
        assert sorted((legs.codes | pick).tolist()) == sorted(full.codes[same].tolist())
        order = np.argsort(full.codes[same])
        np.testing.assert_allclose(
            legs.positions[np.argsort(legs.codes)], full.positions[same][order], atol=1e-9
        )
        assert legs.n_candidates <= 1 << 6
        tested += 1
    assert tested >= 5
    with pytest.raises(ShapeError, match=r"fixed: expected \(15, 3\) joints"):
        enumerate_poses(model, lengths, obs, root, fixed=np.zeros((3, 3)))
