r"""USQUE in the engine: :class:`estimators.USQUE` — filterpy's
``UnscentedKalmanFilter`` with ``MerweScaledSigmaPoints`` on the state
:math:`x = [\delta p, \beta]` (GRPs of the error about the reference
:math:`\hat q`, and the gyro bias), Crassidis & Markley 2003, eqs. 31–45.

A step, as the per-run class makes it:

1. *Update* with a reading (filterpy 2.0's ``update``): the sigma points
   drawn after the last prediction, ``h(χ) = δp``, the unscented mean and
   covariance of ``h`` plus ``R``, the cross covariance, ``K = P_xz S⁻¹``,
   ``x += K (y − ẑ)``, ``P −= K S Kᵀ``, on ``y = GRP(q̂⁻¹ ⊗ z)``; then each
   vector reading in turn, with ``h(χ) = A(q̂ ⊗ δq(δp))ᵀ r`` on sigma points
   redrawn about the current ``(x, P)`` for every update after the first.
   Each is gated as the per-run class gates it.
2. *Reset*: the mean's δp folded into ``q̂`` (eq. 45) after each update, or
   once without any reading.
3. *Propagate* (``predict``): sigma points from the Cholesky factor of
   ``(n + λ) P``, each through the exact kinematics with its own bias and
   back to GRPs about the propagated mean (eqs. 33–36), their unscented mean
   and covariance plus the MEKF's ``Q`` (:func:`estimators.mekf.discrete_error_model`),
   then the sigma points redrawn from ``(x⁻, P⁻)`` for the next update.

A Cholesky factor that does not exist (a covariance no longer positive
definite: scipy raises ``LinAlgError`` on the per-run path) marks the run
diverged at that step, as :meth:`estimators.base.AttitudeEstimator.step` does.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from benchmarks.engine.kernels import imu, usque_imu
from benchmarks.engine.kernels.algebra import add_along_rate, quat_exp, to_body_frame
from benchmarks.engine.kernels.borrowed import borrowed
from benchmarks.engine.kernels.common import (check_health, error_arrays, finite_state,
                                              fold_innovation, gate_thresholds, gyro_errors,
                                              keep_output, norm_tolerances, passes_norm,
                                              mark_diverged, nees_arrays, rate_arrays,
                                              rate_states, record_error, trapezoid_rate)
from benchmarks.engine.kernels.cores import on_every_core_of
from benchmarks.engine.kernels.mekf_steps import series, trigonometric
from benchmarks.engine.kernels.sensors import (first_countdown, gyro_arrays, gyro_reading,
                                               star_arrays, star_step, vector_arrays)
from benchmarks.engine.kernels.twins import compiled
from benchmarks.engine.kernels.unscented import (N_SIGMAS, fold_reference, grp_from_quat,
                                                 output, product, quat_from_grp,
                                                 sigma_points, unit, unscented_mean,
                                                 unscented_update)
from estimators.mekf import transition_coefficients
from estimators.usque import STATE_SIZE

NAME = "usque"
#: It reports a covariance: its kernel streams NEES and NIS.
REPORTS_COVARIANCE = True
#: It applies vector readings and gates readings as the per-run class does.
VECTOR_READINGS = True
GATING = True


class State(NamedTuple):
    q: np.ndarray                # (B, 4) the reference q̂
    x: np.ndarray                # (B, 6) [δp, β], δp about q̂
    P: np.ndarray                # (B, 6, 6)
    sigmas: np.ndarray           # (B, 13, 6) the sigma points the next update uses
    gyro_errors: np.ndarray      # (B, 3) σ_v², σ_u, S_s: each run's filter's gyro model
    R: np.ndarray                # (B, 3, 3)
    spread: np.ndarray           # (B,) n + λ, as filterpy's sigma points compute it
    Wm: np.ndarray               # (B, 13) the weights of the mean
    Wc: np.ndarray               # (B, 13) and of the covariance
    beta_last: np.ndarray        # (B, 3) the output bias at the last step
    P_last: np.ndarray           # (B, 6, 6) and its covariance
    posterior: bool
    gating: np.ndarray           # (B,) bool: the filter gates its readings
    gate: np.ndarray             # (B, 4) the χ² threshold for 1, 2, 3 degrees of freedom
    magnetic_tolerance: np.ndarray  # (B,) the magnetic norm test's (inf: none)
    trapezoid: np.ndarray        # (B,) bool: the trapezoidal rate (estimators.sampled_rate)
    rate_prev: np.ndarray        # (B, 3) the last reading, for it
    has_rate: np.ndarray         # (B,) bool: there is one
    end: np.ndarray              # (B,) bool: the rate at the step's end instead
    # The IMU models (benchmarks.engine.kernels.imu.imu_state), as the MEKF's.
    imu_on: bool
    imu_lowpass: bool
    imu_heading: bool
    imu_rest: bool
    imu_densities: np.ndarray
    imu_strapdown: np.ndarray
    imu_gravity: np.ndarray
    imu_detector: np.ndarray
    imu_trust: np.ndarray
    imu_rate_lp: np.ndarray
    imu_counts: np.ndarray
    imu_rotation: np.ndarray
    imu_field: np.ndarray
    imu_iron_fit: bool
    imu_iron: np.ndarray
    imu_table: np.ndarray        # (3, 5) the low-pass filters' coefficients at imu_table_dt
    imu_table_dt: float
    imu_work: np.ndarray         # (B, 8, 3) the models' working vectors, per run
    imu_drift: np.ndarray        # (B, 3, 3) gravity's bias columns, per run
    imu_nine: np.ndarray         # (B, 9) the rotation integral's low-passed value, per run


@njit(cache=True, inline="always", error_model="numpy")
def _filter_arrays(state):
    """The filters' arrays of the state, taken out of its tuple (before the
    loop over the runs: see the kernels package's docstring)."""
    return (state.q, state.x, state.P, state.sigmas, state.gyro_errors, state.spread,
            state.Wm, state.Wc, state.beta_last, state.P_last, state.posterior)


def _spread(points) -> float:
    """``n + λ`` with ``λ = α² (n + κ) − n``, in filterpy's own order
    (``MerweScaledSigmaPoints.sigma_points``)."""
    lambda_ = points.alpha ** 2 * (points.n + points.kappa) - points.n
    return lambda_ + points.n


def initial_state(estimators) -> State:
    """From the per-run objects (``from_scenario``), one per run: filterpy's
    ``x``, ``P``, the sigma points and weights it holds."""
    def stack(values, shape):
        return np.array(list(values), dtype=float).reshape((-1,) + shape)
    filters = [e.filter for e in estimators]
    P = stack((f.P for f in filters), (6, 6))
    x = stack((f.x for f in filters), (6,))
    return State(q=stack((e.q_hat for e in estimators), (4,)), x=x, P=P,
                 sigmas=stack((f.sigmas_f for f in filters), (N_SIGMAS, 6)),
                 gyro_errors=gyro_errors(estimators),
                 R=stack((f.R for f in filters), (3, 3)),
                 spread=np.array([_spread(f.points_fn) for f in filters]),
                 Wm=stack((f.Wm for f in filters), (N_SIGMAS,)),
                 Wc=stack((f.Wc for f in filters), (N_SIGMAS,)),
                 beta_last=x[:, 3:].copy(), P_last=P.copy(),
                 posterior=estimators[0].output == "posterior",
                 magnetic_tolerance=norm_tolerances(estimators),
                 **gate_thresholds(estimators), **rate_states(estimators),
                 **imu.imu_state(estimators))


def nis_dof(estimators) -> int:
    return 3


def final(state, estimators) -> dict:
    """The output bias estimate and its 6x6 covariance at the last step."""
    return {"bias_radps": state.beta_last, "covariance": state.P_last}


_transition_coefficients = compiled(transition_coefficients, series_coefficients=series,
                                    trigonometric_coefficients=trigonometric)


@njit(cache=True, error_model="numpy")
def _process_noise(o0, o1, o2, dt, errors, Q):
    """The Q of estimators.mekf.discrete_error_model at the rate ω̂ (``errors``:
    σ_v², σ_u, S_s, as common.gyro_errors keeps them)."""
    noise, bias_rw, scale_density = errors[0], errors[1], errors[2]
    rate = math.sqrt(o0 * o0 + o1 * o1 + o2 * o2)
    _, _, s3, q5, q4 = _transition_coefficients(rate, dt)
    W = ((0.0, -o2, o1), (o2, 0.0, -o0), (-o1, o0, 0.0))
    su2 = bias_rw * bias_rw
    for i in range(3):
        for j in range(3):
            eye = 1.0 if i == j else 0.0
            w2 = W[i][0] * W[0][j] + W[i][1] * W[1][j] + W[i][2] * W[2][j]
            Q[i, j] = noise * dt * eye + su2 * (dt * dt * dt / 3.0 * eye + q5 * w2)
            Q[i, j + 3] = -su2 * (0.5 * dt * dt * eye - s3 * W[i][j] + q4 * w2)
            Q[j + 3, i] = Q[i, j + 3]
            Q[i + 3, j + 3] = su2 * dt * eye
    if scale_density > 0.0:
        add_along_rate(Q, o0, o1, o2, scale_density, dt)


@njit(cache=True, error_model="numpy")
def _predict(q, x, P, sigmas, w_meas, dt, errors, spread, Wm, Wc, L, Q, propagated):
    """USQUE.propagate: filterpy's ``predict`` with ``fx`` on each sigma point,
    then q̂ ← q̂⁺. False if a Cholesky factor does not exist."""
    if not sigma_points(x, P, spread, sigmas, L):
        return False
    # The propagated mean q̂⁺ = q̂ ⊗ δq((ω̃ − β̂)Δt), normalised.
    o0, o1, o2 = w_meas[0] - x[3], w_meas[1] - x[4], w_meas[2] - x[5]
    dq = np.empty(4)
    quat_exp(o0 * dt, o1 * dt, o2 * dt, dq)
    n0, n1, n2, n3 = unit(product(q[0], q[1], q[2], q[3], dq[0], dq[1], dq[2], dq[3]))
    for i in range(N_SIGMAS):
        s = sigmas[i]
        if s[0] == 0.0 and s[1] == 0.0 and s[2] == 0.0:
            # δq(0) is [1, 0, 0, 0] exactly and q̂ ⊗ it is q̂ (half the
            # points: U's last three rows have no attitude part, and δp = 0).
            a0, a1, a2, a3 = q[0], q[1], q[2], q[3]
        else:
            g0, g1, g2, g3 = quat_from_grp(s[0], s[1], s[2])
            a0, a1, a2, a3 = product(q[0], q[1], q[2], q[3], g0, g1, g2, g3)
        quat_exp((w_meas[0] - s[3]) * dt, (w_meas[1] - s[4]) * dt, (w_meas[2] - s[5]) * dt, dq)
        b0, b1, b2, b3 = unit(product(a0, a1, a2, a3, dq[0], dq[1], dq[2], dq[3]))
        propagated[i, 0], propagated[i, 1], propagated[i, 2] = grp_from_quat(
            product(n0, -n1, -n2, -n3, b0, b1, b2, b3))
        propagated[i, 3], propagated[i, 4], propagated[i, 5] = s[3], s[4], s[5]
    unscented_mean(propagated, Wm, STATE_SIZE, x)
    _process_noise(o0, o1, o2, dt, errors, Q)
    for a in range(STATE_SIZE):
        for b in range(a, STATE_SIZE):
            total = 0.0
            for i in range(N_SIGMAS):
                total += Wc[i] * (propagated[i, a] - x[a]) * (propagated[i, b] - x[b])
            P[a, b] = total + Q[a, b]
            P[b, a] = total + Q[b, a]
    q[0], q[1], q[2], q[3] = n0, n1, n2, n3
    # filterpy 2.0 redraws the sigma points from (x⁻, P⁻) for the update.
    return sigma_points(x, P, spread, sigmas, L)


@njit(cache=True, error_model="numpy")
def _update(q, x, P, sigmas, z, R, Wm, Wc, gating, threshold, scratch):
    """USQUE.correct: the update with ``h(χ) = δp`` and y = GRP(q̂⁻¹ ⊗ z),
    ``z`` aligned in sign with q̂ first (returns as :func:`unscented_update`)."""
    if q[0] * z[0] + q[1] * z[1] + q[2] * z[2] + q[3] * z[3] < 0:
        z0, z1, z2, z3 = -z[0], -z[1], -z[2], -z[3]
    else:
        z0, z1, z2, z3 = z[0], z[1], z[2], z[3]
    y0, y1, y2 = grp_from_quat(product(q[0], -q[1], -q[2], -q[3], z0, z1, z2, z3))
    return unscented_update(x, P, sigmas, sigmas, y0, y1, y2, R, Wm, Wc, gating, threshold,
                             scratch)


@njit(cache=True, error_model="numpy")
def _vector_update(q, x, P, sigmas, body, reference, variance, Wm, Wc, gating, threshold,
                   scratch, predicted, R):
    """USQUE.correct_vector: the update with ``h(χ) = A(q̂ ⊗ δq(δp))ᵀ r`` on
    each sigma point (``USQUE._hx_vector``) and ``R = σ² I``."""
    for i in range(N_SIGMAS):
        g0, g1, g2, g3 = quat_from_grp(sigmas[i, 0], sigmas[i, 1], sigmas[i, 2])
        a = unit(product(q[0], q[1], q[2], q[3], g0, g1, g2, g3))
        predicted[i, 0], predicted[i, 1], predicted[i, 2] = to_body_frame(a, reference)
    for a in range(3):
        for b in range(3):
            R[a, b] = variance if a == b else 0.0
    return unscented_update(x, P, sigmas, predicted, body[0], body[1], body[2], R, Wm, Wc,
                             gating, threshold, scratch)


@njit(cache=True, error_model="numpy")
def _any_reading(available, run, j):
    """Whether any vector sensor reads at the block's step ``j``."""
    for s in range(available.shape[2]):
        if available[run, j, s]:
            return True
    return False


@njit(cache=True, error_model="numpy")
def _correct(q, x, P, sigmas, available, z, run, j, dt, Wm, Wc, vectors, state, rejected,
             streaming, nis_sum, nis_count, likelihood, check, health, scratch, predicted,
             R_vector):
    """The step's updates, as ``USQUE._estimate_at_step`` makes them: the
    tracker's, then each vector reading's (through the IMU models where they
    take it, :mod:`usque_imu`), each followed by the reset (or the reset alone
    without any reading); each applied one folded into the likelihood sums,
    the tracker's NIS into ``nis_sum``, each vector reading refused (gated, or
    a disturbed field) counted in ``rejected``, and the health checked once
    after the step's readings, if it had any. False if the sigma points of an
    update did not exist (the per-run class's Cholesky factor fails): the run
    diverges there, and its step adds no NIS."""
    (body, reference, variance, vector_available, dof, magnetic, gravity, known) = vectors
    spread, gating, gate = state.spread[run], state.gating[run], state.gate[run]
    updated, applied, nis = False, False, 0.0
    if available:
        nis, applied, determinant = _update(q, x, P, sigmas, z, state.R[run], Wm, Wc, gating,
                                            gate[3], scratch)
        if streaming:
            fold_innovation(run, nis if applied else gate[3], determinant, likelihood)
        fold_reference(q, x)
        updated = True
    elif not _any_reading(vector_available, run, j):
        fold_reference(q, x)
        return True
    for s in range(dof.shape[0]):
        if not vector_available[run, j, s]:
            continue
        if state.imu_on:
            taken, factored, updated = usque_imu.reading(
                q, x, P, sigmas, run, j, s, dt, body, reference, gravity, magnetic, known,
                dof, gating, gate, rejected, streaming, likelihood, state, spread, Wm, Wc,
                updated, scratch, predicted, R_vector)
            if not factored:
                return False
            if taken:
                continue
        # Sigma points about the current (x, P) for a second update within a step.
        if updated and not sigma_points(x, P, spread, sigmas, scratch[0]):
            return False
        if magnetic[s] and not passes_norm(body[run, j, s], reference[j, s],
                                           state.magnetic_tolerance[run]):
            used = False               # a disturbed field: the reset alone
        else:
            vector_nis, used, determinant = _vector_update(
                q, x, P, sigmas, body[run, j, s], reference[j, s], variance[run, j, s], Wm,
                Wc, gating, gate[dof[s]], scratch, predicted, R_vector)
            if streaming:
                fold_innovation(run, vector_nis if used else gate[dof[s]], determinant,
                                likelihood)
        if not used:
            rejected[run, s] += 1
        fold_reference(q, x)
        updated = True
    if streaming and applied:
        nis_sum[run] += nis
        nis_count[run] += 1
    if check:
        check_health(q, True, P, 6, health, scratch[0])
    return True


@njit(cache=True, inline="always", error_model="numpy")
def _batch_scratch(n_runs):
    """Every run's working arrays, made once for the batch."""
    return (np.empty((n_runs, 3)), np.empty((n_runs, 4)), np.empty((n_runs, 4)),
            np.empty((n_runs, 4)), np.empty((n_runs, 3)), np.empty((n_runs, 6, 6, 6)),
            np.empty((n_runs, N_SIGMAS, STATE_SIZE)), np.empty((n_runs, 3, 3)),
            np.empty((n_runs, 1)))


@njit(cache=True, inline="always", error_model="numpy")
def _run_scratch(batch, run):
    """Run ``run``'s rows of :func:`_batch_scratch`'s arrays, borrowed."""
    w, z, dq, out, mean, scratch, propagated, R_vector, bits = batch
    return borrowed((w[run], z[run], dq[run], out[run], mean[run], scratch[run],
                     propagated[run], R_vector[run], bits[run]))


@njit(cache=True, error_model="numpy")
def _propagated(q, x, P, sigmas, rate, dt, run, errors, spread, Wm, Wc, scratch,
                propagated, imu_on, strapdown, rotation, turns):
    """:func:`_predict` with ``rate`` (and the IMU models' strapdown before it):
    True if its Cholesky factors existed and the state is finite after it.
    Called, though it runs every step: inlined at the loop's two places, it
    took 9 s more to compile, and beside the sigma points' propagation its
    call costs nothing measurable."""
    if imu_on:
        usque_imu.propagate_strapdown(strapdown[run], rotation[run, 0], rate, x, dt, turns[run])
    factored = _predict(q, x, P, sigmas, rate, dt, errors[run], spread[run], Wm, Wc,
                        scratch[0], scratch[1], propagated)
    return factored and _finite(q, x, P)


@njit(cache=True, inline="always", error_model="numpy")
def _finite(q, x, P):
    """The divergence test (AttitudeEstimator.state_is_finite) on q̂, x and P."""
    return finite_state(q, 4, P, 6) and finite_state(x, 6, P, 0)


@njit(cache=True, inline="always", error_model="numpy")
def _output(q, x, out, run, k, last_step, q_true_k, P, beta_last, P_last, variances,
            keep_traces, streaming, nees_every, settle, nees_samples, nees_sum, scratch):
    """The estimate output at step ``k`` (:func:`output`, before or after the
    step's readings, as the filter outputs): in ``out``, and kept by
    :func:`keep_output`."""
    output(q, x, out)
    keep_output(run, k, last_step, q_true_k, out, x[3:], P, beta_last, P_last, variances,
                keep_traces, streaming, nees_every, settle, nees_samples, nees_sum, scratch)


@njit(cache=True, nogil=True, error_model="numpy")
def advance_runs(first, last, block, sensors, state, record, row):
    """Runs ``first`` to ``last - 1`` through ``block``: update and reset (or reset alone), output,
    then propagate (see :mod:`benchmarks.engine.kernels`)."""
    k0, steps, last_step, dt = block.k0, block.steps, block.last_step, block.dt
    q_true = borrowed(block.q_true)
    (omega, gyro_std, normals, scale, has_scale, has_bias, bias_model, bias,
     bias_last) = borrowed(gyro_arrays(block, sensors))
    star, vectors, rejected = borrowed((star_arrays(block), vector_arrays(block),
                                        record.rejected[row]))
    (stats, hist, first_bits, traces, keep_traces, error_every, samples, diverged, check,
     health) = borrowed(error_arrays(record, row))
    (streaming, nees_every, settle, nees_samples, nees_sum, nis_sum, nis_count,
     variances, likelihood) = borrowed(nees_arrays(record, row))
    (q_all, x_all, P_all, sigmas_all, errors, spread, Wm_all, Wc_all, beta_last, P_last,
     posterior) = borrowed(_filter_arrays(state))
    (trapezoid, rate_prev, has_rate, end, imu_on, counts, detector, rate_lp, strapdown,
     rotation, imu_table, imu_table_dt, imu_work) = borrowed(rate_arrays(state))
    imu_turns = imu_work[:, imu.TURN]         # (B, 3): each run's strapdown turn
    batch = _batch_scratch(last - first)
    for index in range(first, last):
        run, run_state = np.int64(index), borrowed(state)
        w, z, dq, out, mean, scratch, propagated, R_vector, bits = _run_scratch(batch, run - first)
        bits_int = bits.view(np.int64)
        q, x, P, sigmas = q_all[run], x_all[run], P_all[run], sigmas_all[run]
        Wm, Wc, countdown, reading = Wm_all[run], Wc_all[run], first_countdown(k0, star, run), 0
        for j in range(steps):
            k = k0 + j
            gyro_reading(w, run, j, k, last_step, omega, gyro_std, normals, scale, has_scale,
                         has_bias, bias_model, bias, bias_last)
            available, countdown, reading = star_step(z, dq, run, j, countdown, reading, q_true,
                                                      star)
            if diverged[run] >= 0:       # the per-run class no longer steps
                mark_diverged(run, k, diverged, traces, keep_traces, error_every, samples)
                continue
            if imu_on:
                imu.gyro_reading(counts, detector, rate_lp, run, w, dt, imu_table, imu_table_dt)
            if trapezoid_rate(run, w, mean, trapezoid, rate_prev, has_rate, end) and not \
                    _propagated(q, x, P, sigmas, mean, dt, run, errors, spread, Wm, Wc,
                                scratch, propagated, imu_on, strapdown, rotation, imu_turns):
                mark_diverged(run, k, diverged, traces, keep_traces, error_every, samples)
                continue
            if not posterior:
                _output(q, x, out, run, k, last_step, q_true[j], P, beta_last, P_last, variances,
                        keep_traces, streaming, nees_every, settle, nees_samples, nees_sum, scratch)
            if not _correct(q, x, P, sigmas, available, z, run, j, dt, Wm, Wc, vectors, run_state,
                            rejected, streaming, nis_sum, nis_count, likelihood, check,
                            health[run], scratch, propagated, R_vector):
                mark_diverged(run, k, diverged, traces, keep_traces, error_every, samples)
                continue
            if posterior:
                _output(q, x, out, run, k, last_step, q_true[j], P, beta_last, P_last, variances,
                        keep_traces, streaming, nees_every, settle, nees_samples, nees_sum, scratch)
            record_error(run, k, q_true[j], out, stats, hist, first_bits, traces, keep_traces,
                         error_every, samples, diverged, bits, bits_int)
            if not (_finite(q, x, P) if trapezoid[run] else _propagated(
                    q, x, P, sigmas, w, dt, run, errors, spread, Wm, Wc, scratch,
                    propagated, imu_on, strapdown, rotation, imu_turns)):
                mark_diverged(run, k, diverged, traces, keep_traces, error_every, samples)
            if check:
                check_health(q, True, P, 6, health[run], scratch[0])


#: Every run of the batch through a block, a share of the runs per core.
advance = on_every_core_of(advance_runs)
