"""Scenario defaults, TOML loading and validation."""
import tomllib
from pathlib import Path

import numpy as np
import pytest

from benchmarks.scenario import WORKSHOP_FIELDS, Scenario
from dynamics.validation import InvalidParameterError

DEFAULT_FILE = Path(__file__).resolve().parents[1] / "scenarios" / "default.toml"


def test_defaults_are_the_workshop_values():
    s = Scenario()
    assert (s.tstop, s.dt, s.n_steps) == (50.0, 0.01, 5001)
    assert np.array_equal(s.inertia_tensor_kg_m2, np.diag([1.0, 2.0, 3.0]))
    assert np.array_equal(s.initial_rate_radps, [0.05, 0.05, 0.0])
    assert (s.gyro_noise, s.star_tracker_noise, s.time_between_measurements) == (1e-5, 1e-6, 0.2)
    assert (s.pc_exponent, s.initial_covariance) == (-8.7, 1e-12)
    assert np.array_equal(s.measurement_covariance, np.eye(4))
    assert s.time_s[-1] == pytest.approx(50.0)


def test_shipped_default_file_matches_the_defaults_and_names_every_workshop_field(tmp_path):
    from benchmarks.scenario import flatten_sections
    # In its sections; the EKF's three settings are there as comments, being
    # what it derives on the workshop's sensors (so a copy with other sensors
    # derives its own).
    derived = {"pc_exponent", "measurement_covariance", "initial_covariance"}
    with DEFAULT_FILE.open("rb") as handle:
        assert set(flatten_sections(tomllib.load(handle))) == set(WORKSHOP_FIELDS) - derived
    text = DEFAULT_FILE.read_text()
    assert "# pc_exponent = -8.7" in text and "# initial_covariance = 1e-12" in text
    loaded = Scenario.from_toml(DEFAULT_FILE)
    assert loaded.as_dict() == Scenario().as_dict() and loaded.derived_fields == derived
    # A copy with the rotation tracker: the EKF derives its R from that tracker.
    copy = tmp_path / "copy.toml"
    copy.write_text(text.replace("[star_tracker]\n", '[star_tracker]\nmodel = "rotation"\n'))
    rotation = Scenario.from_toml(copy)
    assert rotation.derived_fields == derived
    assert rotation.measurement_covariance[0, 0] < 1e-6


def test_the_workshops_flat_keys_still_give_the_defaults(tmp_path):
    flat = tmp_path / "flat.toml"
    flat.write_text("".join(f"{name} = {_toml(getattr(Scenario(), name))}\n"
                            for name in WORKSHOP_FIELDS))
    assert Scenario.from_toml(flat).as_dict() == Scenario().as_dict()
    assert "[" not in "".join(line[:1] for line in flat.read_text().splitlines())


def _toml(value) -> str:
    return repr(np.asarray(value).tolist()) if np.ndim(value) else repr(float(value))


def test_partial_file_overrides_only_its_keys(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text("gyro_noise = 1e-4\ninertia_tensor_kg_m2 = [2.0, 3.0, 4.0]\n")
    s = Scenario.from_toml(path)
    assert s.gyro_noise == 1e-4 and s.dt == 0.01
    assert np.array_equal(s.inertia_tensor_kg_m2, np.diag([2.0, 3.0, 4.0]))


@pytest.mark.parametrize("changes, name", [
    ({"dt": 0.0}, "dt"),
    ({"tstop": 0.001}, "tstop"),
    ({"gyro_noise": float("nan")}, "gyro_noise"),
    ({"star_tracker_noise": "loud"}, "star_tracker_noise"),
    ({"pc_exponent": -800.0}, "pc_exponent"),
    ({"initial_state": [0, 0, 0, 0]}, "initial_state"),
    ({"initial_covariance": 0.0}, "initial_covariance"),
    ({"measurement_covariance": [[1, 2], [3, 4]]}, "measurement_covariance"),
    ({"wobble": 1}, "wobble"),
])
def test_bad_values_name_the_parameter(changes, name):
    with pytest.raises(InvalidParameterError) as info:
        Scenario().replace(**changes)
    assert str(info.value).startswith(f"{name} = ")
    assert "\n" not in str(info.value)


def test_quaternions_are_normalised():
    s = Scenario(initial_attitude_quat=[2.0, 0, 0, 0])
    assert np.array_equal(s.initial_attitude_quat, [1.0, 0, 0, 0])


FLIGHT_FILE = DEFAULT_FILE.with_name("flight.toml")


def test_flight_file_sections_reach_their_fields():
    s = Scenario.from_toml(FLIGHT_FILE)
    assert (s.dt, s.tstop, s.time_between_measurements) == (0.1, 3600.0, 1.0)
    assert s.gyro_noise == 1e-13 and s.gyro_bias_random_walk == pytest.approx(10 ** 0.5 * 1e-10)
    # [gyro] initial_bias_deg_per_hr: 0.1 deg/h is 0.1 π / (180 · 3600) rad/s.
    assert np.allclose(s.gyro_initial_bias_radps, 0.1 * np.pi / 180 / 3600, rtol=1e-15)
    assert s.star_tracker_model == "rotation"
    assert np.array_equal(s.star_tracker_sigma_arcsec, [6.0, 6.0, 40.0])
    # [estimators.ekf] keys the EKF owns set the scenario fields (campaigns vary
    # them per run); the others are that estimator's options.
    assert s.pc_exponent == -28.5 and s.initial_covariance == 0.1
    assert s.estimator_options["ekf"]["output"] == "posterior"
    assert "pc_exponent" not in s.estimator_options["ekf"]
    assert not s.is_workshop_sensors and Scenario().is_workshop_sensors


def test_sections_and_flat_keys_mix_and_units_convert(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text("tstop = 2.0\n[gyro]\narw_deg_per_rthr = 0.5\n"
                    "bias_rw_deg_per_hr_rthr = 0.01\n[truth]\ninitial_rate_radps = [0, 0, 0.1]\n")
    s = Scenario.from_toml(path)
    assert s.tstop == 2.0 and np.array_equal(s.initial_rate_radps, [0, 0, 0.1])
    assert s.gyro_noise == pytest.approx((0.5 * np.pi / 180 / 60) ** 2, rel=1e-15)
    assert s.gyro_bias_random_walk == pytest.approx(0.01 * np.pi / 180 / 3600 / 60, rel=1e-15)


@pytest.mark.parametrize("content, name, rule", [
    ("[gyro]\nwobble = 1\n", "gyro.wobble", "is not a setting of [gyro]"),
    ("[star_tracker]\nmodel = 'laser'\n", "star_tracker_model", "must be one of"),
    ("[star_tracker]\nsign = 'up'\n", "star_tracker_sign", "must be one of"),
    ("gyro_noise = 1e-5\n[gyro]\nnoise_power = 1e-6\n", "gyro.noise_power", "already set"),
    ("[gyro]\nnoise_power = 1e-6\narw_deg_per_rthr = 1\n", "gyro.arw_deg_per_rthr",
     "already set"),
    ("[estimators.ukf]\nalpha = 1\n", "estimators.ukf", "is not an estimator"),
    ("[estimators.mekf]\nwobble = 1\n", "estimators.mekf.wobble", "is not a setting of mekf"),
    ("[estimators.mekf]\ninitial_attitude_sigma_rad = -1\n",
     "estimators.mekf.initial_attitude_sigma_rad", "must be >= 0"),
    ("[estimators.ekf]\noutput = 'smoothed'\n", "estimators.ekf.output", "must be"),
    ("[estimators.ekf]\npc_exponent = 'high'\n", "pc_exponent", "must be a number"),
    ("truth = 3\n", "truth", "must be a [section]"),
    ("[star_tracker]\noutages_s = [[3.0, 1.0]]\n", "star_tracker_outages_s", "start < stop"),
])
def test_bad_sections_name_the_key_and_its_section(tmp_path, content, name, rule):
    path = tmp_path / "s.toml"
    path.write_text(content)
    with pytest.raises(InvalidParameterError) as info:
        Scenario.from_toml(path)
    assert str(info.value).startswith(f"{name} = ") and rule in str(info.value)
    assert "\n" not in str(info.value)


def test_estimators_build_from_the_scenario_with_their_options():
    from benchmarks.simulation import build_estimator
    s = Scenario.from_toml(FLIGHT_FILE)
    ekf = build_estimator("ekf", s)
    assert ekf.pc_exponent == -28.5 and ekf.output == "posterior"
    assert ekf.initial_attitude[0] == pytest.approx(0.92759252)
    assert build_estimator("dead-reckoning", s).rate_timing == "step-average"
    assert build_estimator("dead-reckoning", Scenario()).rate_timing == "workshop"
    # A scenario as JSON and back is the same scenario (campaign manifests).
    import json
    again = json.loads(json.dumps(s.as_dict()))
    assert Scenario(**again).as_dict() == s.as_dict()


def test_every_setting_is_declared_once_and_the_tables_come_from_it():
    import dataclasses
    from benchmarks.cli import build_parser
    from benchmarks.commands.options import SCENARIO_FLAGS
    from benchmarks.engine.batch import PER_RUN_SETTINGS, RunTable
    from benchmarks.experiments import SWEEP_PARAMETERS
    from benchmarks.scenario import SECTIONS, SETTINGS
    from estimators import QuaternionEKF
    fields = [f.name for f in dataclasses.fields(Scenario) if f.name != "estimator_options"]
    declared = [setting.field for setting in SETTINGS]
    assert sorted(declared) == sorted(fields) and len(set(declared)) == len(declared)
    assert tuple(RunTable.__dataclass_fields__)[1:] == PER_RUN_SETTINGS
    assert set(PER_RUN_SETTINGS) == {s.field for s in SETTINGS if s.per_run}
    for setting in SETTINGS:
        if setting.section in SECTIONS:
            assert SECTIONS[setting.section][setting.key].field == setting.field
        if setting.sweep:
            assert SWEEP_PARAMETERS[setting.sweep].field == setting.field
        if setting.sweepable and setting.section in SECTIONS:
            assert f"{setting.section}.{setting.key}" in SWEEP_PARAMETERS
    ekf_fields = {QuaternionEKF.scenario_defaults[k] for k in QuaternionEKF.owned_fields}
    assert ekf_fields == {s.field for s in SETTINGS if s.section == "estimators.ekf"}
    args = build_parser().parse_args(["run", "--estimator", "ekf"] + [
        part for field, flag in SCENARIO_FLAGS.items() for part in (flag, "0.5")])
    assert all(getattr(args, field) == 0.5 for field in SCENARIO_FLAGS)
