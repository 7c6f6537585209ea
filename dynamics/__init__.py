"""Truth and quaternion mathematics.

This package is the bottom of the dependency graph: ``sensors`` and
``estimators`` use it, and it uses nothing of the project.

Conventions (declared once, here): quaternions are scalar-first
``[w, x, y, z]`` with the Hamilton product and unit norm; body rates are in
rad/s in the body frame; the kinematics are ``q_dot = 0.5 * q ⊗ [0, ω]``.
"""
from dynamics.quaternion import (
    IDENTITY,
    attitude_error_rad,
    attitude_error_vector_rad,
    from_rotation,
    grp_from_quat,
    kinematics_matrix,
    normalize,
    quat_conjugate,
    quat_from_grp,
    quat_from_rotvec,
    quat_multiply,
    relative_rotation,
    rotation_matrix,
    rotvec_from_quat,
    skew,
    to_rotation,
)
from dynamics.rigid_body import (
    RigidBodyTruth,
    angular_momentum_body,
    closed_form_body_rates,
    kinetic_energy,
    simulate_torque_free,
)
from dynamics.validation import InvalidParameterError

__all__ = [
    "IDENTITY",
    "InvalidParameterError",
    "RigidBodyTruth",
    "angular_momentum_body",
    "attitude_error_rad",
    "attitude_error_vector_rad",
    "closed_form_body_rates",
    "from_rotation",
    "grp_from_quat",
    "kinematics_matrix",
    "kinetic_energy",
    "normalize",
    "quat_conjugate",
    "relative_rotation",
    "quat_from_grp",
    "quat_from_rotvec",
    "quat_multiply",
    "rotation_matrix",
    "rotvec_from_quat",
    "simulate_torque_free",
    "skew",
    "to_rotation",
]
