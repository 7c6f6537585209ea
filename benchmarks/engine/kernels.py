r"""Compiled kernels of the batched engine: the estimators of the registry,
advanced over a block of steps for many runs at once, with the sensors that
feed them.

Why a compiled kernel: the estimators' arithmetic is tiny (4-vectors, 4x4
covariances), so on the per-run path nearly all the time goes to the Python
and numpy call overhead of each step, not to arithmetic. numba compiles the
loops below to machine code; one run is one iteration of a ``prange`` loop
(spread over the cores), its steps a plain loop with the state in registers
and small scratch arrays.

Each formula is the same, in the same order, as its reference on the per-run
path, which stays the readable definition:

* :func:`estimators.model.propagate_with_jacobian` — ``f`` and ``F``;
* :class:`estimators.DeadReckoning`, :class:`estimators.DeadReckoningWithResets`;
* :class:`estimators.QuaternionEKF` (filterpy's update with ``H = I``,
  Joseph form, then the nonlinear predict);
* :class:`estimators.MultiplicativeEKF` (:func:`estimators.mekf.discrete_error_model`,
  filterpy's Joseph update with ``H = [I 0]``, the reset, the exact
  quaternion step);
* :class:`sensors.Gyro` (with its bias random walk, scale and misalignment),
  :class:`sensors.StarTracker` and :class:`sensors.RotationStarTracker`
  (dropouts, outages, sign) — readings from the same standard normals;
* :func:`dynamics.quaternion.attitude_error_rad` — the error metric (its
  arccos within 1 ulp of the C library's, see :func:`_acos`).

The engine's tests check the two paths agree to 1e-9 at every step. Runs
never interact (no reductions across the batch, no fast-math reassociation),
so a run's numbers are bit-identical whatever batch it is computed in.
Division by zero follows numpy's IEEE rules (``error_model="numpy"``), as on
the per-run path, which also spares a check on every division.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from estimators.mekf import transition_coefficients

#: Estimator slots, in the order of ``estimators.ESTIMATORS``.
DEAD_RECKONING, RESETS, EKF, MEKF = 0, 1, 2, 3
#: Per-run streaming accumulators: Welford mean and M2, max, final value.
MEAN, M2, MAX, FINAL = 0, 1, 2, 3
N_ACCUMULATORS = 4
#: Histogram bins keep 7 mantissa bits: 128 bins per octave of error.
HISTOGRAM_SHIFT = 52 - 7
_RAD_TO_DEG = 180.0 / math.pi

# fdlibm's e_acos.c coefficients (Sun Microsystems, 1993): asin(√z)/√z - 1 ≈ z p(z)/q(z).
_PS0 = 1.66666666666666657415e-01
_PS1 = -3.25565818622400915405e-01
_PS2 = 2.01212532134862925881e-01
_PS3 = -4.00555345006794114027e-02
_PS4 = 7.91534994289814532176e-04
_PS5 = 3.47933107596021167570e-05
_QS1 = -2.40339491173441421878e+00
_QS2 = 2.02094576023350569471e+00
_QS3 = -6.88283971605453293030e-01
_QS4 = 7.70381505559019352791e-02
_HIGH_WORD_MASK = np.int64(-4294967296)   # clears the low 32 bits of a double


@njit(cache=True, inline="always", error_model="numpy")
def _acos(x, bits, bits_int):
    """arccos(x) for 0 <= x <= 1, within 1 ulp of the C library's.

    The attitude error needs one arccos per step per estimator, and the C
    library's call was a fifth of the kernel's time. Nearly all attitude
    errors are below 120°, i.e. x > 0.5, where fdlibm's branch
    acos(x) = 2 asin(√((1 - x)/2)) with its rational approximation is
    inlined here; elsewhere the library is called.
    """
    if x >= 1.0:
        return 0.0
    if x <= 0.5:
        return math.acos(x)
    z = (1.0 - x) * 0.5
    s = math.sqrt(z)
    bits[0] = s
    bits_int[0] = bits_int[0] & _HIGH_WORD_MASK
    df = bits[0]
    c = (z - df * df) / (s + df)
    p = z * (_PS0 + z * (_PS1 + z * (_PS2 + z * (_PS3 + z * (_PS4 + z * _PS5)))))
    q = 1.0 + z * (_QS1 + z * (_QS2 + z * (_QS3 + z * _QS4)))
    return 2.0 * (df + (p / q) * s + c)


@njit(cache=True, inline="always", error_model="numpy")
def _propagate(q, w, half_dt, out, jacobian, want_jacobian):
    """out = f(q, ω); jacobian = ∂f/∂q if asked (see estimators.model)."""
    p, qq, r = w[0], w[1], w[2]
    # A = I + (dt/2) Ω(ω), Ω the right-product matrix of [0, ω].
    a00, a01, a02, a03 = 1.0, -half_dt * p, -half_dt * qq, -half_dt * r
    a10, a11, a12, a13 = half_dt * p, 1.0, half_dt * r, -half_dt * qq
    a20, a21, a22, a23 = half_dt * qq, -half_dt * r, 1.0, half_dt * p
    a30, a31, a32, a33 = half_dt * r, half_dt * qq, -half_dt * p, 1.0
    g0 = a00 * q[0] + a01 * q[1] + a02 * q[2] + a03 * q[3]
    g1 = a10 * q[0] + a11 * q[1] + a12 * q[2] + a13 * q[3]
    g2 = a20 * q[0] + a21 * q[1] + a22 * q[2] + a23 * q[3]
    g3 = a30 * q[0] + a31 * q[1] + a32 * q[2] + a33 * q[3]
    norm = math.sqrt(g0 * g0 + g1 * g1 + g2 * g2 + g3 * g3)
    n0, n1, n2, n3 = g0 / norm, g1 / norm, g2 / norm, g3 / norm
    out[0], out[1], out[2], out[3] = n0, n1, n2, n3
    inv_norm = 1.0 / norm   # one division for the 16 entries of F (≤ 1 ulp apart)
    if want_jacobian:
        # F = (A - n (nᵀ A)) / |g|
        c0 = n0 * a00 + n1 * a10 + n2 * a20 + n3 * a30
        c1 = n0 * a01 + n1 * a11 + n2 * a21 + n3 * a31
        c2 = n0 * a02 + n1 * a12 + n2 * a22 + n3 * a32
        c3 = n0 * a03 + n1 * a13 + n2 * a23 + n3 * a33
        a = ((a00, a01, a02, a03), (a10, a11, a12, a13),
             (a20, a21, a22, a23), (a30, a31, a32, a33))
        n = (n0, n1, n2, n3)
        c = (c0, c1, c2, c3)
        for i in range(4):
            for j in range(4):
                jacobian[i, j] = (a[i][j] - n[i] * c[j]) * inv_norm


@njit(cache=True, inline="always", error_model="numpy")
def _mark_diverged(slot, run, k, diverged, traces, keep_traces, error_every, error_samples):
    """Step ``k`` is where the run's estimator ``slot`` stopped being finite
    (unless it already had): from ``k`` on its estimate and error are NaN."""
    if diverged[slot, run] < 0:
        diverged[slot, run] = k
    if keep_traces:
        for i in range(4):
            traces[slot, run, k, i] = math.nan
    if error_every and k % error_every == 0:
        error_samples[slot, run, k // error_every] = math.nan


@njit(cache=True, inline="always", error_model="numpy")
def _finite_state(q, n_q, P, n):
    """The divergence test of estimators.base.AttitudeEstimator.state_is_finite:
    the sum of the first ``n_q`` state entries and the trace of the leading
    ``n`` x ``n`` covariance block are finite (a NaN or infinity anywhere in
    them makes its sum non-finite)."""
    total = 0.0
    for i in range(n_q):
        total += q[i]
    trace = 0.0
    for i in range(n):
        trace += P[i, i]
    return math.isfinite(total) and math.isfinite(trace)


@njit(cache=True, inline="always", error_model="numpy")
def _record(slot, run, k, inv_count, q_true_k, q, stats, hist, hist_first_bits, traces,
            keep_traces, bits, bits_int, error_every, error_samples, diverged):
    """Error of estimate ``q`` at step ``k``, folded into the run's accumulators
    (and kept every ``error_every`` steps if that is not 0). A non-finite
    estimate marks the run diverged (:func:`_mark_diverged`): its error is
    NaN, never the 0 that ``min(1, NaN)`` would give."""
    dot = abs(q_true_k[0] * q[0] + q_true_k[1] * q[1] + q_true_k[2] * q[2]
              + q_true_k[3] * q[3])
    if diverged[slot, run] >= 0 or not math.isfinite(dot):
        _mark_diverged(slot, run, k, diverged, traces, keep_traces, error_every, error_samples)
        return
    error = 2.0 * _acos(min(1.0, dot), bits, bits_int) * _RAD_TO_DEG
    delta = error - stats[slot, run, MEAN]
    stats[slot, run, MEAN] += delta * inv_count
    stats[slot, run, M2] += delta * (error - stats[slot, run, MEAN])
    if error > stats[slot, run, MAX] or k == 0:
        stats[slot, run, MAX] = error
    stats[slot, run, FINAL] = error
    # Histogram bin from the float's bit pattern (exponent and top mantissa
    # bits), monotone in the error: a log-like binning without calling log.
    bits[0] = error
    index = (bits_int[0] >> HISTOGRAM_SHIFT) - hist_first_bits + 1
    if index < 0:
        index = 0
    elif index >= hist.shape[2]:
        index = hist.shape[2] - 1
    hist[slot, run, index] += 1
    if keep_traces:
        for i in range(4):
            traces[slot, run, k, i] = q[i]
    if error_every and k % error_every == 0:
        error_samples[slot, run, k // error_every] = error


@njit(cache=True, inline="always", error_model="numpy")
def _matmul4(a, b, out):
    """out = a b for 4x4 arrays (out distinct from a and b)."""
    for i in range(4):
        for j in range(4):
            total = 0.0
            for m in range(4):
                total += a[i, m] * b[m, j]
            out[i, j] = total


@njit(cache=True, inline="always", error_model="numpy")
def _gauss_jordan(S, inverse, n):
    """inverse = S⁻¹ for the leading n x n block (S is destroyed), with
    partial pivoting; S is positive definite."""
    for i in range(n):
        for j in range(n):
            inverse[i, j] = 1.0 if i == j else 0.0
    for col in range(n):
        pivot = col
        for row in range(col + 1, n):
            if abs(S[row, col]) > abs(S[pivot, col]):
                pivot = row
        if pivot != col:
            for j in range(n):
                S[col, j], S[pivot, j] = S[pivot, j], S[col, j]
                inverse[col, j], inverse[pivot, j] = inverse[pivot, j], inverse[col, j]
        diagonal = S[col, col]
        for j in range(n):
            S[col, j] /= diagonal
            inverse[col, j] /= diagonal
        for row in range(n):
            if row != col:
                factor = S[row, col]
                for j in range(n):
                    S[row, j] -= factor * S[col, j]
                    inverse[row, j] -= factor * inverse[col, j]


@njit(cache=True, inline="always", error_model="numpy")
def _quadratic_form(y, inverse, n):
    """yᵀ S⁻¹ y for the first n entries of ``y`` (the NIS and the NEES)."""
    total = 0.0
    for i in range(n):
        for j in range(n):
            total += y[i] * inverse[i, j] * y[j]
    return total


@njit(cache=True, inline="always", error_model="numpy")
def _ekf_update(x, P, z, R, scratch):
    """filterpy's update with H = I: S = P + R, K = P S⁻¹, x += K (z - x),
    P = (I - K) P (I - K)ᵀ + K R Kᵀ."""
    S = scratch[0]
    inverse = scratch[1]
    K = scratch[2]
    IK = scratch[3]
    T = scratch[4]
    for i in range(4):
        for j in range(4):
            S[i, j] = P[i, j] + R[i, j]
    _gauss_jordan(S, inverse, 4)
    _matmul4(P, inverse, K)
    y0, y1, y2, y3 = z[0] - x[0], z[1] - x[1], z[2] - x[2], z[3] - x[3]
    nis = _quadratic_form((y0, y1, y2, y3), inverse, 4)
    for i in range(4):
        x[i] = x[i] + (K[i, 0] * y0 + K[i, 1] * y1 + K[i, 2] * y2 + K[i, 3] * y3)
    for i in range(4):
        for j in range(4):
            IK[i, j] = (1.0 if i == j else 0.0) - K[i, j]
    # T = (I - K) P ; P = T (I - K)ᵀ + (K R) Kᵀ
    _matmul4(IK, P, T)
    KR = S   # S is no longer needed
    _matmul4(K, R, KR)
    for i in range(4):
        for j in range(4):
            first = 0.0
            second = 0.0
            for m in range(4):
                first += T[i, m] * IK[j, m]
                second += KR[i, m] * K[j, m]
            P[i, j] = first + second
    return nis


@njit(cache=True, inline="always", error_model="numpy")
def _ekf_predict(x, P, w, half_dt, q_variance, F, scratch):
    """x = f(x, ω); P = F P Fᵀ + Q with F the exact Jacobian at the pre-step x."""
    _propagate(x, w, half_dt, x, F, True)
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
def _quat_exp(t0, t1, t2, out):
    """out = δq(θ), the exponential map of dynamics.quaternion.quat_from_rotvec."""
    angle = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    if angle < 1e-4:
        half_sinc = 0.5 - angle * angle / 48.0
    else:
        half_sinc = math.sin(0.5 * angle) / angle
    out[0] = math.cos(0.5 * angle)
    out[1] = half_sinc * t0
    out[2] = half_sinc * t1
    out[3] = half_sinc * t2


@njit(cache=True, inline="always", error_model="numpy")
def _quat_times_normalized(q, d, out):
    """out = (q ⊗ d) / |q ⊗ d| (Hamilton product); out may be q."""
    w = q[0] * d[0] - q[1] * d[1] - q[2] * d[2] - q[3] * d[3]
    x = q[0] * d[1] + q[1] * d[0] + q[2] * d[3] - q[3] * d[2]
    y = q[0] * d[2] - q[1] * d[3] + q[2] * d[0] + q[3] * d[1]
    z = q[0] * d[3] + q[1] * d[2] - q[2] * d[1] + q[3] * d[0]
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    out[0], out[1], out[2], out[3] = w / norm, x / norm, y / norm, z / norm


#: The MEKF's transition coefficients: the per-run function itself, compiled
#: (plain scalar arithmetic, so one definition serves both paths).
_transition_coefficients = njit(cache=True, inline="always",
                                error_model="numpy")(transition_coefficients)


@njit(cache=True, error_model="numpy")
def _mekf_propagate(q, beta, P, w_meas, dt, noise, bias_rw, scratch, dq):
    """q ⊗ δq(ω̂Δt), P = Φ P Φᵀ + Q with Φ = [[A, B], [0, I]] (estimators.mekf)."""
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
    _quat_exp(o0 * dt, o1 * dt, o2 * dt, dq)
    _quat_times_normalized(q, dq, q)


@njit(cache=True, inline="always", error_model="numpy")
def _log_error(q, p, norm):
    """The rotation vector of ``(q⁻¹ ⊗ p) / norm``, aligned to ``w >= 0``
    (dynamics.quaternion.rotvec_from_quat): the body-frame error from ``q`` to ``p``."""
    w = q[0] * p[0] + q[1] * p[1] + q[2] * p[2] + q[3] * p[3]
    v0 = q[0] * p[1] - q[1] * p[0] - q[2] * p[3] + q[3] * p[2]
    v1 = q[0] * p[2] + q[1] * p[3] - q[2] * p[0] - q[3] * p[1]
    v2 = q[0] * p[3] - q[1] * p[2] + q[2] * p[1] - q[3] * p[0]
    if w < 0:
        w, v0, v1, v2 = -w, -v0, -v1, -v2
    w, v0, v1, v2 = w / norm, v0 / norm, v1 / norm, v2 / norm
    vector_norm = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    if vector_norm < 1e-12:
        scale = 2.0 / max(w, 1e-300)
    else:
        scale = 2.0 * math.atan2(vector_norm, w) / vector_norm
    return scale * v0, scale * v1, scale * v2


@njit(cache=True, error_model="numpy")
def _mekf_update(q, beta, P, z, R, scratch, dq):
    """filterpy's Joseph update with H = [I 0] on y = log(q̂⁻¹ ⊗ z), then the reset."""
    # The reading aligned in sign with q̂ is what the alignment inside the log does.
    y0, y1, y2 = _log_error(q, z, 1.0)
    S = scratch[0]
    inverse = scratch[1]
    K = scratch[2]
    IK = scratch[3]
    T = scratch[4]
    KR = scratch[5]
    for i in range(3):
        for j in range(3):
            S[i, j] = P[i, j] + R[i, j]
    _gauss_jordan(S, inverse, 3)
    nis = _quadratic_form((y0, y1, y2), inverse, 3)
    # K = P Hᵀ S⁻¹ (6x3): P's first three columns times S⁻¹.
    for i in range(6):
        for j in range(3):
            K[i, j] = P[i, 0] * inverse[0, j] + P[i, 1] * inverse[1, j] + P[i, 2] * inverse[2, j]
    dx = scratch[6, 0]
    for i in range(6):
        dx[i] = K[i, 0] * y0 + K[i, 1] * y1 + K[i, 2] * y2
    # I - K H: the identity less K in the first three columns.
    for i in range(6):
        for j in range(6):
            IK[i, j] = (1.0 if i == j else 0.0) - (K[i, j] if j < 3 else 0.0)
    for i in range(6):
        for j in range(6):
            total = 0.0
            for m in range(6):
                total += IK[i, m] * P[m, j]
            T[i, j] = total
        for j in range(3):
            KR[i, j] = K[i, 0] * R[0, j] + K[i, 1] * R[1, j] + K[i, 2] * R[2, j]
    for i in range(6):
        for j in range(6):
            first = 0.0
            for m in range(6):
                first += T[i, m] * IK[j, m]
            P[i, j] = first + (KR[i, 0] * K[j, 0] + KR[i, 1] * K[j, 1] + KR[i, 2] * K[j, 2])
    _quat_exp(dx[0], dx[1], dx[2], dq)
    _quat_times_normalized(q, dq, q)
    beta[0] += dx[3]
    beta[1] += dx[4]
    beta[2] += dx[5]
    return nis


@njit(cache=True, error_model="numpy")
def _flight_gyro(w, omega, std, normals, scale_matrix, has_scale, has_bias, bias_step_std,
                 bias, bias_last, last):
    """w = ω (+ K ω) (+ ½(β_k + β_{k+1})) + σ N_v, advancing the true bias β (sensors.gyro)."""
    for i in range(3):
        w[i] = omega[i]
    if has_scale:
        for i in range(3):
            w[i] = w[i] + (omega[0] * scale_matrix[i, 0] + omega[1] * scale_matrix[i, 1]
                           + omega[2] * scale_matrix[i, 2])
    if has_bias:
        if last:
            for i in range(3):
                bias_last[i] = bias[i]
        for i in range(3):
            following = bias[i] + bias_step_std * normals[3 + i]
            w[i] = w[i] + 0.5 * (bias[i] + following)
            bias[i] = following
    for i in range(3):
        w[i] = w[i] + std * normals[i]


@njit(cache=True, error_model="numpy")
def _nees(q_true_k, q, C, scratch):
    """eᵀ C⁻¹ e with e = log(q̂⁻¹ ⊗ q) the body-frame error of estimate ``q``
    and ``C`` its 3x3 covariance (benchmarks.experiments.consistency.nees)."""
    # The EKF's estimate is not unit: normalise it inside the log.
    e = _log_error(q, q_true_k, math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]))
    S = scratch[0]
    inverse = scratch[1]
    for i in range(3):
        for j in range(3):
            S[i, j] = C[i, j]
    _gauss_jordan(S, inverse, 3)
    return _quadratic_form(e, inverse, 3)


@njit(cache=True, error_model="numpy")
def _projected_covariance(x, P, out):
    """4 Ξ(q̂)ᵀ P Ξ(q̂) at the normalised q̂ (estimators.QuaternionEKF.attitude_covariance)."""
    norm = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + x[3] * x[3])
    w, a, b, c = x[0] / norm, x[1] / norm, x[2] / norm, x[3] / norm
    xi = ((-a, -b, -c), (w, -c, b), (c, w, -a), (-b, a, w))
    for i in range(3):
        for j in range(3):
            total = 0.0
            for m in range(4):
                inner = 0.0
                for n in range(4):
                    inner += P[m, n] * xi[n][j]
                total += xi[m][i] * inner
            out[i, j] = 4.0 * total


@njit(cache=True, error_model="numpy")
def _fold_consistency(row, run, k, value, consistency):
    """Add a NEES value to the run's time average (from the settle step) and
    keep it at the sampled steps."""
    (active, every, settle, samples, nees_sum, nis_sum, nis_count) = consistency
    if k >= settle:
        nees_sum[row, run] += value
    if k % every == 0 and k // every < samples.shape[2]:
        samples[row, run, k // every] = value


#: Health counters per estimator and run (``run_batch(health=True)``): the
#: checks made, then how many found |q| off 1 by more than
#: :data:`NORM_TOLERANCE`, a covariance not symmetric to
#: :data:`SYMMETRY_TOLERANCE` of its largest diagonal entry, one not positive
#: definite (a Cholesky pivot <= 0), a NaN or infinity; then the largest
#: ||q| - 1| and the largest relative asymmetry seen.
CHECKS, NORM_OFF, ASYMMETRIC, NOT_POSITIVE_DEFINITE, NON_FINITE = 0, 1, 2, 3, 4
WORST_NORM, WORST_ASYMMETRY = 5, 6
N_HEALTH = 7
NORM_TOLERANCE = 1e-12
SYMMETRY_TOLERANCE = 1e-12


@njit(cache=True, error_model="numpy")
def _check_health(q, unit, P, n, counts, factor):
    """Fold one check of estimate ``q`` (unit by design if ``unit``) and the
    leading ``n`` x ``n`` block of ``P`` (n = 0: no covariance) into ``counts``."""
    counts[CHECKS] += 1
    finite = True
    for i in range(4):
        if not math.isfinite(q[i]):
            finite = False
    if unit:
        deviation = abs(math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]) - 1.0)
        if not deviation <= NORM_TOLERANCE:
            counts[NORM_OFF] += 1
        if deviation > counts[WORST_NORM]:
            counts[WORST_NORM] = deviation
    if n:
        scale = 0.0
        for i in range(n):
            scale = max(scale, abs(P[i, i]))
        asymmetry = 0.0
        for i in range(n):
            for j in range(n):
                if not math.isfinite(P[i, j]):
                    finite = False
                asymmetry = max(asymmetry, abs(P[i, j] - P[j, i]))
        relative = asymmetry / scale if scale > 0.0 else asymmetry
        if not relative <= SYMMETRY_TOLERANCE:
            counts[ASYMMETRIC] += 1
        if relative > counts[WORST_ASYMMETRY]:
            counts[WORST_ASYMMETRY] = relative
        # Cholesky of the symmetric part: positive definite iff every pivot > 0.
        for j in range(n):
            total = P[j, j]
            for m in range(j):
                total -= factor[j, m] * factor[j, m]
            if not total > 0.0:
                counts[NOT_POSITIVE_DEFINITE] += 1
                break
            factor[j, j] = math.sqrt(total)
            for i in range(j + 1, n):
                value = 0.5 * (P[i, j] + P[j, i])
                for m in range(j):
                    value -= factor[i, m] * factor[j, m]
                factor[i, j] = value / factor[j, j]
    if not finite:
        counts[NON_FINITE] += 1


@njit(parallel=True, cache=True, nogil=True, error_model="numpy")
def advance(k0, last_step, q_true, omega_true, dt, gyro, star, state, enabled, rows, options,
            stats, diverged, hist, hist_first_bits, traces, keep_traces, consistency, check_health,
            health, error_every, error_samples):
    """Advance every run by one block of steps starting at step ``k0``.

    ``q_true`` (T, 4) and ``omega_true`` (T, 3) are the block's truth.
    ``gyro`` = (std (B,), normals (B, T, 3 or 6), bias_step_std, K (3, 3),
    has_scale, has_bias, bias (B, 3) the true bias β_k, bias_last (B, 3)).
    ``star`` = (rotation_model, std (B,), steps_between (B,), normals
    (B, readings in this block, 3 or 4) consumed in order, sigma_rad (3,),
    R_bs (3, 3), canonical, outage (T,), dropout_probability, uniforms
    (B, readings in this block)).
    ``state`` = (q_dr, q_resets, previous_rate (B, 3) for step-average
    timing, x_ekf, P_ekf, q_variance (B,), R (4, 4), q_mekf, beta_mekf,
    P_mekf, mekf_noise (B,), mekf_bias_rw (B,), R_mekf (B, 3, 3), and the
    MEKF's output bias and covariance at ``last_step``: beta_mekf_last (B, 3),
    P_mekf_last (B, 6, 6)).
    ``options`` = (dead reckoning step-average, resets step-average, EKF
    posterior, MEKF posterior, resets align sign, EKF align sign). Statistics ``(slots, B, 4)``;
    ``diverged`` ``(slots, B)`` the step where each run stopped being finite
    (-1: never, see :func:`_mark_diverged`); histograms
    ``(slots, B, bins)``, traces ``(slots, B, N, 4)`` when kept; with
    ``check_health``, ``health`` ``(slots, B, N_HEALTH)`` counts each
    estimator's state checks after its update and after its propagation
    (:func:`_check_health`); with ``error_every`` > 0, ``error_samples``
    ``(slots, B, S)`` keeps each estimator's error every that many steps.
    """
    (gyro_std, gyro_normals, bias_step_std, scale_matrix, has_scale, has_bias, bias_true,
     bias_last) = gyro
    (rotation_model, star_std, steps_between, star_normals, sigma_rad, sensor_to_body,
     canonical, outage, dropout_probability, dropout_uniforms) = star
    (q_dr, q_resets, previous_rate, x_ekf, P_ekf, q_variance, R, q_mekf, beta_mekf, P_mekf,
     mekf_noise, mekf_bias_rw, R_mekf, beta_mekf_last, P_mekf_last) = state
    dr_average, resets_average, ekf_posterior, mekf_posterior, resets_align, ekf_align = options
    check = consistency[0]
    nis_sum, nis_count = consistency[5], consistency[6]
    n_runs = gyro_std.shape[0]
    n_steps = gyro_normals.shape[1]
    half_dt = 0.5 * dt
    for run in prange(n_runs):
        w = np.empty(3)
        z = np.empty(4)
        dq = np.empty(4)
        prior = np.empty(4)
        aligned = np.empty(4)
        out_mekf = np.empty(4)
        F = np.empty((4, 4))
        scratch = np.empty((5, 4, 4))
        scratch6 = np.empty((7, 6, 6))
        projected = np.empty((3, 3))
        bits = np.empty(1)
        bits_int = bits.view(np.int64)
        factor = np.empty((6, 6))
        x = x_ekf[run]
        P = P_ekf[run]
        reading = 0
        # Steps until the next reading (readings at k ≡ 0 mod m): a countdown
        # instead of an integer modulo every step.
        until_reading = (steps_between[run] - k0 % steps_between[run]) % steps_between[run]
        for j in range(n_steps):
            k = k0 + j
            inv_count = 1.0 / (k + 1)     # Welford's 1/n, shared by the estimators
            # The gyro: ω (+ K ω) (+ ½(β_k + β_{k+1})) + σ N_v.
            if not (has_scale or has_bias):
                for i in range(3):
                    w[i] = omega_true[j, i] + gyro_std[run] * gyro_normals[run, j, i]
            else:
                _flight_gyro(w, omega_true[j], gyro_std[run], gyro_normals[run, j], scale_matrix,
                             has_scale, has_bias, bias_step_std, bias_true[run], bias_last[run],
                             k == last_step)
            due = until_reading == 0
            until_reading = steps_between[run] - 1 if due else until_reading - 1
            available = False
            if due:
                if rotation_model:
                    t0 = sigma_rad[0] * star_normals[run, reading, 0]
                    t1 = sigma_rad[1] * star_normals[run, reading, 1]
                    t2 = sigma_rad[2] * star_normals[run, reading, 2]
                    _quat_exp(sensor_to_body[0, 0] * t0 + sensor_to_body[0, 1] * t1
                              + sensor_to_body[0, 2] * t2,
                              sensor_to_body[1, 0] * t0 + sensor_to_body[1, 1] * t1
                              + sensor_to_body[1, 2] * t2,
                              sensor_to_body[2, 0] * t0 + sensor_to_body[2, 1] * t1
                              + sensor_to_body[2, 2] * t2, dq)
                    _quat_times_normalized(q_true[j], dq, z)
                    if canonical and z[0] < 0:
                        for i in range(4):
                            z[i] = -z[i]
                    available = not outage[j]
                    if dropout_probability > 0.0 and \
                            dropout_uniforms[run, reading] < dropout_probability:
                        available = False
                else:
                    for i in range(4):
                        z[i] = q_true[j, i] + star_std[run] * star_normals[run, reading, i]
                    norm = math.sqrt(z[0] * z[0] + z[1] * z[1] + z[2] * z[2] + z[3] * z[3])
                    for i in range(4):
                        z[i] = z[i] / norm
                    available = True
                reading += 1
            if enabled[DEAD_RECKONING]:
                q = q_dr[run]
                if not dr_average:
                    _propagate(q, w, half_dt, q, F, False)
                elif k > 0:
                    _propagate(q, previous_rate[run], half_dt, q, F, False)
                _record(rows[DEAD_RECKONING], run, k, inv_count, q_true[j], q, stats, hist,
                        hist_first_bits, traces, keep_traces, bits, bits_int,
                        error_every, error_samples, diverged)
                if check_health:
                    _check_health(q, True, F, 0, health[rows[DEAD_RECKONING], run], factor)
            if enabled[RESETS]:
                q = q_resets[run]
                if available:
                    flip = False
                    if resets_align:
                        # The sign nearest the prediction, as the per-run class compares it.
                        for i in range(4):
                            aligned[i] = q[i]
                        if not resets_average:
                            _propagate(aligned, w, half_dt, aligned, F, False)
                        elif k > 0:
                            _propagate(aligned, previous_rate[run], half_dt, aligned, F, False)
                        flip = (aligned[0] * z[0] + aligned[1] * z[1] + aligned[2] * z[2]
                                + aligned[3] * z[3]) < 0
                    for i in range(4):
                        q[i] = -z[i] if flip else z[i]
                elif not resets_average:
                    _propagate(q, w, half_dt, q, F, False)
                elif k > 0:
                    _propagate(q, previous_rate[run], half_dt, q, F, False)
                _record(rows[RESETS], run, k, inv_count, q_true[j], q, stats, hist, hist_first_bits,
                        traces, keep_traces, bits, bits_int,
                        error_every, error_samples, diverged)
                if check_health:
                    _check_health(q, True, F, 0, health[rows[RESETS], run], factor)
            if dr_average or resets_average:
                for i in range(3):
                    previous_rate[run, i] = w[i]
            if enabled[EKF]:
                for i in range(4):
                    prior[i] = x[i]
                if check and not ekf_posterior:
                    _projected_covariance(x, P, projected)
                    _fold_consistency(rows[EKF], run, k, _nees(q_true[j], x, projected, scratch6),
                                      consistency)
                if available:
                    flip = ekf_align and (x[0] * z[0] + x[1] * z[1] + x[2] * z[2]
                                          + x[3] * z[3]) < 0
                    for i in range(4):
                        aligned[i] = -z[i] if flip else z[i]
                    nis = _ekf_update(x, P, aligned, R, scratch)
                    if check_health:   # the additive update leaves |x| off 1 by design
                        _check_health(x, False, P, 4, health[rows[EKF], run], factor)
                    if check:
                        nis_sum[rows[EKF], run] += nis
                        nis_count[rows[EKF], run] += 1
                if ekf_posterior:
                    for i in range(4):
                        prior[i] = x[i]
                    if check:
                        _projected_covariance(x, P, projected)
                        _fold_consistency(rows[EKF], run, k,
                                          _nees(q_true[j], x, projected, scratch6), consistency)
                _record(rows[EKF], run, k, inv_count, q_true[j], prior, stats, hist, hist_first_bits,
                        traces, keep_traces, bits, bits_int,
                        error_every, error_samples, diverged)
                _ekf_predict(x, P, w, half_dt, q_variance[run], F, scratch)
                if not _finite_state(x, 4, P, 4):
                    _mark_diverged(rows[EKF], run, k, diverged, traces, keep_traces,
                                   error_every, error_samples)
                if check_health:
                    _check_health(x, True, P, 4, health[rows[EKF], run], factor)
            if enabled[MEKF]:
                qm = q_mekf[run]
                for i in range(4):
                    out_mekf[i] = qm[i]
                if k == last_step and not mekf_posterior:
                    beta_mekf_last[run, :] = beta_mekf[run]
                    P_mekf_last[run, :, :] = P_mekf[run]
                if check and not mekf_posterior:
                    _fold_consistency(rows[MEKF], run, k,
                                      _nees(q_true[j], qm, P_mekf[run], scratch6), consistency)
                if available:
                    nis = _mekf_update(qm, beta_mekf[run], P_mekf[run], z, R_mekf[run],
                                       scratch6, dq)
                    if check_health:
                        _check_health(qm, True, P_mekf[run], 6, health[rows[MEKF], run], factor)
                    if check:
                        nis_sum[rows[MEKF], run] += nis
                        nis_count[rows[MEKF], run] += 1
                if mekf_posterior:
                    for i in range(4):
                        out_mekf[i] = qm[i]
                    if k == last_step:
                        beta_mekf_last[run, :] = beta_mekf[run]
                        P_mekf_last[run, :, :] = P_mekf[run]
                    if check:
                        _fold_consistency(rows[MEKF], run, k,
                                          _nees(q_true[j], qm, P_mekf[run], scratch6),
                                          consistency)
                _record(rows[MEKF], run, k, inv_count, q_true[j], out_mekf, stats, hist,
                        hist_first_bits, traces, keep_traces, bits, bits_int,
                        error_every, error_samples, diverged)
                _mekf_propagate(qm, beta_mekf[run], P_mekf[run], w, dt, mekf_noise[run],
                                mekf_bias_rw[run], scratch6, dq)
                if not (_finite_state(qm, 4, P_mekf[run], 6)
                        and _finite_state(beta_mekf[run], 3, P_mekf[run], 0)):
                    _mark_diverged(rows[MEKF], run, k, diverged, traces, keep_traces,
                                   error_every, error_samples)
                if check_health:
                    _check_health(qm, True, P_mekf[run], 6, health[rows[MEKF], run], factor)
