"""Exact tier: the quaternion convention against scipy's Rotation."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import random_unit_quaternions
from dynamics.quaternion import (
    attitude_error_rad,
    from_rotation,
    kinematics_matrix,
    normalize,
    quat_conjugate,
    quat_multiply,
    rotation_matrix,
    to_rotation,
)


def test_hamilton_product_composes_like_rotations(rng):
    qa, qb = random_unit_quaternions(rng, 50), random_unit_quaternions(rng, 50)
    composed = to_rotation(qa) * to_rotation(qb)
    assert np.allclose(rotation_matrix(quat_multiply(qa, qb)), composed.as_matrix(), atol=1e-14)


def test_product_of_basis_quaternions():
    i, j, k = np.eye(4)[1], np.eye(4)[2], np.eye(4)[3]
    assert np.array_equal(quat_multiply(i, j), k)      # Hamilton: ij = k
    assert np.array_equal(quat_multiply(j, i), -k)


def test_conjugate_is_inverse(rng):
    q = random_unit_quaternions(rng, 20)
    assert np.allclose(quat_multiply(q, quat_conjugate(q)), [1, 0, 0, 0], atol=1e-15)


def test_rotation_matrix_matches_scipy_and_rotates_body_to_reference(rng):
    q = random_unit_quaternions(rng, 30)
    assert np.allclose(rotation_matrix(q), Rotation.from_quat(q, scalar_first=True).as_matrix(),
                       atol=1e-14)
    # 90° about z takes body x to reference y.
    q_z90 = np.array([np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)])
    assert np.allclose(rotation_matrix(q_z90) @ [1, 0, 0], [0, 1, 0], atol=1e-15)


def test_scipy_round_trip_keeps_attitude(rng):
    q = random_unit_quaternions(rng, 40)
    back = from_rotation(to_rotation(q))
    assert np.allclose(np.abs(np.sum(back * q, axis=1)), 1.0, atol=1e-14)
    assert np.all(back[:, 0] >= 0)


def test_kinematics_matrix_is_half_product_with_pure_rate(rng):
    q = random_unit_quaternions(rng, 10)
    omega = rng.standard_normal((10, 3))
    pure = np.concatenate([np.zeros((10, 1)), omega], axis=1)
    assert np.allclose(np.einsum("nij,nj->ni", kinematics_matrix(q), omega),
                       quat_multiply(q, pure), atol=1e-15)


def test_attitude_error_is_sign_invariant_rotation_angle(rng):
    q = random_unit_quaternions(rng, 25)
    angle = rng.uniform(0, np.pi, 25)
    axis = normalize(rng.standard_normal((25, 3)))
    delta = np.concatenate([np.cos(angle / 2)[:, None], np.sin(angle / 2)[:, None] * axis], axis=1)
    q_est = quat_multiply(q, delta)
    assert np.allclose(attitude_error_rad(q, q_est), angle, atol=1e-7)
    assert np.allclose(attitude_error_rad(q, -q_est), angle, atol=1e-7)
    # arccos(1 - kε) ≈ √(2kε): a few ulps of rounding in the dot product give ~1e-7 rad.
    assert np.all(attitude_error_rad(q, q) < 1e-7)
    assert attitude_error_rad([1.0, 0, 0, 0], [1.0, 0, 0, 0]) == 0.0


@pytest.mark.parametrize("bad", [[1, 0, 0], [[1, 0, 0, 0, 0]]])
def test_wrong_shape_rejected_by_scipy_conversion(bad):
    with pytest.raises(ValueError, match="shape"):
        to_rotation(bad)
