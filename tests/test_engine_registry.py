"""Adding an estimator to the engine is its kernel module plus one registry
line: a toy kernel, written here and registered from this file alone, runs in
batches like the built-in ones and equals its per-run class."""
import types
from typing import NamedTuple

import numpy as np
import pytest
from numba import njit, prange

from benchmarks import Scenario, simulate
from benchmarks.engine import make_runs, run_batch
from benchmarks.engine.kernels import KERNELS
from benchmarks.engine.kernels.common import record_error
from benchmarks.engine.kernels.sensors import gyro_reading
from estimators import ESTIMATORS, AttitudeEstimator


class Frozen(AttitudeEstimator):
    """The per-run reference: an estimate that never moves from the initial attitude."""

    name, label = "frozen", "Frozen"

    def reset(self):
        self.q = self.initial_attitude.copy()

    def _step(self, omega, reading=None):
        return self.q.copy()


class FrozenState(NamedTuple):
    q: np.ndarray               # (B, 4)


@njit(parallel=True)
def _advance(block, sensors, state, record, row):
    k0, steps, q_true = block.k0, block.steps, block.q_true
    stats, diverged, hist, first_bits = record.stats[row], record.diverged[row], \
        record.hist[row], record.hist_first_bits
    traces, keep, every, samples = record.traces[row], record.keep_traces, \
        record.error_every, record.error_samples[row]
    omega, std, normals = block.omega_true, block.gyro_std, block.gyro_normals
    q_all = state.q
    for run in prange(q_all.shape[0]):
        w = np.empty(3)
        bits = np.empty(1)
        bits_int = bits.view(np.int64)
        for j in range(steps):
            # The toy reads its gyro as every kernel does, and ignores it.
            gyro_reading(w, run, j, k0 + j, block.last_step, omega, std, normals,
                         block.gyro_scale, block.has_scale, block.has_bias,
                         block.bias_model, sensors.bias, sensors.bias_last)
            record_error(run, k0 + j, q_true[j], q_all[run], stats, hist, first_bits, traces,
                         keep, every, samples, diverged, bits, bits_int)


TOY_KERNEL = types.SimpleNamespace(
    NAME="frozen", State=FrozenState, advance=_advance,
    initial_state=lambda estimators: FrozenState(
        q=np.array([e.initial_attitude for e in estimators])))


@pytest.fixture
def registered(monkeypatch):
    """The two registry lines: the per-run class and its kernel."""
    monkeypatch.setitem(ESTIMATORS, "frozen", Frozen)
    monkeypatch.setitem(KERNELS, "frozen", TOY_KERNEL)


@pytest.mark.slow      # its kernel compiled: 4-5 s
def test_a_toy_kernel_registered_from_a_test_file_runs_in_batches(registered):
    scenario = Scenario(tstop=3.0)
    batch = run_batch(scenario, make_runs(scenario, [0, 1, 2]), ["ekf", "frozen"],
                      keep_traces=True)
    assert batch.estimators == ("ekf", "frozen")        # the registry's order
    for seed in range(3):
        reference = simulate(scenario, ["frozen"], seed=seed)
        np.testing.assert_allclose(batch.estimates["frozen"][seed],
                                   reference.estimates["frozen"], atol=1e-9, rtol=0)
        np.testing.assert_allclose(batch.statistics["frozen"]["mean_deg"][seed],
                                   reference.error_deg["frozen"].mean(), rtol=1e-9)
    # The built-in kernel beside it is unchanged by the newcomer.
    alone = run_batch(scenario, make_runs(scenario, [0, 1, 2]), ["ekf"])
    np.testing.assert_array_equal(alone.statistics["ekf"]["mean_deg"],
                                  batch.statistics["ekf"]["mean_deg"])


def test_the_warm_up_compiles_every_kernel_once():
    # The suite's workers and a cluster's compile nothing the warm-up left cold
    # (benchmarks.engine.warm_up): every registered kernel is in one group.
    from benchmarks.engine.warm_up import GROUPS
    grouped = [name for group in GROUPS for name in group if name != "vector-sensors"]
    assert sorted(grouped) == sorted(KERNELS)
