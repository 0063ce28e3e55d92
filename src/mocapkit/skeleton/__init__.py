"""Body models: the frozen `Skeleton`, presets, scaling, kinematics and mass properties."""

from mocapkit.skeleton.kinematics import (
    canonical_positions,
    carried_mass,
    center_of_mass,
    forward_kinematics,
    jacobian,
    joint_positions,
    points_and_jacobian,
    points_on_joints,
    segment_com,
    subtree_com,
    subtree_mass,
)
from mocapkit.skeleton.model import (
    BALL,
    CANONICAL_JOINTS,
    CANONICAL_SEGMENTS,
    PRISMATIC,
    REVOLUTE,
    TRUNK_SEGMENTS,
    UPPER_BODY_JOINTS,
    Skeleton,
)
from mocapkit.skeleton.presets import load_preset, preset_names, preset_options
from mocapkit.skeleton.scaling import (
    fit_segments,
    scale_skeleton,
    segment_lengths_mm,
    segment_vectors_mm,
    standing_height_mm,
)

__all__ = [
    "BALL",
    "CANONICAL_JOINTS",
    "CANONICAL_SEGMENTS",
    "PRISMATIC",
    "REVOLUTE",
    "TRUNK_SEGMENTS",
    "UPPER_BODY_JOINTS",
    "Skeleton",
    "canonical_positions",
    "carried_mass",
    "center_of_mass",
    "fit_segments",
    "forward_kinematics",
    "jacobian",
    "joint_positions",
    "load_preset",
    "points_and_jacobian",
    "points_on_joints",
    "preset_names",
    "preset_options",
    "scale_skeleton",
    "segment_com",
    "segment_lengths_mm",
    "segment_vectors_mm",
    "standing_height_mm",
    "subtree_com",
    "subtree_mass",
]
