"""The workshop EKF's kernel in lanes (:mod:`benchmarks.engine.kernels.lanes`):
eight runs advanced side by side in vector instructions. On one thread of
the 2-core development machine: 46–57 ns a run-step against the one-run
kernel's 107; on a slower day, with its divergence test written out
(:func:`_finite`), 64–74 ns against 91–98 before.

Vectorised: the propagation and its Jacobian, P = F P Fᵀ + Q, the
error's arccos and the Welford sums. Lane by lane, with the one-run
kernel's functions: the star tracker's readings and updates
(:mod:`~benchmarks.engine.kernels.ekf_update`), the histogram's count, a
divergence and an error above 120°.

It covers the campaigns' case — a Monte Carlo campaign, a landscape, a
tuning grid: statistics only (no traces, NEES or health checks), the prior
as output, the rate held over the step, a gyro with white noise only.
Anything else goes through the one-run kernel (:func:`lanes_apply`).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from benchmarks.engine.kernels import lanes
from benchmarks.engine.kernels.borrowed import borrowed
from benchmarks.engine.kernels.common import error_arrays
from benchmarks.engine.kernels.ekf_update import align, ekf_update
from benchmarks.engine.kernels.lanes import CHECK, LANES, Q, W
from benchmarks.engine.kernels.sensors import first_countdown, star_arrays

# A group's buffer after the rows every kernel in lanes has (the state x is
# lanes.Q's), LANES numbers a row: P (row-major), the Jacobian F, Q's diagonal.
_P, _F, _QV, _ROWS = lanes.first_rows(lanes.OWN_ROWS, P=16, F=16, q_variance=1)


def lanes_apply(block, record, state) -> bool:
    """Whether the lanes kernel covers this block, record and state (the
    module's docstring): otherwise the one-run kernel advances them."""
    return lanes.campaign_case(block, record) and not (state.posterior or state.end)


@njit(cache=True, inline="always", error_model="numpy")
def _propagate(b, m, half_dt):
    """x = f(x, ω) and F = ∂f/∂x on every lane: algebra.propagate's
    arithmetic, term by term."""
    for lane in range(m):
        p, qq, r = b[W * LANES + lane], b[(W + 1) * LANES + lane], b[(W + 2) * LANES + lane]
        a = ((1.0, -half_dt * p, -half_dt * qq, -half_dt * r),
             (half_dt * p, 1.0, half_dt * r, -half_dt * qq),
             (half_dt * qq, -half_dt * r, 1.0, half_dt * p),
             (half_dt * r, half_dt * qq, -half_dt * p, 1.0))
        q0, q1, q2 = b[Q * LANES + lane], b[(Q + 1) * LANES + lane], b[(Q + 2) * LANES + lane]
        q3 = b[(Q + 3) * LANES + lane]
        g = (a[0][0] * q0 + a[0][1] * q1 + a[0][2] * q2 + a[0][3] * q3,
             a[1][0] * q0 + a[1][1] * q1 + a[1][2] * q2 + a[1][3] * q3,
             a[2][0] * q0 + a[2][1] * q1 + a[2][2] * q2 + a[2][3] * q3,
             a[3][0] * q0 + a[3][1] * q1 + a[3][2] * q2 + a[3][3] * q3)
        norm = math.sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2] + g[3] * g[3])
        n = (g[0] / norm, g[1] / norm, g[2] / norm, g[3] / norm)
        inv_norm = 1.0 / norm
        for i in range(4):
            b[(Q + i) * LANES + lane] = n[i]
        for j in range(4):
            c = n[0] * a[0][j] + n[1] * a[1][j] + n[2] * a[2][j] + n[3] * a[3][j]
            for i in range(4):
                b[(_F + 4 * i + j) * LANES + lane] = (a[i][j] - n[i] * c) * inv_norm


@njit(cache=True, inline="always", error_model="numpy")
def _sixteen(b, row, lane):
    """Rows ``row`` to ``row + 15`` of one lane: a 4x4 matrix, row-major, as
    values (kept in registers, where the vectorizer wants them)."""
    return (b[row * LANES + lane], b[(row + 1) * LANES + lane], b[(row + 2) * LANES + lane],
            b[(row + 3) * LANES + lane], b[(row + 4) * LANES + lane],
            b[(row + 5) * LANES + lane], b[(row + 6) * LANES + lane],
            b[(row + 7) * LANES + lane], b[(row + 8) * LANES + lane],
            b[(row + 9) * LANES + lane], b[(row + 10) * LANES + lane],
            b[(row + 11) * LANES + lane], b[(row + 12) * LANES + lane],
            b[(row + 13) * LANES + lane], b[(row + 14) * LANES + lane],
            b[(row + 15) * LANES + lane])


@njit(cache=True, inline="always", error_model="numpy")
def _covariance(b, m):
    """P = F P Fᵀ + Q on every lane, in ekf._ekf_predict's order (F P, then
    its upper triangle times Fᵀ, mirrored, then Q's diagonal)."""
    for lane in range(m):
        F, P = _sixteen(b, _F, lane), _sixteen(b, _P, lane)
        FP = (F[0] * P[0] + F[1] * P[4] + F[2] * P[8] + F[3] * P[12],
              F[0] * P[1] + F[1] * P[5] + F[2] * P[9] + F[3] * P[13],
              F[0] * P[2] + F[1] * P[6] + F[2] * P[10] + F[3] * P[14],
              F[0] * P[3] + F[1] * P[7] + F[2] * P[11] + F[3] * P[15],
              F[4] * P[0] + F[5] * P[4] + F[6] * P[8] + F[7] * P[12],
              F[4] * P[1] + F[5] * P[5] + F[6] * P[9] + F[7] * P[13],
              F[4] * P[2] + F[5] * P[6] + F[6] * P[10] + F[7] * P[14],
              F[4] * P[3] + F[5] * P[7] + F[6] * P[11] + F[7] * P[15],
              F[8] * P[0] + F[9] * P[4] + F[10] * P[8] + F[11] * P[12],
              F[8] * P[1] + F[9] * P[5] + F[10] * P[9] + F[11] * P[13],
              F[8] * P[2] + F[9] * P[6] + F[10] * P[10] + F[11] * P[14],
              F[8] * P[3] + F[9] * P[7] + F[10] * P[11] + F[11] * P[15],
              F[12] * P[0] + F[13] * P[4] + F[14] * P[8] + F[15] * P[12],
              F[12] * P[1] + F[13] * P[5] + F[14] * P[9] + F[15] * P[13],
              F[12] * P[2] + F[13] * P[6] + F[14] * P[10] + F[15] * P[14],
              F[12] * P[3] + F[13] * P[7] + F[14] * P[11] + F[15] * P[15])
        q_variance = b[_QV * LANES + lane]
        for i in range(4):
            for j in range(i, 4):
                value = (FP[4 * i] * F[4 * j] + FP[4 * i + 1] * F[4 * j + 1]
                         + FP[4 * i + 2] * F[4 * j + 2] + FP[4 * i + 3] * F[4 * j + 3])
                if i == j:
                    value += q_variance
                b[(_P + 4 * i + j) * LANES + lane] = value
                b[(_P + 4 * j + i) * LANES + lane] = value


@njit(cache=True, inline="always", error_model="numpy")
def _star(b, m, due, z, R_all, first, align_sign, work):
    """Each lane's star tracker update where a reading is ``due``
    (:func:`lanes.star_readings`), on the lane's state copied out and back."""
    aligned, x, P, scratch = work
    for lane in range(m):
        if due[lane]:
            lanes.rows_to_array(b, Q, lane, x)
            lanes.rows_to_array(b, _P, lane, P)
            align(x, z[lane], aligned, align_sign)
            ekf_update(x, P, aligned, R_all[first + lane], scratch)
            lanes.array_to_rows(b, Q, lane, x)
            lanes.array_to_rows(b, _P, lane, P)


@njit(cache=True, inline="always", error_model="numpy")
def _finite(b, m):
    """Each lane's divergence test after its step: common.finite_state's
    sums, each times 0, into lanes.CHECK (NaN where a sum is not finite).
    Written out: the sums' loops left the lanes' loop scalar."""
    for lane in range(m):
        total = (0.0 + b[Q * LANES + lane] + b[(Q + 1) * LANES + lane]
                 + b[(Q + 2) * LANES + lane] + b[(Q + 3) * LANES + lane])
        trace = (0.0 + b[_P * LANES + lane] + b[(_P + 5) * LANES + lane]
                 + b[(_P + 10) * LANES + lane] + b[(_P + 15) * LANES + lane])
        b[CHECK * LANES + lane] = total * 0.0 + trace * 0.0


@njit(cache=True, inline="always", error_model="numpy")
def _group(b, m, first, P_all, q_variance, back):
    """The group's covariances and Q into the buffer's rows, or (``back``)
    the covariances out of them."""
    for lane in range(m):
        if back:
            lanes.rows_to_array(b, _P, lane, P_all[first + lane])
        else:
            lanes.array_to_rows(b, _P, lane, P_all[first + lane])
            b[_QV * LANES + lane] = q_variance[first + lane]


@njit(cache=True, nogil=True, error_model="numpy")
def advance_lanes(first, last, block, sensors, state, record, row):
    """Runs ``first`` to ``last - 1`` through ``block``, :data:`LANES` at a
    time: each step's error from the prior, the tracker's update where a
    reading comes, then the propagation (ekf.advance_runs' order)."""
    k0, steps, half_dt = block.k0, block.steps, 0.5 * block.dt
    q_true, star = borrowed((block.q_true, star_arrays(block)))
    omega, std, normals = borrowed((block.omega_true, block.gyro_std, block.gyro_normals))
    errors = borrowed(error_arrays(record, row))
    x_all, P_all, q_variance, R_all = borrowed((state.x, state.P, state.q_variance, state.R))
    align_sign = state.align_sign
    # Made before the loop, borrowed in it (the kernels package's docstring).
    made = (np.empty(_ROWS * LANES), np.empty(1), np.empty(LANES, np.int64),
            np.empty(LANES, np.int64), np.empty(LANES, np.bool_), np.empty((LANES, 4)),
            np.empty(4), (np.empty(4), np.empty(4), np.empty((4, 4)), np.empty((5, 4, 4))))
    for group in range(first, last, LANES):
        m = min(LANES, last - group)
        b, words, countdown, reading, due, z, dq, work = borrowed(made)
        bits, words_int = b.view(np.int64), words.view(np.int64)
        lanes.group_errors(b, m, group, x_all, errors[0], errors[7], False)
        _group(b, m, group, P_all, q_variance, False)
        for lane in range(m):
            countdown[lane], reading[lane] = first_countdown(k0, star, group + lane), 0
        for j in range(steps):
            k = k0 + j
            lanes.gyro(b, m, j, group, omega, std, normals)
            lanes.record_error(b, bits, m, group, k, q_true[j], errors, words, words_int)
            lanes.star_readings(m, group, j, countdown, reading, q_true, star, z, dq, due)
            _star(b, m, due, z, R_all, group, align_sign, work)
            _propagate(b, m, half_dt)
            _covariance(b, m)
            _finite(b, m)
            lanes.mark_failed(b, m, group, k, errors)
        lanes.group_errors(b, m, group, x_all, errors[0], errors[7], True)
        _group(b, m, group, P_all, q_variance, True)
