"""The MEKF's propagation in lanes: mekf_steps.propagate_covariance's
arithmetic (:func:`estimators.mekf.discrete_error_model`), each part a loop
over the lanes that LLVM vectorises, but the sines and cosines
(:func:`half_angles`: the library's, which it does not)."""
from __future__ import annotations

import math

from numba import njit

from benchmarks.engine.kernels.algebra import (SINC_SERIES_BELOW, half_sinc_series,
                                               product_normalized)
from benchmarks.engine.kernels.lanes import LANES, Q, W, nine, put_three, put_two, three
from benchmarks.engine.kernels.mekf_lanes_rows import (A, ANGLE, B, BETA, BIAS_RW,
                                                       COEFFICIENTS, COS, FP, HALF_SINC, NOISE,
                                                       P, Q11, Q12, RATE, TURN)
from benchmarks.engine.kernels.mekf_steps import series, trigonometric
from estimators.mekf import SERIES_BELOW


@njit(cache=True, inline="always", error_model="numpy")
def _rate(b, lane):
    """ω̂ = ω − β̂ of one lane."""
    w0, w1, w2 = three(b, W, lane)
    beta0, beta1, beta2 = three(b, BETA, lane)
    return w0 - beta0, w1 - beta1, w2 - beta2


@njit(cache=True, inline="always", error_model="numpy")
def turn_angles(b, m):
    """Each lane's angle θ of the rotation vector in rows TURN and its
    sin(θ/2)/θ by the series (algebra.quat_exp; beyond the series' range,
    :func:`half_angles`)."""
    for lane in range(m):
        t0, t1, t2 = three(b, TURN, lane)
        angle = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        b[ANGLE * LANES + lane] = angle
        b[HALF_SINC * LANES + lane] = half_sinc_series(angle)


@njit(cache=True, inline="always", error_model="numpy")
def half_angles(b, m):
    """Each lane's cos(θ/2), and sin(θ/2)/θ beyond the series' range
    (algebra.quat_exp)."""
    for lane in range(m):
        angle = b[ANGLE * LANES + lane]
        b[COS * LANES + lane] = math.cos(0.5 * angle)
        if not angle < SINC_SERIES_BELOW:
            b[HALF_SINC * LANES + lane] = math.sin(0.5 * angle) / angle


@njit(cache=True, inline="always", error_model="numpy")
def turn(b, m):
    """Each lane's q̂ ⊗ δq(θ), normalised (algebra.quat_exp,
    quat_times_normalized), θ the rows TURN."""
    for lane in range(m):
        t0, t1, t2 = three(b, TURN, lane)
        half_sinc = b[HALF_SINC * LANES + lane]
        q0, q1, q2 = three(b, Q, lane)
        q = product_normalized(q0, q1, q2, b[(Q + 3) * LANES + lane], b[COS * LANES + lane],
                               half_sinc * t0, half_sinc * t1, half_sinc * t2)
        put_two(b, Q, lane, q[:2])
        put_two(b, Q + 2, lane, q[2:])


@njit(cache=True, inline="always", error_model="numpy")
def _series(b, m, dt):
    """Each lane's |ω̂|, Φ's and Q's coefficients by their series
    (estimators.mekf.series_coefficients) and the turn ω̂ Δt."""
    for lane in range(m):
        o0, o1, o2 = _rate(b, lane)
        rate = math.sqrt(o0 * o0 + o1 * o1 + o2 * o2)
        b[RATE * LANES + lane] = rate
        coefficients = series(rate * dt, dt)
        put_three(b, COEFFICIENTS, lane, coefficients[:3])
        put_two(b, COEFFICIENTS + 3, lane, coefficients[3:])
        put_three(b, TURN, lane, (o0 * dt, o1 * dt, o2 * dt))


@njit(cache=True, inline="always", error_model="numpy")
def _trigonometric(b, m, dt):
    """The lanes whose |ω̂| Δt is beyond the series' range: their
    coefficients from sin and cos (estimators.mekf.transition_coefficients)."""
    for lane in range(m):
        rate = b[RATE * LANES + lane]
        x = rate * dt
        if not x < SERIES_BELOW:
            coefficients = trigonometric(rate, x)
            put_three(b, COEFFICIENTS, lane, coefficients[:3])
            put_two(b, COEFFICIENTS + 3, lane, coefficients[3:])


@njit(cache=True, inline="always", error_model="numpy")
def _entry(b, lane, i, j, w, coefficients, dt, noise, su2):
    """Entry (i, j) of Φ's blocks A, B and Q's Q11, Q12 into their rows
    (``w``: W = [ω̂×], row-major; ``i``, ``j`` constants, so that the tuples'
    items are found when compiling)."""
    s1, c2, s3, q5, q4 = coefficients
    w2 = w[3 * i] * w[j] + w[3 * i + 1] * w[3 + j] + w[3 * i + 2] * w[6 + j]
    eye = 1.0 if i == j else 0.0
    wij = w[3 * i + j]
    b[(A + 3 * i + j) * LANES + lane] = eye - s1 * wij + c2 * w2
    b[(B + 3 * i + j) * LANES + lane] = -(dt * eye - c2 * wij + s3 * w2)
    b[(Q11 + 3 * i + j) * LANES + lane] = noise * dt * eye + su2 * (dt * dt * dt / 3.0 * eye
                                                                    + q5 * w2)
    b[(Q12 + 3 * i + j) * LANES + lane] = -su2 * (0.5 * dt * dt * eye - s3 * wij + q4 * w2)


@njit(cache=True, inline="always", error_model="numpy")
def _blocks(b, m, dt):
    """Each lane's Φ blocks A, B and Q's blocks Q11, Q12 (3x3): W, W², then
    each entry's sums. Written out entry by entry: loops over the entries
    left the lanes' loop scalar."""
    for lane in range(m):
        o0, o1, o2 = _rate(b, lane)
        c = three(b, COEFFICIENTS, lane) + (b[(COEFFICIENTS + 3) * LANES + lane],
                                            b[(COEFFICIENTS + 4) * LANES + lane])
        noise, bias_rw = b[NOISE * LANES + lane], b[BIAS_RW * LANES + lane]
        su2 = bias_rw * bias_rw
        w = (0.0, -o2, o1, o2, 0.0, -o0, -o1, o0, 0.0)
        _entry(b, lane, 0, 0, w, c, dt, noise, su2)
        _entry(b, lane, 0, 1, w, c, dt, noise, su2)
        _entry(b, lane, 0, 2, w, c, dt, noise, su2)
        _entry(b, lane, 1, 0, w, c, dt, noise, su2)
        _entry(b, lane, 1, 1, w, c, dt, noise, su2)
        _entry(b, lane, 1, 2, w, c, dt, noise, su2)
        _entry(b, lane, 2, 0, w, c, dt, noise, su2)
        _entry(b, lane, 2, 1, w, c, dt, noise, su2)
        _entry(b, lane, 2, 2, w, c, dt, noise, su2)


@njit(cache=True, inline="always", error_model="numpy")
def _phi_p_row(A_, B_, P_, i):
    """Row ``i`` (a constant) of Φ P's top three rows: A P_top + B P_bottom."""
    a0, a1, a2 = A_[3 * i], A_[3 * i + 1], A_[3 * i + 2]
    b0, b1, b2 = B_[3 * i], B_[3 * i + 1], B_[3 * i + 2]
    return (a0 * P_[0] + a1 * P_[6] + a2 * P_[12] + b0 * P_[18] + b1 * P_[24] + b2 * P_[30],
            a0 * P_[1] + a1 * P_[7] + a2 * P_[13] + b0 * P_[19] + b1 * P_[25] + b2 * P_[31],
            a0 * P_[2] + a1 * P_[8] + a2 * P_[14] + b0 * P_[20] + b1 * P_[26] + b2 * P_[32],
            a0 * P_[3] + a1 * P_[9] + a2 * P_[15] + b0 * P_[21] + b1 * P_[27] + b2 * P_[33],
            a0 * P_[4] + a1 * P_[10] + a2 * P_[16] + b0 * P_[22] + b1 * P_[28] + b2 * P_[34],
            a0 * P_[5] + a1 * P_[11] + a2 * P_[17] + b0 * P_[23] + b1 * P_[29] + b2 * P_[35])


@njit(cache=True, inline="always", error_model="numpy")
def _put_six(b, row, lane, values):
    put_three(b, row, lane, values[:3])
    put_three(b, row + 3, lane, values[3:])


@njit(cache=True, inline="always", error_model="numpy")
def _phi_p(b, m):
    """Each lane's top three rows of Φ P into their rows."""
    for lane in range(m):
        A_, B_ = nine(b, A, lane), nine(b, B, lane)
        P_ = nine(b, P, lane) + nine(b, P + 9, lane) + nine(b, P + 18, lane) + nine(b, P + 27,
                                                                                   lane)
        _put_six(b, FP, lane, _phi_p_row(A_, B_, P_, 0))
        _put_six(b, FP + 6, lane, _phi_p_row(A_, B_, P_, 1))
        _put_six(b, FP + 12, lane, _phi_p_row(A_, B_, P_, 2))


@njit(cache=True, inline="always", error_model="numpy")
def _put_pair(b, lane, i, j, value):
    """P's entries (i, j) and (j, i) of one lane."""
    b[(P + 6 * i + j) * LANES + lane] = value
    b[(P + 6 * j + i) * LANES + lane] = value


@njit(cache=True, inline="always", error_model="numpy")
def _attitude_block(FP_, A_, B_, Q11_, i, j):
    """P's entry (i, j) of the attitude block: (Φ P) Φᵀ + Q11 (constants ``i``, ``j``)."""
    value = (FP_[6 * i] * A_[3 * j] + FP_[6 * i + 1] * A_[3 * j + 1]
             + FP_[6 * i + 2] * A_[3 * j + 2] + FP_[6 * i + 3] * B_[3 * j]
             + FP_[6 * i + 4] * B_[3 * j + 1] + FP_[6 * i + 5] * B_[3 * j + 2])
    return value + Q11_[3 * i + j]


@njit(cache=True, inline="always", error_model="numpy")
def _cross(b, lane, FP_, Q12_, i):
    """P's row ``i`` (a constant) of the cross-covariance: Φ P's columns 3-5 + Q12."""
    _put_pair(b, lane, i, 3, FP_[6 * i + 3] + Q12_[3 * i])
    _put_pair(b, lane, i, 4, FP_[6 * i + 4] + Q12_[3 * i + 1])
    _put_pair(b, lane, i, 5, FP_[6 * i + 5] + Q12_[3 * i + 2])


@njit(cache=True, inline="always", error_model="numpy")
def _covariance(b, m, dt):
    """Each lane's P = (Φ P) Φᵀ + Q, its upper triangle mirrored; the bias
    block is (Φ P)'s own rows, P's, plus σ_u² Δt on its diagonal."""
    for lane in range(m):
        A_, B_, Q11_, Q12_ = nine(b, A, lane), nine(b, B, lane), nine(b, Q11, lane), nine(
            b, Q12, lane)
        FP_ = nine(b, FP, lane) + nine(b, FP + 9, lane)
        bottom = (three(b, P + 21, lane) + three(b, P + 27, lane)
                  + three(b, P + 33, lane))      # P's block of rows and columns 3-5
        d = b[BIAS_RW * LANES + lane] * b[BIAS_RW * LANES + lane] * dt
        _put_pair(b, lane, 0, 0, _attitude_block(FP_, A_, B_, Q11_, 0, 0))
        _put_pair(b, lane, 0, 1, _attitude_block(FP_, A_, B_, Q11_, 0, 1))
        _put_pair(b, lane, 0, 2, _attitude_block(FP_, A_, B_, Q11_, 0, 2))
        _put_pair(b, lane, 1, 1, _attitude_block(FP_, A_, B_, Q11_, 1, 1))
        _put_pair(b, lane, 1, 2, _attitude_block(FP_, A_, B_, Q11_, 1, 2))
        _put_pair(b, lane, 2, 2, _attitude_block(FP_, A_, B_, Q11_, 2, 2))
        _cross(b, lane, FP_, Q12_, 0)
        _cross(b, lane, FP_, Q12_, 1)
        _cross(b, lane, FP_, Q12_, 2)
        _put_pair(b, lane, 3, 3, bottom[0] + d)
        _put_pair(b, lane, 3, 4, bottom[1] + 0.0)
        _put_pair(b, lane, 3, 5, bottom[2] + 0.0)
        _put_pair(b, lane, 4, 4, bottom[4] + d)
        _put_pair(b, lane, 4, 5, bottom[5] + 0.0)
        _put_pair(b, lane, 5, 5, bottom[8] + d)


@njit(cache=True, inline="always", error_model="numpy")
def propagate(b, m, dt):
    """Each lane's mekf_steps.propagate_covariance: q̂ ⊗ δq(ω̂ Δt) and
    P = Φ P Φᵀ + Q."""
    _series(b, m, dt)
    _trigonometric(b, m, dt)
    turn_angles(b, m)
    half_angles(b, m)
    _blocks(b, m, dt)
    _phi_p(b, m)
    _covariance(b, m, dt)
    turn(b, m)
