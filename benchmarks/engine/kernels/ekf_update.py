"""The workshop EKF's star tracker update, shared by its two kernels
(:mod:`~benchmarks.engine.kernels.ekf`, one run at a time, and
:mod:`~benchmarks.engine.kernels.ekf_lanes`): :class:`estimators.QuaternionEKF`'s
reading aligned to the estimate's sign, then filterpy's update with H = I
(Joseph form)."""
from __future__ import annotations

from numba import njit

from benchmarks.engine.kernels.algebra import matmul4, quadratic_form
from benchmarks.engine.kernels.common import gauss_jordan_inlined as gauss_jordan


@njit(cache=True, inline="always", error_model="numpy")
def align(x, z, aligned, align_sign):
    """The reading ``z`` into ``aligned``, its sign turned to the estimate's
    where the filter aligns it (``align_sign``)."""
    flip = align_sign and (x[0] * z[0] + x[1] * z[1] + x[2] * z[2] + x[3] * z[3]) < 0
    for i in range(4):
        aligned[i] = -z[i] if flip else z[i]


@njit(cache=True, error_model="numpy")
def ekf_update(x, P, z, R, scratch):
    """filterpy's update with H = I: S = P + R, K = P S⁻¹, x += K (z - x),
    P = (I - K) P (I - K)ᵀ + K R Kᵀ. Returns the NIS and det S."""
    S = scratch[0]
    inverse = scratch[1]
    K = scratch[2]
    IK = scratch[3]
    T = scratch[4]
    for i in range(4):
        for j in range(4):
            S[i, j] = P[i, j] + R[i, j]
    determinant = gauss_jordan(S, inverse, 4)
    matmul4(P, inverse, K)
    y0, y1, y2, y3 = z[0] - x[0], z[1] - x[1], z[2] - x[2], z[3] - x[3]
    nis = quadratic_form((y0, y1, y2, y3), inverse, 4)
    for i in range(4):
        x[i] = x[i] + (K[i, 0] * y0 + K[i, 1] * y1 + K[i, 2] * y2 + K[i, 3] * y3)
    for i in range(4):
        for j in range(4):
            IK[i, j] = (1.0 if i == j else 0.0) - K[i, j]
    # T = (I - K) P ; P = T (I - K)ᵀ + (K R) Kᵀ
    matmul4(IK, P, T)
    KR = S   # S is no longer needed
    matmul4(K, R, KR)
    for i in range(4):
        for j in range(4):
            first = 0.0
            second = 0.0
            for m in range(4):
                first += T[i, m] * IK[j, m]
                second += KR[i, m] * K[j, m]
            P[i, j] = first + second
    return nis, determinant
