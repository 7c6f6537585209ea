"""``--set SECTION.KEY=VALUE``: one setting over the scenario files, under the
name the file gives it (issue 31: one name from the file to the command line)."""
import dataclasses

import numpy as np
import pytest

from benchmarks.commands.scenario_args import set_layer
from benchmarks.scenario import Scenario
from dynamics.validation import InvalidParameterError
from tests.test_cli import assert_clean_failure


def fields(scenario: Scenario) -> dict:
    return {f.name: getattr(scenario, f.name) for f in dataclasses.fields(scenario)}


def assert_same(one: Scenario, other: Scenario) -> None:
    a, b = fields(one), fields(other)
    assert a.keys() == b.keys()
    for name in a:
        assert np.array_equal(np.asarray(a[name], dtype=object),
                              np.asarray(b[name], dtype=object)), name


def test_set_reads_as_the_file_that_says_the_same(tmp_path):
    # Datasheet units, a string, a list, a top-level key and an estimator's
    # option, each as the file line that says it.
    assignments = ["gyro.arw_deg_per_rthr=0.15", "star_tracker.model=rotation",
                   "star_tracker.sigma_arcsec=[5.0, 5.0, 30.0]", "tstop=12.5",
                   "estimators.mekf.gate_probability=0.99"]
    change = tmp_path / "change.toml"
    change.write_text('tstop = 12.5\n[gyro]\narw_deg_per_rthr = 0.15\n[star_tracker]\n'
                      'model = "rotation"\nsigma_arcsec = [5.0, 5.0, 30.0]\n'
                      '[estimators.mekf]\ngate_probability = 0.99\n')
    base = "scenarios/flight.toml"
    by_set = Scenario.from_toml([base, set_layer(assignments)])
    assert_same(by_set, Scenario.from_toml([base, change]))
    assert by_set.gyro.arw_deg_per_rthr == pytest.approx(0.15)
    assert by_set.tstop == 12.5 and by_set.star_tracker_model == "rotation"
    # and it differs from the file alone, so the comparison could fail
    assert by_set.gyro_noise != Scenario.from_toml(base).gyro_noise


def test_a_later_set_overrides_an_earlier_one_and_the_files():
    layer = set_layer(["star_tracker.interval_s=0.5", "star_tracker.interval_s=1.0"])
    scenario = Scenario.from_toml(["scenarios/default.toml", layer])
    assert scenario.time_between_measurements == 1.0


@pytest.mark.parametrize("assignment", ["garbage", "gyro.=1", "=1", "gyro.noise_power=",
                                        ".x=1"])
def test_a_malformed_assignment_names_the_rule(assignment):
    with pytest.raises(InvalidParameterError, match="SECTION.KEY=VALUE"):
        set_layer([assignment])


@pytest.mark.parametrize("argv, expected", [
    (["--set", "gyro.nope=1"], ("gyro.nope", "known: noise_power")),
    (["--set", "garbage"], ("'garbage'", "SECTION.KEY=VALUE")),
    (["--set", "gyro.noise_power=-1"], ("gyro.noise_power (gyro_noise) = -1",
                                         "must be >= 0")),
])
def test_a_bad_set_is_one_line_and_writes_nothing(tmp_path, capsys, argv, expected):
    out = tmp_path / "out"
    assert_clean_failure(capsys, out, ["compare", "--tstop", "1", "--out", str(out), *argv],
                         *expected)
