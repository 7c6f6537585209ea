"""The multiplicative EKF: exact model checks, a Riccati cross-check, and seeded
consistency statistics on the flight scenario."""
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm, solve_discrete_are
from scipy.stats import chi2

from benchmarks import Scenario, simulate
from dynamics.quaternion import (
    attitude_error_rad,
    attitude_error_vector_rad,
    quat_from_rotvec,
    quat_multiply,
    skew,
)
from dynamics.validation import InvalidParameterError
from estimators import MultiplicativeEKF, QuaternionEKF
from estimators.mekf import SERIES_BELOW, discrete_error_model, transition_coefficients

FLIGHT = Path(__file__).resolve().parents[1] / "scenarios" / "flight.toml"


def van_loan(omega_hat, dt, sigma_v2, sigma_u, scale_density=0.0):
    """Φ and Q of dx/dt = F x + G w by Van Loan's matrix exponential (1978);
    ``scale_density``: the rate's own error, white along ω̂ (S_s ω̂ω̂ᵀ more in
    the rate noise's spectral density)."""
    F = np.zeros((6, 6))
    F[:3, :3] = -skew(omega_hat)
    F[:3, 3:] = -np.eye(3)
    G = np.zeros((6, 6))
    G[:3, :3] = -np.eye(3)
    G[3:, 3:] = np.eye(3)
    spectral = np.diag([sigma_v2] * 3 + [sigma_u ** 2] * 3)
    spectral[:3, :3] += scale_density * np.outer(omega_hat, omega_hat)
    block = np.zeros((12, 12))
    block[:6, :6] = -F
    block[:6, 6:] = G @ spectral @ G.T
    block[6:, 6:] = F.T
    exponential = expm(block * dt)
    phi = exponential[6:, 6:].T
    return phi, phi @ exponential[:6, 6:]


@pytest.mark.parametrize("rate_norm", [0.0, 1e-6, 0.0011, 0.9, 1.1, 7.0])
def test_transition_and_process_noise_equal_van_loan(rng, rate_norm):
    # The book's closed forms (and their series below x = 0.1) against the
    # integral they come from, computed independently.
    direction = rng.standard_normal(3)
    omega_hat = rate_norm * direction / np.linalg.norm(direction)
    dt, sigma_v2, sigma_u = 0.1, 1e-8, 3e-5
    phi, q = discrete_error_model(omega_hat, dt, sigma_v2, sigma_u)
    phi_ref, q_ref = van_loan(omega_hat, dt, sigma_v2, sigma_u)
    assert np.allclose(phi, phi_ref, rtol=0, atol=1e-13)
    assert np.allclose(q, q_ref, rtol=1e-9, atol=1e-22)
    assert np.allclose(q, q.T, rtol=0, atol=0)


@pytest.mark.parametrize("rate_norm", [0.0, 0.05, 1.1, 7.9])
def test_the_rates_own_error_is_van_loans_too(rng, rate_norm):
    # The white relative error of the rate (gyro_scale_density) enters Q as
    # S_s Δt ω̂ω̂ᵀ in closed form, because Φ₁₁ turns about ω̂ and leaves it as
    # it is: against the exact integral, 450 °/s (7.9 rad/s) included.
    direction = rng.standard_normal(3)
    omega_hat = rate_norm * direction / np.linalg.norm(direction)
    dt, sigma_v2, sigma_u, density = 0.05, 1e-8, 3e-5, 1e-3
    _, q = discrete_error_model(omega_hat, dt, sigma_v2, sigma_u, density)
    _, q_ref = van_loan(omega_hat, dt, sigma_v2, sigma_u, density)
    assert np.allclose(q, q_ref, rtol=1e-9, atol=1e-22)
    _, q_without = discrete_error_model(omega_hat, dt, sigma_v2, sigma_u)
    assert np.linalg.norm(q - q_without) == pytest.approx(density * dt * rate_norm ** 2,
                                                          rel=1e-12, abs=0)


def test_in_a_fast_turn_the_rates_own_error_widens_the_heading_not_the_tilt():
    # One second at 450 °/s about the vertical (the body's z at the identity,
    # which the turn keeps): the filter's heading variance grows by S_s ω² t
    # more than without the rate's own error; the tilt's is as it was.
    dt, rate, density = 0.005, math.radians(450.0), 1e-7
    covariances = []
    for scale_density in (0.0, density):
        mekf = MultiplicativeEKF(dt=dt, gyro_noise=1e-6, initial_attitude_sigma_rad=1e-3,
                                 initial_bias_sigma_radps=1e-9,
                                 gyro_scale_density=scale_density)
        for _ in range(200):
            mekf.propagate(np.array([0.0, 0.0, rate]))
        covariances.append(mekf.filter.P[:3, :3])
    without, with_ = covariances
    assert with_[2, 2] - without[2, 2] == pytest.approx(density * rate ** 2 * 1.0, rel=1e-9)
    assert np.allclose(with_[:2, :], without[:2, :], rtol=1e-12, atol=0)


@pytest.mark.parametrize("value", [-1e-7, math.nan, math.inf])
def test_the_rates_own_error_is_refused_unless_finite_and_not_negative(value):
    from estimators import USQUE
    for cls in (MultiplicativeEKF, USQUE):
        with pytest.raises(InvalidParameterError, match=r"^gyro_scale_density = .*: must be"):
            cls(gyro_scale_density=value)


def test_series_and_closed_form_meet_at_the_switch():
    dt = 0.1
    below = np.array(transition_coefficients(SERIES_BELOW * (1 - 1e-12) / dt, dt))
    above = np.array(transition_coefficients(SERIES_BELOW * (1 + 1e-12) / dt, dt))
    assert np.allclose(below, above, rtol=1e-9, atol=0)


def propagate_truth(q, beta, omega_meas, dt):
    """The true state one step on, noise-free: the rate is ω̃ - β, held constant."""
    return quat_multiply(q, quat_from_rotvec((omega_meas - beta) * dt)), beta


def test_transition_matches_finite_differences_of_the_full_propagation(rng):
    dt = 0.2
    q_hat = quat_from_rotvec(rng.normal(0, 1, 3))
    beta_hat = rng.normal(0, 1e-3, 3)
    omega_meas = np.array([0.4, -0.3, 0.8])
    phi, _ = discrete_error_model(omega_meas - beta_hat, dt, 0.0, 0.0)
    q_hat_next, beta_hat_next = propagate_truth(q_hat, beta_hat, omega_meas, dt)

    def error_after(delta):
        q = quat_multiply(q_hat, quat_from_rotvec(delta[:3]))
        q_next, beta_next = propagate_truth(q, beta_hat + delta[3:], omega_meas, dt)
        return np.concatenate([attitude_error_vector_rad(q_next, q_hat_next),
                               beta_next - beta_hat_next])

    step = 1e-6
    numeric = np.column_stack([(error_after(step * e) - error_after(-step * e)) / (2 * step)
                               for e in np.eye(6)])
    assert np.allclose(numeric, phi, rtol=0, atol=1e-8)


def test_reset_keeps_the_quaternion_unit_and_sign_does_not_matter(rng):
    def run(flip):
        mekf = MultiplicativeEKF(dt=0.1, gyro_noise=1e-6, gyro_bias_random_walk=1e-5,
                                 measurement_covariance=1e-6, initial_attitude_sigma_rad=1.0)
        out = []
        for k in range(300):
            z = quat_from_rotvec(rng.normal(0, 0.5, 3)) if k % 3 == 0 else None
            if z is not None and flip and k % 2:
                z = -z
            out.append(mekf.step(rng.normal(0, 0.1, 3), z))
            assert abs(np.linalg.norm(mekf.q_hat) - 1) < 1e-15
        return np.array(out)

    state = rng.bit_generator.state
    plain = run(False)
    rng.bit_generator.state = state
    flipped = run(True)
    assert np.allclose(plain, flipped, rtol=0, atol=1e-15)


def test_steady_state_equals_the_riccati_solution_of_its_own_model():
    # σ_u = 0, no bias, a body at rest: between readings (every m steps) Φ = I,
    # so the prior at reading times follows the time-invariant Riccati
    # recursion with Q_m = m σ_v² Δt I₃ and the tracker's anisotropic R.
    scenario = Scenario(tstop=400.0, dt=0.1, initial_rate_radps=[0.0, 0.0, 0.0],
                        gyro_noise=1e-10, star_tracker_model="rotation",
                        time_between_measurements=1.0, star_tracker_sigma_arcsec=[6, 6, 40])
    # The rate held over each step: its predict follows each step's reading,
    # so the last step's predict is there to read (a trapezoidal filter
    # predicts at the next step, when its reading comes).
    mekf = MultiplicativeEKF.from_scenario(scenario, initial_bias_sigma_radps=0.0,
                                           rate_interpolation="hold")
    result = simulate(scenario, [mekf], seed=3)
    assert result.error_deg["mekf"][-1] < 0.01
    m = 10
    prior = mekf.filter.P_prior[:3, :3]            # after the last step's predict: m·Q on a posterior
    dare = solve_discrete_are(np.eye(3), np.eye(3), m * 1e-10 * 0.1 * np.eye(3), mekf.R)
    # The run ends at k = 4000, a reading step: its predict is the first of the m.
    posterior = dare - dare @ np.linalg.solve(dare + mekf.R, dare)
    expected = posterior + 1e-10 * 0.1 * np.eye(3)
    assert np.allclose(np.diagonal(prior), np.diagonal(expected), rtol=0.01, atol=0)
    assert not np.allclose(np.diagonal(prior), np.diagonal(dare), rtol=0.01, atol=0)


def test_additive_ekf_and_mekf_agree_to_first_order_on_the_workshop():
    # Tuned alike: Q_θ = 4 e^pc I₃ (δθ = 2 Ξᵀ δq), R_θ = 4 R, P₀ likewise,
    # prior output. What differs is second order: the EKF's first-order step
    # and additive update against the exact rotation and multiplicative reset.
    scenario = Scenario()
    ekf = QuaternionEKF.from_scenario(scenario)
    mekf = MultiplicativeEKF.from_scenario(
        scenario, gyro_noise=4 * math.exp(scenario.pc_exponent) / scenario.dt,
        measurement_covariance=4.0, initial_attitude_sigma_rad=2e-6,
        initial_bias_sigma_radps=0.0, output="prior")
    result = simulate(scenario, [ekf, mekf], seed=0)
    q_ekf = result.estimates["ekf"] / np.linalg.norm(result.estimates["ekf"], axis=1,
                                                     keepdims=True)
    difference_deg = np.degrees(attitude_error_rad(q_ekf, result.estimates["mekf"]))
    rms_deg = np.sqrt(np.mean(result.error_deg["ekf"] ** 2))
    # Measured: 1.2e-4 degrees at most, against an RMS error of 0.47 degrees.
    assert difference_deg.max() < 1e-3 * rms_deg


def flight_runs(n_runs, tstop=300.0, **options):
    scenario = Scenario.from_toml(FLIGHT).replace(tstop=tstop)
    runs = []
    for seed in range(n_runs):
        mekf = MultiplicativeEKF.from_scenario(scenario, **options)
        runs.append(simulate(scenario, [mekf], seed=seed, traces=True))
    return runs


def attitude_nees(result):
    trace = result.traces["mekf"]
    error = attitude_error_vector_rad(result.truth.q_true, trace.quat)
    return np.einsum("ki,kij,kj->k", error, np.linalg.inv(trace.attitude_covariance), error)


N_RUNS = 10
SETTLE_STEPS = 100      # the first 10 s: the linearisation's transient from 44 degrees


def anees_band(n_runs, level=0.99):
    """Two-sided band of the N-run average NEES at one time: N·ANEES ~ χ²(3N)."""
    return (chi2.ppf((1 - level) / 2, 3 * n_runs) / n_runs,
            chi2.ppf((1 + level) / 2, 3 * n_runs) / n_runs)


@pytest.fixture(scope="module")
def matched_runs():
    return flight_runs(N_RUNS)


@pytest.mark.slow      # with the test below, flight runs of their own: 8 s on two workers
def test_mekf_converges_from_a_large_error_and_its_bias_to_the_truth(matched_runs):
    bias_nees = []
    for result in matched_runs:
        start = result.scenario.estimator_options["mekf"]["initial_attitude"]
        assert math.degrees(attitude_error_rad(result.truth.q_true[0], start)) > 40
        # Within 36 arcsec from 30 s on (the roll axis's 40-arcsec readings
        # need a few to average down).
        assert np.all(result.error_deg["mekf"][300:] < 0.01)
        bias_nees.append(final_bias_nees(result))
    # The final bias errors, normalised by the filter's own covariance, pooled
    # over runs: Σ ~ χ²(3N) if the bias estimate is unbiased and its
    # covariance right; the 99 % band. (Over 300 s it reads the bias's
    # prior, not its random walk: σ_u 0 or ten times gives 37 and 24, inside.)
    low, high = chi2.ppf([0.005, 0.995], 3 * N_RUNS)
    assert low < sum(bias_nees) < high


def final_bias_nees(result) -> float:
    trace = result.traces["mekf"]
    bias_error = trace.bias_radps[-1] - result.sensors.gyro_bias_radps[-1]
    return bias_error @ np.linalg.solve(trace.bias_covariance[-1], bias_error)


@pytest.mark.slow      # ten flight runs of their own: 4 s
def test_the_bias_nees_detects_a_filter_too_sure_of_its_bias():
    # The same check on a filter told a bias prior a tenth of the truth's
    # spread: it must fail (measured: 226 against the band's 53.7).
    scenario = Scenario.from_toml(FLIGHT)
    prior = np.asarray(MultiplicativeEKF.configured_settings(scenario)["initial_bias_sigma_radps"])
    sure = flight_runs(N_RUNS, initial_bias_sigma_radps=prior / 10.0)
    assert sum(final_bias_nees(result) for result in sure) > chi2.ppf(0.995, 3 * N_RUNS)


@pytest.mark.slow
def test_time_averaged_attitude_nees_is_inside_the_chi_square_band(matched_runs):
    # ANEES at each time is ~ χ²(3N)/N for a consistent filter; its average
    # over time has the same mean and no larger a variance, so the single-time
    # 99 % band is a conservative band for the time average.
    nees = np.array([attitude_nees(result) for result in matched_runs])
    time_averaged = nees[:, SETTLE_STEPS:].mean()
    low, high = anees_band(N_RUNS)
    assert low < time_averaged < high


@pytest.mark.slow      # beside the consistency it fails, above
def test_nees_detects_a_mistuned_mekf():
    # The same check on a filter told the star tracker is 10x better than it
    # is (R / 100): it must fail.
    scenario = Scenario.from_toml(FLIGHT)
    mistuned = flight_runs(N_RUNS, tstop=120.0, measurement_covariance=(
        scenario.star_tracker_attitude_covariance_rad2 / 100.0))
    nees = np.array([attitude_nees(result) for result in mistuned])
    low, high = anees_band(N_RUNS)
    assert nees[:, SETTLE_STEPS:].mean() > high


def test_mekf_defaults_come_from_the_scenario_sensors():
    scenario = Scenario.from_toml(FLIGHT)
    mekf = MultiplicativeEKF.from_scenario(scenario)
    assert mekf.gyro_noise == scenario.gyro_noise
    assert mekf.gyro_bias_random_walk == scenario.gyro_bias_random_walk
    assert np.array_equal(mekf.R, scenario.star_tracker_attitude_covariance_rad2)
    assert mekf.dt == 0.1 and mekf.initial_attitude[0] == pytest.approx(0.92759252)
    assert mekf.attitude_covariance.shape == (3, 3) and mekf.bias_radps.shape == (3,)


@pytest.mark.parametrize("settings, name", [
    ({"measurement_covariance": -1.0}, "measurement_covariance"),
    ({"measurement_covariance": [[1, 2, 0], [2, 1, 0], [0, 0, 1]]}, "measurement_covariance"),
    ({"gyro_noise": float("nan")}, "gyro_noise"),
    ({"initial_bias_radps": [1.0]}, "initial_bias_radps"),
    ({"initial_attitude_sigma_rad": -1.0}, "initial_attitude_sigma_rad"),
    ({"output": "smoothed"}, "output"),
])
def test_bad_mekf_settings_rejected(settings, name):
    with pytest.raises(InvalidParameterError, match=name):
        MultiplicativeEKF(**settings)
