"""Sensors on their own clocks: a star tracker whose interval is not a
multiple of the gyro's step, its readings applied at their own times."""
import numpy as np
import pytest

from benchmarks import Scenario, simulate
from benchmarks.engine import make_runs
from benchmarks.engine.batch import engine_limitation
from benchmarks.engine.runner import run_many
from benchmarks.experiments.consistency import run_consistency
from dynamics.quaternion import attitude_error_rad, attitude_error_vector_rad
from estimators import USQUE, AttitudeEstimator, MultiplicativeEKF
from sensors.star_tracker import reading_schedule

#: A 5 Hz gyro and a 2 Hz star tracker: readings at t = 0, 0.5, 1.0, … fall
#: on a gyro step every other time and 0.1 s after one in between.
OWN_CLOCK = dict(dt=0.2, time_between_measurements=0.5, star_tracker_model="rotation",
                 gyro_sampling="average")


def test_the_schedule_puts_each_reading_in_the_step_that_holds_it():
    steps, offsets = reading_schedule(0.5, 0.2, 11)
    assert steps.tolist() == [0, 2, 5, 7, 10]
    assert np.allclose(offsets, [0.0, 0.1, 0.0, 0.1, 0.0], atol=1e-12)
    on_grid_steps, on_grid_offsets = reading_schedule(0.4, 0.2, 11)
    assert on_grid_steps.tolist() == [0, 2, 4, 6, 8, 10] and not on_grid_offsets.any()


def test_readings_carry_their_times_and_are_taken_from_the_truth_then():
    scenario = Scenario(tstop=20.0, star_tracker_sigma_arcsec=[0.0, 0.0, 0.0], **OWN_CLOCK)
    run = simulate(scenario, ["dead-reckoning"], seed=0)
    sensors = run.sensors
    assert sensors.available.sum() == 41                       # t = 0, 0.5, …, 20
    taken = sensors.available & (sensors.star_tracker_offset_s > 0)
    assert taken.sum() == 20 and np.allclose(sensors.star_tracker_offset_s[taken], 0.1)
    # A noise-free reading is the truth at its own time, not at its step's.
    from dynamics.rigid_body import simulate_torque_free
    k = np.flatnonzero(taken)[3]
    at_time = simulate_torque_free(scenario.inertia_tensor_kg_m2,
                                   scenario.initial_attitude_quat,
                                   scenario.initial_rate_radps, [0.0, k * 0.2 + 0.1]).q_true[-1]
    assert attitude_error_rad(at_time, sensors.star_tracker_quat[k]) < 1e-11
    assert attitude_error_rad(run.truth.q_true[k], sensors.star_tracker_quat[k]) > 1e-4


class AtTheStep(MultiplicativeEKF):
    """The MEKF, but applying each reading at its gyro step (the base's
    ``_step_at``): what a filter without reading times does."""

    name = "mekf-at-step"
    applies_reading_times = False

    def _step_at(self, omega, reading, offset_s):
        return AttitudeEstimator._step_at(self, omega, reading, offset_s)


def test_a_filter_fed_noise_free_readings_off_the_grid_tracks_the_truth():
    # A spherical body spins at a constant 2.5 °/s, so the MEKF's exact
    # constant-rate step is exact over any part of a step, and a near-perfect
    # tracker (1e-6 arcsec, 5e-12 rad) keeps it there: 1e-9 rad at every step.
    scenario = Scenario(tstop=30.0, inertia_tensor_kg_m2=[2.0, 2.0, 2.0],
                        initial_rate_radps=[0.025, -0.02, 0.03], gyro_noise=0.0,
                        star_tracker_sigma_arcsec=[1e-6, 1e-6, 1e-6], **OWN_CLOCK)
    late = AtTheStep.from_scenario(scenario)
    # USQUE's sigma points need a covariance that stays positive definite: a
    # whisper of process noise and a prior at the readings' scale.
    usque = USQUE.from_scenario(scenario, gyro_noise=1e-18, initial_attitude_sigma_rad=1e-6,
                                initial_bias_sigma_radps=1e-9)
    with pytest.warns(UserWarning, match="at its gyro step"):
        run = simulate(scenario, ["mekf", usque, late], seed=1)
    for name in ("mekf", "usque"):
        # (The rotation-vector error: the degrees' arccos cannot resolve below 2e-8 rad.)
        error_rad = np.linalg.norm(attitude_error_vector_rad(run.truth.q_true,
                                                             run.estimates[name]), axis=1)
        assert error_rad.max() < 1e-9, name
    # Applied at its step, a reading 0.1 s late is off by |ω| τ ≈ 4e-3 rad.
    assert np.radians(run.error_deg["mekf-at-step"]).max() > 1e-3


@pytest.mark.slow      # 40 runs of two filters on the per-run path: 6 s
def test_the_mekf_stays_consistent_and_at_the_bound_off_the_grid():
    # The user's tumble (2.5 °/s, 5 Hz integrating gyro) with a 2 Hz tracker:
    # 40 seeds on the per-run path (the engine hands off-grid readings to
    # it). The ANEES of 40 runs must lie in its 99 % band χ²(120)/40; the
    # efficiency, RMS over the bound that processes each reading at its time,
    # within 0.97 and 1.10 (40 runs' RMS has a Monte Carlo error of about
    # 2 %: the bound's 1 within 1.5 of it below, within 5 above). The same
    # MEKF applying each reading at its gyro step fails both (measured:
    # ANEES 1,800, efficiency 18; the MEKF 3.1 and 1.03).
    scenario = Scenario.from_toml("scenarios/smallsat.toml").replace(
        tstop=100.0, time_between_measurements=0.5)
    assert "off the gyro's time grid" in engine_limitation(scenario)
    at_step = f"{__name__}:AtTheStep"
    with pytest.warns(UserWarning, match="per-run path"):
        result = run_consistency(scenario, ["mekf", at_step], 40, level=0.99)
    row = result.summary["mekf"]
    assert row["anees_low"] < row["anees"] < row["anees_high"]
    assert 0.97 <= row["efficiency"] <= 1.10
    late = result.summary[at_step]
    assert late["anees"] > late["anees_high"] and late["efficiency"] > 1.10


def test_the_runner_takes_off_grid_runs_to_the_per_run_path(tmp_path, capsys):
    scenario = Scenario(tstop=6.0, **OWN_CLOCK)
    runs = make_runs(scenario, [3, 4])
    with pytest.warns(UserWarning, match="per-run path"):
        batch = run_many(scenario, runs, ["dead-reckoning-resets", "ekf"], keep_traces=True)
    # On the command line the same warning is one line on stderr.
    from benchmarks.cli import main
    assert main(["montecarlo", "--runs", "2", "--tstop", "2", "--dt", "0.2",
                 "--time-between-measurements", "0.5", "--out", str(tmp_path), "--quiet"]) == 0
    notes = [line for line in capsys.readouterr().err.splitlines() if "per-run path" in line]
    assert notes and notes[0].startswith("attitude-bench: note: the engine does not model")
    reference = simulate(scenario, ["dead-reckoning-resets", "ekf"], seed=4)
    for name in ("dead-reckoning-resets", "ekf"):
        assert np.array_equal(batch.estimates[name][1], reference.estimates[name])
    # An on-grid scenario whose runs vary the interval off the grid goes there too.
    grid = Scenario(tstop=6.0, dt=0.2, time_between_measurements=0.4)
    assert engine_limitation(grid) is None
    assert engine_limitation(grid, make_runs(grid, [0, 1],
                                             time_between_measurements=[0.4, 0.5])) is not None


@pytest.mark.parametrize("timing", ["workshop", "step-average"])
def test_resets_take_a_reading_at_its_time_and_propagate_the_rest(timing):
    # Spherical body, constant rate, noise-free: both timings reach the truth
    # at the next step from a reading 0.1 s into the step (the first-order
    # step's own error, (|ω|Δt)³/12 ≈ 6e-8 rad, aside).
    scenario = Scenario(tstop=10.0, inertia_tensor_kg_m2=[2.0, 2.0, 2.0],
                        initial_rate_radps=[0.025, -0.02, 0.03], gyro_noise=0.0,
                        star_tracker_sigma_arcsec=[0.0, 0.0, 0.0], **OWN_CLOCK)
    from estimators import DeadReckoningWithResets
    resets = DeadReckoningWithResets.from_scenario(scenario, rate_timing=timing)
    run = simulate(scenario, [resets], seed=0)
    taken = np.flatnonzero(run.sensors.available & (run.sensors.star_tracker_offset_s > 0))
    after = np.radians(run.error_deg["dead-reckoning-resets"][taken + 1])
    assert after.max() < 2e-7, timing


def test_an_offset_outside_the_step_is_refused():
    estimator = MultiplicativeEKF(dt=0.2)
    with pytest.raises(ValueError, match=r"offset_s at step 0 = 0.2: must be in \[0, dt"):
        estimator.step(np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]), 0.2)


def test_a_subclass_with_the_old_propagate_applies_readings_at_its_steps():
    class OldStyle(MultiplicativeEKF):
        name = "old-style"

        def propagate(self, omega_meas_radps):           # no dt: written before clocks
            super().propagate(omega_meas_radps)

    assert not OldStyle.applies_reading_times and MultiplicativeEKF.applies_reading_times
    scenario = Scenario(tstop=3.0, **OWN_CLOCK)
    with pytest.warns(UserWarning, match="old-style applies each star tracker reading"):
        run = simulate(scenario, [OldStyle.from_scenario(scenario)], seed=0)
    assert np.isfinite(run.error_deg["old-style"]).all()
    with pytest.raises(ValueError, match="offset_s at step 0 = 'soon'"):
        MultiplicativeEKF(dt=0.2).step(np.zeros(3), np.array([1.0, 0, 0, 0]), "soon")
