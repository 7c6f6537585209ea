"""The MEKF's compiled steps (:class:`estimators.MultiplicativeEKF`'s
formulas, in the same order): the propagation of the error covariance
through Φ and Q (:func:`estimators.mekf.discrete_error_model`), filterpy's
Joseph update with the reset after it, and the updates of a star tracker
reading (``H = [I 0]``), a vector reading (``H = [[b̂×] 0]``, a
magnetometer's ``[[b̂×] 0 I]`` with the hard-iron states) and the IMU
models' gravity direction. The kernel's loop
(:mod:`benchmarks.engine.kernels.mekf`) calls them; the covariance is 6x6,
or 9x9 with the hard-iron states."""
from __future__ import annotations

import math

from numba import njit

from benchmarks.engine.kernels.algebra import (add_along_rate, gauss_jordan, joseph_covariance,
                                               log_error, quadratic_form, quat_exp,
                                               quat_times_normalized, to_body_frame)
from benchmarks.engine.kernels.common import passes_norm
from benchmarks.engine.kernels.twins import compiled
from estimators.mekf import (series_coefficients, transition_coefficients,
                             trigonometric_coefficients)


#: The MEKF's transition coefficients: the per-run functions themselves,
#: compiled (plain scalar arithmetic, so one definition serves both paths);
#: the series and the trigonometric ones apart for the kernel in lanes.
series = compiled(series_coefficients, inline=True)
trigonometric = compiled(trigonometric_coefficients, inline=True)
_transition_coefficients = compiled(transition_coefficients, inline=True,
                                    series_coefficients=series,
                                    trigonometric_coefficients=trigonometric)


@njit(cache=True, error_model="numpy")
def propagate_covariance(q, beta, P, w_meas, dt, errors, scratch, dq):
    """q ⊗ δq(ω̂Δt), P = Φ P Φᵀ + Q with Φ = [[A, B], [0, I]] (estimators.mekf;
    ``errors``: the filter's gyro model, σ_v², σ_u and S_s: common.gyro_errors)."""
    noise, bias_rw, scale_density = errors[0], errors[1], errors[2]
    o0, o1, o2 = w_meas[0] - beta[0], w_meas[1] - beta[1], w_meas[2] - beta[2]
    rate = math.sqrt(o0 * o0 + o1 * o1 + o2 * o2)
    s1, c2, s3, q5, q4 = _transition_coefficients(rate, dt)
    W = scratch[0]
    W2 = scratch[1]
    A = scratch[2]
    Bm = scratch[3]
    Q11 = scratch[4]
    Q12 = scratch[5]
    W[0, 0], W[0, 1], W[0, 2] = 0.0, -o2, o1
    W[1, 0], W[1, 1], W[1, 2] = o2, 0.0, -o0
    W[2, 0], W[2, 1], W[2, 2] = -o1, o0, 0.0
    su2 = bias_rw * bias_rw
    for i in range(3):
        for j in range(3):
            W2[i, j] = W[i, 0] * W[0, j] + W[i, 1] * W[1, j] + W[i, 2] * W[2, j]
    for i in range(3):
        for j in range(3):
            eye = 1.0 if i == j else 0.0
            A[i, j] = eye - s1 * W[i, j] + c2 * W2[i, j]
            Bm[i, j] = -(dt * eye - c2 * W[i, j] + s3 * W2[i, j])
            Q11[i, j] = noise * dt * eye + su2 * (dt * dt * dt / 3.0 * eye + q5 * W2[i, j])
            Q12[i, j] = -su2 * (0.5 * dt * dt * eye - s3 * W[i, j] + q4 * W2[i, j])
    if scale_density > 0.0:
        add_along_rate(Q11, o0, o1, o2, scale_density, dt)
    # FP = Φ P: the top three rows A P_top + B P_bottom, the bottom three P's own.
    FP = scratch[6]
    for i in range(3):
        for j in range(6):
            FP[i, j] = (A[i, 0] * P[0, j] + A[i, 1] * P[1, j] + A[i, 2] * P[2, j]
                        + Bm[i, 0] * P[3, j] + Bm[i, 1] * P[4, j] + Bm[i, 2] * P[5, j])
    for i in range(3, 6):
        for j in range(6):
            FP[i, j] = P[i, j]
    # P = FP Φᵀ + Q, upper triangle mirrored (P is symmetric).
    for i in range(6):
        for j in range(i, 6):
            if j < 3:
                value = (FP[i, 0] * A[j, 0] + FP[i, 1] * A[j, 1] + FP[i, 2] * A[j, 2]
                         + FP[i, 3] * Bm[j, 0] + FP[i, 4] * Bm[j, 1] + FP[i, 5] * Bm[j, 2])
            else:
                value = FP[i, j]
            if i < 3 and j < 3:
                value += Q11[i, j]
            elif i < 3:
                value += Q12[i, j - 3]
            elif j >= 3:
                value += su2 * dt if i == j else 0.0
            P[i, j] = value
            P[j, i] = value
    quat_exp(o0 * dt, o1 * dt, o2 * dt, dq)
    quat_times_normalized(q, dq, q)


@njit(cache=True, error_model="numpy")
def carry_constant_states(P, A, Bm, top):
    """The cross-covariance of the core states with constant ones (the hard
    iron: Φ = I, Q = 0 in their block) through Φ: its top three rows become
    ``A P_top + B P_bias``, the rest stay; mirrored. ``top`` is scratch."""
    n = P.shape[0]
    for i in range(3):
        for j in range(6, n):
            top[i, j] = (A[i, 0] * P[0, j] + A[i, 1] * P[1, j] + A[i, 2] * P[2, j]
                         + Bm[i, 0] * P[3, j] + Bm[i, 1] * P[4, j] + Bm[i, 2] * P[5, j])
    for i in range(3):
        for j in range(6, n):
            P[i, j] = top[i, j]
            P[j, i] = top[i, j]


@njit(cache=True, error_model="numpy")
def joseph_update(q, beta, P, y0, y1, y2, H, R, gating, threshold, scratch, dq, mag_bias,
                   bias_columns=False):
    """filterpy's update with innovation ``y`` and Jacobian ``H`` (3 x n, zero
    in its gyro-bias columns unless ``bias_columns``), ``K = P Hᵀ S⁻¹`` and
    Joseph's form, then the reset (the hard-iron estimate ``mag_bias`` too,
    where P has its states); not applied if gating rejects it. Returns the
    NIS, whether it was applied and det S."""
    n = P.shape[0]
    PHT, S, inverse, K, IK, T, KR = (scratch[0], scratch[1], scratch[2], scratch[3],
                                     scratch[4], scratch[5], scratch[6])
    for i in range(n):
        for j in range(3):
            PHT[i, j] = P[i, 0] * H[j, 0] + P[i, 1] * H[j, 1] + P[i, 2] * H[j, 2]
            if bias_columns:
                PHT[i, j] += P[i, 3] * H[j, 3] + P[i, 4] * H[j, 4] + P[i, 5] * H[j, 5]
            for m in range(6, n):
                PHT[i, j] += P[i, m] * H[j, m]
    for i in range(3):
        for j in range(3):
            S[i, j] = (H[i, 0] * PHT[0, j] + H[i, 1] * PHT[1, j] + H[i, 2] * PHT[2, j]) \
                + R[i, j]
            if bias_columns:
                S[i, j] += H[i, 3] * PHT[3, j] + H[i, 4] * PHT[4, j] + H[i, 5] * PHT[5, j]
            for m in range(6, n):
                S[i, j] += H[i, m] * PHT[m, j]
    determinant = gauss_jordan(S, inverse, 3)
    nis = quadratic_form((y0, y1, y2), inverse, 3)
    if gating and not nis <= threshold:
        return nis, False, determinant
    for i in range(n):
        for j in range(3):
            K[i, j] = PHT[i, 0] * inverse[0, j] + PHT[i, 1] * inverse[1, j] \
                + PHT[i, 2] * inverse[2, j]
    dx = scratch[7, 0]
    for i in range(n):
        dx[i] = K[i, 0] * y0 + K[i, 1] * y1 + K[i, 2] * y2
    # I - K H: H's gyro-bias columns are zero unless bias_columns.
    for i in range(n):
        for j in range(n):
            IK[i, j] = (1.0 if i == j else 0.0) - (
                K[i, 0] * H[0, j] + K[i, 1] * H[1, j] + K[i, 2] * H[2, j]
                if j < 3 or j >= 6 or bias_columns else 0.0)
    for i in range(n):
        for j in range(3):
            KR[i, j] = K[i, 0] * R[0, j] + K[i, 1] * R[1, j] + K[i, 2] * R[2, j]
    KRK = PHT                                      # P Hᵀ is spent: its slot holds K R Kᵀ
    for i in range(n):
        for j in range(n):
            KRK[i, j] = KR[i, 0] * K[j, 0] + KR[i, 1] * K[j, 1] + KR[i, 2] * K[j, 2]
    # Without bias columns in H, I − KH's are the identity's: their products are skipped.
    joseph_covariance(P, IK, KRK, T, n, not bias_columns)
    quat_exp(dx[0], dx[1], dx[2], dq)
    quat_times_normalized(q, dq, q)
    beta[0] += dx[3]
    beta[1] += dx[4]
    beta[2] += dx[5]
    for i in range(6, n):
        mag_bias[i - 6] += dx[i]
    return nis, True, determinant


@njit(cache=True, inline="always", error_model="numpy")
def _identity_jacobian(H):
    """H = [I 0], a full-attitude reading's."""
    for i in range(3):
        for j in range(H.shape[1]):
            H[i, j] = 1.0 if i == j else 0.0


@njit(cache=True, error_model="numpy")
def star_update(q, beta, P, z, R, gating, threshold, scratch, dq, mag_bias):
    """MultiplicativeEKF.correct: y = log(q̂⁻¹ ⊗ z), H = [I 0]."""
    # The reading aligned in sign with q̂ is what the alignment inside the log does.
    y0, y1, y2 = log_error(q, z, 1.0)
    H = scratch[8]
    _identity_jacobian(H)
    return joseph_update(q, beta, P, y0, y1, y2, H, R, gating, threshold, scratch, dq,
                          mag_bias)


@njit(cache=True, error_model="numpy")
def vector_update(q, beta, P, body, reference, variance, gating, threshold, scratch, dq,
                        mag_bias, hard_iron):
    """MultiplicativeEKF.correct_vector: y = b − A(q̂)ᵀ r, H = [[A(q̂)ᵀ r ×] 0],
    R = σ² I; a magnetometer's with its hard iron (``hard_iron``)
    y = b − A(q̂)ᵀ r − b̂_m, H = [[A(q̂)ᵀ r ×] 0 I]."""
    p0, p1, p2 = to_body_frame(q, reference)
    H = scratch[8]
    R = scratch[9]
    for i in range(3):
        for j in range(P.shape[0]):
            H[i, j] = 0.0
        for j in range(3):
            R[i, j] = variance if i == j else 0.0
        if hard_iron:
            H[i, 6 + i] = 1.0
    H[0, 1], H[0, 2] = -p2, p1
    H[1, 0], H[1, 2] = p2, -p0
    H[2, 0], H[2, 1] = -p1, p0
    if hard_iron:
        p0, p1, p2 = p0 + mag_bias[0], p1 + mag_bias[1], p2 + mag_bias[2]
    return joseph_update(q, beta, P, body[0] - p0, body[1] - p1, body[2] - p2, H, R,
                          gating, threshold, scratch, dq, mag_bias)


@njit(cache=True, inline="always", error_model="numpy")
def field_passes(body, reference, tolerance, mag_bias, hard_iron):
    """The magnetic norm test (MultiplicativeEKF.correct_vector) on the field
    less the hard-iron estimate where the filter estimates it."""
    if not hard_iron:
        return passes_norm(body, reference, tolerance)
    return passes_norm((body[0] - mag_bias[0], body[1] - mag_bias[1], body[2] - mag_bias[2]),
                       reference, tolerance)


@njit(cache=True, error_model="numpy")
def gravity_update(q, beta, P, up, variance, drift, gating, threshold, scratch, dq, mag_bias):
    """The low-passed gravity direction (estimators.imu.updates): the vector
    update of e_z with the strapdown's drift in H's bias columns."""
    p0, p1, p2 = to_body_frame(q, (0.0, 0.0, 1.0))
    H = scratch[8]
    R = scratch[9]
    for i in range(3):
        for j in range(3):
            R[i, j] = variance if i == j else 0.0
            H[i, 3 + j] = drift[i, j]
        for j in range(6, P.shape[0]):
            H[i, j] = 0.0
    H[0, 0], H[0, 1], H[0, 2] = 0.0, -p2, p1
    H[1, 0], H[1, 1], H[1, 2] = p2, 0.0, -p0
    H[2, 0], H[2, 1], H[2, 2] = -p1, p0, 0.0
    return joseph_update(q, beta, P, up[0] - p0, up[1] - p1, up[2] - p2, H, R,
                          gating, threshold, scratch, dq, mag_bias, True)
