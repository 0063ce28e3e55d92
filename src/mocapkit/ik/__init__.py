"""Inverse kinematics solvers on the shared skeleton model."""
