"""Dead reckoning in the engine: :class:`estimators.DeadReckoning`, the
gyro integrated step by step (``f`` of :func:`estimators.model.propagate_with_jacobian`),
with the workshop's or the step-average rate timing."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit, prange

from benchmarks.engine.kernels.algebra import propagate
from benchmarks.engine.kernels.common import check_health, error_arrays
from benchmarks.engine.kernels.common import record_error_inlined as record_error
from benchmarks.engine.kernels.sensors import gyro_arrays, gyro_reading

NAME = "dead-reckoning"


class State(NamedTuple):
    q: np.ndarray                # (B, 4) the estimate
    previous_rate: np.ndarray    # (B, 3) the last step's rate (step-average timing)
    step_average: bool


def initial_state(estimators) -> State:
    """From the per-run objects (``from_scenario``), one per run."""
    return State(q=np.array([e.initial_attitude for e in estimators]),
                 previous_rate=np.zeros((len(estimators), 3)),
                 step_average=estimators[0].rate_timing == "step-average")


@njit(parallel=True, cache=True, nogil=True, error_model="numpy")
def advance(block, sensors, state, record, row):
    """Every run through ``block``: the gyro integrated (see :mod:`benchmarks.engine.kernels`)."""
    k0, steps, last_step, dt, q_true = block.k0, block.steps, block.last_step, block.dt, \
        block.q_true
    (omega, gyro_std, normals, scale, has_scale, has_bias, bias_model, bias,
     bias_last) = gyro_arrays(block, sensors)
    (stats, hist, first_bits, traces, keep_traces, error_every, samples, diverged, check,
     health) = error_arrays(record, row)
    q_all, previous_all, step_average = state.q, state.previous_rate, state.step_average
    half_dt = 0.5 * dt
    for index in prange(q_all.shape[0]):
        run = np.int64(index)
        w = np.empty(3)
        F = np.empty((4, 4))
        bits = np.empty(1)
        bits_int = bits.view(np.int64)
        factor = np.empty((6, 6))
        q, previous_rate = q_all[run], previous_all[run]
        for j in range(steps):
            k = k0 + j
            gyro_reading(w, run, j, k, last_step, omega, gyro_std, normals, scale, has_scale,
                         has_bias, bias_model, bias, bias_last)
            if not step_average:
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

