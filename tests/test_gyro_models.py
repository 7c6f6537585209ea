"""What a gyro measures: the average rate over its sample, and a bias with a
Gauss–Markov part (bias instability), with their datasheet units.

Statistical checks use fixed seeds and bounds from the theory of the
first-order Gauss–Markov (AR(1)) process, stated where they are used.
"""
import math

import numpy as np
import pytest

from benchmarks import Scenario, simulate
from benchmarks.engine import make_runs, run_batch
from benchmarks.engine.batch import engine_limitation
from benchmarks.engine.runner import run_many
from benchmarks.simulation import simulate_truth
from dynamics.quaternion import quat_conjugate, quat_multiply, rotvec_from_quat
from sensors import Gyro
from sensors.gyro import average_rates, equivalent_bias_random_walk
from sensors.noise import (
    arw_rad_per_rts_to_deg_per_rthr,
    bias_instability_deg_per_hr_to_radps,
    noise_density_deg_per_s_rthz_to_rad_per_rts,
)

#: A user's tumbling small satellite on a 5 Hz integrating gyro.
TUMBLE = Scenario(tstop=30.0, dt=0.2, inertia_tensor_kg_m2=[[0.035, 0.0012, -0.0008],
                                                            [0.0012, 0.042, 0.0015],
                                                            [-0.0008, 0.0015, 0.018]],
                  initial_rate_radps=[0.025, -0.02, 0.03], gyro_noise=1.9e-9,
                  gyro_bias_random_walk=4e-8, gyro_initial_bias_radps=[2e-5, -1e-5, 1e-5],
                  gyro_sampling="average", star_tracker_model="rotation",
                  star_tracker_sigma_arcsec=[10.0, 10.0, 70.0], time_between_measurements=0.4)


def test_the_average_rate_gyro_reads_the_truths_attitude_increment():
    # Without noise, ω̃_k Δt is the rotation vector of q_k⁻¹ ⊗ q_{k+1} (to the
    # truth's own 1e-12), so an exact constant-rate step reproduces the truth.
    scenario = TUMBLE.replace(gyro_noise=0.0, gyro_bias_random_walk=0.0,
                              gyro_initial_bias_radps=[0.0, 0.0, 0.0])
    truth = simulate_truth(scenario)
    run = simulate(scenario, ["dead-reckoning"], seed=3)
    increments = rotvec_from_quat(quat_multiply(quat_conjugate(truth.q_true[:-1]),
                                                truth.q_true[1:]))
    assert np.abs(run.sensors.omega_meas_radps[:-1] * scenario.dt - increments).max() < 1e-12
    # The last reading, which no estimate uses, is the sampled rate.
    assert np.array_equal(run.sensors.omega_meas_radps[-1], truth.omega_true_radps[-1])
    # And the sampled gyro differs from it by about ½ ω̇ Δt per step (here ~1e-5 rad/s).
    sampled = simulate(scenario.replace(gyro_sampling="sample"), ["dead-reckoning"], seed=3)
    gap = np.abs(sampled.sensors.omega_meas_radps[:-1] - run.sensors.omega_meas_radps[:-1])
    assert gap.max() > 1e-6


def test_average_rates_with_the_next_attitude_fill_the_last_row():
    truth = simulate_truth(TUMBLE)
    head = average_rates(truth.q_true[:10], TUMBLE.dt, q_after=truth.q_true[10])
    whole = average_rates(truth.q_true, TUMBLE.dt, last_rate=truth.omega_true_radps[-1])
    assert np.array_equal(head, whole[:10])


def test_the_engine_reads_the_same_average_rates_as_the_per_run_path():
    # Two paths, one truth: blocks of 7 steps hand each block's last rate the
    # next block's first attitude; a streamed truth (cache_steps=0) too.
    names = ("dead-reckoning", "ekf", "mekf", "usque")
    runs = make_runs(TUMBLE, seeds=[1, 4])
    for cache_steps in (10**6, 0):
        batch = run_batch(TUMBLE, runs, names, keep_traces=True, block_steps=7,
                          cache_steps=cache_steps)
        for i, seed in enumerate(runs.seeds):
            reference = simulate(TUMBLE, names, seed=int(seed))
            for name in names:
                difference = np.abs(batch.estimates[name][i] - reference.estimates[name]).max()
                assert difference < 1e-9, (cache_steps, name, difference)


def markov_gyro(sigma_b=1e-4, tau=20.0, dt=0.5):
    return Gyro(0.0, dt, bias_instability_radps=sigma_b, bias_correlation_time_s=tau)


def ar1_autocorrelation_sd(phi: float, lag: int, n: int) -> float:
    """Bartlett's standard deviation of an AR(1) series' sample autocorrelation
    at ``lag`` from ``n`` samples (Box & Jenkins, *Time Series Analysis*, §2.1.6):
    var r_L ≈ [(1 + φ²)(1 − φ^{2L})/(1 − φ²) − 2 L φ^{2L}] / n."""
    p2 = phi * phi
    return math.sqrt(((1 + p2) * (1 - p2 ** lag) / (1 - p2) - 2 * lag * p2 ** lag) / n)


def test_the_gauss_markov_bias_has_its_correlation_time_and_variance():
    gyro = markov_gyro()
    n = 400_000
    _, bias = gyro.measure_with_bias(np.zeros((n, 3)), np.random.default_rng(20261201))
    phi = math.exp(-gyro.dt / gyro.bias_correlation_time_s)
    centred = bias - bias.mean(axis=0)
    variance = np.mean(centred ** 2, axis=0)
    for lag in (1, 40, 80):             # τ = 40 steps: e⁻¹ at 40, e⁻² at 80
        r = np.mean(np.sum(centred[lag:] * centred[:-lag], axis=0) / (n * variance))
        # Three independent axes pooled: the standard deviation over √3; 4σ.
        bound = 4 * ar1_autocorrelation_sd(phi, lag, n) / math.sqrt(3)
        assert abs(r - phi ** lag) < bound, (lag, r, phi ** lag, bound)
    # Stationary from the start: var b = σ_b². The sample variance of an AR(1)
    # has relative variance ≈ 2(1 + φ²)/((1 − φ²) n); 4σ, pooled over axes.
    relative_sd = math.sqrt(2 * (1 + phi ** 2) / ((1 - phi ** 2) * n) / 3)
    assert abs(variance.mean() / gyro.bias_instability_radps ** 2 - 1) < 4 * relative_sd
    first = np.array([markov_gyro().measure_with_bias(np.zeros((2, 3)),
                                                      np.random.default_rng(s))[1][0]
                      for s in range(2000)])
    # b_0 ~ N(0, σ_b²): 6000 draws, the variance within 4 √(2/6000) of σ_b².
    assert abs(np.mean(first ** 2) / 1e-8 - 1) < 4 * math.sqrt(2 / first.size)


def test_a_wrong_correlation_time_fails_the_same_check():
    # The check above can fail: a process of τ = 10 s read as τ = 20 s.
    gyro = markov_gyro(tau=10.0)
    n = 100_000
    _, bias = gyro.measure_with_bias(np.zeros((n, 3)), np.random.default_rng(7))
    centred = bias - bias.mean(axis=0)
    r = np.mean(np.sum(centred[40:] * centred[:-40], axis=0) / (n * np.mean(centred ** 2, 0)))
    claimed = math.exp(-40 * 0.5 / 20.0)
    assert abs(r - claimed) > 4 * ar1_autocorrelation_sd(claimed, 40, n) / math.sqrt(3)


def test_filters_take_the_gauss_markov_part_as_its_driving_noise():
    scenario = TUMBLE.replace(gyro_bias_instability_radps=1e-5,
                              gyro_bias_correlation_time_s=200.0)
    assert scenario.gyro_filter_bias_random_walk == pytest.approx(
        math.sqrt(4e-8 ** 2 + 2 * 1e-10 / 200.0))
    from estimators import MultiplicativeEKF
    assert MultiplicativeEKF.from_scenario(scenario).gyro_bias_random_walk == \
        scenario.gyro_filter_bias_random_walk
    assert equivalent_bias_random_walk(3e-9, 0.0, 1.0) == 3e-9


@pytest.mark.parametrize("walk", [4e-8, 0.0])
def test_the_engine_draws_the_gauss_markov_bias_as_the_per_run_path_does(walk):
    # Two paths, one truth: with and without a random walk beside it (the
    # Gauss–Markov part's normals sit after the walk's, or in its place).
    scenario = TUMBLE.replace(tstop=20.0, gyro_bias_random_walk=walk,
                              gyro_bias_instability_radps=1e-5,
                              gyro_bias_correlation_time_s=50.0)
    assert engine_limitation(scenario) is None
    names = ("dead-reckoning", "ekf", "mekf", "usque")
    runs = make_runs(scenario, [0, 6])
    batch = run_batch(scenario, runs, names, keep_traces=True, block_steps=9)
    for i, seed in enumerate(runs.seeds):
        reference = simulate(scenario, names, seed=int(seed))
        for name in names:
            difference = np.abs(batch.estimates[name][i] - reference.estimates[name]).max()
            assert difference < 1e-9, (walk, name, difference)
        assert np.allclose(batch.final["gyro_bias_radps"][i],
                           reference.sensors.gyro_bias_radps[-1], rtol=1e-12, atol=0)
    # and through the runner, on the engine: no note that it is not.
    assert np.array_equal(run_many(scenario, runs, ["mekf"], keep_traces=True).estimates["mekf"],
                          batch.estimates["mekf"])


def test_datasheet_units_convert_as_their_doctests_say():
    assert noise_density_deg_per_s_rthz_to_rad_per_rts(1.0) == pytest.approx(math.pi / 180)
    assert arw_rad_per_rts_to_deg_per_rthr(
        noise_density_deg_per_s_rthz_to_rad_per_rts(0.0025)) == pytest.approx(0.15)
    assert bias_instability_deg_per_hr_to_radps(3600.0) == pytest.approx(math.pi / 180)


def test_a_scenario_takes_the_datasheet_keys(tmp_path):
    path = tmp_path / "gyro.toml"
    path.write_text('dt = 0.2\n[gyro]\nsampling = "average"\n'
                    "noise_density_deg_per_s_rthz = 0.0025\n"
                    "bias_instability_deg_per_hr = 3.0\nbias_correlation_time_s = 300.0\n")
    scenario = Scenario.from_toml(path)
    assert scenario.gyro_sampling == "average"
    assert scenario.gyro_noise == pytest.approx((0.0025 * math.pi / 180) ** 2)
    assert scenario.gyro_bias_instability_radps == pytest.approx(3.0 * math.pi / 180 / 3600)
    assert scenario.gyro_bias_correlation_time_s == 300.0
    assert not scenario.is_workshop_sensors


@pytest.mark.parametrize("settings, name", [
    ({"gyro_sampling": "integrated"}, "gyro_sampling"),
    ({"gyro_bias_instability_radps": -1e-5}, "gyro_bias_instability_radps"),
    ({"gyro_bias_correlation_time_s": 0.0}, "gyro_bias_correlation_time_s"),
])
def test_bad_gyro_settings_name_themselves(settings, name):
    with pytest.raises(ValueError, match=name):
        Scenario(**settings)
