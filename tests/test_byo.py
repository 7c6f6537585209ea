"""A user's own estimator, from Python and from the command line."""
import textwrap

import numpy as np
import pandas as pd

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
    assert main(["consistency", "--estimators", f"mekf,{spec}", "--runs", "2", "--out",
                 str(tmp_path / "k"), *common]) == 0
    assert "no covariance" in capsys.readouterr().out


def test_bad_user_specs_are_one_line_errors(tmp_path, monkeypatch, capsys):
    user_module(tmp_path, monkeypatch)
    for spec, text in (("userpkg.filters:NotAnEstimator", "must be a subclass"),
                       ("userpkg.missing:Thing", "cannot import userpkg.missing"),
                       ("userpkg.filters:", "package.module:ClassName")):
        assert main(["compare", "--estimators", spec, "--out", str(tmp_path / "x")]) == 2
        err = capsys.readouterr().err
        assert text in err and err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "x").exists()
