"""Exact tier: the truth against the Jacobi-elliptic closed form and the
conservation laws of a torque-free body (the workshop model, "Truth")."""
import numpy as np
import pytest

from dynamics.rigid_body import (
    angular_momentum_body,
    closed_form_body_rates,
    kinetic_energy,
    simulate_torque_free,
)
from dynamics.quaternion import rotation_matrix
from dynamics.validation import InvalidParameterError, inertia_tensor

TIME_S = np.arange(5001) * 0.01


@pytest.mark.parametrize("moments, omega0", [
    ([1.0, 2.0, 3.0], [0.05, 0.05, 0.0]),      # the workshop tumble (M² < 2 E I_mid)
    ([1.0, 2.0, 3.0], [0.01, 0.02, 0.1]),      # about the major axis (M² > 2 E I_mid)
    ([3.0, 1.0, 2.0], [-0.03, 0.02, -0.1]),    # axes in another order, negative rates
])
def test_rates_match_jacobi_elliptic_closed_form(moments, omega0):
    truth = simulate_torque_free(np.diag(moments), [1, 0, 0, 0], omega0, TIME_S)
    exact = closed_form_body_rates(moments, omega0, TIME_S)
    assert np.allclose(exact[0], omega0, atol=1e-15)
    # 1e-10 rad/s is 1e-9 of the rates: the integrator is held to rtol 1e-12.
    assert np.max(np.abs(truth.omega_true_radps - exact)) < 1e-10


def test_closed_form_parameter_is_the_textbook_one():
    # Landau & Lifshitz §37: k² = (I3-I2)(M²-2E I1) / ((I2-I1)(2E I3-M²)) = 0.5 for the
    # workshop tumble, so the rates have the period 4 K(0.5) / λ.
    moments, omega0 = np.array([1.0, 2.0, 3.0]), np.array([0.05, 0.05, 0.0])
    two_e, m_sq = np.sum(moments * omega0**2), np.sum((moments * omega0) ** 2)
    k_sq = (3 - 2) * (m_sq - two_e * 1) / ((2 - 1) * (two_e * 3 - m_sq))   # 0.5 here
    from scipy.special import ellipk
    rate = np.sqrt((3 - 2) * (two_e * 3 - m_sq) / (1 * 2 * 3))
    period = 4 * ellipk(k_sq) / rate
    t = np.array([0.0, period / 2, period])
    rates = closed_form_body_rates(moments, omega0, t)
    assert np.allclose(rates[2], rates[0], atol=1e-15)
    # ...and not a shorter one: half a period on, the rate about the
    # intermediate axis has turned sign (dn's and cn's half periods).
    assert np.allclose(rates[1], [0.05, -0.05, 0.0], atol=1e-12)


def test_invariants_conserved_and_quaternion_unit():
    inertia = np.diag([1.0, 2.0, 3.0])
    truth = simulate_torque_free(inertia, [1, 0, 0, 0], [0.05, 0.05, 0.0], TIME_S)
    energy = kinetic_energy(inertia, truth.omega_true_radps)
    momentum_norm = np.linalg.norm(angular_momentum_body(inertia, truth.omega_true_radps), axis=1)
    assert np.max(np.abs(energy / energy[0] - 1)) < 1e-9
    assert np.max(np.abs(momentum_norm / momentum_norm[0] - 1)) < 1e-9
    assert np.max(np.abs(np.linalg.norm(truth.q_true, axis=1) - 1)) < 1e-12


def test_inertial_angular_momentum_is_fixed_so_attitude_is_right():
    # H_ref = R(q) I ω is constant only if the attitude kinematics are integrated correctly.
    inertia = np.array([[2.0, 0.1, 0.0], [0.1, 2.5, 0.2], [0.0, 0.2, 3.0]])
    truth = simulate_torque_free(inertia, [0.9, 0.1, -0.3, 0.2], [0.1, -0.2, 0.3], TIME_S)
    h_body = angular_momentum_body(inertia, truth.omega_true_radps)
    h_ref = np.einsum("nij,nj->ni", rotation_matrix(truth.q_true), h_body)
    assert np.max(np.abs(h_ref - h_ref[0])) < 1e-9 * np.linalg.norm(h_ref[0])


@pytest.mark.parametrize("value, rule", [
    ([[1, 0.5, 0], [0, 2, 0], [0, 0, 3]], "symmetric"),
    ([1.0, -2.0, 3.0], "positive definite"),
    ([1.0, 1.0, 3.0], "triangle inequality"),
    ([1.0, 2.0], "3x3 matrix"),
])
def test_unphysical_inertia_rejected(value, rule):
    with pytest.raises(InvalidParameterError, match=rule):
        inertia_tensor("inertia_tensor_kg_m2", value)
