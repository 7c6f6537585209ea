"""The small linear algebra and quaternion steps of the engine's kernels:
4x4 products, Joseph's covariance update, Gauss–Jordan inversion, a
quadratic form, the quaternion exponential and product, a vector into the
body frame, the small-angle error, the EKF's quaternion step and its
projected covariance. Each formula is the same, in the same order, as its
reference on the per-run path (named in each docstring), so the kernels
reproduce it to rounding (``error_model="numpy"``: IEEE division, as numpy's)."""
from __future__ import annotations

import math

from numba import njit


@njit(cache=True, inline="always", error_model="numpy")
def propagate(q, w, half_dt, out, jacobian, want_jacobian):
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
def add_along_rate(Q, o0, o1, o2, density, dt):
    """``Q[:3, :3] += S_s Δt ω̂ω̂ᵀ`` (estimators.mekf.discrete_error_model's
    share of the rate's own error, in its order: (S_s Δt)(ω̂ᵢ ω̂ⱼ))."""
    along = density * dt
    o = (o0, o1, o2)
    for i in range(3):
        for j in range(3):
            Q[i, j] += along * (o[i] * o[j])


@njit(cache=True, inline="always", error_model="numpy")
def matmul4(a, b, out):
    """out = a b for 4x4 arrays (out distinct from a and b)."""
    for i in range(4):
        for j in range(4):
            total = 0.0
            for m in range(4):
                total += a[i, m] * b[m, j]
            out[i, j] = total


@njit(cache=True, inline="always", error_model="numpy")
def joseph_covariance(P, IK, KRK, T, n=6, bias_identity=False):
    """Joseph's form of an ``n``-state covariance update, in place:
    P ← (I − KH) P (I − KH)ᵀ + K R Kᵀ, given ``IK`` = I − KH and ``KRK`` =
    K R Kᵀ; ``T`` (n, n) scratch. Inlined, so that a constant ``n`` is
    compiled into unrolled loops.

    ``bias_identity``: H is zero in the gyro-bias columns (3 to 5), so IK's
    are the identity's and their products are skipped: a skipped product is
    ±0 (finite entries), and adding ±0 leaves a sum begun at +0 as it is, so
    every entry is the full product's to the bit, in half the arithmetic."""
    for i in range(n):
        for j in range(n):
            T[i, j] = _row_times(IK, i, P[:, j], n, bias_identity)
    for i in range(n):
        for j in range(n):
            P[i, j] = _row_times(IK, j, T[i], n, bias_identity) + KRK[i, j]


@njit(cache=True, inline="always", error_model="numpy")
def _row_times(IK, row, v, n, bias_identity):
    """Σ_m IK[row, m] v[m] over the ``n`` states, in order; with
    ``bias_identity``, the bias columns' products (IK's identity there) are
    skipped, ``v[row]`` added for the one on the diagonal."""
    total = 0.0
    if bias_identity:
        for m in range(3):
            total += IK[row, m] * v[m]
        if 3 <= row < 6:
            total += v[row]
        for m in range(6, n):
            total += IK[row, m] * v[m]
    else:
        for m in range(n):
            total += IK[row, m] * v[m]
    return total


@njit(cache=True, error_model="numpy")
def gauss_jordan(S, inverse, n):
    """inverse = S⁻¹ for the leading n x n block (S is destroyed), with
    partial pivoting; S is positive definite. Returns det S (the pivots'
    product, signed by the row swaps)."""
    determinant = 1.0
    for i in range(n):
        for j in range(n):
            inverse[i, j] = 1.0 if i == j else 0.0
    for col in range(n):
        pivot = col
        for row in range(col + 1, n):
            if abs(S[row, col]) > abs(S[pivot, col]):
                pivot = row
        if pivot != col:
            determinant = -determinant
            for j in range(n):
                S[col, j], S[pivot, j] = S[pivot, j], S[col, j]
                inverse[col, j], inverse[pivot, j] = inverse[pivot, j], inverse[col, j]
        diagonal = S[col, col]
        determinant *= diagonal
        for j in range(n):
            S[col, j] /= diagonal
            inverse[col, j] /= diagonal
        for row in range(n):
            if row != col:
                factor = S[row, col]
                for j in range(n):
                    S[row, j] -= factor * S[col, j]
                    inverse[row, j] -= factor * inverse[col, j]
    return determinant


@njit(cache=True, inline="always", error_model="numpy")
def quadratic_form(y, inverse, n):
    """yᵀ S⁻¹ y for the first n entries of ``y`` (the NIS and the NEES)."""
    total = 0.0
    for i in range(n):
        for j in range(n):
            total += y[i] * inverse[i, j] * y[j]
    return total


#: Below this angle δq's sin(θ/2)/θ is its series (:func:`quat_exp`).
SINC_SERIES_BELOW = 1e-4


@njit(cache=True, inline="always", error_model="numpy")
def half_sinc_series(angle):
    """sin(θ/2)/θ by its series, for θ below :data:`SINC_SERIES_BELOW`."""
    return 0.5 - angle * angle / 48.0


@njit(cache=True, inline="always", error_model="numpy")
def quat_exp(t0, t1, t2, out):
    """out = δq(θ), the exponential map of dynamics.quaternion.quat_from_rotvec."""
    angle = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    if angle < SINC_SERIES_BELOW:
        half_sinc = half_sinc_series(angle)
    else:
        half_sinc = math.sin(0.5 * angle) / angle
    out[0] = math.cos(0.5 * angle)
    out[1] = half_sinc * t0
    out[2] = half_sinc * t1
    out[3] = half_sinc * t2


@njit(cache=True, inline="always", error_model="numpy")
def product_normalized(q0, q1, q2, q3, d0, d1, d2, d3):
    """(q ⊗ d) / |q ⊗ d| (Hamilton product), on values."""
    w = q0 * d0 - q1 * d1 - q2 * d2 - q3 * d3
    x = q0 * d1 + q1 * d0 + q2 * d3 - q3 * d2
    y = q0 * d2 - q1 * d3 + q2 * d0 + q3 * d1
    z = q0 * d3 + q1 * d2 - q2 * d1 + q3 * d0
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    return w / norm, x / norm, y / norm, z / norm


@njit(cache=True, inline="always", error_model="numpy")
def quat_times_normalized(q, d, out):
    """out = (q ⊗ d) / |q ⊗ d| (Hamilton product); out may be q."""
    out[0], out[1], out[2], out[3] = product_normalized(q[0], q[1], q[2], q[3], d[0], d[1],
                                                        d[2], d[3])


@njit(cache=True, inline="always", error_model="numpy")
def to_body_frame(q, v):
    """A(q)ᵀ v for a unit quaternion ``q`` (dynamics.quaternion.to_body_frame,
    the same operations in the same order)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    a, b, c = v[0], v[1], v[2]
    tx, ty, tz = y * c - z * b, z * a - x * c, x * b - y * a
    return (a - 2.0 * w * tx + 2.0 * (y * tz - z * ty),
            b - 2.0 * w * ty + 2.0 * (z * tx - x * tz),
            c - 2.0 * w * tz + 2.0 * (x * ty - y * tx))


@njit(cache=True, inline="always", error_model="numpy")
def log_error(q, p, norm):
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
def projected_covariance(x, P, out):
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
