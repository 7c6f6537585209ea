"""Sensors: exact behaviour and seeded statistics with chi-square bounds."""
import math

import numpy as np
import pytest
from scipy.stats import chi2

from dynamics.quaternion import attitude_error_rad
from dynamics.validation import InvalidParameterError
from sensors import (
    Gyro,
    StarTracker,
    arw_deg_per_rthr_to_noise_power,
    noise_power_to_arw_deg_per_rthr,
    noise_power_to_std,
    std_to_noise_power,
)

# Two-sided 99.8% acceptance region for every chi-square test below: with a
# fixed seed the test is deterministic; the bound says how surprising a
# failure would be if the noise had the stated variance.
ALPHA = 0.002


def chi2_bounds(dof):
    return chi2.ppf(ALPHA / 2, dof), chi2.ppf(1 - ALPHA / 2, dof)


@pytest.mark.parametrize("power, dt", [(1e-5, 0.01), (1e-4, 0.01), (1e-5, 0.002)])
def test_gyro_noise_sample_variance_is_power_over_dt(power, dt):
    omega_true = np.tile([0.05, -0.02, 0.01], (5001, 1))
    noise = Gyro(power, dt).measure(omega_true, np.random.default_rng(7)) - omega_true
    variance = power / dt
    # (n - 1) s² / σ² ~ χ²(n - 1) for each of the 3 axes, pooled: χ²(3 (n - 1)).
    statistic = np.sum((len(noise) - 1) * noise.var(axis=0, ddof=1)) / variance
    low, high = chi2_bounds(3 * (len(noise) - 1))
    assert low < statistic < high
    assert abs(noise.mean()) < 4 * math.sqrt(variance / noise.size)   # zero mean, 4σ


def test_star_tracker_holds_readings_and_flags_them():
    q_true = np.tile([1.0, 0.0, 0.0, 0.0], (101, 1))
    readings = StarTracker(1e-6, 0.2, 0.01).measure(q_true, np.random.default_rng(1))
    assert np.array_equal(np.flatnonzero(readings.available), np.arange(0, 101, 20))
    for k in range(101):
        assert np.array_equal(readings.quat[k], readings.quat[20 * (k // 20)])
    assert np.allclose(np.linalg.norm(readings.quat, axis=1), 1.0, atol=1e-15)


def test_noiseless_star_tracker_reads_the_truth(rng):
    q_true = rng.standard_normal((50, 4))
    q_true /= np.linalg.norm(q_true, axis=1, keepdims=True)
    readings = StarTracker(0.0, 0.05, 0.01).measure(q_true, rng)
    assert np.allclose(readings.quat[readings.available], q_true[readings.available], atol=1e-15)


def test_star_tracker_error_has_power_over_dt_variance():
    # z = normalize(q + v), v ~ N(0, σ² I4): to first order in σ the error angle is
    # 2 |v⊥| with v⊥ the 3 components of v orthogonal to q, so e² / (4σ²) ~ χ²(3)
    # (the neglected terms are O(σ²) = 1e-4 relative).
    power, dt = 1e-6, 0.01
    sigma = noise_power_to_std(power, dt)
    q_true = np.tile([0.5, 0.5, -0.5, 0.5], (20001, 1))
    readings = StarTracker(power, 0.2, dt).measure(q_true, np.random.default_rng(3))
    error = attitude_error_rad(q_true[readings.available], readings.quat[readings.available])
    statistic = np.sum(error**2) / (4 * sigma**2)
    low, high = chi2_bounds(3 * error.size)
    assert low < statistic < high


@pytest.mark.parametrize("interval", [0.0, -0.2, 0.005])
def test_interval_shorter_than_dt_or_not_positive_is_rejected(interval):
    with pytest.raises(InvalidParameterError, match="time_between_measurements"):
        StarTracker(1e-6, interval, 0.01)


def test_interval_from_binary_rounding_is_accepted():
    assert StarTracker(1e-6, 0.1 + 0.2 - 0.1, 0.01).steps_between_readings == 20


@pytest.mark.parametrize("power", [-1e-6, float("nan"), float("inf")])
def test_bad_noise_power_rejected(power):
    with pytest.raises(InvalidParameterError, match="gyro_noise"):
        Gyro(power, 0.01)


def test_unit_helpers_round_trip_and_worked_examples():
    assert noise_power_to_std(1e-5, 0.01) == pytest.approx(0.0316227766)
    assert std_to_noise_power(noise_power_to_std(3e-7, 0.02), 0.02) == pytest.approx(3e-7)
    assert arw_deg_per_rthr_to_noise_power(noise_power_to_arw_deg_per_rthr(2e-9)) == \
        pytest.approx(2e-9)
    # 1 deg/√h is (π/180)/60 rad/√s, so its power is that squared.
    assert arw_deg_per_rthr_to_noise_power(1.0) == pytest.approx((math.pi / 180 / 60) ** 2)


def test_arw_predicts_integrated_gyro_noise():
    # Angle random walk: after t seconds each axis has drifted with variance p t, with
    # p recovered from the ARW figure. 2000 independent 10-s walks per axis, pooled:
    # Σ θ² / (p t) ~ χ²(6000).
    power = arw_deg_per_rthr_to_noise_power(10.0)
    dt, steps = 0.01, 1000
    gyro = Gyro(power, dt)
    noise = gyro.measure(np.zeros((steps, 3 * 2000)), np.random.default_rng(11))
    angle = noise.sum(axis=0) * dt
    statistic = np.sum(angle**2) / (power * steps * dt)
    low, high = chi2_bounds(angle.size)
    assert low < statistic < high


def test_both_star_trackers_answer_one_interface():
    from sensors.star_tracker import RotationStarTracker, StarTracker
    q_true = np.tile([1.0, 0.0, 0.0, 0.0], (11, 1))
    time_s = np.arange(11) * 0.1
    for tracker in (StarTracker(1e-6, 0.2, 0.1), RotationStarTracker([6, 6, 40], 0.2, 0.1)):
        readings = tracker.measure(q_true, np.random.default_rng(1), np.random.default_rng(2))
        assert readings.available.tolist() == [k % 2 == 0 for k in range(11)]
        assert tracker.model in ("workshop", "rotation")
        assert tracker.dropout_probability == 0.0
        assert not tracker.in_outage(time_s).any()
        assert tracker.attitude_covariance_rad2.shape == (3, 3)
