"""Dead reckoning with star-tracker resets in the engine:
:class:`estimators.DeadReckoningWithResets` — the estimate replaced by each
available reading (in the sign nearest the prediction), integrated between."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from benchmarks.engine.kernels.algebra import propagate
from benchmarks.engine.kernels.borrowed import borrowed
from benchmarks.engine.kernels.common import check_health, error_arrays
from benchmarks.engine.kernels.common import record_error_inlined as record_error
from benchmarks.engine.kernels.cores import on_every_core_of
from benchmarks.engine.kernels.sensors import (first_countdown, gyro_arrays, gyro_reading,
                                               star_arrays, star_step)

NAME = "dead-reckoning-resets"


class State(NamedTuple):
    q: np.ndarray                # (B, 4) the estimate
    previous_rate: np.ndarray    # (B, 3) the last step's rate (step-average timing)
    step_average: bool
    skip_first: bool             # "end" timing: reading 0 is not integrated
    align_sign: bool


def initial_state(estimators) -> State:
    """From the per-run objects (``from_scenario``), one per run."""
    first = estimators[0]
    return State(q=np.array([e.initial_attitude for e in estimators]),
                 previous_rate=np.zeros((len(estimators), 3)),
                 step_average=first.rate_timing == "step-average",
                 skip_first=first.rate_timing == "end", align_sign=first.align_sign)


@njit(cache=True, inline="always", error_model="numpy")
def _predict(q, w, previous_rate, k, step_average, skip_first, half_dt, out, F):
    """out = q propagated as the per-run class propagates it at step ``k``."""
    if not step_average and (k > 0 or not skip_first):
        propagate(q, w, half_dt, out, F, False)
    elif step_average and k > 0:
        propagate(q, previous_rate, half_dt, out, F, False)
    else:
        for i in range(4):
            out[i] = q[i]


@njit(cache=True, inline="always", error_model="numpy")
def _run_scratch(batch, run):
    """Run ``run``'s rows of the share's working arrays, borrowed (no atomic
    count at each call that takes them: the kernels package's docstring)."""
    w, z, dq, aligned, F, bits, factor = batch
    return borrowed((w[run], z[run], dq[run], aligned[run], F[run], bits[run], factor[run]))


@njit(cache=True, nogil=True, error_model="numpy")
def advance_runs(first, last, block, sensors, state, record, row):
    """Runs ``first`` to ``last - 1`` through ``block``: resets to each
    reading, integrated between."""
    k0, steps, last_step, dt = block.k0, block.steps, block.last_step, block.dt
    q_true = borrowed(block.q_true)
    (omega, gyro_std, normals, scale, has_scale, has_bias, bias_model, bias,
     bias_last) = borrowed(gyro_arrays(block, sensors))
    star = borrowed(star_arrays(block))
    (stats, hist, first_bits, traces, keep_traces, error_every, samples, diverged, check,
     health) = borrowed(error_arrays(record, row))
    q_all, previous_all = borrowed((state.q, state.previous_rate))
    step_average, skip_first = state.step_average, state.skip_first
    align_sign, half_dt = state.align_sign, 0.5 * dt
    n = last - first
    batch = (np.empty((n, 3)), np.empty((n, 4)), np.empty((n, 4)), np.empty((n, 4)),
             np.empty((n, 4, 4)), np.empty((n, 1)), np.empty((n, 6, 6)))
    for index in range(first, last):
        run = np.int64(index)
        w, z, dq, aligned, F, bits, factor = _run_scratch(batch, run - first)
        bits_int = bits.view(np.int64)
        q, previous_rate = q_all[run], previous_all[run]
        countdown, reading = first_countdown(k0, star, run), 0
        for j in range(steps):
            k = k0 + j
            gyro_reading(w, run, j, k, last_step, omega, gyro_std, normals, scale, has_scale,
                         has_bias, bias_model, bias, bias_last)
            available, countdown, reading = star_step(z, dq, run, j, countdown, reading, q_true,
                                                      star)
            if available:
                flip = False
                if align_sign:
                    # The sign nearest the prediction, as the per-run class compares it.
                    for i in range(4):
                        aligned[i] = q[i]
                    _predict(aligned, w, previous_rate, k, step_average, skip_first, half_dt,
                             aligned, F)
                    flip = (aligned[0] * z[0] + aligned[1] * z[1] + aligned[2] * z[2]
                            + aligned[3] * z[3]) < 0
                for i in range(4):
                    q[i] = -z[i] if flip else z[i]
            else:
                _predict(q, w, previous_rate, k, step_average, skip_first, half_dt, q, F)
            record_error(run, k, q_true[j], q, stats, hist, first_bits, traces, keep_traces,
                         error_every, samples, diverged, bits, bits_int)
            if check:
                check_health(q, True, F, 0, health[run], factor)
            if step_average:
                for i in range(3):
                    previous_rate[i] = w[i]


#: Every run of the batch through a block, a share of the runs per core.
advance = on_every_core_of(advance_runs)
