r"""Wahba's problem: the attitude that best fits a set of vector observations.

Find the rotation :math:`A` minimising (Wahba 1965; Markley & Crassidis
2014, ch. 5; Markley & Mortari 2000)

.. math:: L(A) = \tfrac12 \sum_i a_i \lVert r_i - A\, b_i \rVert^2, \qquad
          a_i = \sigma_i^{-2},

with :math:`b_i` the measured unit vectors in the body frame, :math:`r_i` the
same directions in the reference frame, and :math:`A` the body-to-reference
rotation (this toolkit's convention, :mod:`dynamics`; the book's attitude
matrix is its transpose, so the book's :math:`b_i` and :math:`r_i` trade
places in every formula below). Minimising :math:`L` maximises the gain
:math:`\operatorname{tr}(A B^\mathsf{T})` of the *attitude profile matrix*

.. math:: B = \sum_i a_i\, r_i b_i^\mathsf{T}.

**Davenport's q-method** (§5.3.1): with :math:`S = B + B^\mathsf{T}`,
:math:`\sigma = \operatorname{tr} B` and :math:`z = [B_{23} - B_{32},\ B_{31} -
B_{13},\ B_{12} - B_{21}]^\mathsf{T}`, the optimal quaternion (vector part
first, as the book writes it) is the eigenvector of the largest eigenvalue
:math:`\lambda_\text{max}` of

.. math:: K = \begin{bmatrix} S - \sigma I_3 & z \\ z^\mathsf{T} & \sigma \end{bmatrix}.

**QUEST** (§5.3.2; Shuster & Oh 1981): :math:`\lambda_\text{max}` from the
characteristic equation of :math:`K`, then

.. math:: q \propto \begin{bmatrix}\operatorname{adj}\bigl((\lambda+\sigma) I_3 - S\bigr) z \\
          \det\bigl((\lambda+\sigma) I_3 - S\bigr)\end{bmatrix},

written with :math:`\alpha = \lambda^2 - \sigma^2 + \kappa`,
:math:`\beta = \lambda - \sigma`, :math:`\gamma = (\lambda+\sigma)\alpha - \Delta`,
:math:`x = (\alpha I_3 + \beta S + S^2) z` as :math:`q \propto [x;\ \gamma]`
(:math:`\kappa = \operatorname{tr}\operatorname{adj} S`,
:math:`\Delta = \det S`). :math:`[x;\ \gamma]` is the last column of
:math:`\operatorname{adj}(\lambda I_4 - K) = \prod_{j>1}(\lambda_\text{max} - \lambda_j)\,
q q^\mathsf{T}`, so it vanishes with :math:`q_4` (a rotation of 180°). The
method of sequential rotations (Shuster & Oh 1981; Shuster & Natanson 1993)
solves it instead in the reference frame turned by 180° about x, y or z,
which moves :math:`q_1`, :math:`q_2` or :math:`q_3` into the scalar place;
turning permutes the rows and columns of :math:`K`, so the four frames'
:math:`\gamma` are the four diagonal cofactors of :math:`\lambda I_4 - K`,
proportional to :math:`q_i^2`. QUEST works in the frame of the largest,
where :math:`|q_4| \ge 1/2`.

**ESOQ2** (Mortari 1997; §5.3.3): the vector part is the null vector of the
symmetric rank-2 matrix :math:`M = (\lambda - \sigma)\bigl((\lambda+\sigma)
I_3 - S\bigr) - z z^\mathsf{T}`, the largest cross product of two of its
rows, :math:`e`; then :math:`q \propto [(\lambda - \sigma) e;\ z^\mathsf{T} e]`.
:math:`M` vanishes with :math:`\lambda - \sigma` (a rotation near zero), so
ESOQ2 works in the frame turned by 180° of the least trace
:math:`\operatorname{tr} B` (turning about axis :math:`i` makes it
:math:`2B_{ii} - \operatorname{tr} B`; the four sum to zero, so the least
leaves :math:`\lambda - \sigma \ge \lambda`: the singularity avoidance of
Markley's variant ESOQ2.1, 1999).

**FOAM** (Markley 1993; §5.3.4): the matrix itself, from
:math:`\lambda_\text{max}`,

.. math:: A = \frac{(\kappa + \lVert B\rVert_F^2) B + \lambda \operatorname{adj}(B^\mathsf{T})
          - B B^\mathsf{T} B}{\zeta}, \qquad
          \kappa = \tfrac12(\lambda^2 - \lVert B\rVert_F^2), \quad \zeta = \kappa\lambda - \det B.

Markley finds :math:`\lambda_\text{max}` by Newton's method on the same
characteristic equation written in :math:`B`'s invariants,
:math:`(\lambda^2 - \lVert B\rVert_F^2)^2 - 8\lambda \det B -
4\lVert\operatorname{adj} B\rVert_F^2 = 0`; here FOAM shares QUEST's (below).

**λ_max** (shared by QUEST, ESOQ2 and FOAM; the weights normalised to
:math:`\sum a_i = 1`, so :math:`\lambda_\text{max} \le 1` and the optimal
loss is :math:`1 - \lambda_\text{max}`). For two observations, Markley &
Mortari's (2000) closed form,

.. math:: \lambda_\text{max}^2 = a_1^2 + a_2^2 + 2 a_1 a_2 \bigl[(b_1 \cdot b_2)(r_1 \cdot r_2)
          + \lVert b_1 \times b_2\rVert\, \lVert r_1 \times r_2\rVert\bigr].

For more, Newton's method on the characteristic equation
:math:`p(\lambda) = \det(\lambda I_4 - K) = 0` from :math:`\lambda_0 = 1`,
as in QUEST and FOAM, but with :math:`p'/p = \operatorname{tr}(\lambda I_4 -
K)^{-1}` taken from the Cholesky factor of :math:`\lambda I_4 - K` rather
than from the expanded quartic.

Why: where the weights differ by orders of magnitude, or two directions are
nearly parallel, the two largest roots crowd, and the quartic's
coefficients cancel (Cheng & Shuster, "Robustness and Accuracy of the QUEST
Algorithm", AAS 07-102, 2007: a complete loss of significance in extreme
cases). For two observations the roots are :math:`\pm\lambda_\pm` with
:math:`\lambda_\pm^2 = a_1^2 + a_2^2 + 2 a_1 a_2 \cos(\theta_b \mp
\theta_r)`, :math:`\theta` the directions' separation, so the gap is about
:math:`2 a_2 \sin\theta_b \sin\theta_r` for a light :math:`a_2`. Newton's
iteration on the quartic then lands anywhere in the cluster, and the
quaternion mixes the two eigenvectors, up to a flip by 180° (Markley &
Mortari's cases 2, 4, 6 and 7). The Cholesky factor is backward stable, so
:math:`\lambda` comes within a few :math:`\varepsilon` of
:math:`\lambda_\text{max}`. From above a real-rooted polynomial's largest
root (:math:`\lambda_0 = \sum a_i`) Newton's iterates decrease to it
monotonically, and the factor exists exactly while :math:`\lambda >
\lambda_\text{max}`, so its failure marks arrival. Two roots :math:`g`
apart cost :math:`\log_2\bigl((\lambda_0 - \lambda_\text{max})/g\bigr)`
halving steps before the quadratic convergence; :data:`NEWTON_LIMIT`
bounds them.

**The check** (QUEST, ESOQ2, FOAM): the quaternion's gain
:math:`q^\mathsf{T} K q` must be within :data:`OPTIMALITY_TOLERANCE` of
:math:`\lambda_\text{max}`, that is its loss within that of the optimum.
Each closed form is exact at the exact :math:`\lambda` but rounds: its
error, of relative order :math:`\varepsilon / g` with :math:`g =
\lambda_\text{max} - \lambda_2` the eigengap, lies in every direction (the
q-method's, of the same order, only along the weakly determined axis), so
its gain falls short by about :math:`(\varepsilon / g)^2`. Past :math:`g
\approx \sqrt{\varepsilon}/4` (weights about 10⁹ apart on well-separated
directions, less on directions a fraction of a degree apart) the check
fails, and the q-method's eigenvector is returned instead (:func:`solution`
says so).

**SVD** (§5.3.5; Markley 1988): scipy's ``Rotation.align_vectors``, which
solves Wahba's problem by the singular value decomposition of :math:`B`.

**TRIAD** (§5.2; Black 1964), not optimal, and its covariance:
:mod:`estimators.triad`.

**Covariance** (Shuster's QUEST measurement model, §5.4): the optimal
solutions share the Fisher information of the body-frame error angle,

.. math:: P_{\theta\theta} = \Bigl[\sum_i a_i \bigl(I_3 - b_i b_i^\mathsf{T}\bigr)\Bigr]^{-1},

and TRIAD's is in :mod:`estimators.triad`.

Every solver takes ``(body (n, 3), reference (n, 3), weights (n,))`` with unit
vectors and returns a scalar-first unit quaternion, body to reference.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from dynamics.quaternion import from_rotation, quat_multiply, rotation_matrix
from estimators.triad import matrix_quaternion, triad

MACHINE_EPSILON = float(np.finfo(float).eps)
#: How far below λ_max (weights summing to one) a solver's gain may fall:
#: its loss may exceed the optimum's by this fraction of Σ a_i. Rounding
#: alone leaves λ_max and the gain a few ε apart (module docstring).
OPTIMALITY_TOLERANCE = 16.0 * MACHINE_EPSILON
#: Newton steps on the characteristic equation at most: from λ0 = 1 to
#: λ_max, halving through a cluster of roots down to ε takes 53.
NEWTON_LIMIT = 64
#: What a solver's formula yields where it gives no rotation: fails the check.
_NOT_A_ROTATION = np.full(4, np.nan)


def profile_matrix(body: np.ndarray, reference: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """:math:`B = \\sum_i a_i r_i b_i^\\mathsf{T}` (3x3)."""
    return (reference * weights[:, None]).T @ body


def _from_book(q_book: np.ndarray) -> np.ndarray:
    """The book's quaternion (vector first) of :math:`A` as this toolkit's
    (scalar first) of the same body-to-reference matrix: the book's attitude
    matrix of ``[e; q4]`` is the transpose of Hamilton's, so the vector part
    changes sign. An all-zero ``q_book`` (a solver's degenerate case) gives NaN."""
    size = math.sqrt(float(q_book @ q_book))
    if not size > 0.0:
        return _NOT_A_ROTATION
    q = np.array([q_book[3], -q_book[0], -q_book[1], -q_book[2]]) / size
    return q if q[0] >= 0 else -q


def _to_book(q: np.ndarray) -> np.ndarray:
    """The inverse of :func:`_from_book`."""
    return np.array([-q[1], -q[2], -q[3], q[0]])


def _davenport_parts(B: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
    """``(S, σ, z)`` of the profile matrix."""
    z = np.array([B[1, 2] - B[2, 1], B[2, 0] - B[0, 2], B[0, 1] - B[1, 0]])
    return B + B.T, float(np.trace(B)), z


def _davenport_matrix(B: np.ndarray) -> np.ndarray:
    """Davenport's :math:`K` of the profile matrix (the book's order, vector
    part first), written out: it is built for every solution."""
    (b00, b01, b02), (b10, b11, b12), (b20, b21, b22) = B.tolist()
    sigma = b00 + b11 + b22
    z0, z1, z2 = b12 - b21, b20 - b02, b01 - b10
    return np.array([[2.0 * b00 - sigma, b01 + b10, b02 + b20, z0],
                     [b01 + b10, 2.0 * b11 - sigma, b12 + b21, z1],
                     [b02 + b20, b12 + b21, 2.0 * b22 - sigma, z2],
                     [z0, z1, z2, sigma]])


def davenport_q(body, reference, weights) -> np.ndarray:
    """Davenport's q-method: the dominant eigenvector of :math:`K` (``numpy.linalg.eigh``)."""
    return _dominant_eigenvector(_davenport_matrix(profile_matrix(body, reference, weights)))


def _dominant_eigenvector(K: np.ndarray) -> np.ndarray:
    """The q-method's quaternion from :math:`K`."""
    _, vectors = np.linalg.eigh(K)
    return _from_book(vectors[:, -1])


class Solution(NamedTuple):
    """A solver's answer (:func:`solution`)."""

    #: Scalar-first unit quaternion, body to reference.
    quaternion: np.ndarray
    #: Whether the solver's own quaternion failed the optimality check
    #: (module docstring) and the q-method's is returned in its place.
    fell_back: bool = False


def solution(name: str, body, reference, weights) -> Solution:
    """The solver ``name``'s (:data:`SOLVERS`) quaternion, and whether QUEST's,
    ESOQ2's or FOAM's own failed its check (the others have none)."""
    checked = _CHECKED.get(name)
    if checked is not None:
        return checked(body, reference, weights)
    return Solution(SOLVERS[name](body, reference, weights))


def _normalised(weights) -> np.ndarray:
    weights = np.asarray(weights, dtype=float)
    total = float(np.sum(weights))
    if not total > 0.0:
        raise ValueError(f"weights must have a positive sum, got {weights.tolist()}")
    return weights / total


def _lambda_max(K: np.ndarray, body, reference, weights) -> float:
    """:math:`\\lambda_\\text{max}` of :math:`K` for weights summing to one
    (module docstring): the closed form for two observations, Newton's
    method on the characteristic equation otherwise."""
    if len(weights) == 2:
        return _lambda_max_of_two(body, reference, weights)
    K_rows = K.tolist()
    lam = 1.0                                     # Σ a_i, at or above λ_max
    for _ in range(NEWTON_LIMIT):
        log_slope = _characteristic_log_slope(K_rows, lam)
        if log_slope is None:                     # λ I − K no longer positive definite
            break
        step = 1.0 / log_slope
        lam -= step
        if step <= MACHINE_EPSILON:
            break
    return lam


def _lambda_max_of_two(body, reference, weights) -> float:
    """Markley & Mortari's closed form (module docstring); cross products
    written out, so that directions a fraction of a degree apart keep their sine."""
    (b1, b2), (r1, r2) = body.tolist(), reference.tolist()
    a1, a2 = weights.tolist()
    cross_b, cross_r = _cross(b1, b2), _cross(r1, r2)
    cos_b, sin_b = _dot(b1, b2), math.sqrt(_dot(cross_b, cross_b))
    cos_r, sin_r = _dot(r1, r2), math.sqrt(_dot(cross_r, cross_r))
    return math.sqrt(max(0.0, a1 * a1 + a2 * a2 + 2.0 * a1 * a2 * (cos_b * cos_r + sin_b * sin_r)))


def _characteristic_log_slope(K_rows, lam: float) -> float | None:
    """:math:`p'(\\lambda)/p(\\lambda) = \\operatorname{tr}(\\lambda I_4 - K)^{-1}
    = \\lVert L^{-1}\\rVert_F^2` for the Cholesky factor :math:`L L^\\mathsf{T} =
    \\lambda I_4 - K`, or None where that is not positive definite (λ at or
    below λ_max). Written out for the 4x4 case: numpy's calls cost ten times more."""
    (k00, k01, k02, k03), (_, k11, k12, k13), (_, _, k22, k23), (_, _, _, k33) = K_rows
    pivot = lam - k00
    if not pivot > 0.0:
        return None
    l00 = math.sqrt(pivot)
    l10, l20, l30 = -k01 / l00, -k02 / l00, -k03 / l00
    pivot = lam - k11 - l10 * l10
    if not pivot > 0.0:
        return None
    l11 = math.sqrt(pivot)
    l21, l31 = (-k12 - l20 * l10) / l11, (-k13 - l30 * l10) / l11
    pivot = lam - k22 - l20 * l20 - l21 * l21
    if not pivot > 0.0:
        return None
    l22 = math.sqrt(pivot)
    l32 = (-k23 - l30 * l20 - l31 * l21) / l22
    pivot = lam - k33 - l30 * l30 - l31 * l31 - l32 * l32
    if not pivot > 0.0:
        return None
    l33 = math.sqrt(pivot)
    # L⁻¹, lower triangular, by forward substitution
    m00, m11, m22, m33 = 1.0 / l00, 1.0 / l11, 1.0 / l22, 1.0 / l33
    m10 = -l10 * m00 * m11
    m21 = -l21 * m11 * m22
    m20 = -(l20 * m00 + l21 * m10) * m22
    m32 = -l32 * m22 * m33
    m31 = -(l31 * m11 + l32 * m21) * m33
    m30 = -(l30 * m00 + l31 * m10 + l32 * m20) * m33
    return (m00 * m00 + m11 * m11 + m22 * m22 + m33 * m33 + m10 * m10 + m21 * m21
            + m20 * m20 + m32 * m32 + m31 * m31 + m30 * m30)


def _dot(u, v) -> float:
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


def _cross(u, v) -> list:
    """``np.cross`` of two 3-vectors written out (it costs more than the solvers)."""
    return [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]


def _adjugate(M: np.ndarray) -> np.ndarray:
    """The adjugate of a 3x3 matrix (transposed cofactors; defined when ``M``
    is singular), written out: ``np.cross`` costs more than the solvers."""
    (a, b, c), (d, e, f), (g, h, i) = M.tolist()
    return np.array([[e * i - f * h, c * h - b * i, b * f - c * e],
                     [f * g - d * i, a * i - c * g, c * d - a * f],
                     [d * h - e * g, b * g - a * h, a * e - b * d]])


def _det3(rows) -> float:
    (a, b, c), (d, e, f), (g, h, i) = rows
    return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)


def quest(body, reference, weights) -> np.ndarray:
    r"""QUEST (module docstring): :math:`[x;\ \gamma]` in the frame of the
    largest :math:`\gamma` (sequential rotations), checked."""
    return _quest(body, reference, weights).quaternion


def _quest(body, reference, weights) -> Solution:
    B, K, lam = _problem(body, reference, weights)
    axis = _largest_gamma_frame(K, lam)
    S, sigma, z = _davenport_parts(_turned(B, axis))
    kappa = float(np.trace(_adjugate(S)))
    alpha = lam * lam - sigma * sigma + kappa
    gamma = (lam + sigma) * alpha - float(np.linalg.det(S))
    x = (alpha * np.eye(3) + (lam - sigma) * S + S @ S) @ z
    return _checked(_unturned(_from_book(np.append(x, gamma)), axis), K, lam)


#: Indices left when one of K's four is removed (its diagonal cofactors).
_COMPLEMENTS = ((1, 2, 3), (0, 2, 3), (0, 1, 3), (0, 1, 2))


def _problem(body, reference, weights) -> tuple[np.ndarray, np.ndarray, float]:
    """What QUEST, ESOQ2 and FOAM start from: the profile matrix ``B`` and
    Davenport's ``K`` of the weights normalised to sum 1, and ``λ_max``."""
    weights = _normalised(weights)
    B = profile_matrix(body, reference, weights)
    K = _davenport_matrix(B)
    return B, K, _lambda_max(K, body, reference, weights)


def _largest_gamma_frame(K: np.ndarray, lam: float):
    r"""The axis of the half turn (None: no turn) whose frame has QUEST's
    largest :math:`\gamma`: the diagonal cofactors of :math:`\lambda I_4 - K`,
    in the order of the quaternion's components (x, y, z, then the scalar
    part, which is the unturned frame)."""
    N = (lam * np.eye(4) - K).tolist()
    gammas = [_det3([[N[i][j] for j in keep] for i in keep]) for keep in _COMPLEMENTS]
    best = max(range(4), key=gammas.__getitem__)
    return None if best == 3 else best


def esoq2(body, reference, weights) -> np.ndarray:
    r"""ESOQ2 (module docstring): the null vector of :math:`M`, the largest
    cross product of two of its rows (Mortari's choice), in the frame of the
    least trace, checked."""
    return _esoq2(body, reference, weights).quaternion


def _esoq2(body, reference, weights) -> Solution:
    B, K, lam = _problem(body, reference, weights)
    trace = float(np.trace(B))
    traces = [2.0 * B[0, 0] - trace, 2.0 * B[1, 1] - trace, 2.0 * B[2, 2] - trace, trace]
    least = min(range(4), key=traces.__getitem__)
    axis = None if least == 3 else least
    S, sigma, z = _davenport_parts(_turned(B, axis))
    M = ((lam - sigma) * ((lam + sigma) * np.eye(3) - S) - np.outer(z, z)).tolist()
    e = max((_cross(M[1], M[2]), _cross(M[2], M[0]), _cross(M[0], M[1])),
            key=lambda v: _dot(v, v))
    e = np.array(e)
    return _checked(_unturned(_from_book(np.append((lam - sigma) * e, z @ e)), axis), K, lam)


def _turned(B: np.ndarray, axis) -> np.ndarray:
    """The profile matrix with the reference frame turned by 180° about
    ``axis`` (None: unturned): the other two rows change sign."""
    if axis is None:
        return B
    turned = -B
    turned[axis] = B[axis]
    return turned


def _unturned(q: np.ndarray, axis) -> np.ndarray:
    """Undo :func:`_turned`: ``A = R_axis(180°) A_turned``, the product with
    the half turn's quaternion."""
    if axis is None:
        return q
    half_turn = np.zeros(4)
    half_turn[1 + axis] = 1.0
    product = quat_multiply(half_turn, q)
    return product if product[0] >= 0 else -product


def _checked(q: np.ndarray, K: np.ndarray, lam: float) -> Solution:
    """``q`` if its gain is within :data:`OPTIMALITY_TOLERANCE` of λ_max
    (module docstring), the q-method's eigenvector otherwise."""
    q_book = _to_book(q)
    if lam - float(q_book @ K @ q_book) <= OPTIMALITY_TOLERANCE:    # NaN fails too
        return Solution(q)
    return Solution(_dominant_eigenvector(K), fell_back=True)


def foam(body, reference, weights) -> np.ndarray:
    """FOAM (module docstring): the optimal matrix from :math:`B`, its adjugate
    and determinant, checked."""
    return _foam(body, reference, weights).quaternion


def _foam(body, reference, weights) -> Solution:
    B, K, lam = _problem(body, reference, weights)
    norm2 = float(np.sum(B * B))
    det = float(np.linalg.det(B))
    kappa = 0.5 * (lam * lam - norm2)
    zeta = kappa * lam - det
    q = _NOT_A_ROTATION
    if zeta != 0.0:
        A = ((kappa + norm2) * B + lam * _adjugate(B).T - B @ B.T @ B) / zeta
        try:
            q = matrix_quaternion(A)
        except ValueError:                  # det A <= 0: no rotation
            pass
    return _checked(q, K, lam)


def svd(body, reference, weights) -> np.ndarray:
    """The SVD solution: scipy's ``Rotation.align_vectors(r, b, weights)``."""
    from scipy.spatial.transform import Rotation  # here: a scenario is built without scipy
    rotation, _ = Rotation.align_vectors(reference, body, weights=weights)
    return from_rotation(rotation)


def wahba_covariance(body, sigmas_rad) -> np.ndarray:
    """Shuster's covariance of the optimal solutions, rad² (module docstring)."""
    information = np.zeros((3, 3))
    for b, sigma in zip(body, sigmas_rad):
        information += (np.eye(3) - np.outer(b, b)) / (sigma * sigma)
    return np.linalg.inv(information)


#: Solver name → function.
SOLVERS = {"triad": triad, "q-method": davenport_q, "quest": quest, "esoq2": esoq2,
           "foam": foam, "svd": svd}
#: The solvers with an optimality check (module docstring).
_CHECKED = {"quest": _quest, "esoq2": _esoq2, "foam": _foam}


def loss(q: np.ndarray, body, reference, weights) -> float:
    """Wahba's loss :math:`L(A)` of the quaternion ``q`` (body to reference)."""
    residual = reference - body @ rotation_matrix(q).T
    return 0.5 * float(np.sum(weights * np.sum(residual * residual, axis=1)))
