"""Truth and quaternion mathematics.

This package is the bottom of the dependency graph: ``sensors`` and
``estimators`` use it, and it uses nothing of the project.

Conventions (declared once, here): quaternions are scalar-first
``[w, x, y, z]`` with the Hamilton product and unit norm; body rates are in
rad/s in the body frame; the kinematics are ``q_dot = 0.5 * q ⊗ [0, ω]``.
"""
from dynamics.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    "quaternion": ("IDENTITY", "attitude_error_rad", "attitude_error_vector_rad", "from_rotation",
                   "grp_from_quat", "kinematics_matrix", "normalize", "quat_conjugate",
                   "quat_from_grp", "quat_from_rotvec", "quat_multiply", "relative_rotation",
                   "rotation_matrix", "rotvec_from_quat", "skew", "to_rotation"),
    "rigid_body": ("RigidBodyTruth", "angular_momentum_body", "closed_form_body_rates",
                   "kinetic_energy", "simulate_torque_free"),
    "validation": ("InvalidParameterError",),
})
