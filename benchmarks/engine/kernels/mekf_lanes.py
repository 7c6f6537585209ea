"""The MEKF's kernel in lanes (:mod:`benchmarks.engine.kernels.lanes`):
eight runs advanced side by side in vector instructions.

Vectorised: the propagation (:mod:`~benchmarks.engine.kernels.mekf_lanes_propagation`:
the bias-corrected rate, Φ's and Q's blocks, P = Φ P Φᵀ + Q, the
quaternion's step), the error's arccos and the Welford sums. Lane by lane:
the library's sines and cosines, the star tracker's readings and updates
(the one-run kernel's :func:`~benchmarks.engine.kernels.mekf_steps.star_update`),
the histogram's count, a divergence and an error above 120°. The buffer's
rows: :mod:`~benchmarks.engine.kernels.mekf_lanes_rows`.

Tried and dropped: the tracker's update in lanes, where every lane has a
reading at the same step (Joseph's form entry by entry, the Gauss–Jordan
and arctangent lane by lane). Written on values it was the same to the bit
and 1.4x as fast as lane by lane (16 % of the kernel), but took over four
minutes to compile; written with helpers that LLVM inlines, a minute, and
no faster.

It covers the campaigns' case, as the EKF's does: statistics only (no
traces, NEES or health checks), a gyro with white noise only, the rate held
over the step, a star tracker and no vector sensor, no IMU model, no
hard-iron state and no scale-factor noise in the filter's model; the
output prior or posterior. Anything else goes through the one-run kernel
(:func:`lanes_apply`).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from benchmarks.engine.kernels import lanes
from benchmarks.engine.kernels.borrowed import borrowed
from benchmarks.engine.kernels.common import error_arrays
from benchmarks.engine.kernels.lanes import CHECK, LANES, Q, three
from benchmarks.engine.kernels.mekf_lanes_propagation import propagate
from benchmarks.engine.kernels.mekf_lanes_rows import BETA, BIAS_RW, NOISE, P, ROWS
from benchmarks.engine.kernels.mekf_steps import star_update
from benchmarks.engine.kernels.sensors import first_countdown, star_arrays


def lanes_apply(block, record, state) -> bool:
    """Whether the lanes kernel covers this block, record and state (the
    module's docstring): otherwise the one-run kernel advances them."""
    return lanes.campaign_case(block, record) and not (
        state.imu_on or state.hard_iron or state.trapezoid.any()
        or block.vector_available.shape[2] > 0 or (state.gyro_errors[:, 2] != 0.0).any())


@njit(cache=True, inline="always", error_model="numpy")
def _star(b, m, due, z, first, filters, work):
    """Each due lane's star tracker update (:func:`lanes.star_readings`), the
    one-run kernel's, on the lane's state copied out and back."""
    R_, gating, gate, mag_bias = filters
    q, beta, P_, scratch, dq = work
    for lane in range(m):
        if due[lane]:
            run = first + lane
            lanes.rows_to_array(b, Q, lane, q)
            lanes.rows_to_array(b, BETA, lane, beta)
            lanes.rows_to_array(b, P, lane, P_)
            star_update(q, beta, P_, z[lane], R_[run], gating[run], gate[run, 3], scratch, dq,
                        mag_bias[run])
            lanes.array_to_rows(b, Q, lane, q)
            lanes.array_to_rows(b, BETA, lane, beta)
            lanes.array_to_rows(b, P, lane, P_)


@njit(cache=True, inline="always", error_model="numpy")
def _finite(b, m):
    """Each lane's divergence test after its step (mekf.advance_runs':
    common.finite_state of q̂ and P, then of β̂): the sums, each times 0, into
    lanes.CHECK (NaN where a sum is not finite). Written out: the sums'
    loops left the lanes' loop scalar."""
    for lane in range(m):
        q0, q1, q2 = three(b, Q, lane)
        total = 0.0 + q0 + q1 + q2 + b[(Q + 3) * LANES + lane]
        trace = (0.0 + b[P * LANES + lane] + b[(P + 7) * LANES + lane]
                 + b[(P + 14) * LANES + lane] + b[(P + 21) * LANES + lane]
                 + b[(P + 28) * LANES + lane] + b[(P + 35) * LANES + lane])
        beta0, beta1, beta2 = three(b, BETA, lane)
        bias = 0.0 + beta0 + beta1 + beta2
        b[CHECK * LANES + lane] = total * 0.0 + trace * 0.0 + bias * 0.0


@njit(cache=True, inline="always", error_model="numpy")
def _group(b, m, first, beta_all, P_all, gyro_errors, back):
    """The group's bias estimates, covariances and gyro models into the
    buffer's rows, or (``back``) the estimates and covariances out of them."""
    for lane in range(m):
        run = first + lane
        if back:
            lanes.rows_to_array(b, BETA, lane, beta_all[run])
            lanes.rows_to_array(b, P, lane, P_all[run])
        else:
            lanes.array_to_rows(b, BETA, lane, beta_all[run])
            lanes.array_to_rows(b, P, lane, P_all[run])
            b[NOISE * LANES + lane] = gyro_errors[run, 0]
            b[BIAS_RW * LANES + lane] = gyro_errors[run, 1]


@njit(cache=True, error_model="numpy")
def _output(b, bits, m, first, k, last_step, q_true_k, errors, words, words_int, last):
    """Each lane's error of its output at step ``k``; at the last step its
    bias estimate and covariance kept for the final report (``last``:
    beta_last, P_last). Called, not inlined: inlined at its two places (the
    prior's and the posterior's) it took 8 s more of the cold compile, and
    its call, once a step for eight runs, costs nothing measurable (a
    1024-run batch 0.91-1.03 s against 0.91-1.01)."""
    lanes.record_error(b, bits, m, first, k, q_true_k, errors, words, words_int)
    if k == last_step:
        for lane in range(m):
            lanes.rows_to_array(b, BETA, lane, last[0][first + lane])
            lanes.rows_to_array(b, P, lane, last[1][first + lane])


@njit(cache=True, nogil=True, error_model="numpy")
def advance_lanes(first, last, block, sensors, state, record, row):
    """Runs ``first`` to ``last - 1`` through ``block``, :data:`LANES` at a
    time: each step's tracker update where a reading comes, the error of the
    output (before the update with the prior as output), then the
    propagation (mekf.advance_runs' order)."""
    k0, steps, last_step, dt = block.k0, block.steps, block.last_step, block.dt
    q_true, star = borrowed((block.q_true, star_arrays(block)))
    omega, std, normals = borrowed((block.omega_true, block.gyro_std, block.gyro_normals))
    errors = borrowed(error_arrays(record, row))
    q_all, beta_all, P_all, gyro_errors, posterior = borrowed(
        (state.q, state.beta, state.P, state.gyro_errors, state.posterior))
    filters = borrowed((state.R, state.gating, state.gate, state.mag_bias))
    kept = borrowed((state.beta_last, state.P_last))
    # Made before the loop, borrowed in it (the kernels package's docstring).
    made = (np.empty(ROWS * LANES), np.empty(1), np.empty(LANES, np.int64),
            np.empty(LANES, np.int64), np.empty(LANES, np.bool_), np.empty((LANES, 4)),
            np.empty(4), (np.empty(4), np.empty(3), np.empty((6, 6)), np.empty((10, 9, 9)),
                          np.empty(4)))
    for group in range(first, last, LANES):
        m = min(LANES, last - group)
        b, words, countdown, reading, due, z, dq, work = borrowed(made)
        bits, words_int = b.view(np.int64), words.view(np.int64)
        lanes.group_errors(b, m, group, q_all, errors[0], errors[7], False)
        _group(b, m, group, beta_all, P_all, gyro_errors, False)
        for lane in range(m):
            countdown[lane], reading[lane] = first_countdown(k0, star, group + lane), 0
        for j in range(steps):
            k = k0 + j
            lanes.gyro(b, m, j, group, omega, std, normals)
            lanes.star_readings(m, group, j, countdown, reading, q_true, star, z, dq, due)
            if not posterior:
                _output(b, bits, m, group, k, last_step, q_true[j], errors, words, words_int,
                        kept)
            _star(b, m, due, z, group, filters, work)
            if posterior:
                _output(b, bits, m, group, k, last_step, q_true[j], errors, words, words_int,
                        kept)
            propagate(b, m, dt)
            _finite(b, m)
            lanes.mark_failed(b, m, group, k, errors)
        lanes.group_errors(b, m, group, q_all, errors[0], errors[7], True)
        _group(b, m, group, beta_all, P_all, gyro_errors, True)
