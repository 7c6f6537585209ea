"""The unscented filter's arithmetic in the engine, shared by USQUE's kernel
(:mod:`benchmarks.engine.kernels.usque`) and its IMU models'
(:mod:`benchmarks.engine.kernels.usque_imu`): the quaternion and GRP maps
of :mod:`dynamics.quaternion`, filterpy's sigma points
(``MerweScaledSigmaPoints``) and its unscented ``update``, each as the
per-run class computes it (Crassidis & Markley 2003, eqs. 31–45)."""
from __future__ import annotations

import math

from numba import njit

from benchmarks.engine.kernels.algebra import gauss_jordan, quadratic_form
from dynamics.quaternion import GRP_A, GRP_F
from estimators.usque import STATE_SIZE

#: 2n + 1 sigma points.
N_SIGMAS = 2 * STATE_SIZE + 1


@njit(cache=True, error_model="numpy")
def product(a0, a1, a2, a3, b0, b1, b2, b3):
    """a ⊗ b (dynamics.quaternion.quat_multiply), not normalised."""
    return (a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
            a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
            a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
            a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0)


@njit(cache=True, error_model="numpy")
def quat_from_grp(p0, p1, p2):
    """dynamics.quaternion.quat_from_grp (a = 1, f = 4)."""
    norm2 = p0 * p0 + p1 * p1 + p2 * p2
    w = (-GRP_A * norm2 + GRP_F * math.sqrt(GRP_F * GRP_F + (1.0 - GRP_A * GRP_A) * norm2)) \
        / (GRP_F * GRP_F + norm2)
    s = (GRP_A + w) / GRP_F
    return w, s * p0, s * p1, s * p2


@njit(cache=True, error_model="numpy")
def grp_from_quat(e):
    """dynamics.quaternion.grp_from_quat, sign-aligned to w >= 0 first."""
    w, x, y, z = e
    if w < 0:
        w, x, y, z = -w, -x, -y, -z
    return GRP_F * x / (GRP_A + w), GRP_F * y / (GRP_A + w), GRP_F * z / (GRP_A + w)


@njit(cache=True, error_model="numpy")
def unit(p):
    w, x, y, z = p
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    return w / norm, x / norm, y / norm, z / norm


@njit(cache=True, error_model="numpy")
def fold_reference(q, x):
    """q̂ ← q̂ ⊗ δq(δp) normalised, δp ← 0 (USQUE._reset, eq. 45)."""
    g0, g1, g2, g3 = quat_from_grp(x[0], x[1], x[2])
    q[0], q[1], q[2], q[3] = unit(product(q[0], q[1], q[2], q[3], g0, g1, g2, g3))
    x[0], x[1], x[2] = 0.0, 0.0, 0.0


@njit(cache=True, error_model="numpy")
def output(q, x, out):
    """USQUE._record's estimate: q̂, or q̂ ⊗ δq(δp) normalised while δp ≠ 0."""
    if x[0] == 0.0 and x[1] == 0.0 and x[2] == 0.0:
        for i in range(4):
            out[i] = q[i]
    else:
        g0, g1, g2, g3 = quat_from_grp(x[0], x[1], x[2])
        out[0], out[1], out[2], out[3] = unit(product(q[0], q[1], q[2], q[3], g0, g1, g2, g3))


@njit(cache=True, error_model="numpy")
def sigma_points(x, P, spread, sigmas, L):
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


@njit(cache=True, error_model="numpy")
def unscented_mean(sigmas, Wm, rows, mean):
    """Σ Wm_i χ_i over the first ``rows`` columns of the sigma points."""
    for m in range(rows):
        total = 0.0
        for i in range(N_SIGMAS):
            total += Wm[i] * sigmas[i, m]
        mean[m] = total


@njit(cache=True, error_model="numpy")
def unscented_update(x, P, sigmas, predicted, y0, y1, y2, R, Wm, Wc, gating, threshold,
                      scratch):
    """filterpy's unscented ``update`` with the sigma points' predicted
    measurements ``predicted`` (their first three columns) and the
    measurement ``y``; not applied if gating rejects it. Returns the NIS,
    whether it was applied and det S."""
    S, inverse, Pxz, K, KS = scratch[0], scratch[1], scratch[2], scratch[3], scratch[4]
    zp, kept = scratch[5, 0], scratch[5, 1:4]
    unscented_mean(predicted, Wm, 3, zp)
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
