"""Every estimator declares the sensors it reads and needs: one that can use
none of the data's readings is refused, never scored under its own name;
one that ran without using any, or without a heading reference, says so."""
import math
import textwrap

import numpy as np
import pytest

from benchmarks.cli import main
from benchmarks.scenario import Scenario
from benchmarks.sensor_use import present_sensors, refuse_unreadable, scenario_sensors
from benchmarks.simulation import simulate
from dynamics.validation import InvalidParameterError
from estimators import ESTIMATORS, sensing
from estimators.base import InvalidEstimateError

CUBESAT = "scenarios/cubesat.toml"
MAGNETOMETER_ONLY = "scenarios/magnetometer_only.toml"
#: A ground IMU with an accelerometer alone: gravity fixes the inclination only.
GRAVITY_ONLY = textwrap.dedent("""
    tstop = 20.0
    dt = 0.1
    [star_tracker]
    model = "none"
    [site]
    latitude_deg = 48.0
    longitude_deg = 11.0
    [accelerometer]
    interval_s = 0.1
    sigma_mps2 = 0.01
""")


def test_every_registry_estimator_declares_what_it_reads_and_needs():
    for name, cls in ESTIMATORS.items():
        assert cls.reads is not None, name
        assert set(cls.reads) <= set(sensing.ATTITUDE_SENSORS), name
        for group in cls.needs:
            assert group <= cls.reads, name      # it needs only what it reads
    assert ESTIMATORS["dead-reckoning"].needs == ()     # the gyro suffices


@pytest.mark.parametrize("name, present, usable", [
    ("madgwick", {"star_tracker"}, False),
    ("mahony", {"accelerometer"}, True),                   # the IMU update: gravity alone
    ("mahony", {"magnetometer"}, False),                   # a field alone: neither update
    ("madgwick", {"accelerometer", "magnetometer"}, True),
    ("vqf", {"star_tracker"}, False),
    ("vqf", {"accelerometer"}, True),
    ("fusion", {"magnetometer", "sun_sensor", "coarse_sun_sensors"}, False),
    ("triad", {"star_tracker"}, False),
    ("quest", {"magnetometer"}, False),
    ("quest", {"sun_sensor", "coarse_sun_sensors"}, False),     # one direction, twice
    ("quest", {"magnetometer", "coarse_sun_sensors"}, True),
    ("dead-reckoning-resets", {"accelerometer", "magnetometer"}, False),
    ("dead-reckoning-resets", {"star_tracker"}, True),
    ("mekf", {"magnetometer"}, True),
    ("dead-reckoning", set(), True),
])
def test_unusable_reason_follows_the_declarations(name, present, usable):
    reason = sensing.unusable_reason(ESTIMATORS[name], present)
    assert (reason is None) == usable
    if not usable:
        assert "would only dead-reckon" in reason


@pytest.mark.parametrize("argv, name", [
    (["run", "--estimator", "triad"], "triad"),
    (["compare", "--estimators", "madgwick,mahony,dead-reckoning", "--tstop", "5"], "madgwick"),
    (["compare", "--scenario", CUBESAT, "--estimators", "vqf", "--tstop", "10"], "vqf"),
    (["compare", "--scenario", CUBESAT, "--estimators", "mahony", "--tstop", "10"], "mahony"),
    (["compare", "--scenario", MAGNETOMETER_ONLY, "--estimators", "quest,mekf"], "quest"),
    (["replay", "--estimators", "madgwick"], "madgwick"),
    (["replay", "--estimators", "mekf,triad"], "triad"),
    (["broad", "--estimators", "dead-reckoning-resets"], "dead-reckoning-resets"),
])
def test_the_command_line_refuses_an_estimator_without_its_sensors(argv, name, tmp_path,
                                                                   capsys):
    out = tmp_path / "o"
    assert main([*argv, "--quiet", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"attitude-bench: error: estimator = '{name}': needs")
    assert "\n" not in err
    assert not out.exists()          # nothing written


def test_a_scenario_without_a_star_tracker_refuses_resets(tmp_path):
    scenario = Scenario.from_toml(MAGNETOMETER_ONLY).replace(tstop=100.0)
    assert scenario_sensors(scenario) == {"magnetometer"}
    with pytest.raises(InvalidParameterError, match="dead-reckoning-resets"):
        simulate(scenario, ["dead-reckoning-resets"])


def test_the_default_estimators_leave_out_those_that_cannot_read(tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["compare", "--scenario", MAGNETOMETER_ONLY, "--tstop", "600", "--quiet",
                 "--out", str(out)]) == 0
    names = [line.split(",")[0] for line in (out / "summary.csv").read_text().splitlines()[1:]]
    assert names == ["dead-reckoning", "ekf", "mekf", "usque"]      # no static solver


def test_a_static_solver_that_never_solved_says_so_in_table_and_legend(tmp_path, capsys):
    # Two directions must be 95° apart: never (the sine is capped at 1).
    toml = tmp_path / "never.toml"
    toml.write_text("[estimators.triad]\nmin_separation_deg = 95.0\n")
    result = simulate(Scenario.from_toml([CUBESAT, toml]).replace(tstop=60.0), ["triad", "mekf"])
    assert "used none of its" in result.notes["triad"]
    assert result.labels["triad"] == "TRIAD [no reading used]"
    assert "mekf" not in result.notes and result.labels["mekf"] == "MEKF"
    out = tmp_path / "o"
    assert main(["compare", "--scenario", CUBESAT, "--scenario", str(toml), "--tstop", "60",
                 "--estimators", "triad,mekf", "--quiet", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "note: triad: used none of its" in printed
    last = (out / "summary.csv").read_text().splitlines()
    assert last[1].startswith("triad,") and "used none of its" in last[1]


def test_gravity_alone_is_scored_on_the_inclination(tmp_path):
    toml = tmp_path / "gravity.toml"
    toml.write_text(GRAVITY_ONLY)
    scenario = Scenario.from_toml(toml)
    assert scenario_sensors(scenario) == {"accelerometer"}
    result = simulate(scenario, ["mekf"], seed=1)
    assert "inclination only" in result.notes["mekf"]
    assert result.labels["mekf"] == "MEKF [inclination only]"
    # The inclination is found (the tilt of gravity, to a fraction of a degree)
    # where the total error holds whatever heading error the start had.
    from benchmarks.metrics import attitude_error_deg
    total = attitude_error_deg(result.truth.q_true, result.estimates["mekf"])
    assert result.error_deg["mekf"][-1] < 0.2
    assert np.all(result.error_deg["mekf"] <= total + 1e-9)
    # The score leaves the heading out: the total error ends at 2.8° (the
    # start's heading, which gravity cannot see), and a pure turn about the
    # vertical scores nothing.
    assert total[-1] > 10 * result.error_deg["mekf"][-1]
    from benchmarks.metrics import inclination_error_deg
    from dynamics.quaternion import quat_from_rotvec, quat_multiply
    yawed = quat_multiply(quat_from_rotvec(np.array([0.0, 0.0, 0.7])), result.truth.q_true[-1])
    assert inclination_error_deg(result.truth.q_true[-1:], yawed[None]) < 1e-6


USER_MODULE = textwrap.dedent('''
    import numpy as np
    from estimators import AttitudeEstimator

    class Scaled(AttitudeEstimator):
        name, label = "scaled", "Scaled"
        factor = 10.0

        def __init__(self, *, dt=0.01, initial_attitude=(1.0, 0.0, 0.0, 0.0),
                     on_invalid="raise"):
            super().__init__(dt=dt, initial_attitude=initial_attitude, on_invalid=on_invalid)

        def reset(self):
            pass

        def _step(self, omega, reading=None):
            return self.factor * np.array([1.0, 0.0, 0.0, 0.0])

    class Zero(Scaled):
        factor = 0.0

    class Doubled(Scaled):
        factor = 2.0
''')


@pytest.mark.parametrize("cls, norm2", [("Scaled", 100.0), ("Zero", 0.0), ("Doubled", 4.0)])
def test_an_estimate_off_the_unit_sphere_is_refused_not_scored(cls, norm2, tmp_path,
                                                                monkeypatch, capsys):
    (tmp_path / "offsphere.py").write_text(USER_MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.chdir(tmp_path)
    spec = f"offsphere:{cls}"
    with pytest.raises(InvalidEstimateError, match=f"is {norm2:g}\\)"):
        simulate(Scenario(tstop=1.0), [spec])
    assert main(["compare", "--estimators", spec, "--tstop", "1", "--quiet", "--out", "o"]) == 2
    err = capsys.readouterr().err
    assert "must be a unit quaternion" in err and err.count("\n") == 1
    assert not (tmp_path / "o").exists()


def test_a_unit_estimate_passes_and_the_tolerance_is_far_from_rounding():
    from estimators.base import UNIT_NORM_TOLERANCE
    assert 1e-12 < UNIT_NORM_TOLERANCE < 1e-3
    result = simulate(Scenario(tstop=1.0), ["dead-reckoning", "ekf"])
    for estimate in result.estimates.values():
        assert np.all(np.abs(np.sum(estimate ** 2, axis=1) - 1.0) < 1e-12)


def test_present_sensors_are_read_from_the_data():
    scenario = Scenario.from_toml(CUBESAT).replace(tstop=60.0)
    result = simulate(scenario, ["dead-reckoning"])
    # What read in the data: the fine sun sensor (70° field of view) never saw
    # the Sun in this minute, so the data holds less than the scenario declares.
    assert present_sensors(result.sensors) == {"magnetometer", "coarse_sun_sensors"}
    assert scenario_sensors(scenario) == {"magnetometer", "coarse_sun_sensors", "sun_sensor"}
    with pytest.raises(InvalidParameterError, match="estimator = 'madgwick'"):
        refuse_unreadable(["madgwick"], present_sensors(result.sensors))
    assert math.isfinite(result.error_deg["dead-reckoning"][-1])


def test_a_tunable_setting_of_a_sensor_the_data_lacks_is_not_tuned():
    from benchmarks.experiments.objectives import seed_cases
    from benchmarks.experiments.estimator_tuning import tune_estimator, tuning_plan
    from estimators import MultiplicativeEKF
    scenario = Scenario.from_toml(MAGNETOMETER_ONLY).replace(tstop=600.0)
    settings = MultiplicativeEKF.configured_settings(scenario)
    default = [t.name for t, _, _ in tuning_plan(MultiplicativeEKF, settings)]
    assert "measurement_scale" in default          # without the data's sensors, it would be
    here = [t.name for t, _, _ in tuning_plan(MultiplicativeEKF, settings,
                                               present={"magnetometer"})]
    assert "measurement_scale" not in here and "gyro_noise" in here
    with pytest.raises(InvalidParameterError, match="measurement_scale.*star_tracker.*change "
                                                    "nothing"):
        tune_estimator("mekf", seed_cases(scenario, [0]), "rms",
                       parameters=["measurement_scale"])


@pytest.mark.parametrize("argv, first_line", [
    (["sweep", "--estimator", "dead-reckoning", "--param", "magnetometer.sigma_nT",
      "--values", "10,100", "--scenario", CUBESAT, "--tstop", "10"],
     "param = 'magnetometer.sigma_nT': has no effect on dead-reckoning, which read no "
     "magnetometer"),
    (["sweep", "--estimator", "mekf", "--param", "magnetometer.sigma_nT", "--values", "10,100"],
     "param = 'magnetometer.sigma_nT': has no effect: the scenario has no magnetometer"),
    (["sweep", "--estimator", "mekf", "--param", "time-between-measurements", "--values", "1,2",
      "--scenario", MAGNETOMETER_ONLY],
     "param = 'time-between-measurements': has no effect: the scenario has no star_tracker"),
    # Was a KeyError: 'none'.
    (["sweep", "--estimator", "mekf", "--param", "star_tracker.sigma_arcsec", "--values", "1,2",
      "--scenario", MAGNETOMETER_ONLY], "param = 'star_tracker.sigma_arcsec': has no effect: "
     "the scenario has no star_tracker"),
    (["compare", "--star-tracker-noise", "1e-5", "--scenario", MAGNETOMETER_ONLY],
     "star_tracker_noise = 1e-05: has no effect: the scenario has no star_tracker"),
    (["compare", "--estimators", "triad,mekf", "--scenario", CUBESAT, "--pc-exponent", "-5"],
     "pc_exponent = -5.0: has no effect on triad, mekf; it is read only by ekf"),
])
def test_a_setting_that_changes_nothing_is_refused(argv, first_line, tmp_path, capsys):
    assert main([*argv, "--quiet", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"attitude-bench: error: {first_line}")
    assert err.count("\n") == 1 and not (tmp_path / "o").exists()


def test_a_sensor_setting_read_by_one_of_the_estimators_is_taken(tmp_path):
    assert main(["sweep", "--estimator", "mekf", "--param", "magnetometer.sigma_nT",
                 "--values", "50,500", "--scenario", CUBESAT, "--tstop", "20", "--quiet",
                 "--out", str(tmp_path)]) == 0
    rows = (tmp_path / "sweep.csv").read_text().splitlines()[1:]
    assert rows[0].split(",")[2:] != rows[1].split(",")[2:]       # the rows differ


@pytest.mark.parametrize("name", ["madgwick", "mahony", "vqf", "fusion"])
def test_magnetic_north_filters_are_scored_in_the_frame_they_estimate(name, tmp_path):
    """On the ground, magnetic north is the site's declination (about 4° here)
    off geographic north; the filters that estimate against the field's
    horizontal direction are turned by it, so their error is their own."""
    if name in ("vqf", "fusion"):
        pytest.importorskip({"vqf": "vqf", "fusion": "imufusion"}[name])
    toml = tmp_path / "ground.toml"
    toml.write_text(GRAVITY_ONLY.replace("tstop = 20.0\ndt = 0.1", "tstop = 30.0\ndt = 0.01")
                    .replace("interval_s = 0.1", "interval_s = 0.01")
                    + "[magnetometer]\ninterval_s = 0.01\nsigma_nT = 50.0\n")
    scenario = Scenario.from_toml(toml)
    result = simulate(scenario, [name], seed=0)
    reference = result.sensors.vectors[0].reference[0]
    declination = math.degrees(math.atan2(reference[0], reference[1]))
    assert 3.0 < declination < 5.0
    settled = result.error_deg[name][-1000:]
    assert settled.mean() < declination / 4      # was the declination itself


@pytest.mark.slow
def test_campaigns_say_what_their_runs_made_of_their_readings(tmp_path, capsys):
    """montecarlo and consistency print the notes a single run's table prints,
    summed over their runs (engine and per-run paths alike)."""
    never = tmp_path / "never.toml"
    never.write_text("[estimators.triad]\nmin_separation_deg = 95.0\n")
    common = ["--scenario", CUBESAT, "--scenario", str(never), "--estimators", "triad,mekf",
              "--runs", "3", "--tstop", "60", "--quiet"]
    assert main(["montecarlo", *common, "--out", str(tmp_path / "m")]) == 0
    assert ("note: triad: used none of its readings in 3 of 3 runs"
            in capsys.readouterr().out)
    assert main(["consistency", *common, "--out", str(tmp_path / "k")]) == 0
    assert "note: triad: used none of its readings in 3 of 3 runs" in capsys.readouterr().out
