"""The flight sensor models: the Farrenkopf gyro and the rotation-noise star tracker.

Seeded statistics with bounds from the theory; exact checks where the models
must reduce to the workshop's.
"""
import math

import numpy as np
import pytest
from scipy.stats import binom, chi2

from dynamics.quaternion import (
    attitude_error_vector_rad,
    quat_from_rotvec,
    rotation_matrix,
)
from dynamics.validation import InvalidParameterError
from sensors import ARCSEC_PER_RAD, Gyro, RotationStarTracker, allan_deviation

# Two-sided 99.8 % acceptance for every chi-square test here (fixed seeds: the
# tests are deterministic; the level says how surprising a failure would be).
ALPHA = 0.002


def chi2_bounds(dof):
    return chi2.ppf(ALPHA / 2, dof), chi2.ppf(1 - ALPHA / 2, dof)


def test_without_bias_the_gyro_is_the_workshop_gyro_bit_for_bit():
    omega = np.tile([0.05, -0.02, 0.01], (1000, 1))
    measured, bias = Gyro(1e-5, 0.01).measure_with_bias(omega, np.random.default_rng(4))
    expected = omega + math.sqrt(1e-5 / 0.01) * np.random.default_rng(4).standard_normal((1000, 3))
    assert np.array_equal(measured, expected)
    assert not np.any(bias)


def test_constant_bias_and_scale_misalignment_enter_the_reading():
    omega = np.tile([0.05, -0.02, 0.01], (20000, 1))
    bias0 = np.array([1e-3, -2e-3, 5e-4])
    K = np.array([[1e-3, 2e-4, 0.0], [0.0, -5e-4, 1e-4], [3e-4, 0.0, 2e-3]])
    gyro = Gyro(1e-8, 0.1, initial_bias_radps=bias0, scale_misalignment=K)
    measured, bias = gyro.measure_with_bias(omega, np.random.default_rng(5))
    assert np.array_equal(bias, np.tile(bias0, (20000, 1)))
    residual = measured - omega @ (np.eye(3) + K).T - bias0
    # The residual is the white noise alone: its mean is within 4σ/√n of zero.
    assert np.all(np.abs(residual.mean(axis=0)) < 4 * gyro.std_radps / math.sqrt(20000))


def test_bias_random_walk_has_the_stated_increments():
    # β_{k+1} - β_k ~ N(0, σ_u² Δt): Σ Δβ² / (σ_u² Δt) ~ χ²(3 (N - 1)).
    sigma_u, dt, n = 1e-6, 0.5, 20000
    gyro = Gyro(1e-10, dt, bias_random_walk=sigma_u)
    _, bias = gyro.measure_with_bias(np.zeros((n, 3)), np.random.default_rng(6))
    statistic = np.sum(np.diff(bias, axis=0) ** 2) / (sigma_u ** 2 * dt)
    low, high = chi2_bounds(3 * (n - 1))
    assert low < statistic < high
    assert gyro.normals_per_step == 6


def allan_relative_bound(clusters):
    """3σ relative error of a 3-axis Allan deviation at a cluster count M.

    For M non-overlapping clusters the Allan variance has M - 1 squared
    differences, so the deviation's relative standard deviation is about
    1/√(2 (M - 1)) (IEEE Std 952-1997, Annex C); pooling three independent
    axes divides it by √3, and overlapping estimates only do better.
    """
    return 3.0 / math.sqrt(2 * 3 * (clusters - 1))


def test_allan_deviation_shows_arw_and_rrw_slopes():
    # σ²(τ) = σ_v²/τ + σ_u² τ / 3 (Farrenkopf model); crossover at √3 σ_v/σ_u ≈ 17 s.
    sigma_v, sigma_u, dt, n = 1e-4, 1e-5, 0.1, 1_000_000
    gyro = Gyro(sigma_v ** 2, dt, bias_random_walk=sigma_u)
    rates = gyro.measure(np.zeros((n, 3)), np.random.default_rng(2026))
    cluster_sizes = np.array([2, 20, 3000, 30000])
    tau = cluster_sizes * dt
    adev = allan_deviation(rates, dt, cluster_sizes)            # (4, 3)
    pooled = np.sqrt(np.mean(adev ** 2, axis=1))
    theory = np.sqrt(sigma_v ** 2 / tau + sigma_u ** 2 * tau / 3)
    bounds = np.array([allan_relative_bound(n // m) for m in cluster_sizes])
    assert np.all(np.abs(pooled / theory - 1) < bounds)
    # Slopes over a decade on each side of the crossover: −½ (ARW), +½ (RRW). A
    # relative error e₁, e₂ at the ends moves a slope by at most
    # (|ln(1 - e₁)| + |ln(1 - e₂)|) / ln 10; the theory's own slope there
    # (both terms) is within 0.01 of ±½.
    for first, expected in ((0, -0.5), (2, 0.5)):
        slope = np.log(pooled[first + 1] / pooled[first]) / np.log(10.0)
        allowed = (-math.log(1 - bounds[first]) - math.log(1 - bounds[first + 1])) / math.log(10)
        assert abs(slope - expected) < allowed + 0.01
    assert bounds[-1] < 0.25     # so the check above is a real one: at most 22 % at τ = 3000 s


def test_allan_deviation_rejects_impossible_clusters():
    with pytest.raises(ValueError, match="cluster size"):
        allan_deviation(np.zeros(10), 0.1, [6])


def tracker(**settings):
    defaults = dict(sigma_arcsec=[5.0, 8.0, 40.0], time_between_measurements=0.5, dt=0.1)
    defaults.update(settings)
    return RotationStarTracker(defaults.pop("sigma_arcsec"), defaults.pop("time_between_measurements"),
                               defaults.pop("dt"), **defaults)


def slow_truth(n, dt=0.1):
    rate = np.array([0.01, -0.02, 0.03])
    return quat_from_rotvec(np.outer(np.arange(n) * dt, rate))


def test_reading_error_has_the_stated_covariance_in_the_sensor_frame():
    mounting = quat_from_rotvec([0.4, -1.1, 0.7])
    st = tracker(sensor_to_body_quat=mounting)
    q_true = slow_truth(60001)
    readings = st.measure(q_true, np.random.default_rng(8))
    kept = readings.available
    error_body = attitude_error_vector_rad(q_true[kept], readings.quat[kept])
    error_sensor = error_body @ rotation_matrix(mounting)      # R_bsᵀ applied to each row
    sigma = st.sigma_arcsec / ARCSEC_PER_RAD
    # Per axis, Σ θ² / σ² ~ χ²(n); all three pooled ~ χ²(3n).
    statistic = np.sum((error_sensor / sigma) ** 2, axis=0)
    low, high = chi2_bounds(len(error_sensor))
    assert np.all((low < statistic) & (statistic < high))
    # Axes independent: the sample correlation of x and z within 4/√n of zero.
    correlation = np.corrcoef(error_sensor[:, 0], error_sensor[:, 2])[0, 1]
    assert abs(correlation) < 4 / math.sqrt(len(error_sensor))
    assert np.allclose(st.attitude_covariance_rad2,
                       rotation_matrix(mounting) @ np.diag(sigma ** 2) @ rotation_matrix(mounting).T)


def test_scheduled_outages_remove_exactly_those_readings_and_change_no_other():
    q_true = slow_truth(1001)
    plain = tracker().measure(q_true, np.random.default_rng(9))
    cut = tracker(outages_s=[[10.0, 20.0], [55.5, 60.0]]).measure(q_true, np.random.default_rng(9))
    time_s = np.arange(1001) * 0.1
    due = np.isclose(time_s / 0.5, np.round(time_s / 0.5))
    lost = ((time_s >= 10.0) & (time_s < 20.0)) | ((time_s >= 55.5) & (time_s < 60.0))
    assert np.array_equal(plain.available, due)
    assert np.array_equal(cut.available, due & ~lost)
    kept = cut.available
    assert np.array_equal(cut.quat[kept], plain.quat[kept])
    # Through an outage the last reading before it is held.
    assert np.array_equal(cut.quat[150], plain.quat[95])


def test_random_dropouts_follow_the_probability():
    q_true = slow_truth(50001)
    st = tracker(dropout_probability=0.3)
    readings = st.measure(q_true, np.random.default_rng(10), np.random.default_rng(11))
    due = len(st.schedule(50001)[0])
    lost = due - readings.available.sum()
    # Losses ~ Binomial(due, 0.3): inside its central 99.8 %.
    assert binom.ppf(ALPHA / 2, due, 0.3) <= lost <= binom.ppf(1 - ALPHA / 2, due, 0.3)
    with pytest.raises(ValueError, match="dropout_rng"):
        st.measure(q_true, np.random.default_rng(10))


def test_canonical_sign_has_w_nonnegative_and_raw_follows_the_truth():
    q_true = slow_truth(3001, dt=1.0)        # turns by 112 degrees… and past 180: w changes sign
    assert q_true[:, 0].min() < 0
    raw = tracker(time_between_measurements=1.0, dt=1.0).measure(q_true, np.random.default_rng(3))
    canonical = tracker(time_between_measurements=1.0, dt=1.0, sign="canonical").measure(
        q_true, np.random.default_rng(3))
    assert np.all(canonical.quat[:, 0] >= 0)
    assert np.all(np.sum(raw.quat * q_true, axis=1) > 0.999)
    assert np.allclose(np.abs(np.sum(raw.quat * canonical.quat, axis=1)), 1.0, atol=1e-15)


@pytest.mark.parametrize("settings, name", [
    ({"sigma_arcsec": [1.0, -1.0, 2.0]}, "star_tracker_sigma_arcsec"),
    ({"dropout_probability": 1.0}, "star_tracker_dropout_probability"),
    ({"outages_s": [[5.0, 2.0]]}, "star_tracker_outages_s"),
    ({"outages_s": [[1.0, 2.0, 3.0]]}, "star_tracker_outages_s"),
    ({"sign": "positive"}, "star_tracker_sign"),
    ({"sensor_to_body_quat": [0, 0, 0, 0]}, "star_tracker_to_body_quat"),
    ({"time_between_measurements": 0.05}, "time_between_measurements"),
])
def test_bad_star_tracker_settings_rejected(settings, name):
    with pytest.raises(InvalidParameterError, match=name):
        tracker(**settings)


@pytest.mark.parametrize("settings, name", [
    ({"bias_random_walk": -1.0}, "gyro_bias_random_walk"),
    ({"initial_bias_radps": [1.0, 2.0]}, "gyro_initial_bias_radps"),
    ({"scale_misalignment": np.eye(3)}, "gyro_scale_misalignment"),
    ({"scale_misalignment": [1.0, 2.0]}, "gyro_scale_misalignment"),
])
def test_bad_gyro_settings_rejected(settings, name):
    with pytest.raises(InvalidParameterError, match=name):
        Gyro(1e-10, 0.1, **settings)
