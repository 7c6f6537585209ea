r"""The process model every workshop estimator shares, and its exact Jacobian.

One first-order step of the kinematics followed by normalisation:

.. math::

    g(q) = q + \tfrac{\Delta t}{2}\,\Xi(q)\,\tilde\omega
         = A(\tilde\omega)\, q, \qquad
    A = I_4 + \tfrac{\Delta t}{2}\,\Omega(\tilde\omega), \qquad
    f(q) = \frac{g(q)}{\lVert g(q)\rVert},

with :math:`\Omega(\omega)` the 4x4 matrix of right multiplication by the
pure quaternion :math:`[0, \omega]`. Its Jacobian, *including the
normalisation* (the workshop model, "The three estimators"), is

.. math::

    F = \frac{\partial f}{\partial q}
      = \frac{1}{\lVert g\rVert}\,\bigl(I_4 - n n^\mathsf{T}\bigr) A,
    \qquad n = f(q).

This is the model the filters *assume*; the truth they are compared with is
integrated separately, to high accuracy, in :mod:`dynamics.rigid_body`.
"""
from __future__ import annotations

import numpy as np


def right_product_matrix(omega_radps: np.ndarray) -> np.ndarray:
    r""":math:`\Omega(\omega)` with :math:`q \otimes [0, \omega] = \Omega(\omega)\, q`."""
    p, q, r = omega_radps
    return np.array([
        [0.0, -p, -q, -r],
        [p, 0.0, r, -q],
        [q, -r, 0.0, p],
        [r, q, -p, 0.0],
    ])


def propagate(q: np.ndarray, omega_radps: np.ndarray, dt: float) -> np.ndarray:
    """``f(q, ω)``: one normalised first-order kinematics step of ``dt`` seconds."""
    g = q + 0.5 * dt * (right_product_matrix(omega_radps) @ q)
    return g / np.sqrt(g @ g)


def propagate_with_jacobian(q: np.ndarray, omega_radps: np.ndarray,
                            dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``f(q, ω)`` and its exact Jacobian ``∂f/∂q`` (4x4), evaluated at ``q``."""
    transition = np.eye(4) + 0.5 * dt * right_product_matrix(omega_radps)
    g = transition @ q
    norm = np.sqrt(g @ g)
    n = g / norm
    jacobian = (transition - np.outer(n, n @ transition)) / norm
    return n, jacobian
