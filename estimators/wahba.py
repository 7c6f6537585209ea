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

**QUEST** (§5.3.2; Shuster & Oh 1981): :math:`\lambda_\text{max}` by Newton's
method on the characteristic equation of :math:`K` from
:math:`\lambda_0 = \sum a_i` (close to it when the fit is good), then

.. math:: q \propto \begin{bmatrix}\operatorname{adj}\bigl((\lambda+\sigma) I_3 - S\bigr) z \\
          \det\bigl((\lambda+\sigma) I_3 - S\bigr)\end{bmatrix},

written with :math:`\alpha = \lambda^2 - \sigma^2 + \kappa`,
:math:`\beta = \lambda - \sigma`, :math:`\gamma = (\lambda+\sigma)\alpha - \Delta`,
:math:`x = (\alpha I_3 + \beta S + S^2) z` as :math:`q \propto [x;\ \gamma]`
(:math:`\kappa = \operatorname{tr}\operatorname{adj} S`,
:math:`\Delta = \det S`). Where :math:`\gamma` vanishes (a rotation of 180°)
the method of sequential rotations solves it in a frame turned by 180° about
a reference axis.

**ESOQ2** (Mortari 1997; §5.3.3): the vector part is the null vector of the
symmetric rank-2 matrix :math:`M = (\lambda - \sigma)\bigl((\lambda+\sigma)
I_3 - S\bigr) - z z^\mathsf{T}`, the largest cross product of two of its
rows, :math:`e`; then :math:`q \propto [(\lambda - \sigma) e;\ z^\mathsf{T} e]`.

**FOAM** (Markley 1993; §5.3.4): :math:`\lambda_\text{max}` by Newton's method on

.. math:: (\lambda^2 - \lVert B\rVert_F^2)^2 - 8\lambda \det B
          - 4\lVert\operatorname{adj} B\rVert_F^2 = 0,

then the matrix itself,

.. math:: A = \frac{(\kappa + \lVert B\rVert_F^2) B + \lambda \operatorname{adj}(B^\mathsf{T})
          - B B^\mathsf{T} B}{\zeta}, \qquad
          \kappa = \tfrac12(\lambda^2 - \lVert B\rVert_F^2), \quad \zeta = \kappa\lambda - \det B.

**SVD** (§5.3.5; Markley 1988): scipy's ``Rotation.align_vectors``, which
solves Wahba's problem by the singular value decomposition of :math:`B`.

**TRIAD** (§5.2; Black 1964): not optimal: the two most accurate
observations define a frame in each system, anchored on the more accurate,

.. math:: A = [\,r_1\ \ r_\times\ \ r_1 \times r_\times\,]\,
              [\,b_1\ \ b_\times\ \ b_1 \times b_\times\,]^\mathsf{T}, \qquad
          v_\times = \frac{v_1 \times v_2}{\lVert v_1 \times v_2\rVert}.

**Covariance** (Shuster's QUEST measurement model, §5.4): the optimal
solutions share the Fisher information of the body-frame error angle,

.. math:: P_{\theta\theta} = \Bigl[\sum_i a_i \bigl(I_3 - b_i b_i^\mathsf{T}\bigr)\Bigr]^{-1},

and TRIAD's (Shuster & Oh 1981, eq. 5.48 of the book) is

.. math:: P_\text{TRIAD} = \sigma_1^2 I_3 + \lVert b_1 \times b_2\rVert^{-2}
          \Bigl[(\sigma_2^2 - \sigma_1^2)\, b_1 b_1^\mathsf{T}
          + \sigma_1^2 (b_1 \cdot b_2)(b_1 b_2^\mathsf{T} + b_2 b_1^\mathsf{T})\Bigr].

Every solver takes ``(body (n, 3), reference (n, 3), weights (n,))`` with unit
vectors and returns a scalar-first unit quaternion, body to reference.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from dynamics.quaternion import from_rotation, quat_multiply, rotation_matrix

#: Newton iterations on λ_max: QUEST and FOAM converge quadratically from
#: Σ a_i, to machine precision in two or three; five keeps a margin.
NEWTON_ITERATIONS = 5
#: Below this fraction of the unnormalised quaternion's size, its scalar part
#: makes QUEST rotate the frame (sequential rotations; ESOQ2 likewise).
QUEST_ROTATE_BELOW = 1e-2


def profile_matrix(body: np.ndarray, reference: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """:math:`B = \\sum_i a_i r_i b_i^\\mathsf{T}` (3x3)."""
    return (reference * weights[:, None]).T @ body


def _from_book(q_book: np.ndarray) -> np.ndarray:
    """The book's quaternion (vector first) of :math:`A` as this toolkit's
    (scalar first) of the same body-to-reference matrix: the book's attitude
    matrix of ``[e; q4]`` is the transpose of Hamilton's, so the vector part
    changes sign."""
    q = np.array([q_book[3], -q_book[0], -q_book[1], -q_book[2]])
    q /= np.sqrt(q @ q)
    return q if q[0] >= 0 else -q


def _davenport_parts(B: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
    """``(S, σ, z)`` of the profile matrix."""
    z = np.array([B[1, 2] - B[2, 1], B[2, 0] - B[0, 2], B[0, 1] - B[1, 0]])
    return B + B.T, float(np.trace(B)), z


def davenport_q(body, reference, weights) -> np.ndarray:
    """Davenport's q-method: the dominant eigenvector of :math:`K` (``numpy.linalg.eigh``)."""
    S, sigma, z = _davenport_parts(profile_matrix(body, reference, weights))
    K = np.empty((4, 4))
    K[:3, :3] = S - sigma * np.eye(3)
    K[:3, 3] = K[3, :3] = z
    K[3, 3] = sigma
    _, vectors = np.linalg.eigh(K)
    return _from_book(vectors[:, -1])


def _lambda_max(S, sigma, z, lambda0: float) -> float:
    """QUEST's Newton iteration on the characteristic equation of :math:`K`."""
    kappa = float(np.trace(_adjugate(S)))
    delta = float(np.linalg.det(S))
    a = sigma * sigma - kappa
    b = sigma * sigma + z @ z
    c = delta + z @ S @ z
    d = z @ S @ S @ z
    lam = lambda0
    for _ in range(NEWTON_ITERATIONS):
        f = lam ** 4 - (a + b) * lam ** 2 - c * lam + (a * b + c * sigma - d)
        slope = 4.0 * lam ** 3 - 2.0 * (a + b) * lam - c
        if slope == 0.0:
            break
        lam -= f / slope
    return lam


def _adjugate(M: np.ndarray) -> np.ndarray:
    """The adjugate of a 3x3 matrix (transposed cofactors; defined when ``M``
    is singular), written out: ``np.cross`` costs more than the solvers."""
    (a, b, c), (d, e, f), (g, h, i) = M.tolist()
    return np.array([[e * i - f * h, c * h - b * i, b * f - c * e],
                     [f * g - d * i, a * i - c * g, c * d - a * f],
                     [d * h - e * g, b * g - a * h, a * e - b * d]])


def quest(body, reference, weights) -> np.ndarray:
    r"""QUEST (module docstring), with sequential rotations near 180°
    (:func:`_in_the_best_frame`; :math:`\gamma` vanishes there)."""
    return _in_the_best_frame(_quest_in_frame, body, reference, weights,
                              lambda q_book, lam: abs(q_book[3]), 3)


def _quest_in_frame(body, reference, weights) -> tuple[np.ndarray, float]:
    """QUEST's unnormalised ``[x; γ]`` (the book's order) and ``λ_max``."""
    S, sigma, z = _davenport_parts(profile_matrix(body, reference, weights))
    lam = _lambda_max(S, sigma, z, float(np.sum(weights)))
    kappa = float(np.trace(_adjugate(S)))
    alpha = lam * lam - sigma * sigma + kappa
    beta = lam - sigma
    gamma = (lam + sigma) * alpha - float(np.linalg.det(S))
    x = (alpha * np.eye(3) + beta * S + S @ S) @ z
    return np.append(x, gamma), lam


def esoq2(body, reference, weights) -> np.ndarray:
    r"""ESOQ2 (module docstring): the null vector of :math:`M` by cross
    products. Its axis is undefined for a rotation near zero, where :math:`M`
    vanishes: there the frame is turned (:func:`_in_the_best_frame`)."""
    return _in_the_best_frame(_esoq2_in_frame, body, reference, weights,
                              lambda q_book, lam: float(np.sqrt(q_book @ q_book)), 5)


def _esoq2_in_frame(body, reference, weights) -> tuple[np.ndarray, float]:
    """ESOQ2's unnormalised ``[(λ − σ) e; zᵀ e]`` and ``λ_max``."""
    S, sigma, z = _davenport_parts(profile_matrix(body, reference, weights))
    lam = _lambda_max(S, sigma, z, float(np.sum(weights)))
    M = (lam - sigma) * ((lam + sigma) * np.eye(3) - S) - np.outer(z, z)
    crosses = (np.cross(M[0], M[1]), np.cross(M[1], M[2]), np.cross(M[2], M[0]))
    e = max(crosses, key=lambda v: v @ v)
    return np.append((lam - sigma) * e, z @ e), lam


def _in_the_best_frame(solve_in_frame, body, reference, weights, measure, power: int
                       ) -> np.ndarray:
    r"""The method of sequential rotations (Shuster & Natanson 1993; M&C §5.3):
    ``solve_in_frame`` in the reference frame, and where its ``measure`` of
    the unnormalised quaternion falls below :data:`QUEST_ROTATE_BELOW` of its
    size (or of :math:`10^{-6}\lambda^{\text{power}}`, where both vanish) in
    the frames turned by a half turn about x, y and z too, keeping the one
    of the largest measure; the solution is turned back."""
    best = None
    for axis in (None, 0, 1, 2):
        turned = reference if axis is None else _turned(reference, axis)
        q_book, lam = solve_in_frame(body, turned, weights)
        value = measure(q_book, lam)
        if best is None or value > best[1]:
            best = (q_book, value, axis)
        size = float(np.sqrt(q_book @ q_book))
        if axis is None and value >= QUEST_ROTATE_BELOW * max(size, 1e-6 * lam ** power):
            break
    return _unturned(_from_book(best[0]), best[2])


def _turned(reference: np.ndarray, axis: int) -> np.ndarray:
    """The reference vectors in a frame turned by 180° about ``axis``
    (the sign of the other two components changes)."""
    turned = -reference.copy()
    turned[:, axis] *= -1.0
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


def foam(body, reference, weights) -> np.ndarray:
    """FOAM (module docstring): the optimal matrix from :math:`B`, its adjugate and determinant."""
    B = profile_matrix(body, reference, weights)
    norm2 = float(np.sum(B * B))
    det = float(np.linalg.det(B))
    adj = _adjugate(B)
    adj_norm2 = float(np.sum(adj * adj))
    lam = float(np.sum(weights))
    for _ in range(NEWTON_ITERATIONS):
        f = (lam * lam - norm2) ** 2 - 8.0 * lam * det - 4.0 * adj_norm2
        slope = 4.0 * lam * (lam * lam - norm2) - 8.0 * det
        if slope == 0.0:
            break
        lam -= f / slope
    kappa = 0.5 * (lam * lam - norm2)
    zeta = kappa * lam - det
    A = ((kappa + norm2) * B + lam * adj.T - B @ B.T @ B) / zeta
    return _matrix_quaternion(A)


def _matrix_quaternion(A: np.ndarray) -> np.ndarray:
    """The quaternion of a body-to-reference rotation matrix (scipy's, ``w >= 0``)."""
    return from_rotation(Rotation.from_matrix(A))


def svd(body, reference, weights) -> np.ndarray:
    """The SVD solution: scipy's ``Rotation.align_vectors(r, b, weights)``."""
    rotation, _ = Rotation.align_vectors(reference, body, weights=weights)
    return from_rotation(rotation)


def triad(body, reference, weights, min_sine: float = 0.0) -> np.ndarray:
    """TRIAD on the two most heavily weighted separated observations,
    anchored on the first (module docstring; :func:`triad_pair`)."""
    first, second = triad_pair(body, reference, weights, min_sine)
    return triad_attitudes(body[first], body[second], reference[first], reference[second])


def triad_attitudes(b1, b2, r1, r2) -> np.ndarray:
    """TRIAD's quaternion of the pairs ``(b1, r1)`` (the anchor) and
    ``(b2, r2)`` of separated unit vectors; stacks along leading axes (a
    record's samples at once, as :meth:`estimators.static.TRIAD.run_batch`
    takes them)."""
    def frame(v1, v2):
        cross = np.cross(v1, v2)
        cross = cross / np.linalg.norm(cross, axis=-1, keepdims=True)
        return np.stack([v1, cross, np.cross(v1, cross)], axis=-1)

    A = frame(r1, r2) @ np.swapaxes(frame(b1, b2), -1, -2)
    return _matrix_quaternion(A)


def separated(u: np.ndarray, v: np.ndarray, min_sine: float = 0.0) -> bool:
    """Whether two unit vectors are more than ``asin(min_sine)`` from parallel
    (or antiparallel)."""
    return bool(np.linalg.norm(np.cross(u, v)) > max(min_sine, 1e-12))


def triad_pair(body, reference, weights, min_sine: float = 0.0) -> tuple[int, int]:
    """TRIAD's observations: the heaviest, and the heaviest of the rest whose
    directions are separated from it in both frames (two sensors of one
    direction, a coarse and a fine sun sensor, are not a pair)."""
    order = np.argsort(-np.asarray(weights), kind="stable")
    first = int(order[0])
    for index in order[1:]:
        if separated(body[first], body[index], min_sine) and \
                separated(reference[first], reference[index], min_sine):
            return first, int(index)
    raise ValueError("TRIAD needs two non-parallel observations")


def wahba_covariance(body, sigmas_rad) -> np.ndarray:
    """Shuster's covariance of the optimal solutions, rad² (module docstring)."""
    information = np.zeros((3, 3))
    for b, sigma in zip(body, sigmas_rad):
        information += (np.eye(3) - np.outer(b, b)) / (sigma * sigma)
    return np.linalg.inv(information)


def triad_covariance(body, sigmas_rad, first: int, second: int) -> np.ndarray:
    """TRIAD's covariance (Shuster & Oh 1981), rad²."""
    b1, b2 = body[first], body[second]
    s1, s2 = sigmas_rad[first] ** 2, sigmas_rad[second] ** 2
    cross2 = float(np.sum(np.cross(b1, b2) ** 2))
    return s1 * np.eye(3) + (
        (s2 - s1) * np.outer(b1, b1) + s1 * (b1 @ b2) * (np.outer(b1, b2) + np.outer(b2, b1))
    ) / cross2


#: Solver name → function.
SOLVERS = {"triad": triad, "q-method": davenport_q, "quest": quest, "esoq2": esoq2,
           "foam": foam, "svd": svd}


def loss(q: np.ndarray, body, reference, weights) -> float:
    """Wahba's loss :math:`L(A)` of the quaternion ``q`` (body to reference)."""
    residual = reference - body @ rotation_matrix(q).T
    return 0.5 * float(np.sum(weights * np.sum(residual * residual, axis=1)))
