"""Estimators: exact tier (Jacobian, step order, resets, discretisation) and
the shared interface."""
import math

import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter

from benchmarks import Scenario, simulate
from conftest import random_unit_quaternions
from estimators import (
    ESTIMATORS,
    AttitudeEstimator,
    DeadReckoning,
    DeadReckoningWithResets,
    QuaternionEKF,
)
from estimators.model import propagate, propagate_with_jacobian
from sensors.vector import VectorReadings


def central_difference_jacobian(func, q, step=1e-6):
    columns = []
    for i in range(4):
        dq = np.zeros(4)
        dq[i] = step
        columns.append((func(q + dq) - func(q - dq)) / (2 * step))
    return np.stack(columns, axis=1)


@pytest.mark.parametrize("scale", [1.0, 0.7, 1.3])   # off the unit sphere too, as in the EKF
def test_jacobian_matches_central_differences(rng, scale):
    for q in random_unit_quaternions(rng, 20) * scale:
        omega = rng.normal(0, 3.0, 3)   # large rates so the normalisation term matters
        dt = 0.05
        value, jacobian = propagate_with_jacobian(q, omega, dt)
        assert np.allclose(value, propagate(q, omega, dt), atol=1e-15)
        numeric = central_difference_jacobian(lambda x: propagate(x, omega, dt), q)
        # Central differences have O(h²) truncation and O(ε/h) rounding: ~1e-10 here.
        assert np.max(np.abs(jacobian - numeric)) < 1e-8


def test_jacobian_includes_the_normalisation():
    q, omega, dt = np.array([1.0, 0, 0, 0]), np.array([0.0, 0, 0]), 0.01
    _, jacobian = propagate_with_jacobian(q, omega, dt)
    # With zero rate f(q) = q/|q|: its Jacobian at [1,0,0,0] is I - e₀e₀ᵀ, not I.
    assert np.allclose(jacobian, np.diag([0.0, 1, 1, 1]), atol=1e-16)


def test_ekf_step_order_on_hand_computed_case():
    # x0 = [1,0,0,0], P0 = I, R = I, Q = e^0 I = I, zero rate, reading z = [0,1,0,0] at k = 0.
    ekf = QuaternionEKF(dt=0.01, pc_exponent=0.0, measurement_covariance=1.0,
                        initial_covariance=1.0)
    z = np.array([0.0, 1.0, 0.0, 0.0])
    q_hat0 = ekf.step(np.zeros(3), z)
    assert np.array_equal(q_hat0, [1.0, 0.0, 0.0, 0.0])        # the prior x̂[0|-1] is output
    # Update: K = P/(P+R) = ½ I, x⁺ = x0 + ½(z - x0) = [½, ½, 0, 0];
    # Joseph form P⁺ = (½)² I + (½)² I = ½ I.
    assert np.allclose(ekf.filter.x_post, [0.5, 0.5, 0, 0], atol=1e-15)
    assert np.allclose(ekf.filter.P_post, 0.5 * np.eye(4), atol=1e-15)
    # Predict with ω = 0: f(x⁺) = x⁺/|x⁺| = [1/√2, 1/√2, 0, 0]; F = (I - n nᵀ)/|x⁺| with
    # |x⁺| = 1/√2, so F P⁺ Fᵀ + Q = 2 · ½ (I - n nᵀ) + I.
    n = np.array([1, 1, 0, 0]) / math.sqrt(2)
    assert np.allclose(ekf.filter.x_prior, n, atol=1e-15)
    assert np.allclose(ekf.filter.P_prior, (np.eye(4) - np.outer(n, n)) + np.eye(4), atol=1e-14)
    # Step 1 outputs that prediction, before any correction.
    assert np.allclose(ekf.step(np.zeros(3)), n, atol=1e-15)


def test_ekf_posterior_output_option_returns_corrected_estimate():
    ekf = QuaternionEKF(pc_exponent=0.0, measurement_covariance=1.0, initial_covariance=1.0,
                        output="posterior")
    # The additive update gives x⁺ = [½, ½, 0, 0], off the unit sphere; the
    # attitude it estimates, and outputs, is its direction.
    assert np.allclose(ekf.step(np.zeros(3), np.array([0.0, 1, 0, 0])),
                       np.array([1, 1, 0, 0]) / math.sqrt(2), atol=1e-15)
    assert np.allclose(ekf.filter.x_post, [0.5, 0.5, 0, 0])


def test_ekf_is_filterpy_with_nonlinear_predict_and_1d_state(rng):
    ekf = QuaternionEKF(dt=0.01)
    assert isinstance(ekf.filter, ExtendedKalmanFilter)    # held, not inherited
    omega = np.array([0.3, -0.2, 0.1])
    x_before = np.array([0.9, 0.1, -0.2, 0.3])
    ekf.filter.x = x_before.copy()
    ekf.filter.predict(u=omega)
    assert ekf.filter.x.shape == (4,) and ekf.filter.x_prior.shape == (4,)
    assert np.allclose(ekf.filter.x, propagate(x_before, omega, 0.01), atol=1e-15)
    assert np.allclose(ekf.filter.F, central_difference_jacobian(
        lambda x: propagate(x, omega, 0.01), x_before), atol=1e-8)


def test_filters_hold_filterpy_and_expose_only_what_means_something():
    from estimators import ESTIMATORS
    for name in ("ekf", "mekf", "usque"):
        estimator = ESTIMATORS[name]()
        # filterpy's batch_filter and rts_smoother would run on the error state
        # without its reset: they are the filter's, not the estimator's.
        for method in ("batch_filter", "rts_smoother", "predict", "update"):
            assert not hasattr(estimator, method), (name, method)
        assert hasattr(estimator.filter, "predict") and hasattr(estimator.filter, "update")
        estimator.step(np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]))
        # A reading equal to the prediction: no innovation, and the NIS says so.
        assert estimator.innovation_nis == pytest.approx(0.0, abs=1e-12)
        assert estimator.innovation_dof == (4 if name == "ekf" else 3)


def test_the_ekf_takes_initial_attitude_and_its_former_name():
    q = np.array([0.0, 0.6, 0.0, 0.8])
    new, old = QuaternionEKF(initial_attitude=q), QuaternionEKF(initial_state=q)
    assert np.array_equal(new.attitude, old.attitude)
    assert np.allclose(new.attitude, q, rtol=0, atol=1e-15)
    assert not np.allclose(QuaternionEKF().attitude, q)


def test_resets_equal_the_reading_at_available_steps():
    result = simulate(Scenario(tstop=5.0), ["dead-reckoning-resets"], seed=4)
    available = result.sensors.available
    q_est = result.estimates["dead-reckoning-resets"]
    assert available.sum() == 26
    assert np.array_equal(q_est[available], result.sensors.star_tracker_quat[available])
    # Between readings it dead-reckons from the last one.
    k = 7
    q = q_est[0]
    for j in range(1, k + 1):
        q = propagate(q, result.sensors.omega_meas_radps[j], 0.01)
    assert np.allclose(q_est[k], q, atol=1e-15)


def dead_reckoning_error_rad(dt):
    scenario = Scenario(gyro_noise=0.0, star_tracker_noise=0.0, dt=dt)
    result = simulate(scenario, ["dead-reckoning"], seed=0)
    return result, np.radians(result.error_deg["dead-reckoning"])


def test_noiseless_dead_reckoning_error_is_small_and_first_order():
    # Bound: q̂[k] applies ω(t_0)…ω(t_k), each for dt, so it approximates the truth at
    # t_{k+1} (a one-step lead, ≤ |ω| dt) by a left Riemann product (≤ t |ω̇| dt / 2);
    # the Euler-and-normalise step's own error, |ω|³dt³/12 per step, is ~1e-11 here.
    #   e_k ≤ dt (max|ω| + t_k max|ω̇| / 2)
    result, error = dead_reckoning_error_rad(0.01)
    omega = result.truth.omega_true_radps
    omega_dot = np.diff(omega, axis=0) / 0.01
    bound = 0.01 * (np.linalg.norm(omega, axis=1).max()
                    + result.time_s * np.linalg.norm(omega_dot, axis=1).max() / 2)
    assert np.all(error <= bound + 1e-12)
    assert error.max() < 1e-3                       # under 0.06° over the 50-s tumble
    _, error_half = dead_reckoning_error_rad(0.005)
    assert error.max() / error_half.max() == pytest.approx(2.0, rel=0.02)   # first order


#: The estimators that step (the offline ones run on whole records only).
ONLINE = [cls for cls in ESTIMATORS.values() if cls.mode == "online"]


@pytest.mark.parametrize("cls", ONLINE)
def test_every_estimator_shares_the_interface(cls, rng):
    estimator = cls(dt=0.01)
    assert isinstance(estimator, AttitudeEstimator)
    out = estimator.step(np.array([0.01, 0.02, 0.03]), None)
    assert out.shape == (4,)
    out = estimator.step(np.array([0.01, 0.02, 0.03]), np.array([1.0, 0, 0, 0]))
    assert out.shape == (4,)
    n = 40
    omega = rng.normal(0, 0.05, (n, 3))
    star = np.tile([1.0, 0, 0, 0], (n, 1))
    available = np.arange(n) % 10 == 0
    first = estimator.run(omega, star, available)
    assert first.shape == (n, 4)
    assert np.array_equal(estimator.run(omega, star, available), first)   # run() resets


@pytest.mark.parametrize("cls", [cls for cls in ESTIMATORS.values() if cls.mode == "offline"])
def test_an_offline_estimator_runs_on_whole_records_and_refuses_to_step(cls, rng):
    if cls.name == "vqf-offline":
        pytest.importorskip("vqf")
    estimator = cls(dt=0.01)
    with pytest.raises(TypeError, match="is offline"):
        estimator.step(np.array([0.01, 0.02, 0.03]), None)
    n = 200
    omega = rng.normal(0, 0.05, (n, 3))
    up, north = np.array([0.0, 0.0, 9.81]), np.array([0.0, 20.0, -40.0])
    vectors = tuple(VectorReadings(sensor=name, body=np.tile(v, (n, 1)),
                                   reference=np.tile(v, (n, 1)), available=np.ones(n, bool),
                                   variance=np.full(n, 0.1), unit=unit)
                    for name, v, unit in (("accelerometer", up, "m/s^2"),
                                          ("magnetometer", north, "uT")))
    star = np.tile([1.0, 0, 0, 0], (n, 1))
    first = estimator.run(omega, star, np.zeros(n, bool), vectors=vectors)
    assert first.shape == (n, 4) and np.isfinite(first).all()
    again = estimator.run(omega, star, np.zeros(n, bool), vectors=vectors)
    np.testing.assert_array_equal(again, first)                      # run() starts afresh


def test_swapping_estimators_is_one_line():
    from benchmarks.simulation import simulate as run_all
    for estimator in (DeadReckoning(), DeadReckoningWithResets(), QuaternionEKF()):
        result = run_all(Scenario(tstop=1.0), [estimator], seed=0)
        assert result.error_deg[estimator.name].shape == (101,)


def test_bad_estimator_settings_rejected():
    from dynamics.validation import InvalidParameterError
    with pytest.raises(InvalidParameterError, match="initial_state"):
        DeadReckoning(initial_attitude=[0, 0, 0, 0])
    with pytest.raises(InvalidParameterError, match="measurement_covariance"):
        QuaternionEKF(measurement_covariance=-1.0)
    with pytest.raises(InvalidParameterError, match="output"):
        QuaternionEKF(output="smoothed")
