"""Scenario defaults, TOML loading and validation."""
import tomllib
from pathlib import Path

import numpy as np
import pytest

from benchmarks.scenario import Scenario, field_names
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


def test_shipped_default_file_matches_the_defaults_and_names_every_field():
    with DEFAULT_FILE.open("rb") as handle:
        assert set(tomllib.load(handle)) == set(field_names())
    assert Scenario.from_toml(DEFAULT_FILE).as_dict() == Scenario().as_dict()


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
