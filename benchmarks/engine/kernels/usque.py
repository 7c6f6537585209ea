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
from numba import njit, prange

from benchmarks.engine.kernels.common import (check_health, error_arrays, finite_state,
                                              fold_innovation,
                                              gate_thresholds, gauss_jordan, keep_output,
                                              norm_tolerances, passes_norm, mark_diverged,
                                              nees_arrays, quadratic_form, quat_exp,
                                              rate_states, record_error, to_body_frame,
                                              trapezoid_rate)
from benchmarks.engine.kernels.sensors import (first_countdown, gyro_arrays, gyro_reading,
                                               star_arrays, star_step, vector_arrays)
from dynamics.quaternion import GRP_A, GRP_F
from estimators.mekf import transition_coefficients
from estimators.usque import STATE_SIZE

NAME = "usque"
#: It reports a covariance: its kernel streams NEES and NIS.
REPORTS_COVARIANCE = True
#: It applies vector readings and gates readings as the per-run class does.
VECTOR_READINGS = True
GATING = True
#: 2n + 1 sigma points.
N_SIGMAS = 2 * STATE_SIZE + 1


class State(NamedTuple):
    q: np.ndarray                # (B, 4) the reference q̂
    x: np.ndarray                # (B, 6) [δp, β], δp about q̂
    P: np.ndarray                # (B, 6, 6)
    sigmas: np.ndarray           # (B, 13, 6) the sigma points the next update uses
    noise: np.ndarray            # (B,) σ_v², each run's filter's
    bias_rw: np.ndarray          # (B,) σ_u
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
                 noise=stack((e.gyro_noise for e in estimators), ()),
                 bias_rw=stack((e.gyro_bias_random_walk for e in estimators), ()),
                 R=stack((f.R for f in filters), (3, 3)),
                 spread=np.array([_spread(f.points_fn) for f in filters]),
                 Wm=stack((f.Wm for f in filters), (N_SIGMAS,)),
                 Wc=stack((f.Wc for f in filters), (N_SIGMAS,)),
                 beta_last=x[:, 3:].copy(), P_last=P.copy(),
                 posterior=estimators[0].output == "posterior",
                 magnetic_tolerance=norm_tolerances(estimators),
                 **gate_thresholds(estimators), **rate_states(estimators))


def nis_dof(estimators) -> int:
    return 3


def final(state, estimators) -> dict:
    """The output bias estimate and its 6x6 covariance at the last step."""
    return {"bias_radps": state.beta_last, "covariance": state.P_last}


_transition_coefficients = njit(cache=True, inline="always",
                                error_model="numpy")(transition_coefficients)


@njit(cache=True, inline="always", error_model="numpy")
def _product(a0, a1, a2, a3, b0, b1, b2, b3):
    """a ⊗ b (dynamics.quaternion.quat_multiply), not normalised."""
    return (a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
            a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
            a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
            a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0)


@njit(cache=True, inline="always", error_model="numpy")
def _quat_from_grp(p0, p1, p2):
    """dynamics.quaternion.quat_from_grp (a = 1, f = 4)."""
    norm2 = p0 * p0 + p1 * p1 + p2 * p2
    w = (-GRP_A * norm2 + GRP_F * math.sqrt(GRP_F * GRP_F + (1.0 - GRP_A * GRP_A) * norm2)) \
        / (GRP_F * GRP_F + norm2)
    s = (GRP_A + w) / GRP_F
    return w, s * p0, s * p1, s * p2


@njit(cache=True, inline="always", error_model="numpy")
def _grp_from_quat(e):
    """dynamics.quaternion.grp_from_quat, sign-aligned to w >= 0 first."""
    w, x, y, z = e
    if w < 0:
        w, x, y, z = -w, -x, -y, -z
    return GRP_F * x / (GRP_A + w), GRP_F * y / (GRP_A + w), GRP_F * z / (GRP_A + w)


@njit(cache=True, inline="always", error_model="numpy")
def _unit(p):
    w, x, y, z = p
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    return w / norm, x / norm, y / norm, z / norm


@njit(cache=True, inline="always", error_model="numpy")
def _fold_reference(q, x):
    """q̂ ← q̂ ⊗ δq(δp) normalised, δp ← 0 (USQUE._reset, eq. 45)."""
    g0, g1, g2, g3 = _quat_from_grp(x[0], x[1], x[2])
    q[0], q[1], q[2], q[3] = _unit(_product(q[0], q[1], q[2], q[3], g0, g1, g2, g3))
    x[0], x[1], x[2] = 0.0, 0.0, 0.0


@njit(cache=True, inline="always", error_model="numpy")
def _output(q, x, out):
    """USQUE._record's estimate: q̂, or q̂ ⊗ δq(δp) normalised while δp ≠ 0."""
    if x[0] == 0.0 and x[1] == 0.0 and x[2] == 0.0:
        for i in range(4):
            out[i] = q[i]
    else:
        g0, g1, g2, g3 = _quat_from_grp(x[0], x[1], x[2])
        out[0], out[1], out[2], out[3] = _unit(_product(q[0], q[1], q[2], q[3], g0, g1, g2, g3))


@njit(cache=True, error_model="numpy")
def _sigma_points(x, P, spread, sigmas, L):
    """filterpy's ``MerweScaledSigmaPoints.sigma_points``: χ₀ = x, χ_{k+1} = x + U_k,
    χ_{n+k+1} = x − U_k with U the upper Cholesky factor of (n + λ) P (scipy's,
    from P's upper triangle). False if the factor does not exist."""
    n = STATE_SIZE
    # L = Uᵀ, lower, from the upper triangle: U's row k is L's column k.
    for j in range(n):
        total = spread * P[j, j]
        for m in range(j):
            total -= L[j, m] * L[j, m]
        if not total > 0.0 or not math.isfinite(total):
            return False
        L[j, j] = math.sqrt(total)
        for i in range(j + 1, n):
            value = spread * P[j, i]
            for m in range(j):
                value -= L[i, m] * L[j, m]
            L[i, j] = value / L[j, j]
    for m in range(n):
        sigmas[0, m] = x[m]
    for k in range(n):
        for m in range(n):
            u = L[m, k] if m >= k else 0.0
            sigmas[k + 1, m] = x[m] + u
            sigmas[n + k + 1, m] = x[m] - u
    return True


@njit(cache=True, inline="always", error_model="numpy")
def _unscented_mean(sigmas, Wm, rows, mean):
    """Σ Wm_i χ_i over the first ``rows`` columns of the sigma points."""
    for m in range(rows):
        total = 0.0
        for i in range(N_SIGMAS):
            total += Wm[i] * sigmas[i, m]
        mean[m] = total


@njit(cache=True, error_model="numpy")
def _process_noise(o0, o1, o2, dt, noise, bias_rw, Q):
    """The Q of estimators.mekf.discrete_error_model at the rate ω̂."""
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


@njit(cache=True, error_model="numpy")
def _predict(q, x, P, sigmas, w_meas, dt, noise, bias_rw, spread, Wm, Wc, L, Q, propagated):
    """USQUE.propagate: filterpy's ``predict`` with ``fx`` on each sigma point,
    then q̂ ← q̂⁺. False if a Cholesky factor does not exist."""
    if not _sigma_points(x, P, spread, sigmas, L):
        return False
    # The propagated mean q̂⁺ = q̂ ⊗ δq((ω̃ − β̂)Δt), normalised.
    o0, o1, o2 = w_meas[0] - x[3], w_meas[1] - x[4], w_meas[2] - x[5]
    dq = np.empty(4)
    quat_exp(o0 * dt, o1 * dt, o2 * dt, dq)
    n0, n1, n2, n3 = _unit(_product(q[0], q[1], q[2], q[3], dq[0], dq[1], dq[2], dq[3]))
    for i in range(N_SIGMAS):
        s = sigmas[i]
        if s[0] == 0.0 and s[1] == 0.0 and s[2] == 0.0:
            # δq(0) is [1, 0, 0, 0] exactly and q̂ ⊗ it is q̂ (half the
            # points: U's last three rows have no attitude part, and δp = 0).
            a0, a1, a2, a3 = q[0], q[1], q[2], q[3]
        else:
            g0, g1, g2, g3 = _quat_from_grp(s[0], s[1], s[2])
            a0, a1, a2, a3 = _product(q[0], q[1], q[2], q[3], g0, g1, g2, g3)
        quat_exp((w_meas[0] - s[3]) * dt, (w_meas[1] - s[4]) * dt, (w_meas[2] - s[5]) * dt, dq)
        b0, b1, b2, b3 = _unit(_product(a0, a1, a2, a3, dq[0], dq[1], dq[2], dq[3]))
        propagated[i, 0], propagated[i, 1], propagated[i, 2] = _grp_from_quat(
            _product(n0, -n1, -n2, -n3, b0, b1, b2, b3))
        propagated[i, 3], propagated[i, 4], propagated[i, 5] = s[3], s[4], s[5]
    _unscented_mean(propagated, Wm, STATE_SIZE, x)
    _process_noise(o0, o1, o2, dt, noise, bias_rw, Q)
    for a in range(STATE_SIZE):
        for b in range(a, STATE_SIZE):
            total = 0.0
            for i in range(N_SIGMAS):
                total += Wc[i] * (propagated[i, a] - x[a]) * (propagated[i, b] - x[b])
            P[a, b] = total + Q[a, b]
            P[b, a] = total + Q[b, a]
    q[0], q[1], q[2], q[3] = n0, n1, n2, n3
    # filterpy 2.0 redraws the sigma points from (x⁻, P⁻) for the update.
    return _sigma_points(x, P, spread, sigmas, L)


@njit(cache=True, error_model="numpy")
def _update(q, x, P, sigmas, z, R, Wm, Wc, gating, threshold, scratch):
    """USQUE.correct: the update with ``h(χ) = δp`` and y = GRP(q̂⁻¹ ⊗ z),
    ``z`` aligned in sign with q̂ first (returns as :func:`_unscented_update`)."""
    if q[0] * z[0] + q[1] * z[1] + q[2] * z[2] + q[3] * z[3] < 0:
        z0, z1, z2, z3 = -z[0], -z[1], -z[2], -z[3]
    else:
        z0, z1, z2, z3 = z[0], z[1], z[2], z[3]
    y0, y1, y2 = _grp_from_quat(_product(q[0], -q[1], -q[2], -q[3], z0, z1, z2, z3))
    return _unscented_update(x, P, sigmas, sigmas, y0, y1, y2, R, Wm, Wc, gating, threshold,
                             scratch)


@njit(cache=True, error_model="numpy")
def _vector_update(q, x, P, sigmas, body, reference, variance, Wm, Wc, gating, threshold,
                   scratch, predicted, R):
    """USQUE.correct_vector: the update with ``h(χ) = A(q̂ ⊗ δq(δp))ᵀ r`` on
    each sigma point (``USQUE._hx_vector``) and ``R = σ² I``."""
    for i in range(N_SIGMAS):
        g0, g1, g2, g3 = _quat_from_grp(sigmas[i, 0], sigmas[i, 1], sigmas[i, 2])
        a = _unit(_product(q[0], q[1], q[2], q[3], g0, g1, g2, g3))
        predicted[i, 0], predicted[i, 1], predicted[i, 2] = to_body_frame(a, reference)
    for a in range(3):
        for b in range(3):
            R[a, b] = variance if a == b else 0.0
    return _unscented_update(x, P, sigmas, predicted, body[0], body[1], body[2], R, Wm, Wc,
                             gating, threshold, scratch)


@njit(cache=True, error_model="numpy")
def _unscented_update(x, P, sigmas, predicted, y0, y1, y2, R, Wm, Wc, gating, threshold,
                      scratch):
    """filterpy's unscented ``update`` with the sigma points' predicted
    measurements ``predicted`` (their first three columns) and the
    measurement ``y``; not applied if gating rejects it. Returns the NIS,
    whether it was applied and det S."""
    S, inverse, Pxz, K, KS = scratch[0], scratch[1], scratch[2], scratch[3], scratch[4]
    zp, kept = scratch[5, 0], scratch[5, 1:4]
    _unscented_mean(predicted, Wm, 3, zp)
    for a in range(3):
        for b in range(3):
            total = 0.0
            for i in range(N_SIGMAS):
                total += Wc[i] * (predicted[i, a] - zp[a]) * (predicted[i, b] - zp[b])
            S[a, b] = total + R[a, b]
            kept[a, b] = S[a, b]          # gauss_jordan works in place
    for a in range(STATE_SIZE):
        for b in range(3):
            total = 0.0
            for i in range(N_SIGMAS):
                total += Wc[i] * (sigmas[i, a] - x[a]) * (predicted[i, b] - zp[b])
            Pxz[a, b] = total
    determinant = gauss_jordan(S, inverse, 3)
    r0, r1, r2 = y0 - zp[0], y1 - zp[1], y2 - zp[2]
    nis = quadratic_form((r0, r1, r2), inverse, 3)
    if gating and not nis <= threshold:
        return nis, False, determinant
    for a in range(STATE_SIZE):
        for b in range(3):
            K[a, b] = Pxz[a, 0] * inverse[0, b] + Pxz[a, 1] * inverse[1, b] \
                + Pxz[a, 2] * inverse[2, b]
    for a in range(STATE_SIZE):
        x[a] += K[a, 0] * r0 + K[a, 1] * r1 + K[a, 2] * r2
        for b in range(3):
            KS[a, b] = K[a, 0] * kept[0, b] + K[a, 1] * kept[1, b] + K[a, 2] * kept[2, b]
    for a in range(STATE_SIZE):
        for b in range(STATE_SIZE):
            P[a, b] -= KS[a, 0] * K[b, 0] + KS[a, 1] * K[b, 1] + KS[a, 2] * K[b, 2]
    return nis, True, determinant


@njit(cache=True, inline="always", error_model="numpy")
def _any_reading(available, run, j):
    """Whether any vector sensor reads at the block's step ``j``."""
    for s in range(available.shape[2]):
        if available[run, j, s]:
            return True
    return False


@njit(cache=True, error_model="numpy")
def _correct(q, x, P, sigmas, available, z, run, j, R, Wm, Wc, spread, gating, gate,
             vector_body, vector_reference, vector_variance, vector_available, vector_dof,
             scratch, predicted, R_vector, nis_out, streaming, likelihood, rejected,
             vector_magnetic, magnetic_tolerance):
    """The step's updates, as ``USQUE._estimate_at_step`` makes them: the
    tracker's, then each vector reading's, each followed by the reset (or the
    reset alone without any reading), each applied one folded into the
    likelihood sums if ``streaming``. Returns whether the sigma points of
    every update existed (``False``: the per-run class's Cholesky factor
    fails) and whether the tracker's reading was applied (its NIS in
    ``nis_out[0]``); each vector reading gating rejects is counted in
    ``rejected[run, s]``."""
    updated, applied = False, False
    if available:
        nis_out[0], applied, determinant = _update(q, x, P, sigmas, z, R, Wm, Wc, gating,
                                                   gate[3], scratch)
        if streaming and applied:
            fold_innovation(run, nis_out[0], determinant, likelihood)
        _fold_reference(q, x)
        updated = True
    elif not _any_reading(vector_available, run, j):
        _fold_reference(q, x)
    for s in range(vector_dof.shape[0]):
        if vector_available[run, j, s]:
            # Sigma points about the current (x, P) for a second update within a step.
            if updated and not _sigma_points(x, P, spread, sigmas, scratch[0]):
                return False, applied
            if vector_magnetic[s] and not passes_norm(vector_body[run, j, s],
                                                      vector_reference[j, s],
                                                      magnetic_tolerance):
                nis, used, determinant = 0.0, False, 1.0   # a disturbed field: the reset alone
            else:
                nis, used, determinant = _vector_update(
                    q, x, P, sigmas, vector_body[run, j, s], vector_reference[j, s],
                    vector_variance[run, j, s], Wm, Wc, gating, gate[vector_dof[s]], scratch,
                    predicted, R_vector)
            if streaming and used:
                fold_innovation(run, nis, determinant, likelihood)
            if not used:
                rejected[run, s] += 1
            _fold_reference(q, x)
            updated = True
    return True, applied


@njit(parallel=True, cache=True, nogil=True, error_model="numpy")
def advance(block, sensors, state, record, row):
    """Every run through ``block``: update and reset (or reset alone), output,
    then propagate (see :mod:`benchmarks.engine.kernels`)."""
    k0, steps, last_step, dt, q_true = block.k0, block.steps, block.last_step, block.dt, \
        block.q_true
    (omega, gyro_std, normals, scale, has_scale, has_bias, bias_model, bias,
     bias_last) = gyro_arrays(block, sensors)
    (rotation_model, star_std, steps_between, star_normals, sigma_rad, mount, canonical,
     outage, dropout_probability, uniforms) = star_arrays(block)
    (vector_body, vector_reference, vector_variance, vector_available,
     vector_dof, vector_magnetic, _, _) = vector_arrays(block)
    (stats, hist, first_bits, traces, keep_traces, error_every, samples, diverged, check,
     health) = error_arrays(record, row)
    (streaming, nees_every, settle, nees_samples, nees_sum, nis_sum, nis_count,
     variances, likelihood) = nees_arrays(record, row)
    q_all, x_all, P_all, sigmas_all, R_all = state.q, state.x, state.P, state.sigmas, state.R
    noise, bias_rw, spread, Wm_all, Wc_all = (state.noise, state.bias_rw, state.spread,
                                              state.Wm, state.Wc)
    beta_last, P_last, posterior = state.beta_last, state.P_last, state.posterior
    gating, gate = state.gating, state.gate
    rejected, magnetic_tolerance = record.rejected[row], state.magnetic_tolerance
    trapezoid, rate_prev, has_rate, end = (state.trapezoid, state.rate_prev, state.has_rate,
                                           state.end)
    for run in prange(q_all.shape[0]):
        w, z, dq, out, mean = np.empty(3), np.empty(4), np.empty(4), np.empty(4), np.empty(3)
        scratch = np.empty((6, 6, 6))
        propagated = np.empty((N_SIGMAS, STATE_SIZE))
        R_vector, nis = np.empty((3, 3)), np.empty(1)
        bits = np.empty(1)
        bits_int = bits.view(np.int64)
        q, x, P, sigmas = q_all[run], x_all[run], P_all[run], sigmas_all[run]
        Wm, Wc = Wm_all[run], Wc_all[run]
        countdown, reading = first_countdown(k0, steps_between[run]), 0
        for j in range(steps):
            k = k0 + j
            gyro_reading(w, run, j, k, last_step, omega, gyro_std, normals, scale, has_scale,
                         has_bias, bias_model, bias, bias_last)
            available, countdown, reading = star_step(
                z, dq, run, j, countdown, reading, q_true, rotation_model, star_std,
                steps_between, star_normals, sigma_rad, mount, canonical, outage,
                dropout_probability, uniforms)
            if diverged[run] >= 0:       # the per-run class no longer steps
                mark_diverged(run, k, diverged, traces, keep_traces, error_every, samples)
                continue
            if trapezoid_rate(run, w, mean, trapezoid, rate_prev, has_rate, end):
                factored = _predict(q, x, P, sigmas, mean, dt, noise[run], bias_rw[run],
                                    spread[run], Wm, Wc, scratch[0], scratch[1], propagated)
                if not (factored and finite_state(q, 4, P, 6) and finite_state(x, 6, P, 0)):
                    mark_diverged(run, k, diverged, traces, keep_traces, error_every, samples)
                    continue
            if not posterior:
                _output(q, x, out)
                keep_output(run, k, last_step, q_true[j], out, x[3:], P, beta_last, P_last,
                            variances, keep_traces, streaming, nees_every, settle,
                            nees_samples, nees_sum, scratch)
            factored, applied = _correct(
                q, x, P, sigmas, available, z, run, j, R_all[run], Wm, Wc, spread[run],
                gating[run], gate[run], vector_body, vector_reference, vector_variance,
                vector_available, vector_dof, scratch, propagated, R_vector, nis, streaming,
                likelihood, rejected, vector_magnetic, magnetic_tolerance[run])
            if not factored:
                mark_diverged(run, k, diverged, traces, keep_traces, error_every, samples)
                continue
            if streaming and applied:
                nis_sum[run] += nis[0]
                nis_count[run] += 1
            if check and (available or _any_reading(vector_available, run, j)):
                check_health(q, True, P, 6, health[run], scratch[0])
            if posterior:
                _output(q, x, out)
                keep_output(run, k, last_step, q_true[j], out, x[3:], P, beta_last, P_last,
                            variances, keep_traces, streaming, nees_every, settle,
                            nees_samples, nees_sum, scratch)
            record_error(run, k, q_true[j], out, stats, hist, first_bits, traces, keep_traces,
                         error_every, samples, diverged, bits, bits_int)
            if not trapezoid[run]:
                factored = _predict(q, x, P, sigmas, w, dt, noise[run], bias_rw[run],
                                    spread[run], Wm, Wc, scratch[0], scratch[1], propagated)
            else:
                factored = True
            if not (factored and finite_state(q, 4, P, 6) and finite_state(x, 6, P, 0)):
                mark_diverged(run, k, diverged, traces, keep_traces, error_every, samples)
            if check:
                check_health(q, True, P, 6, health[run], scratch[0])
