r"""Compiled kernels of the batched engine: the three workshop estimators,
advanced over a block of steps for many runs at once.

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
* :class:`sensors.Gyro` and :class:`sensors.StarTracker` — readings from the
  same standard normals;
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

#: Estimator slots, in the order of ``estimators.ESTIMATORS``.
DEAD_RECKONING, RESETS, EKF = 0, 1, 2
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
def _record(slot, run, k, inv_count, q_true_k, q, stats, hist, hist_first_bits, traces,
            keep_traces, bits, bits_int):
    """Error of estimate ``q`` at step ``k``, folded into the run's accumulators."""
    dot = abs(q_true_k[0] * q[0] + q_true_k[1] * q[1] + q_true_k[2] * q[2]
              + q_true_k[3] * q[3])
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
            inverse[i, j] = 1.0 if i == j else 0.0
    # Gauss–Jordan with partial pivoting on the 4x4 S (positive definite).
    for col in range(4):
        pivot = col
        for row in range(col + 1, 4):
            if abs(S[row, col]) > abs(S[pivot, col]):
                pivot = row
        if pivot != col:
            for j in range(4):
                S[col, j], S[pivot, j] = S[pivot, j], S[col, j]
                inverse[col, j], inverse[pivot, j] = inverse[pivot, j], inverse[col, j]
        diagonal = S[col, col]
        for j in range(4):
            S[col, j] /= diagonal
            inverse[col, j] /= diagonal
        for row in range(4):
            if row != col:
                factor = S[row, col]
                for j in range(4):
                    S[row, j] -= factor * S[col, j]
                    inverse[row, j] -= factor * inverse[col, j]
    _matmul4(P, inverse, K)
    y0, y1, y2, y3 = z[0] - x[0], z[1] - x[1], z[2] - x[2], z[3] - x[3]
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


@njit(parallel=True, cache=True, nogil=True, error_model="numpy")
def advance(k0, q_true, omega_true, dt, gyro_std, star_std, steps_between, gyro_normals,
            star_normals, enabled, q_dr, q_resets, x_ekf, P_ekf, q_variance, R,
            stats, hist, hist_first_bits, traces, keep_traces):
    """Advance every run by ``gyro_normals.shape[1]`` steps starting at step ``k0``.

    Shapes: q_true (N, 4) and omega_true (N, 3) shared; per run r: gyro_std,
    star_std, steps_between, q_variance (B,); gyro_normals (B, T, 3);
    star_normals (B, readings in this block, 4), consumed in order; states
    q_dr, q_resets, x_ekf (B, 4), P_ekf (B, 4, 4); stats (3, B, 4);
    hist (3, B, bins); traces (3, B, N, 4) when keep_traces.
    """
    n_runs = gyro_std.shape[0]
    n_steps = gyro_normals.shape[1]
    half_dt = 0.5 * dt
    for run in prange(n_runs):
        w = np.empty(3)
        z = np.empty(4)
        prior = np.empty(4)
        F = np.empty((4, 4))
        scratch = np.empty((5, 4, 4))
        bits = np.empty(1)
        bits_int = bits.view(np.int64)
        x = x_ekf[run]
        P = P_ekf[run]
        reading = 0
        # Steps until the next reading (readings at k ≡ 0 mod m): a countdown
        # instead of an integer modulo every step.
        until_reading = (steps_between[run] - k0 % steps_between[run]) % steps_between[run]
        for j in range(n_steps):
            k = k0 + j
            inv_count = 1.0 / (k + 1)     # Welford's 1/n, shared by the estimators
            for i in range(3):
                w[i] = omega_true[k, i] + gyro_std[run] * gyro_normals[run, j, i]
            available = until_reading == 0
            until_reading = steps_between[run] - 1 if available else until_reading - 1
            if available:
                for i in range(4):
                    z[i] = q_true[k, i] + star_std[run] * star_normals[run, reading, i]
                norm = math.sqrt(z[0] * z[0] + z[1] * z[1] + z[2] * z[2] + z[3] * z[3])
                for i in range(4):
                    z[i] = z[i] / norm
                reading += 1
            if enabled[DEAD_RECKONING]:
                q = q_dr[run]
                _propagate(q, w, half_dt, q, F, False)
                _record(DEAD_RECKONING, run, k, inv_count, q_true[k], q, stats, hist, hist_first_bits,
                        traces, keep_traces, bits, bits_int)
            if enabled[RESETS]:
                q = q_resets[run]
                if available:
                    for i in range(4):
                        q[i] = z[i]
                else:
                    _propagate(q, w, half_dt, q, F, False)
                _record(RESETS, run, k, inv_count, q_true[k], q, stats, hist, hist_first_bits,
                        traces, keep_traces, bits, bits_int)
            if enabled[EKF]:
                for i in range(4):
                    prior[i] = x[i]
                _record(EKF, run, k, inv_count, q_true[k], prior, stats, hist, hist_first_bits,
                        traces, keep_traces, bits, bits_int)
                if available:
                    _ekf_update(x, P, z, R, scratch)
                _ekf_predict(x, P, w, half_dt, q_variance[run], F, scratch)
