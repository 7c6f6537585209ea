"""The multiplicative EKF in the engine: :class:`estimators.MultiplicativeEKF`
— :func:`estimators.mekf.discrete_error_model`, filterpy's Joseph update with
``H = [I 0]`` for a star tracker reading and ``H = [[b̂×] 0]`` for each vector
reading after it (sequential updates, gated as the per-run class gates
them), the reset after each, and the exact quaternion step.

With the magnetometer's hard-iron states (``magnetometer_bias_states``) the
error state has nine entries: the covariance is 9x9, a magnetometer reading's
``H = [[b̂×] 0 I]`` and its innovation and norm test read the field less the
hard-iron estimate, and the propagation carries the cross-covariance of the
constant states through Φ (:class:`estimators.MultiplicativeEKF`). The
six-state arithmetic is unchanged: the propagation's 6x6 block is the same
code, and the update's loops run to the covariance's size. The scratch
arrays have one constant shape, room for nine states: six run as fast in
them as in their own (a shape read at run time slowed the kernel by ~7 %)."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from benchmarks.engine.kernels.common import (check_health, error_arrays, finite_state,
                                              fold_innovation, gate_thresholds, gyro_errors,
                                              keep_output, mark_diverged, nees_arrays,
                                              norm_tolerances, rate_arrays, rate_states,
                                              record_error, trapezoid_rate)
from benchmarks.engine.kernels import imu, mekf_lanes
from benchmarks.engine.kernels.borrowed import borrowed
from benchmarks.engine.kernels.cores import on_every_core_in_lanes
from benchmarks.engine.kernels.mekf_steps import (carry_constant_states, field_passes,
                                                  gravity_update, propagate_covariance,
                                                  star_update, vector_update)
from benchmarks.engine.kernels.sensors import (first_countdown, gyro_arrays, gyro_reading,
                                               star_arrays, star_step)
from estimators.imu.updates import imu_models_on
from estimators.mekf import estimates_hard_iron

NAME = "mekf"
#: It reports a covariance: its kernel streams NEES and NIS.
REPORTS_COVARIANCE = True
#: It applies vector readings and gates readings as the per-run class does.
VECTOR_READINGS = True
GATING = True


class State(NamedTuple):
    q: np.ndarray                # (B, 4)
    beta: np.ndarray             # (B, 3) the bias estimate, rad/s
    P: np.ndarray                # (B, n, n) n = 6, or 9 with the hard-iron states
    gyro_errors: np.ndarray      # (B, 3) σ_v², σ_u, S_s: each run's filter's gyro model
    R: np.ndarray                # (B, 3, 3)
    beta_last: np.ndarray        # (B, 3) the output bias at the last step
    P_last: np.ndarray           # (B, n, n) and its covariance
    hard_iron: bool              # the magnetometer's hard-iron states are on
    mag_bias: np.ndarray         # (B, 3) their estimate (zero without them)
    posterior: bool
    gating: np.ndarray           # (B,) bool: the filter gates its readings
    gate: np.ndarray             # (B, 4) the χ² threshold for 1, 2, 3 degrees of freedom
    magnetic_tolerance: np.ndarray  # (B,) the magnetic norm test's (inf: none)
    trapezoid: np.ndarray        # (B,) bool: the trapezoidal rate (estimators.sampled_rate)
    rate_prev: np.ndarray        # (B, 3) the last reading, for it
    has_rate: np.ndarray         # (B,) bool: there is one
    end: np.ndarray              # (B,) bool: the rate at the step's end instead
    # The IMU models (benchmarks.engine.kernels.imu.imu_state).
    imu_on: bool
    imu_lowpass: bool
    imu_heading: bool
    imu_rest: bool
    imu_densities: np.ndarray    # (B, 3) gravity, heading, rest
    imu_strapdown: np.ndarray    # (B, 4)
    imu_gravity: np.ndarray      # (B, 4, 3)
    imu_detector: np.ndarray     # (B, 9, 3)
    imu_trust: np.ndarray        # (B, heading.STATE_SIZE) the heading's trust
    imu_rate_lp: np.ndarray      # (B, 3)
    imu_counts: np.ndarray       # (B, 5) int64
    imu_rotation: np.ndarray     # (B, 5, 9) the strapdown's rotation integrated, its LP state
    imu_field: np.ndarray        # (B, 4, 3) the field's low-pass filter in the strapdown frame
    imu_iron_fit: bool           # the hard iron fitted online (estimators.imu.hard_iron)
    imu_iron: np.ndarray         # (B, hard_iron.STATE_SIZE) its fit
    imu_table: np.ndarray        # (3, 5) the low-pass filters' coefficients at imu_table_dt
    imu_table_dt: float
    imu_work: np.ndarray         # (B, 8, 3) the models' working vectors, per run
    imu_drift: np.ndarray        # (B, 3, 3) gravity's bias columns, per run
    imu_nine: np.ndarray         # (B, 9) the rotation integral's low-passed value, per run


def initial_state(estimators) -> State:
    """From the per-run objects (``from_scenario``), one per run."""
    beta = np.array([e.initial_bias_radps for e in estimators]).reshape(-1, 3)
    size = _state_size(estimators)
    P = np.array([e.initial_covariance for e in estimators]).reshape(-1, size, size)
    return State(q=np.array([e.initial_attitude for e in estimators]).reshape(-1, 4),
                 beta=beta, P=P,
                 gyro_errors=gyro_errors(estimators),
                 R=np.array([e.filter.R for e in estimators]).reshape(-1, 3, 3),
                 beta_last=beta.copy(), P_last=P.copy(), hard_iron=size > 6,
                 mag_bias=np.array([e.magnetometer_bias for e in estimators]).reshape(-1, 3),
                 posterior=estimators[0].output == "posterior",
                 magnetic_tolerance=norm_tolerances(estimators),
                 **gate_thresholds(estimators), **rate_states(estimators),
                 **imu.imu_state(estimators))


def _state_size(estimators) -> int:
    """The runs' error-state size (6, or 9 with the hard-iron states): one
    batch holds one size."""
    sizes = {e.state_size for e in estimators}
    if len(sizes) > 1:
        raise ValueError(f"one batch of MEKF runs holds one state size, not {sorted(sizes)}")
    return sizes.pop()


def limitation(settings: dict) -> str | None:
    """What of the per-run object's settings (its constructor's keywords, or
    its attributes) this kernel does not model: the hard-iron states beside
    the IMU models (the per-run path runs them together), or None."""
    if estimates_hard_iron(settings) and imu_models_on(settings):
        return ("the magnetometer's hard-iron states (magnetometer_bias_states) beside the "
                "IMU models (gravity_model, rest_updates)")
    return None


def nis_dof(estimators) -> int:
    return estimators[0].filter.dim_z


def final(state, estimators) -> dict:
    """The output bias estimate and its covariance (6x6, or 9x9 with the
    hard-iron states) at the last step; the hard-iron estimate after it."""
    report = {"bias_radps": state.beta_last, "covariance": state.P_last}
    if state.hard_iron:
        report["magnetometer_bias"] = state.mag_bias
    return report


@njit(cache=True, inline="always", error_model="numpy")
def _batch_scratch(n_runs):
    """Every run's working arrays, made once for the batch: vectors, and the
    scratch matrices of a constant shape (the module's docstring)."""
    return (np.empty((n_runs, 3)), np.empty((n_runs, 4)), np.empty((n_runs, 4)),
            np.empty((n_runs, 4)), np.empty((n_runs, 3)), np.empty((n_runs, 10, 9, 9)),
            np.empty((n_runs, 1)), np.empty((n_runs, 9, 9)))


@njit(cache=True, inline="always", error_model="numpy")
def _run_scratch(batch, run):
    """Run ``run``'s rows of :func:`_batch_scratch`'s arrays, borrowed."""
    w, z, dq, out, mean, scratch, bits, factor = batch
    return borrowed((w[run], z[run], dq[run], out[run], mean[run], scratch[run], bits[run],
                     factor[run]))


@njit(cache=True, inline="always", error_model="numpy")
def _filter_arrays(state, record, row):
    """The filters' arrays of the state, its rejections' counts in the record
    and the IMU models' arrays (:func:`~benchmarks.engine.kernels.imu.gravity_models`),
    taken out of their tuples before the loop over the runs, to be borrowed
    (the package's docstring)."""
    return (state.q, state.beta, state.P, state.mag_bias, state.gyro_errors, state.beta_last,
            state.P_last, state.posterior, record.rejected[row], imu.gravity_models(state),
            imu.field_models(state))


@njit(cache=True, inline="always", error_model="numpy")
def _propagate(q, beta, P, rate, dt, errors, scratch, dq, imu_on, strapdown, rotation, turn):
    """:func:`propagate_covariance`, and the IMU models' strapdown by the same
    bias-corrected rotation (MultiplicativeEKF.propagate); ``turn`` (3,) scratch."""
    if imu_on:
        for i in range(3):
            turn[i] = (rate[i] - beta[i]) * dt
        imu.strapdown_step(strapdown, turn, strapdown)
        imu.integrate_rotation(strapdown, dt, rotation)
    propagate_covariance(q, beta, P, rate, dt, errors, scratch, dq)
    if P.shape[0] > 6:                  # the hard iron's cross-covariance through Φ
        carry_constant_states(P, scratch[2], scratch[3], scratch[0])


@njit(cache=True, inline="always", error_model="numpy")
def _star_reading(q, beta, P, z, run, R, gating, gate, scratch, dq, mag_bias, check, health,
                  factor, streaming, nis_sum, nis_count, likelihood):
    """A star tracker reading (MultiplicativeEKF.correct, gated as the filter
    gates it), the health check after it and its NIS. The update is called,
    as every update is (the kernels package's docstring)."""
    nis, applied, determinant = star_update(q, beta, P, z, R, gating, gate, scratch, dq,
                                            mag_bias)
    if check:
        check_health(q, True, P, P.shape[0], health, factor)
    if streaming and applied:
        nis_sum[run] += nis
        nis_count[run] += 1
    if streaming:
        fold_innovation(run, nis if applied else gate, determinant, likelihood)


@njit(cache=True, error_model="numpy")
def _gravity_reading(q, beta, P, run, s, dt, body, models, gating, threshold, mag_bias, rejected,
                     streaming, likelihood, scratch, dq, lowpass, rest_updates):
    """An accelerometer reading through the IMU models
    (estimators.imu.updates.ImuUpdates._imu_reading), ``models`` their
    :func:`~benchmarks.engine.kernels.imu.gravity_models`: True if they took
    it (the low-passed gravity's update), False where the reading goes on to
    the vector update, the rest detector having read it."""
    densities = models[imu.G_DENSITIES][run]
    up, drift, interval, at_rest = imu.accelerometer_reading(models, run, body, dt)
    last, kept = (0.0, 0.0), True
    if lowpass:
        variance = imu.gravity_variance(models, run, densities[0], interval)
        nis, applied, determinant = gravity_update(q, beta, P, up, variance, drift, gating,
                                                   threshold, scratch, dq, mag_bias)
        if applied:
            last = (nis, determinant)
        else:
            rejected[run, s] += 1
            kept = False
            if streaming:                  # at the gate (InnovationGate.accepts)
                fold_innovation(run, threshold, determinant, likelihood)
    if rest_updates and at_rest:
        last = imu.rest_update(q, beta, P, models[imu.G_RATE_LP][run], densities[2] / interval,
                               scratch, dq)
    if streaming and kept and lowpass:
        fold_innovation(run, last[0], last[1], likelihood)
    return lowpass


@njit(cache=True, error_model="numpy")
def _heading_reading(q, beta, P, run, s, dt, body, reference, known, models, gating, threshold,
                     rejected, streaming, likelihood, scratch, dq):
    """A magnetometer reading through the heading model
    (estimators.imu.updates.ImuUpdates._heading), ``models`` its arrays
    (:func:`~benchmarks.engine.kernels.imu.field_models`)."""
    field = imu.calibrated_field(models, run, body, dt)
    psi, interval, trust, validated, forget = imu.field_reading(models, run, q, field, reference,
                                                                known, dt)
    if forget:
        imu.forget_heading(q, P)
    if trust == 0.0:
        rejected[run, s] += 1
        return
    variance = trust * trust * models[imu.F_DENSITIES][run, 1] / interval
    nis, applied, determinant = imu.heading_update(q, beta, P, psi, variance, validated, gating,
                                                   threshold, scratch, dq)
    if not applied:
        rejected[run, s] += 1
    if streaming:
        fold_innovation(run, nis if applied else threshold, determinant, likelihood)


@njit(cache=True, inline="always", error_model="numpy")
def _vector_reading(q, beta, P, run, j, s, dt, block, state, rejected, streaming, likelihood,
                    scratch, dq, mag_bias, check, health, factor, gravity_models,
                    field_models):
    """Vector reading ``s`` of step ``j``: through the IMU models where they
    take it (:func:`_gravity_reading`, :func:`_heading_reading`; ``*_models``
    their arrays, :func:`~benchmarks.engine.kernels.imu.gravity_models`), else the
    magnetic norm test and the gated update with its reset
    (MultiplicativeEKF.correct_vector); the health check after it where the
    filter's state was touched (not after a field the norm test refused).
    Inlined, as what runs every step on a recording is; the updates it makes
    are called (the kernels package's docstring)."""
    body, reference = block.vector_body[run, j, s], block.vector_reference[j, s]
    taken = False
    if state.imu_on and block.vector_gravity[s]:
        taken = _gravity_reading(q, beta, P, run, s, dt, body, gravity_models, state.gating[run],
                                 state.gate[run, block.vector_dof[s]], mag_bias, rejected,
                                 streaming, likelihood, scratch, dq, state.imu_lowpass,
                                 state.imu_rest)
    elif state.imu_on and block.vector_magnetic[s] and state.imu_heading:
        _heading_reading(q, beta, P, run, s, dt, body, reference, block.vector_known[s],
                         field_models, state.gating[run], state.gate[run, 1], rejected, streaming,
                         likelihood, scratch, dq)
        taken = True
    if not taken:
        reads_hard_iron = state.hard_iron and block.vector_magnetic[s]
        if block.vector_magnetic[s] and not field_passes(
                body, reference, state.magnetic_tolerance[run], mag_bias, reads_hard_iron):
            rejected[run, s] += 1      # a disturbed field: no update
            return
        nis, applied, determinant = vector_update(
            q, beta, P, body, reference, block.vector_variance[run, j, s], state.gating[run],
            state.gate[run, block.vector_dof[s]], scratch, dq, mag_bias, reads_hard_iron)
        if streaming:
            fold_innovation(run, nis if applied else state.gate[run, block.vector_dof[s]],
                            determinant, likelihood)
        if not applied:
            rejected[run, s] += 1
    if check:
        check_health(q, True, P, P.shape[0], health, factor)


@njit(cache=True, inline="always", error_model="numpy")
def _output(q, out, run, k, last_step, q_true_k, beta, P, beta_last, P_last, variances,
            keep_traces, streaming, nees_every, settle, nees_samples, nees_sum, scratch):
    """The estimate output at step ``k`` is ``q`` now (before or after the
    step's readings, as the filter outputs): kept in ``out`` and by
    :func:`keep_output`."""
    for i in range(4):
        out[i] = q[i]
    keep_output(run, k, last_step, q_true_k, out, beta, P, beta_last, P_last, variances,
                keep_traces, streaming, nees_every, settle, nees_samples, nees_sum, scratch)


@njit(cache=True, nogil=True, error_model="numpy")
def advance_runs(first, last, block, sensors, state, record, row):
    """Runs ``first`` to ``last - 1``: each reading's update and reset, then propagation."""
    k0, steps, last_step, dt = block.k0, block.steps, block.last_step, block.dt
    q_true, vector_available, star = borrowed((block.q_true, block.vector_available,
                                               star_arrays(block)))
    (omega, gyro_std, normals, scale, has_scale, has_bias, bias_model, bias,
     bias_last) = borrowed(gyro_arrays(block, sensors))
    (stats, hist, first_bits, traces, keep_traces, error_every, samples, diverged, check,
     health) = borrowed(error_arrays(record, row))
    (streaming, nees_every, settle, nees_samples, nees_sum, nis_sum, nis_count,
     variances, likelihood) = borrowed(nees_arrays(record, row))
    (q_all, beta_all, P_all, mag_bias_all, errors, beta_last, P_last, posterior, rejected,
     gravity_models, field_models) = borrowed(_filter_arrays(state, record, row))
    (trapezoid, rate_prev, has_rate, end, imu_on, counts, detector, rate_lp, strapdown,
     rotation, imu_table, imu_table_dt, imu_work) = borrowed(rate_arrays(state))
    batch = _batch_scratch(last - first)
    for index in range(first, last):
        run, run_block, run_state = np.int64(index), borrowed(block), borrowed(state)
        w, z, dq, out, mean, scratch6, bits, factor = _run_scratch(batch, run - first)
        bits_int = bits.view(np.int64)
        q, beta, P, mag_bias = q_all[run], beta_all[run], P_all[run], mag_bias_all[run]
        countdown, reading = first_countdown(k0, star, run), 0
        for j in range(steps):
            k = k0 + j
            gyro_reading(w, run, j, k, last_step, omega, gyro_std, normals, scale, has_scale,
                         has_bias, bias_model, bias, bias_last)
            available, countdown, reading = star_step(z, dq, run, j, countdown, reading, q_true,
                                                      star)
            if imu_on:
                imu.gyro_reading(counts, detector, rate_lp, run, w, dt, imu_table, imu_table_dt)
            if trapezoid_rate(run, w, mean, trapezoid, rate_prev, has_rate, end):
                _propagate(q, beta, P, mean, dt, errors[run], scratch6, dq,
                           imu_on, strapdown[run], rotation[run, 0], imu_work[run, imu.TURN])
            if not posterior:
                _output(q, out, run, k, last_step, q_true[j], beta, P, beta_last, P_last,
                        variances, keep_traces, streaming, nees_every, settle, nees_samples,
                        nees_sum, scratch6)
            if available:
                _star_reading(q, beta, P, z, run, run_state.R[run], run_state.gating[run],
                              run_state.gate[run, 3], scratch6, dq, mag_bias, check, health[run],
                              factor, streaming, nis_sum, nis_count, likelihood)
            for s in range(vector_available.shape[2]):
                if vector_available[run, j, s]:
                    _vector_reading(q, beta, P, run, j, s, dt, run_block, run_state, rejected,
                                    streaming, likelihood, scratch6, dq, mag_bias, check,
                                    health[run], factor, gravity_models,
                                    field_models)
            if posterior:
                _output(q, out, run, k, last_step, q_true[j], beta, P, beta_last, P_last,
                        variances, keep_traces, streaming, nees_every, settle, nees_samples,
                        nees_sum, scratch6)
            record_error(run, k, q_true[j], out, stats, hist, first_bits, traces, keep_traces,
                         error_every, samples, diverged, bits, bits_int)
            if not trapezoid[run]:
                _propagate(q, beta, P, w, dt, errors[run], scratch6, dq, imu_on,
                           strapdown[run], rotation[run, 0], imu_work[run, imu.TURN])
            if not (finite_state(q, 4, P, P.shape[0]) and finite_state(beta, 3, P, 0)):
                mark_diverged(run, k, diverged, traces, keep_traces, error_every, samples)
            if check:
                check_health(q, True, P, P.shape[0], health[run], factor)


#: Every run of the batch through a block, a share of the runs per core:
#: eight runs side by side where the lanes kernel covers the case (a
#: campaign's), one at a time otherwise (the same numbers either way).
advance = on_every_core_in_lanes(advance_runs, mekf_lanes)
