r"""TRIAD: the attitude of two vector observations (Markley & Crassidis
2014, §5.2; Black 1964), beside the optimal solutions of Wahba's problem
(:mod:`estimators.wahba`, whose conventions it shares).

Not optimal: the two most accurate observations define a frame in each
system, anchored on the more accurate,

.. math:: A = [\,r_1\ \ r_\times\ \ r_1 \times r_\times\,]\,
              [\,b_1\ \ b_\times\ \ b_1 \times b_\times\,]^\mathsf{T}, \qquad
          v_\times = \frac{v_1 \times v_2}{\lVert v_1 \times v_2\rVert}.

Its covariance (Shuster & Oh 1981, eq. 5.48 of the book) is

.. math:: P_\text{TRIAD} = \sigma_1^2 I_3 + \lVert b_1 \times b_2\rVert^{-2}
          \Bigl[(\sigma_2^2 - \sigma_1^2)\, b_1 b_1^\mathsf{T}
          + \sigma_1^2 (b_1 \cdot b_2)(b_1 b_2^\mathsf{T} + b_2 b_1^\mathsf{T})\Bigr].
"""
from __future__ import annotations

import numpy as np

from dynamics.quaternion import from_rotation


def matrix_quaternion(A: np.ndarray) -> np.ndarray:
    """The quaternion of a body-to-reference rotation matrix (scipy's, ``w >= 0``)."""
    from scipy.spatial.transform import Rotation  # here: a scenario is built without scipy
    return from_rotation(Rotation.from_matrix(A))


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
    return matrix_quaternion(A)


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


def triad_covariance(body, sigmas_rad, first: int, second: int) -> np.ndarray:
    """TRIAD's covariance (Shuster & Oh 1981), rad²."""
    b1, b2 = body[first], body[second]
    s1, s2 = sigmas_rad[first] ** 2, sigmas_rad[second] ** 2
    cross2 = float(np.sum(np.cross(b1, b2) ** 2))
    return s1 * np.eye(3) + (
        (s2 - s1) * np.outer(b1, b1) + s1 * (b1 @ b2) * (np.outer(b1, b2) + np.outer(b2, b1))
    ) / cross2
