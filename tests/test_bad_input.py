"""Inputs that used to end in a traceback or a silent surprise: each now gets
one clear line (issue 9's "What was seen")."""
import numpy as np
import pytest

from benchmarks import Scenario
from benchmarks.cli import main
from benchmarks.engine import make_runs
from dynamics.validation import InvalidParameterError
from estimators import QuaternionEKF


@pytest.mark.parametrize("build", [
    lambda: Scenario(pc_exponent=710.0),
    lambda: QuaternionEKF(pc_exponent=1e4),
    lambda: make_runs(Scenario(), [0], pc_exponent=[800.0]),
])
def test_pc_exponent_too_large_is_a_value_error_not_an_overflow(build):
    with pytest.raises(InvalidParameterError, match="pc_exponent = .*must be <= 709"):
        build()


def test_pc_exponent_too_large_from_the_command_line_and_a_file(tmp_path, capsys):
    assert main(["compare", "--pc-exponent", "710", "--out", str(tmp_path / "a")]) == 2
    assert "pc_exponent = 710.0: must be <= 709" in capsys.readouterr().err
    scenario = tmp_path / "s.toml"
    scenario.write_text("pc_exponent = 1000.0\n")
    assert main(["compare", "--scenario", str(scenario), "--out", str(tmp_path / "b")]) == 2
    assert "pc_exponent = 1000.0" in capsys.readouterr().err
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


@pytest.mark.parametrize("seeds", [[1.7], [-1], [2 ** 63], ["one"], [True]])
def test_make_runs_refuses_seeds_that_are_not_int64_whole_numbers(seeds):
    with pytest.raises(InvalidParameterError, match="seed"):
        make_runs(Scenario(tstop=1.0), seeds)


@pytest.mark.parametrize("argv, text", [
    (["tune", "--seeds", "9223372036854775808"], "at most 2^63 - 1"),
    (["montecarlo", "--seed", "9223372036854775807", "--runs", "3"], "would pass 2^63 - 1"),
    (["montecarlo", "--seed", "9223372036854775808"], "from 0 to 9223372036854775807"),
    (["montecarlo", "--estimators", "ekf,ekf"], "names ekf more than once"),
    (["compare", "--estimators", "mekf,ekf,mekf"], "names mekf more than once"),
])
def test_seed_and_estimator_lists_refused_before_anything_is_written(tmp_path, capsys, argv,
                                                                     text):
    out = tmp_path / "out"
    assert main([*argv, "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert text in err and "Traceback" not in err and err.count("\n") == 1
    assert not out.exists()


def test_largest_seed_still_runs():
    runs = make_runs(Scenario(tstop=1.0), [2 ** 63 - 1])
    assert runs.seeds.dtype == np.int64 and runs.seeds[0] == 2 ** 63 - 1
