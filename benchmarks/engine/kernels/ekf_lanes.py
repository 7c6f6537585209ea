"""The workshop EKF's kernel in lanes: eight runs advanced side by side, so
that the processor's vector units (four doubles at a time with AVX2) do the
arithmetic of several runs in one instruction.

Why: :func:`benchmarks.engine.kernels.ekf.advance_runs` takes one run at a
time, and each of its steps is a few hundred scalar operations (the
propagation, its Jacobian, P = F P Fᵀ + Q, the attitude error's arccos)
that the processor retires one by one. Here each quantity is a row of
:data:`LANES` numbers, one a run, in one buffer with its rows a constant
stride apart, and each step is a loop over the lanes whose body reads its
rows into values, computes and writes them back, without calls or
branches: LLVM's loop vectorizer turns it into vector instructions. (One
buffer, so that it can prove the lanes apart; several arrays, rows a
run-time stride apart, or a body storing and reloading many rows left it
scalar: measured.) On one thread of the 2-core development machine: 46–57
ns a run-step against the one-run kernel's 107.

What is not the same arithmetic on every lane is done lane by lane with the
functions the one-run kernel calls (:mod:`~benchmarks.engine.kernels.ekf_update`,
:mod:`~benchmarks.engine.kernels.common`): the star tracker's readings
and updates (due every few steps, not in every lane at once; its
Gauss–Jordan pivots on each lane's data: written on values with choices
instead of branches it ran no faster and took 13 minutes to compile), the
histogram's count (a scatter), a divergence's bookkeeping and the rare
error above 120° (the library's arccos).

The same operations in the same order as the one-run kernel, so the same
numbers to the bit (no fast-math, no reassociation; tests/test_engine_lanes.py
holds the two kernels' errors equal at every step). It covers the
campaigns' case — a Monte Carlo campaign, a landscape, a tuning grid:
statistics only (no traces, NEES or health checks), the prior as output,
the rate held over the step, a gyro with white noise only. Anything else
goes through the one-run kernel (:func:`lanes_apply`).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from benchmarks.engine.kernels.borrowed import borrowed
from benchmarks.engine.kernels.common import (HIGH_WORD_MASK, RAD_TO_DEG, acos_near_one,
                                              count_error, error_arrays, mark_diverged,
                                              welford)
from benchmarks.engine.kernels.ekf_update import align, ekf_update
from benchmarks.engine.kernels.sensors import first_countdown, star_arrays, star_step

#: Runs advanced side by side: two AVX2 vectors of four doubles each.
LANES = 8


def _first_rows(**sizes) -> tuple:
    """Each quantity's first row in a group's buffer, in order, then the rows in all."""
    return tuple(int(row) for row in np.cumsum((0,) + tuple(sizes.values())))


# A group's buffer, LANES numbers a row: the state x and P (row-major), the
# gyro's reading, the Jacobian F, Q's diagonal; the |q̂ · q| of the error,
# the arccos's √z, its high word and its value, the error, the run's
# statistics (Record.stats' MEAN, M2, MAX, FINAL of common), whether it diverged
# (1.0) or its error needs a lane's own care (1.0), its divergence test (NaN:
# not finite).
(_X, _P, _W, _F, _QV, _DOT, _ROOT, _HIGH, _ACOS, _ERROR, _STATS, _DIVERGED, _OWN, _CHECK,
 _ROWS) = _first_rows(x=4, P=16, w=3, F=16, q_variance=1, dot=1, root=1, high=1, acos=1,
                      error=1, stats=4, diverged=1, own=1, check=1)


def lanes_apply(block, record, state) -> bool:
    """Whether the lanes kernel covers this block, record and state (the
    module's docstring): otherwise the one-run kernel advances them."""
    return not (block.has_scale or block.has_bias or record.consistency or record.keep_traces
                or record.check_health or state.posterior or state.end)


@njit(cache=True, inline="always", error_model="numpy")
def _gyro(b, m, t, first, omega, std, normals):
    """Each lane's gyro reading ω + σ N (sensors.gyro_reading's white-noise case)."""
    for i in range(3):
        for lane in range(m):
            run = first + lane
            b[(_W + i) * LANES + lane] = omega[t, i] + std[run] * normals[run, t, i]


@njit(cache=True, inline="always", error_model="numpy")
def _propagate(b, m, half_dt):
    """x = f(x, ω) and F = ∂f/∂x on every lane: algebra.propagate's
    arithmetic, term by term."""
    for lane in range(m):
        p, qq, r = b[_W * LANES + lane], b[(_W + 1) * LANES + lane], b[(_W + 2) * LANES + lane]
        a = ((1.0, -half_dt * p, -half_dt * qq, -half_dt * r),
             (half_dt * p, 1.0, half_dt * r, -half_dt * qq),
             (half_dt * qq, -half_dt * r, 1.0, half_dt * p),
             (half_dt * r, half_dt * qq, -half_dt * p, 1.0))
        q0, q1, q2 = b[_X * LANES + lane], b[(_X + 1) * LANES + lane], b[(_X + 2) * LANES + lane]
        q3 = b[(_X + 3) * LANES + lane]
        g = (a[0][0] * q0 + a[0][1] * q1 + a[0][2] * q2 + a[0][3] * q3,
             a[1][0] * q0 + a[1][1] * q1 + a[1][2] * q2 + a[1][3] * q3,
             a[2][0] * q0 + a[2][1] * q1 + a[2][2] * q2 + a[2][3] * q3,
             a[3][0] * q0 + a[3][1] * q1 + a[3][2] * q2 + a[3][3] * q3)
        norm = math.sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2] + g[3] * g[3])
        n = (g[0] / norm, g[1] / norm, g[2] / norm, g[3] / norm)
        inv_norm = 1.0 / norm
        for i in range(4):
            b[(_X + i) * LANES + lane] = n[i]
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
def _arccos(b, bits, m, q_true_k):
    """Each lane's |q̂ · q| and, for it, common.acos's fdlibm branch (x >= 1
    is 0 in :func:`_fold`, x <= 0.5 the library's in :func:`_fold_own`)."""
    for lane in range(m):
        dot = abs(q_true_k[0] * b[_X * LANES + lane] + q_true_k[1] * b[(_X + 1) * LANES + lane]
                  + q_true_k[2] * b[(_X + 2) * LANES + lane]
                  + q_true_k[3] * b[(_X + 3) * LANES + lane])
        b[_DOT * LANES + lane] = dot
        s = math.sqrt((1.0 - min(1.0, dot)) * 0.5)
        b[_ROOT * LANES + lane] = s
        b[_HIGH * LANES + lane] = s
    for lane in range(m):        # acos's bits_int & HIGH_WORD_MASK
        bits[_HIGH * LANES + lane] = bits[_HIGH * LANES + lane] & HIGH_WORD_MASK
    for lane in range(m):
        z = (1.0 - min(1.0, b[_DOT * LANES + lane])) * 0.5
        b[_ACOS * LANES + lane] = acos_near_one(z, b[_ROOT * LANES + lane],
                                                b[_HIGH * LANES + lane])


@njit(cache=True, inline="always", error_model="numpy")
def _fold(b, m, k):
    """Each lane's error at step ``k`` folded into its statistics' rows
    (common.fold_error's Welford), where the error is the arccos's fdlibm
    branch and the run has not diverged; the other lanes are marked for
    :func:`_fold_own` and left as they were."""
    inv_count = 1.0 / (k + 1)
    for lane in range(m):
        dot = b[_DOT * LANES + lane]
        x = min(1.0, dot)
        error = 2.0 * (0.0 if x >= 1.0 else b[_ACOS * LANES + lane]) * RAD_TO_DEG
        own = b[_DIVERGED * LANES + lane] != 0.0 or not dot < math.inf or x <= 0.5
        mean, m2, maximum = welford(b[_STATS * LANES + lane], b[(_STATS + 1) * LANES + lane],
                                    b[(_STATS + 2) * LANES + lane], error, inv_count, k == 0)
        b[_STATS * LANES + lane] = b[_STATS * LANES + lane] if own else mean
        b[(_STATS + 1) * LANES + lane] = b[(_STATS + 1) * LANES + lane] if own else m2
        b[(_STATS + 2) * LANES + lane] = b[(_STATS + 2) * LANES + lane] if own else maximum
        b[(_STATS + 3) * LANES + lane] = b[(_STATS + 3) * LANES + lane] if own else error
        b[_ERROR * LANES + lane] = error
        b[_OWN * LANES + lane] = 1.0 if own else 0.0


@njit(cache=True, inline="always", error_model="numpy")
def _fold_own(b, m, first, k, errors, words, words_int):
    """What :func:`_fold` leaves to each lane: a divergence marked, an error
    at x <= 0.5 from the library's arccos (as common.acos takes it), then the
    histogram's count and the kept sample (common.count_error; ``words``,
    ``words_int``: its scratch float and int64 view)."""
    hist, first_bits, traces, keep_traces, every, samples, diverged = errors[1:8]
    for lane in range(m):
        run = np.int64(first + lane)
        if b[_OWN * LANES + lane] != 0.0:
            dot = b[_DOT * LANES + lane]
            if b[_DIVERGED * LANES + lane] != 0.0 or not math.isfinite(dot):
                mark_diverged(run, k, diverged, traces, keep_traces, every, samples)
                b[_DIVERGED * LANES + lane] = 1.0
                continue
            error = 2.0 * math.acos(min(1.0, dot)) * RAD_TO_DEG
            mean, m2, maximum = welford(b[_STATS * LANES + lane], b[(_STATS + 1) * LANES + lane],
                                        b[(_STATS + 2) * LANES + lane], error, 1.0 / (k + 1),
                                        k == 0)
            b[_STATS * LANES + lane], b[(_STATS + 1) * LANES + lane] = mean, m2
            b[(_STATS + 2) * LANES + lane], b[(_STATS + 3) * LANES + lane] = maximum, error
            b[_ERROR * LANES + lane] = error
        count_error(run, k, b[_ERROR * LANES + lane], hist, first_bits, every, samples, words,
                    words_int)


@njit(cache=True, inline="always", error_model="numpy")
def _star(b, m, first, j, countdown, reading, q_true, star, R_all, align_sign, work):
    """Each lane's star tracker at the block's step ``j``: its reading, if
    one is due, and the update, on the lane's state copied out and back."""
    z, dq, aligned, x, P, scratch = work
    for lane in range(m):
        if countdown[lane] > 0:        # star_step's first case, without its call
            countdown[lane] -= 1
            continue
        run = np.int64(first + lane)
        available, countdown[lane], reading[lane] = star_step(z, dq, run, j, countdown[lane],
                                                              reading[lane], q_true, star)
        if available:
            for i in range(4):
                x[i] = b[(_X + i) * LANES + lane]
                for jj in range(4):
                    P[i, jj] = b[(_P + 4 * i + jj) * LANES + lane]
            align(x, z, aligned, align_sign)
            ekf_update(x, P, aligned, R_all[run], scratch)
            for i in range(4):
                b[(_X + i) * LANES + lane] = x[i]
                for jj in range(4):
                    b[(_P + 4 * i + jj) * LANES + lane] = P[i, jj]


@njit(cache=True, inline="always", error_model="numpy")
def _finite(b, m, first, k, errors):
    """Each lane's divergence test after its step: common.finite_state's
    sums, each times 0 (NaN where a sum is not finite), then the lanes that
    failed marked diverged."""
    traces, keep_traces, every, samples, diverged = errors[3:8]
    for lane in range(m):
        total = 0.0
        trace = 0.0
        for i in range(4):
            total += b[(_X + i) * LANES + lane]
            trace += b[(_P + 5 * i) * LANES + lane]
        b[_CHECK * LANES + lane] = total * 0.0 + trace * 0.0
    for lane in range(m):
        if b[_CHECK * LANES + lane] != b[_CHECK * LANES + lane]:
            mark_diverged(np.int64(first + lane), k, diverged, traces, keep_traces, every,
                          samples)
            b[_DIVERGED * LANES + lane] = 1.0


@njit(cache=True, inline="always", error_model="numpy")
def _group(b, m, first, x_all, P_all, q_variance, stats, diverged, back):
    """The group's states and statistics into the buffer's rows, or
    (``back``) out of them."""
    for lane in range(m):
        run = first + lane
        for i in range(4):
            if back:
                x_all[run, i] = b[(_X + i) * LANES + lane]
                stats[run, i] = b[(_STATS + i) * LANES + lane]
            else:
                b[(_X + i) * LANES + lane] = x_all[run, i]
                b[(_STATS + i) * LANES + lane] = stats[run, i]
            for j in range(4):
                if back:
                    P_all[run, i, j] = b[(_P + 4 * i + j) * LANES + lane]
                else:
                    b[(_P + 4 * i + j) * LANES + lane] = P_all[run, i, j]
        b[_QV * LANES + lane] = q_variance[run]
        b[_DIVERGED * LANES + lane] = 1.0 if diverged[run] >= 0 else 0.0


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
            np.empty(LANES, np.int64), (np.empty(4), np.empty(4), np.empty(4), np.empty(4),
                                        np.empty((4, 4)), np.empty((5, 4, 4))))
    for group in range(first, last, LANES):
        m = min(LANES, last - group)
        b, words, countdown, reading, work = borrowed(made)
        bits, words_int = b.view(np.int64), words.view(np.int64)
        _group(b, m, group, x_all, P_all, q_variance, errors[0], errors[7], False)
        for lane in range(m):
            countdown[lane], reading[lane] = first_countdown(k0, star, group + lane), 0
        for j in range(steps):
            k = k0 + j
            _gyro(b, m, j, group, omega, std, normals)
            _arccos(b, bits, m, q_true[j])
            _fold(b, m, k)
            _fold_own(b, m, group, k, errors, words, words_int)
            _star(b, m, group, j, countdown, reading, q_true, star, R_all, align_sign, work)
            _propagate(b, m, half_dt)
            _covariance(b, m)
            _finite(b, m, group, k, errors)
        _group(b, m, group, x_all, P_all, q_variance, errors[0], errors[7], True)
