"""A user's own estimator, from Python and from the command line."""
import textwrap

import numpy as np
import pandas as pd
import pytest

from benchmarks.cli import main

MODULE = textwrap.dedent('''
    import numpy as np
    from estimators import AttitudeEstimator
    from dynamics.quaternion import quat_from_rotvec, quat_multiply


    class Complementary(AttitudeEstimator):
        name, label = "complementary", "Complementary filter"

        def __init__(self, *, dt=0.01, initial_attitude=(1.0, 0.0, 0.0, 0.0), gain=0.05,
                     on_invalid="raise"):
            super().__init__(dt=dt, initial_attitude=initial_attitude, on_invalid=on_invalid)
            self.gain = gain
            self.reset()

        def reset(self):
            self.attitude = self.initial_attitude.copy()

        def _step(self, omega, reading=None):
            if reading is not None:
                reading = reading if reading @ self.attitude >= 0 else -reading
                q = self.attitude + self.gain * (reading - self.attitude)
                self.attitude = q / np.linalg.norm(q)
            estimate = self.attitude.copy()
            q = quat_multiply(self.attitude, quat_from_rotvec(omega * self.dt))
            self.attitude = q / np.linalg.norm(q)
            return estimate


    class NotAnEstimator:
        pass
''')


def user_module(tmp_path, monkeypatch):
    package = tmp_path / "userpkg"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "filters.py").write_text(MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    return "userpkg.filters:Complementary"


def test_users_estimator_in_compare_montecarlo_and_consistency(tmp_path, monkeypatch, capsys):
    spec = user_module(tmp_path, monkeypatch)
    common = ["--tstop", "5", "--quiet"]
    assert main(["compare", "--estimators", f"ekf,{spec}", "--out", str(tmp_path / "c"),
                 *common]) == 0
    summary = pd.read_csv(tmp_path / "c" / "summary.csv")
    assert list(summary["estimator"]) == ["ekf", spec]
    assert main(["montecarlo", "--estimators", f"ekf,{spec}", "--runs", "3", "--out",
                 str(tmp_path / "m"), *common]) == 0
    runs = pd.read_csv(tmp_path / "m" / "montecarlo.csv")
    mine = runs[runs["estimator"] == spec]
    assert len(mine) == 3 and np.all(mine["mean_deg"] > 0)
    # The campaign's per-run statistics are the per-run path's, seed by seed.
    from benchmarks import Scenario, error_statistics, simulate
    expected = error_statistics(simulate(Scenario(tstop=5.0), [spec], seed=2).error_deg[spec])
    assert mine["std_deg"].iloc[2] == expected["std_deg"]
    assert main(["consistency", "--estimators", f"mekf,{spec}", "--runs", "3",
                 "--per-run-limit", "2", "--out", str(tmp_path / "k"), *common]) == 0
    assert "no covariance" in capsys.readouterr().out
    # An estimator without a kernel runs per run, at most --per-run-limit seeds.
    frame = pd.read_csv(tmp_path / "k" / "consistency.csv")
    assert (frame[frame["estimator"] == "mekf"]["runs"] == 3).all()
    assert (frame[frame["estimator"] == spec]["runs"] == 2).all()


def test_bad_user_specs_are_one_line_errors(tmp_path, monkeypatch, capsys):
    user_module(tmp_path, monkeypatch)
    for spec, text in (("userpkg.filters:NotAnEstimator", "must be a subclass"),
                       ("userpkg.missing:Thing", "cannot import userpkg.missing"),
                       ("userpkg.filters:", "package.module:ClassName")):
        assert main(["compare", "--estimators", spec, "--out", str(tmp_path / "x")]) == 2
        err = capsys.readouterr().err
        assert text in err and err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "x").exists()


def test_users_estimator_takes_its_own_scenario_section(tmp_path, monkeypatch, capsys):
    spec = user_module(tmp_path, monkeypatch)
    from benchmarks import Scenario
    from benchmarks.simulation import build_estimator
    scenario_file = tmp_path / "s.toml"
    scenario_file.write_text(f'tstop = 2.0\n[estimators."{spec}"]\ngain = 0.5\n')
    scenario = Scenario.from_toml(scenario_file, allow_imports=[spec])
    assert build_estimator(spec, scenario).gain == 0.5
    assert build_estimator(spec, Scenario()).gain == 0.05            # the class's default
    assert main(["compare", "--scenario", str(scenario_file), "--estimators", spec,
                 "--out", str(tmp_path / "c"), "--quiet"]) == 0
    capsys.readouterr()
    scenario_file.write_text(f'[estimators."{spec}"]\nwobble = 1\n')
    assert main(["compare", "--scenario", str(scenario_file), "--out", str(tmp_path / "x"),
                 "--allow-import", spec.partition(":")[0]]) == 2
    assert capsys.readouterr().err == (
        f'attitude-bench: error: estimators."{spec}".wobble = 1: is not a setting of {spec}; '
        "known: initial_attitude, gain, on_invalid\n")
    assert not (tmp_path / "x").exists()


def test_a_module_in_the_current_folder_imports_from_the_command_line(tmp_path, monkeypatch):
    # As a console script sees it: the current folder is not on the path.
    (tmp_path / "myfilters.py").write_text(MODULE)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("sys.path", [p for p in __import__("sys").path
                                     if p not in ("", str(tmp_path))])
    assert main(["compare", "--estimators", "ekf,myfilters:Complementary", "--tstop", "2",
                 "--out", str(tmp_path / "c"), "--quiet"]) == 0
    summary = pd.read_csv(tmp_path / "c" / "summary.csv")
    assert list(summary["estimator"]) == ["ekf", "myfilters:Complementary"]


@pytest.mark.slow
def test_dask_workers_import_a_users_module_from_the_main_process_path(tmp_path, monkeypatch):
    __import__("pytest").importorskip("distributed")
    spec = user_module(tmp_path, monkeypatch)          # on sys.path only, not PYTHONPATH
    monkeypatch.delenv("PYTHONPATH", raising=False)
    from benchmarks import Scenario
    from benchmarks.engine.campaign import Campaign, run_campaign
    campaign = Campaign(Scenario(tstop=1.0), ("ekf", spec), runs=4, base_seed=0, chunk_runs=2)
    on_dask = run_campaign(campaign, tmp_path / "dask", workers=2)
    in_process = run_campaign(campaign, tmp_path / "local")
    pd.testing.assert_frame_equal(on_dask, in_process, check_exact=True)
    assert set(on_dask["estimator"]) == {"ekf", spec}
