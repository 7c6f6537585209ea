"""USQUE, the unscented quaternion estimator: its sigma points, first-order
agreement with the MEKF, and convergence from a large error."""
from pathlib import Path

import numpy as np
import pytest

from benchmarks import Scenario, simulate
from dynamics.quaternion import (
    attitude_error_rad,
    grp_from_quat,
    quat_from_grp,
    quat_from_rotvec,
)
from dynamics.validation import InvalidParameterError
from estimators import USQUE

FLIGHT = Path(__file__).resolve().parents[1] / "scenarios" / "flight.toml"


def test_sigma_point_weights_sum_as_they_must_and_reproduce_mean_and_covariance(rng):
    ukf = USQUE(initial_attitude_sigma_rad=[0.1, 0.2, 0.3], initial_bias_sigma_radps=1e-3)
    points = ukf.filter.points_fn
    assert points.num_sigmas() == 13
    assert np.sum(ukf.filter.Wm) == pytest.approx(1.0, abs=1e-15)
    # Van der Merwe's covariance weights: the mean's gets 1 - α² + β on top.
    assert np.sum(ukf.filter.Wc) == pytest.approx(1.0 + (1 - 1.0 ** 2 + 2.0), abs=1e-15)
    x = rng.normal(0, 1, 6)
    A = rng.normal(0, 1, (6, 6))
    P = A @ A.T + np.eye(6)
    sigmas = points.sigma_points(x, P)
    mean = ukf.filter.Wm @ sigmas
    covariance = (ukf.filter.Wc[:, None] * (sigmas - mean)).T @ (sigmas - mean)
    assert np.allclose(mean, x, atol=1e-12)
    assert np.allclose(covariance, P, atol=1e-10)


def test_grp_round_trip_and_first_order_rotation_vector(rng):
    for _ in range(20):
        theta = rng.normal(0, 1.0, 3)
        q = quat_from_rotvec(theta)
        p = grp_from_quat(q)
        assert np.allclose(quat_from_grp(p), q, atol=1e-14)
        # |p| = 4 tan(θ/4)
        assert np.linalg.norm(p) == pytest.approx(4 * np.tan(np.linalg.norm(theta) / 4))
    small = np.array([1e-5, -2e-5, 3e-5])
    assert np.allclose(grp_from_quat(quat_from_rotvec(small)), small, rtol=1e-9)
    assert np.allclose(grp_from_quat(-quat_from_rotvec(small)), small, rtol=1e-9)


def paired(options, tstop, seeds):
    scenario = Scenario.from_toml(FLIGHT).replace(tstop=tstop)
    scenario = scenario.replace(estimator_options={"mekf": options, "usque": options})
    return [simulate(scenario, ["mekf", "usque"], seed=seed, traces=True) for seed in seeds]


@pytest.mark.slow      # 300 s of both per-run filters: 5 s
def test_with_tiny_initial_errors_usque_agrees_with_the_mekf_to_first_order():
    # Both start on the truth with a tiny P₀: the sigma points then sample an
    # almost linear model, so the two filters differ only at second order.
    options = dict(initial_attitude=[1.0, 0.0, 0.0, 0.0], initial_attitude_sigma_rad=1e-4,
                   initial_bias_sigma_radps=1e-6)
    (result,) = paired(options, 300.0, [1])
    difference = np.degrees(attitude_error_rad(result.estimates["mekf"],
                                               result.estimates["usque"]))
    rms = np.sqrt(np.mean(result.error_deg["mekf"] ** 2))
    # Measured: 0.009 arcsec at most against an RMS error of 5.5 arcsec.
    assert difference.max() < 1e-2 * rms
    mekf, usque = result.traces["mekf"], result.traces["usque"]
    assert np.allclose(usque.attitude_covariance[-1], mekf.attitude_covariance[-1], rtol=1e-6)
    assert np.allclose(usque.bias_radps, mekf.bias_radps, rtol=0, atol=1e-12)


def convergence_time_s(result, name, threshold_deg):
    """First time after which the error stays below ``threshold_deg``."""
    above = np.flatnonzero(result.error_deg[name] > threshold_deg)
    return 0.0 if not len(above) else result.time_s[min(above[-1] + 1, len(result.time_s) - 1)]


@pytest.mark.slow      # four seeds of 120 s on both per-run filters: 6 s
def test_from_a_large_error_usque_converges_at_least_as_fast_as_the_mekf():
    # 119 degrees off (rotation vector [100, -60, 80] deg), told σ = 57° per axis.
    options = dict(initial_attitude=quat_from_rotvec(np.radians([100, -60, 80])).tolist(),
                   initial_attitude_sigma_rad=1.0, initial_bias_sigma_radps=1e-6)
    times = {"mekf": [], "usque": []}
    for result in paired(options, 120.0, range(4)):
        assert np.degrees(attitude_error_rad(result.truth.q_true[0],
                                             options["initial_attitude"])) > 100
        for name in times:
            # Below 60 arcsec, about three times the roll axis's reading error.
            times[name].append(convergence_time_s(result, name, 60 / 3600))
    # Measured: both converge at the first reading (t = 0 s) on every seed.
    assert max(times["usque"]) <= max(times["mekf"])
    assert max(times["usque"]) < 30.0


def test_usque_builds_from_the_scenario_and_rejects_bad_settings():
    ukf = USQUE.from_scenario(Scenario.from_toml(FLIGHT))
    assert ukf.dt == 0.1 and np.allclose(ukf.R, Scenario.from_toml(FLIGHT)
                                         .star_tracker_attitude_covariance_rad2)
    with pytest.raises(InvalidParameterError, match="alpha"):
        USQUE(alpha=0.0)
    with pytest.raises(InvalidParameterError, match="kappa"):
        USQUE(kappa=-6.0)
    with pytest.raises(InvalidParameterError, match="measurement_covariance"):
        USQUE(measurement_covariance=[1.0, -1.0, 1.0])
