"""Forward kinematics, Jacobians and mass properties over batches."""

from __future__ import annotations

import numpy as np
import pytest

from mocapkit.errors import ShapeError
from mocapkit.geometry import matrix_from_rotvec
from mocapkit.skeleton import (
    carried_mass,
    center_of_mass,
    forward_kinematics,
    jacobian,
    joint_positions,
    load_preset,
    points_and_jacobian,
    points_on_joints,
    subtree_com,
    subtree_mass,
)

CASES = [
    ("zhang21", ("root_rotation",), ["head", "l_hand_end", "r_hand_end", "l_foot", "r_foot"]),
    (
        "zhang21",
        ("root_rotation", "clavicle", "spine_rotation", "neck_rotation"),
        ["head_end", "l_hand_end", "r_hand_end", "l_foot", "r_foot"],
    ),
    ("azad14", ("adaptive_shoulder",), ["l_hand", "r_hand", "head_end"]),
    ("upper_stick", (), ["l_wrist", "r_wrist", "head_end"]),
]


def _random_pose(sk, rng, shape):  # type: ignore[no-untyped-def]
    lo = np.clip(sk.lower, -1.2, 1.2)
    hi = np.clip(sk.upper, -1.2, 1.2)
    q = rng.uniform(lo, hi, size=(*shape, sk.n_dofs))
    pris = sk.dof_kind == 1
    q[..., pris] = rng.normal(size=(*shape, int(pris.sum()))) * 40
    return q


@pytest.mark.parametrize(("name", "options", "targets"), CASES)
def test_jacobian_matches_central_differences(name, options, targets, rng) -> None:  # type: ignore[no-untyped-def]
    sk = load_preset(name, options)
    q = _random_pose(sk, rng, (3,))
    points_in_joint = rng.normal(size=(len(targets), 3)) * 30
    pts, jac = points_and_jacobian(sk, q, targets, points_in_joint)
    np.testing.assert_allclose(pts, points_on_joints(sk, q, targets, points_in_joint), atol=1e-9)
    eps = 1e-6
    numeric = np.empty_like(jac)
    for d in range(sk.n_dofs):
        dq = np.zeros(sk.n_dofs)
        dq[d] = eps
        plus = points_on_joints(sk, q + dq, targets, points_in_joint)
        minus = points_on_joints(sk, q - dq, targets, points_in_joint)
        numeric[..., d] = ((plus - minus) / (2 * eps)).reshape(3, -1)
    scale = max(1.0, float(np.abs(numeric).max()))
    np.testing.assert_allclose(jac, numeric, atol=1e-6 * scale)


def test_batch_shapes_and_consistency(rng: np.random.Generator) -> None:
    sk = load_preset("zhang21")
    q = _random_pose(sk, rng, (2, 5))
    world = forward_kinematics(sk, q)
    assert world.shape == (2, 5, sk.n_joints, 4, 4)
    single = forward_kinematics(sk, q[1, 3])
    np.testing.assert_allclose(world[1, 3], single, atol=1e-12)
    assert jacobian(sk, q, ["head"]).shape == (2, 5, 3, sk.n_dofs)
    rot = world[..., :3, :3]
    np.testing.assert_allclose(
        rot @ np.swapaxes(rot, -1, -2), np.broadcast_to(np.eye(3), rot.shape), atol=1e-12
    )


def test_known_values_elbow_and_root() -> None:
    sk = load_preset("zhang21")
    q = sk.zero_pose()
    q[sk.dof_index("root_tx")] = 100.0
    q[sk.dof_index("r_elbow_flexion")] = np.pi / 2
    p = joint_positions(sk, q)
    elbow = p[sk.joint_index("r_radius")]
    wrist = p[sk.joint_index("r_hand")]
    np.testing.assert_allclose(wrist - elbow, [0, 350, 0], atol=1e-9)  # forearm points forward
    assert p[sk.joint_index("root")][0] == pytest.approx(100.0)


def test_ball_joint_is_rotation_vector() -> None:
    sk = load_preset("azad14")
    q = sk.zero_pose()
    rv = np.array([0.4, -0.2, 0.9])
    d = sk.dof_index("l_shoulder_rx")
    q[d : d + 3] = rv
    p = joint_positions(sk, q)
    upper_arm = p[sk.joint_index("l_elbow")] - p[sk.joint_index("l_shoulder")]
    np.testing.assert_allclose(upper_arm, matrix_from_rotvec(rv) @ [0, 0, -300], atol=1e-9)


def test_mass_properties() -> None:
    sk = load_preset("zhang21")
    m = subtree_mass(sk)
    assert m[0] == pytest.approx(sk.total_mass_kg)
    arm = sum(sk.mass_kg[sk.joint_index(n)] for n in ("l_humerus", "l_radius", "l_hand"))
    assert m[sk.joint_index("l_humerus")] == pytest.approx(arm)
    cm = carried_mass(sk)
    assert cm[sk.dof_index("l_elbow_flexion")] == pytest.approx(1.31 + 0.52)
    assert cm[sk.dof_index("root_tz")] == pytest.approx(sk.total_mass_kg)
    com = center_of_mass(sk, sk.zero_pose())
    assert com[0] == pytest.approx(0.0, abs=1e-9)  # left-right symmetric
    sub = subtree_com(sk, sk.zero_pose())
    np.testing.assert_allclose(sub[0], com, atol=1e-9)


def test_bad_q_rejected() -> None:
    sk = load_preset("zhang21")
    with pytest.raises(ShapeError, match=r"expected joint parameters of shape \(\.\.\., 24\)"):
        forward_kinematics(sk, np.zeros(5))
    q = sk.zero_pose()
    q[3] = np.nan
    with pytest.raises(ShapeError, match="NaN"):
        joint_positions(sk, q)
    with pytest.raises(ShapeError, match=r"points_in_joint: expected shape \(1, 3\)"):
        jacobian(sk, sk.zero_pose(), ["head"], np.zeros((2, 3)))


def test_kernel_layout_cache_does_not_keep_skeletons_alive() -> None:
    import gc
    import weakref

    from mocapkit.skeleton.kinematics import _KINEMATIC_ARRAYS

    sk = load_preset("upper_stick")
    joint_positions(sk, sk.zero_pose())
    assert sk in _KINEMATIC_ARRAYS
    alive = weakref.ref(sk)
    del sk
    gc.collect()
    assert alive() is None  # the cache alone does not keep the skeleton


@pytest.mark.parametrize("name", ["zhang21", "azad14", "upper_stick"])
def test_kinematic_arrays_is_one_read_only_kernel_argument(name: str) -> None:
    from mocapkit.skeleton.kinematics import fk_pose_nb, kinematic_arrays

    sk = load_preset(name)
    kin = kinematic_arrays(sk)
    assert kinematic_arrays(sk) is kin  # cached per skeleton
    assert isinstance(kin, tuple) and kin._fields[0] == "parents"
    j, d = sk.n_joints, sk.n_dofs
    assert kin.offsets.shape == (j, 3) and kin.ancestors.shape == (j, j)
    assert kin.dof_axis.shape == (d, 3) and kin.dof_joint.shape == (d,)
    np.testing.assert_array_equal(np.repeat(np.arange(j), kin.dof_count), kin.dof_joint)
    np.testing.assert_array_equal(kin.dof_start + kin.dof_count, np.cumsum(kin.dof_count))
    for field in kin:
        assert field.flags.c_contiguous and not field.flags.writeable
    # the compiled kernel takes the whole layout as one argument
    q = sk.zero_pose() + 0.1
    world = np.empty((j, 4, 4))
    fk_pose_nb(q, kin, world, np.empty((d, 3)), np.empty((d, 3)))
    np.testing.assert_array_equal(world, forward_kinematics(sk, q))


@pytest.mark.parametrize("name", ["zhang21", "azad14"])
def test_center_of_mass_jacobian_matches_central_differences(name, rng) -> None:  # type: ignore[no-untyped-def]
    from mocapkit.skeleton.kinematics import center_of_mass_jacobian

    sk = load_preset(name)
    q = _random_pose(sk, rng, ())
    com, jac = center_of_mass_jacobian(sk, q)
    np.testing.assert_allclose(com, center_of_mass(sk, q), atol=1e-9)
    assert jac.shape == (3, sk.n_dofs)
    eps = 1e-6
    numeric = np.empty_like(jac)
    for d in range(sk.n_dofs):
        dq = np.zeros(sk.n_dofs)
        dq[d] = eps
        numeric[:, d] = (center_of_mass(sk, q + dq) - center_of_mass(sk, q - dq)) / (2 * eps)
    scale = max(1.0, float(np.abs(numeric).max()))
    np.testing.assert_allclose(jac, numeric, atol=1e-6 * scale)
    # the root translations move the whole mass: identity columns
    for axis, dof in enumerate(("root_tx", "root_ty", "root_tz")):
        if dof in sk.dof_names:
            np.testing.assert_allclose(jac[:, sk.dof_index(dof)], np.eye(3)[axis], atol=1e-12)
    with pytest.raises(ShapeError, match="q: expected shape"):
        center_of_mass_jacobian(sk, np.zeros(sk.n_dofs + 1))
