"""Dead reckoning in the engine: :class:`estimators.DeadReckoning`, the
gyro integrated step by step (``f`` of :func:`estimators.model.propagate_with_jacobian`),
with the workshop's, the step-average or the end rate timing."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from benchmarks.engine.kernels.algebra import propagate
from benchmarks.engine.kernels.borrowed import borrowed
from benchmarks.engine.kernels.common import check_health, error_arrays
from benchmarks.engine.kernels.common import record_error_inlined as record_error
from benchmarks.engine.kernels.cores import on_every_core_of
from benchmarks.engine.kernels.sensors import gyro_arrays, gyro_reading

NAME = "dead-reckoning"


class State(NamedTuple):
    q: np.ndarray                # (B, 4) the estimate
    previous_rate: np.ndarray    # (B, 3) the last step's rate (step-average timing)
    step_average: bool
    skip_first: bool             # "end" timing: reading 0 is not integrated


def initial_state(estimators) -> State:
    """From the per-run objects (``from_scenario``), one per run."""
    return State(q=np.array([e.initial_attitude for e in estimators]),
                 previous_rate=np.zeros((len(estimators), 3)),
                 step_average=estimators[0].rate_timing == "step-average",
                 skip_first=estimators[0].rate_timing == "end")


@njit(cache=True, inline="always", error_model="numpy")
def _run_scratch(batch, run):
    """Run ``run``'s rows of the share's working arrays, borrowed (no atomic
    count at each call that takes them: the kernels package's docstring)."""
    w, F, bits, factor = batch
    return borrowed((w[run], F[run], bits[run], factor[run]))


@njit(cache=True, nogil=True, error_model="numpy")
def advance_runs(first, last, block, sensors, state, record, row):
    """Runs ``first`` to ``last - 1`` through ``block``: the gyro integrated
    (see :mod:`benchmarks.engine.kernels`)."""
    k0, steps, last_step, dt = block.k0, block.steps, block.last_step, block.dt
    q_true = borrowed(block.q_true)
    (omega, gyro_std, normals, scale, has_scale, has_bias, bias_model, bias,
     bias_last) = borrowed(gyro_arrays(block, sensors))
    (stats, hist, first_bits, traces, keep_traces, error_every, samples, diverged, check,
     health) = borrowed(error_arrays(record, row))
    q_all, previous_all = borrowed((state.q, state.previous_rate))
    step_average, skip_first = state.step_average, state.skip_first
    half_dt = 0.5 * dt
    batch = (np.empty((last - first, 3)), np.empty((last - first, 4, 4)),
             np.empty((last - first, 1)), np.empty((last - first, 6, 6)))
    for index in range(first, last):
        run = np.int64(index)
        w, F, bits, factor = _run_scratch(batch, run - first)
        bits_int = bits.view(np.int64)
        q, previous_rate = q_all[run], previous_all[run]
        for j in range(steps):
            k = k0 + j
            gyro_reading(w, run, j, k, last_step, omega, gyro_std, normals, scale, has_scale,
                         has_bias, bias_model, bias, bias_last)
            if not step_average:
                if k > 0 or not skip_first:
                    propagate(q, w, half_dt, q, F, False)
            elif k > 0:
                propagate(q, previous_rate, half_dt, q, F, False)
            record_error(run, k, q_true[j], q, stats, hist, first_bits, traces, keep_traces,
                         error_every, samples, diverged, bits, bits_int)
            if check:
                check_health(q, True, F, 0, health[run], factor)
            if step_average:
                for i in range(3):
                    previous_rate[i] = w[i]


#: Every run of the batch through a block, a share of the runs per core.
advance = on_every_core_of(advance_runs)
