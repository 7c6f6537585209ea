"""The workshop's additive quaternion EKF in the engine:
:class:`estimators.QuaternionEKF` — filterpy's update with ``H = I`` (Joseph
form), then the nonlinear predict with the exact Jacobian (with
``rate_interpolation = "end"``, an IMU's reading, the predict first, from
the step before)."""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from benchmarks.engine.kernels import ekf_lanes
from benchmarks.engine.kernels.algebra import projected_covariance, propagate
from benchmarks.engine.kernels.borrowed import borrowed
from benchmarks.engine.kernels.common import (check_health, error_arrays, finite_state,
                                              fold_innovation, fold_nees, keep_variances,
                                              mark_diverged, nees, nees_arrays)
from benchmarks.engine.kernels.common import record_error_inlined as record_error
from benchmarks.engine.kernels.cores import on_every_core_in_lanes
from benchmarks.engine.kernels.ekf_update import align, ekf_update
from benchmarks.engine.kernels.sensors import (first_countdown, gyro_arrays, gyro_reading,
                                               star_arrays, star_step)

NAME = "ekf"
#: It reports a covariance: its kernel streams NEES and NIS.
REPORTS_COVARIANCE = True


class State(NamedTuple):
    x: np.ndarray                # (B, 4)
    P: np.ndarray                # (B, 4, 4)
    q_variance: np.ndarray       # (B,) Q = q_variance I4, read off each run's filter
    R: np.ndarray                # (B, 4, 4): each run's (derived from its tracker's noise)
    posterior: bool
    align_sign: bool
    end: bool                    # rate_interpolation "end": predict to the step, then update


def initial_state(estimators) -> State:
    """From the per-run objects (``from_scenario``), one per run: every
    setting is read off them, Q included, so the two paths cannot disagree."""
    first = estimators[0]
    return State(x=np.array([e.initial_attitude for e in estimators]),
                 P=np.array([e.initial_covariance * np.eye(4) for e in estimators]),
                 q_variance=np.array([e.filter.Q[0, 0] for e in estimators]),
                 R=np.array([e.filter.R for e in estimators]),
                 posterior=first.output == "posterior",
                 align_sign=first.align_sign, end=first.rate_interpolation == "end")


def nis_dof(estimators) -> int:
    return estimators[0].filter.dim_z


@njit(cache=True, inline="always", error_model="numpy")
def _ekf_predict(x, P, w, half_dt, q_variance, F, scratch):
    """x = f(x, ω); P = F P Fᵀ + Q with F the exact Jacobian at the pre-step x."""
    propagate(x, w, half_dt, x, F, True)
    FP = scratch[0]
    for i in range(4):
        for j in range(4):
            FP[i, j] = F[i, 0] * P[0, j] + F[i, 1] * P[1, j] + F[i, 2] * P[2, j] \
                + F[i, 3] * P[3, j]
    # P is symmetric: compute the upper triangle and mirror it.
    for i in range(4):
        for j in range(i, 4):
            value = FP[i, 0] * F[j, 0] + FP[i, 1] * F[j, 1] + FP[i, 2] * F[j, 2] \
                + FP[i, 3] * F[j, 3]
            P[i, j] = value
            P[j, i] = value
        P[i, i] += q_variance


@njit(cache=True, inline="always", error_model="numpy")
def _star_update(run, x, P, z, aligned, R, align_sign, scratch, check, health, factor,
                 streaming, nis_sum, nis_count, likelihood):
    """A star tracker reading: its sign turned to the estimate's where the
    filter aligns it, the update, its health and its NIS."""
    align(x, z, aligned, align_sign)
    nis, determinant = ekf_update(x, P, aligned, R, scratch)
    if check:   # the additive update leaves |x| off 1 by design
        check_health(x, False, P, 4, health, factor)
    if streaming:
        nis_sum[run] += nis
        nis_count[run] += 1
        fold_innovation(run, nis, determinant, likelihood)


@njit(cache=True, inline="always", error_model="numpy")
def _batch_scratch(n_runs):
    """Every run's working arrays, made once for the runs of a share."""
    return (np.empty((n_runs, 3)), np.empty((n_runs, 4)), np.empty((n_runs, 4)),
            np.empty((n_runs, 4)), np.empty((n_runs, 4)), np.empty((n_runs, 4, 4)),
            np.empty((n_runs, 5, 4, 4)), np.empty((n_runs, 7, 6, 6)), np.empty((n_runs, 3, 3)),
            np.empty((n_runs, 1)), np.empty((n_runs, 6, 6)))


@njit(cache=True, inline="always", error_model="numpy")
def _run_scratch(batch, run):
    """Run ``run``'s rows of :func:`_batch_scratch`'s arrays, borrowed (no
    atomic count at each call that takes them: the kernels package's
    docstring)."""
    w, z, dq, prior, aligned, F, scratch, scratch6, projected, bits, factor = batch
    return borrowed((w[run], z[run], dq[run], prior[run], aligned[run], F[run], scratch[run],
                     scratch6[run], projected[run], bits[run], factor[run]))


@njit(cache=True, nogil=True, error_model="numpy")
def advance_runs(first, last, block, sensors, state, record, row):
    """Runs ``first`` to ``last - 1`` through ``block``: update with each
    reading, then predict (with ``"end"``, predict to the step, then update)."""
    k0, steps, last_step, dt = block.k0, block.steps, block.last_step, block.dt
    q_true, star = borrowed((block.q_true, star_arrays(block)))
    (omega, gyro_std, normals, scale, has_scale, has_bias, bias_model, bias,
     bias_last) = borrowed(gyro_arrays(block, sensors))
    (stats, hist, first_bits, traces, keep_traces, error_every, samples, diverged, check,
     health) = borrowed(error_arrays(record, row))
    (streaming, nees_every, settle, nees_samples, nees_sum, nis_sum, nis_count,
     variances, likelihood) = borrowed(nees_arrays(record, row))
    x_all, P_all, q_variance, R_all = borrowed((state.x, state.P, state.q_variance, state.R))
    posterior, align_sign, end, half_dt = state.posterior, state.align_sign, state.end, 0.5 * dt
    batch = _batch_scratch(last - first)
    for index in range(first, last):
        run = np.int64(index)
        w, z, dq, prior, aligned, F, scratch, scratch6, projected, bits, factor = \
            _run_scratch(batch, run - first)
        bits_int = bits.view(np.int64)
        x, P = x_all[run], P_all[run]
        countdown, reading = first_countdown(k0, star, run), 0
        for j in range(steps):
            k = k0 + j
            gyro_reading(w, run, j, k, last_step, omega, gyro_std, normals, scale, has_scale,
                         has_bias, bias_model, bias, bias_last)
            available, countdown, reading = star_step(z, dq, run, j, countdown, reading, q_true,
                                                      star)
            if end and k > 0:
                _ekf_predict(x, P, w, half_dt, q_variance[run], F, scratch)
            for i in range(4):
                prior[i] = x[i]
            if (streaming or keep_traces) and not posterior:
                projected_covariance(x, P, projected)
                keep_variances(run, k, projected, variances, keep_traces)
                if streaming:
                    fold_nees(run, k, nees(q_true[j], x, projected, scratch6), nees_every,
                              settle, nees_samples, nees_sum)
            if available:
                _star_update(run, x, P, z, aligned, R_all[run], align_sign, scratch, check,
                             health[run], factor, streaming, nis_sum, nis_count, likelihood)
            if posterior:    # its direction, as QuaternionEKF._record outputs it
                norm = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + x[3] * x[3])
                for i in range(4):
                    prior[i] = x[i] / norm
                if streaming or keep_traces:
                    projected_covariance(prior, P, projected)
                    keep_variances(run, k, projected, variances, keep_traces)
                if streaming:
                    fold_nees(run, k, nees(q_true[j], prior, projected, scratch6), nees_every,
                              settle, nees_samples, nees_sum)
            record_error(run, k, q_true[j], prior, stats, hist, first_bits, traces, keep_traces,
                         error_every, samples, diverged, bits, bits_int)
            if not end:
                _ekf_predict(x, P, w, half_dt, q_variance[run], F, scratch)
            if not finite_state(x, 4, P, 4):     # the step's state, as the per-run class checks it
                mark_diverged(run, k, diverged, traces, keep_traces, error_every, samples)
            if check:
                check_health(x, True, P, 4, health[run], factor)


#: Every run of the batch through a block, a share of the runs per core:
#: eight runs side by side where the lanes kernel covers the case (a
#: campaign's), one at a time otherwise (the same numbers either way).
advance = on_every_core_in_lanes(advance_runs, ekf_lanes)
