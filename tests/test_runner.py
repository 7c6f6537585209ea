"""The one runner: the engine and the per-run path give one result."""
import numpy as np

from benchmarks import Scenario
from benchmarks.engine import make_runs, run_many

#: The MEKF by its class path: not a registry name, so it runs per run.
PER_RUN_MEKF = "estimators.mekf:MultiplicativeEKF"


def test_the_engine_and_the_per_run_path_agree_through_the_runner():
    scenario = Scenario(tstop=2.0)
    runs = make_runs(scenario, [0, 1, 2], gyro_noise=[1e-5, 4e-5, 1e-6])
    batch = run_many(scenario, runs, ["mekf", PER_RUN_MEKF], keep_traces=True,
                     consistency=True, nees_every=7, settle_steps=20, per_run_limit=2,
                     chunk_runs=2)
    engine, per_run = "mekf", PER_RUN_MEKF
    assert batch.estimates[engine].shape == (3, scenario.n_steps, 4)
    assert batch.estimates[per_run].shape == (2, scenario.n_steps, 4)   # the limit
    assert np.abs(batch.estimates[engine][:2] - batch.estimates[per_run]).max() < 1e-9
    assert np.allclose(batch.attitude_variances[engine][:2], batch.attitude_variances[per_run],
                       rtol=1e-9, atol=0)
    assert np.allclose(batch.statistics[engine]["rms_deg"][:2],
                       batch.statistics[per_run]["rms_deg"], rtol=1e-9)
    for key in ("nees_samples", "nees_time_average", "nis_mean"):
        assert np.allclose(batch.consistency[engine][key][:2], batch.consistency[per_run][key],
                           rtol=1e-6), key
    assert batch.consistency[engine]["nis_dof"] == batch.consistency[per_run]["nis_dof"] == 3
    assert (batch.diverged_step[engine] == -1).all() and (batch.diverged_step[per_run] == -1).all()
