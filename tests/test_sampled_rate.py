"""The rate over a step (estimators.sampled_rate): the trapezoidal rule for a
gyro that samples the rate, the held reading for one that averages it."""
import numpy as np
import pytest

from benchmarks.metrics import attitude_error_deg
from benchmarks.scenario import Scenario
from benchmarks.simulation import simulate_truth
from dynamics.validation import InvalidParameterError
from estimators import USQUE, MultiplicativeEKF

SMALLSAT = "scenarios/smallsat.toml"


def _gyro_only_error_deg(cls, dt: float, interpolation: str) -> float:
    """The final error of ``cls`` fed the noise-free sampled rate of the small
    satellite's tumble (2.5 °/s, a full inertia) for 60 s, with no reading."""
    scenario = Scenario.from_toml(SMALLSAT).replace(tstop=60.0, dt=dt)
    truth = simulate_truth(scenario)
    n = scenario.n_steps
    # A tight prior: USQUE's sigma points about a wide one move its mean by
    # the curvature of the kinematics (some 6e-4° here), which is not the rate's.
    estimator = cls(dt=dt, initial_attitude=truth.q_true[0], gyro_noise=1e-12,
                    initial_attitude_sigma_rad=1e-6, initial_bias_sigma_radps=1e-9,
                    rate_interpolation=interpolation)
    estimates = estimator.run(truth.omega_true_radps, np.tile([1.0, 0, 0, 0], (n, 1)),
                              np.zeros(n, dtype=bool))
    return float(attitude_error_deg(truth.q_true[-1:], estimates[-1:])[0])


@pytest.mark.parametrize("cls", [MultiplicativeEKF, pytest.param(USQUE, marks=pytest.mark.slow)])
def test_the_trapezoid_is_second_order_where_holding_the_reading_is_first(cls):
    # Holding a sampled rate misses ½ ω̇ Δt² a step: an error linear in Δt
    # over a fixed time. The trapezoidal rule's is third order a step,
    # quadratic in Δt over the time: halving Δt halves the one, quarters the other.
    hold = [_gyro_only_error_deg(cls, dt, "hold") for dt in (0.2, 0.1)]
    trapezoid = [_gyro_only_error_deg(cls, dt, "trapezoid") for dt in (0.2, 0.1)]
    assert trapezoid[0] < hold[0] / 20
    assert 1.8 < hold[0] / hold[1] < 2.2
    assert 3.5 < trapezoid[0] / trapezoid[1] < 4.5


@pytest.mark.parametrize("files, expected", [
    ([], "hold"),                                       # the workshop's sensors, its numbers
    ([SMALLSAT], "hold"),                               # an averaging gyro
    (["scenarios/cubesat.toml"], "hold"),
    (["scenarios/flight.toml"], "trapezoid"),           # a gyro that samples the rate
])
def test_the_rate_interpolation_follows_what_the_gyro_reports(files, expected):
    scenario = Scenario.from_toml(files) if files else Scenario()
    for cls in (MultiplicativeEKF, USQUE):
        assert cls.configured_settings(scenario)["rate_interpolation"] == expected


def test_a_sampled_small_satellite_takes_the_trapezoid(tmp_path):
    sampled = tmp_path / "sampled.toml"
    sampled.write_text('[gyro]\nsampling = "sample"\n')
    scenario = Scenario.from_toml([SMALLSAT, sampled])
    assert MultiplicativeEKF.from_scenario(scenario).rate_interpolation == "trapezoid"
    with pytest.raises(InvalidParameterError, match="rate_interpolation"):
        MultiplicativeEKF(rate_interpolation="cubic")


def test_the_output_is_the_same_instant_either_way():
    # With a constant rate the two rules are one: the same estimates, step for
    # step (the trapezoid only moves each step's propagation to the next
    # step's start, before its readings).
    dt, n = 0.1, 200
    omega = np.tile([0.01, -0.02, 0.03], (n, 1))
    star = np.tile([1.0, 0, 0, 0], (n, 1))
    available = np.zeros(n, dtype=bool)
    available[::10] = True
    runs = [MultiplicativeEKF(dt=dt, rate_interpolation=mode).run(omega, star, available)
            for mode in ("hold", "trapezoid")]
    assert np.abs(runs[0] - runs[1]).max() < 1e-12


@pytest.mark.parametrize("interpolation", ["hold", "end"])
@pytest.mark.parametrize("output", ["prior", "posterior"])
def test_the_ekfs_kernel_marks_a_divergence_where_its_class_does(interpolation, output):
    # An update that overflows P (a prior and an R of 1e308) leaves the state
    # not finite at step 0: the kernel, which with "end" predicts before the
    # update, marks it at that step as the per-run class does (it had marked
    # it a step late, its estimate at step 0 still finite).
    import warnings
    from benchmarks.engine import make_runs, run_batch
    from benchmarks.simulation import simulate
    scenario = Scenario(tstop=0.1, initial_covariance=1e308,
                        measurement_covariance=1e308 * np.eye(4),
                        estimator_options={"ekf": {"rate_interpolation": interpolation,
                                                   "output": output}})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        batch = run_batch(scenario, make_runs(scenario, [1]), ["ekf"], keep_traces=True)
        reference = simulate(scenario, ["ekf"], seed=1)
    assert reference.diverged_step["ekf"] == 0
    assert batch.diverged_step["ekf"][0] == 0
    assert np.isnan(batch.estimates["ekf"][0][0]).all()


def test_an_imus_reading_off_the_grid_keeps_each_steps_turn():
    # With "end" each gyro reading is the mean rate over the step before it.
    # A tracker reading inside a step splits that step: its first part is
    # reached with the rate extrapolated from the last readings, and the rest
    # turns by what is left of the next reading's whole turn, so the step
    # turns by its reading's angle whatever the split. A perfect IMU, a
    # reading every 10 steps half a step off the grid, R so wide that the
    # updates move nothing: the estimates with no reading at all, but for
    # the second order of splitting a turn in two (0.002° RMS over 9 s at
    # 150 °/s; the split steps had turned by the instant's extrapolation,
    # 0.073°).
    from dynamics.handheld import HandheldMotion
    from sensors.handheld import HandheldImu, simulated_recording
    perfect = HandheldImu(gyro_bias_dps=0.0, gyro_scale_percent=0.0, gyro_misalignment_deg=0.0,
                          gyro_noise_density=0.0, accelerometer_sigma_mps2=0.0,
                          magnetometer_sigma_uT=0.0)
    recording = simulated_recording(4, HandheldMotion(rate_hz=100.0, rest_s=0.5, moving_s=8.0,
                                                      final_rest_s=0.5, rate_rms_dps=150.0),
                                    perfect)
    n, dt = recording.n_samples, recording.dt
    settings = dict(dt=dt, rate_interpolation="end", initial_attitude=recording.reference_quat[0],
                    gyro_noise=1e-10, measurement_covariance=1e6 * np.eye(3))
    available = np.arange(n) % 10 == 5
    offsets = np.where(available, 0.5 * dt, 0.0)
    alone = MultiplicativeEKF(**settings).run(recording.gyro_radps, recording.reference_quat,
                                              np.zeros(n, bool))
    split = MultiplicativeEKF(**settings).run(recording.gyro_radps, recording.reference_quat,
                                              available, offsets)
    apart = attitude_error_deg(split, alone)
    assert np.sqrt(np.mean(apart ** 2)) < 5e-3
