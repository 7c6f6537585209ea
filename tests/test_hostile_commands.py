"""The third audit's hostile cases on the commands and the Python API: each
gets one clean line (exit 2, nothing written) or a right answer."""
import textwrap

import numpy as np
import pytest

from benchmarks.cli import main
from benchmarks.engine.runner import run_many
from benchmarks.engine.batch import make_runs
from benchmarks.scenario import Scenario
from benchmarks.simulation import simulate
from dynamics.validation import InvalidParameterError
from estimators import MultiplicativeEKF
from estimators.base import InvalidMeasurementError
from sensors.vector import VectorObservation, VectorReadings

CUBESAT = "scenarios/cubesat.toml"
SHIPPED_02 = "datasets/broad/02_undisturbed_slow_rotation_B.npz"


def _refused(argv, tmp_path, capsys) -> str:
    """The one line of a refused command, after checking it wrote nothing."""
    out = tmp_path / "o"
    assert main([*argv, "--quiet", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert not out.exists()
    return err


@pytest.mark.parametrize("argv, first_line", [
    # A test set that is the training set by content, or of another kind.
    (["tune", "--estimator", "mekf", "--dataset", "broad-02", "--test-dataset", SHIPPED_02],
     "test set = ['broad-02']: must share no seed or recording"),
    (["tune", "--estimator", "mekf", "--dataset", "broad-02", "--dataset", SHIPPED_02],
     "holds the same recording as broad-02"),
    (["replay", "--estimators", "mekf", "--tuned", "rms", "--train-dataset", SHIPPED_02],
     "must share no seed or recording"),
    (["tune", "--estimator", "mekf", "--dataset", "broad-02", "--test-seeds", "3"],
     "test set = ['seed 3']: must be of the training set's kind (recordings)"),
    (["tune", "--estimator", "mekf", "--dataset", "broad-02", "--seeds", "3"],
     "training seeds = [3]: are simulated"),
    (["tune", "--estimator", "mekf", "--dataset", "broad-02", "--tstop", "3"],
     "tstop = 3.0: a recording's scenario comes from it"),
    (["tune", "--estimator", "mekf", "--tstop", "2", "--range", "gyro_noise=1e-8:1e-4",
      "--range", "gyro_noise=1e-7:1e-5"], "range = 'gyro_noise': given more than once"),
    (["tune", "--estimator", "mekf", "--tstop", "2", "--xtol", "nan"], "xtol = nan: must be finite"),
    (["tune", "--estimator", "mekf", "--tstop", "2", "--xtol", "-1"], "xtol = -1.0: must be > 0"),
    (["tune", "--estimator", "mekf", "--tstop", "2", "--xtol", "1e9"],
     "xtol = 1000000000.0: must be below the search interval's width"),
    (["tune", "--tstop", "2", "--xtol", "1e9"],
     "xtol = 1000000000.0: must be below the search interval's width (16"),
    (["compare", "--allow-import", ""], "allow_import = '': must be a module name"),
])
def test_nonsense_is_refused_in_one_line(argv, first_line, tmp_path, capsys):
    assert first_line in _refused(argv, tmp_path, capsys)


def test_a_module_that_exits_on_import_is_refused_not_obeyed(tmp_path, monkeypatch, capsys):
    (tmp_path / "quitter.py").write_text("import sys\nsys.exit(0)\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    err = _refused(["compare", "--estimators", "quitter:Filter"], tmp_path, capsys)
    assert "cannot import quitter: it calls sys.exit(0) when imported" in err


def test_a_users_class_named_like_a_registry_one_gets_only_its_own_section(tmp_path,
                                                                         monkeypatch):
    (tmp_path / "namesake.py").write_text(textwrap.dedent('''
        from estimators import DeadReckoning

        class Mine(DeadReckoning):
            name, label = "mekf", "Not the MEKF"
    '''))
    monkeypatch.syspath_prepend(str(tmp_path))
    # [estimators.mekf]'s keywords are the MEKF's: handed to this class they
    # were a TypeError.
    scenario = Scenario(estimator_options={"mekf": {"gyro_noise": 1e-6}})
    result = simulate(scenario.replace(tstop=1.0), ["namesake:Mine"])
    assert np.isfinite(result.error_deg["namesake:Mine"]).all()


@pytest.mark.parametrize("vectors, rule", [
    (VectorObservation(np.ones(3), np.ones(3), 0.01, "magnetometer"),
     "must be a sequence of VectorObservation"),
    ([VectorObservation(np.ones(3), np.ones(3), "0.01", "magnetometer")], "a variance > 0"),
    ([VectorObservation(np.ones(3), np.ones(3), None, "magnetometer")], "a variance > 0"),
])
def test_bad_vector_readings_from_python_are_measurement_errors(vectors, rule):
    with pytest.raises(InvalidMeasurementError, match=rule):
        MultiplicativeEKF().step(np.zeros(3), None, 0.0, vectors=vectors)


def test_one_sensors_readings_not_in_a_list_are_refused():
    n = 5
    readings = VectorReadings("magnetometer", np.ones((n, 3)), np.ones((n, 3)),
                              np.ones(n, bool), np.ones(n))
    with pytest.raises(InvalidMeasurementError, match="must be a sequence of VectorReadings"):
        MultiplicativeEKF().run(np.zeros((n, 3)), np.tile([1.0, 0, 0, 0], (n, 1)),
                                np.zeros(n, bool), vectors=readings)


def test_convergence_reports_a_diverged_filter_with_exit_3(tmp_path, capsys):
    assert main(["convergence", "--estimators", "ekf", "--pc-exponent", "709", "--tstop", "5",
                 "--seeds", "0", "--quiet", "--out", str(tmp_path)]) == 3
    assert "ekf diverged in 3 of 3 runs" in capsys.readouterr().err


def test_show_config_calls_a_given_value_given_even_at_its_default(tmp_path, capsys):
    given = tmp_path / "given.toml"
    given.write_text("[gyro]\nnoise_power = 1e-5\n")        # the workshop's own value
    assert main(["show-config", "--scenario", str(given), "--estimators", "mekf"]) == 0
    line = next(l for l in capsys.readouterr().out.splitlines() if "gyro_noise" in l)
    assert line.split()[2] == "scenario"
    assert main(["show-config", "--estimators", "mekf"]) == 0
    line = next(l for l in capsys.readouterr().out.splitlines() if "gyro_noise" in l)
    assert line.split()[2] == "default"


def test_show_config_takes_every_commands_flags_and_writes_its_table(tmp_path):
    assert main(["show-config", "--estimators", "mekf,ekf", "--quiet", "--allow-divergence",
                 "--out", str(tmp_path)]) == 0
    rows = (tmp_path / "config.csv").read_text().splitlines()
    assert rows[0] == "estimator,setting,value,source,from"
    assert {row.split(",")[0] for row in rows[1:]} == {"mekf", "ekf"}


def test_montecarlo_tuned_resume_into_an_empty_folder_writes_nothing(tmp_path, capsys):
    out = tmp_path / "m"
    assert main(["montecarlo", "--resume", "--tuned", "rms", "--runs", "2", "--tstop", "1",
                 "--estimators", "ekf", "--quiet", "--out", str(out)]) == 2
    assert "holds no campaign to resume" in capsys.readouterr().err
    assert not out.exists()


def test_montecarlo_tuned_into_a_campaigns_folder_keeps_its_files(tmp_path, capsys):
    out = tmp_path / "m"
    common = ["--runs", "2", "--tstop", "1", "--estimators", "ekf", "--quiet", "--out", str(out)]
    assert main(["montecarlo", *common]) == 0
    before = {path.name: path.read_bytes() for path in out.iterdir() if path.is_file()}
    assert main(["montecarlo", "--tuned", "rms", "--train-seeds", "7", *common]) == 2
    assert "already holds a campaign" in capsys.readouterr().err
    after = {path.name: path.read_bytes() for path in out.iterdir() if path.is_file()}
    assert after == before and "tuned.toml" not in after


def test_a_figure_that_cannot_be_drawn_leaves_no_new_summary(tmp_path, monkeypatch):
    from benchmarks.experiments import runs
    out = tmp_path / "c"
    assert main(["compare", "--tstop", "1", "--quiet", "--out", str(out)]) == 0
    old = (out / "summary.csv").read_bytes()

    def broken(*_args, **_kwargs):
        raise MemoryError("cannot draw")
    monkeypatch.setattr(runs, "comparison_figure", broken)
    with pytest.raises(MemoryError):
        main(["compare", "--tstop", "1", "--seed", "5", "--quiet", "--out", str(out)])
    assert (out / "summary.csv").read_bytes() == old


def test_the_per_run_limit_caps_every_estimator_on_the_per_run_path():
    # Gating sends the EKF to the per-run path (its kernel has no gate).
    scenario = Scenario.from_toml(CUBESAT).replace(
        tstop=10.0, estimator_options={"ekf": {"gate_probability": 0.999}})
    with pytest.warns(UserWarning, match="per-run path"):
        batch = run_many(scenario, make_runs(scenario, range(4)), ["ekf", "mekf"],
                         per_run_limit=2)
    assert len(batch.diverged_step["ekf"]) == 2        # was 4: the EKF has a kernel
    assert len(batch.diverged_step["mekf"]) == 4       # on the engine, every run


def test_the_bias_prior_covers_the_declared_initial_bias(tmp_path):
    toml = tmp_path / "bias.toml"
    toml.write_text("[gyro]\ninitial_bias_deg_per_hr = [234.0, -50.0, 0.0]\n")
    scenario = Scenario.from_toml(["scenarios/smallsat.toml", toml])
    sigma = np.asarray(MultiplicativeEKF.configured_settings(scenario)["initial_bias_sigma_radps"])
    assert np.all(sigma >= np.abs(scenario.gyro_initial_bias_radps))
    assert sigma[2] == 1e-4                  # the default where the bias is smaller
    # Below the default σ, nothing changes: the shipped scenarios keep their numbers.
    smallsat = Scenario.from_toml("scenarios/smallsat.toml")
    assert "initial_bias_sigma_radps" not in MultiplicativeEKF.settings_from_scenario(smallsat)


def test_an_unmodelled_hard_iron_is_said(tmp_path):
    toml = tmp_path / "hard.toml"
    toml.write_text("[magnetometer]\nbias_nT = [950.0, 0.0, 0.0]\n")
    scenario = Scenario.from_toml([CUBESAT, toml]).replace(tstop=20.0)
    # The MEKF estimates a declared hard iron (tests/test_magnetometer_bias_states.py):
    # USQUE and the EKF do not.
    with pytest.warns(UserWarning, match=r"hard iron \(bias_nT = \[950.0, 0.0, 0.0\]\) is in "
                                         r"the simulated readings but in no estimator's model "
                                         r"\(usque\)"):
        simulate(scenario, ["mekf", "usque", "dead-reckoning"])
    with pytest.warns(UserWarning, match=r"no estimator's model \(usque, ekf\)"):
        run_many(scenario, make_runs(scenario, range(2)), ["usque", "ekf"])
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        simulate(scenario, ["dead-reckoning"])       # it reads no magnetometer: nothing to say
        simulate(Scenario.from_toml(CUBESAT).replace(tstop=20.0), ["mekf"])


def test_seeds_and_recordings_are_one_kind_each_in_the_python_api():
    from benchmarks.experiments.estimator_tuning import cases_of
    with pytest.raises(InvalidParameterError, match="are simulated"):
        cases_of(Scenario(), seeds=(0,), datasets=["broad-02"])


@pytest.mark.parametrize("command", ["run", "compare", "sweep", "tune", "landscape", "animate",
                                     "montecarlo", "consistency", "replay", "broad", "workshop",
                                     "show-config", "wahba", "convergence"])
def test_every_command_takes_the_flags_every_command_takes(command, capsys):
    """The README: every command takes --out, --quiet and --allow-divergence."""
    with pytest.raises(SystemExit) as exit_:
        main([command, "--help"])
    assert exit_.value.code == 0
    shown = capsys.readouterr().out
    for flag in ("--out", "--quiet", "--allow-divergence"):
        assert flag in shown, (command, flag)


@pytest.mark.parametrize("section, key, first_line", [
    ("gyro", "initial_bias_radps = [1e100, 0, 0]",
     "gyro.initial_bias_radps (gyro_initial_bias_radps) = [1e+100, 0, 0]: "
     "must be at most 10 rad/s"),
    ("gyro", "bias_random_walk = 1e100",
     "gyro.bias_random_walk (gyro_bias_random_walk) = 1e+100: must be at most 1"),
    ("gyro", "bias_instability_radps = 1e100",
     "gyro.bias_instability_radps (gyro_bias_instability_radps) = 1e+100: must be at most 10"),
    ("star_tracker", 'model = "rotation"\nsigma_arcsec = 1e100',
     "star_tracker.sigma_arcsec (star_tracker_sigma_arcsec) = [1e+100, 1e+100, 1e+100]: "
     "must be at most 648000 arcsec"),
])
def test_huge_sensor_settings_are_refused_by_their_own_keys(section, key, first_line, tmp_path,
                                                           capsys):
    """Were accepted, and refused only at step 0 as a rate beyond ±1000 rad/s."""
    toml = tmp_path / "huge.toml"
    toml.write_text(f"[{section}]\n{key}\n")
    assert first_line in _refused(["compare", "--scenario", str(toml)], tmp_path, capsys)
