r"""Quaternion algebra in the toolkit's one convention.

Quaternions are scalar-first ``q = [w, x, y, z]`` and multiply with the
Hamilton product, so that ``q_a ⊗ q_b`` composes rotations like the matrix
product ``R(q_a) R(q_b)``. ``q`` rotates body-frame vectors into the
reference frame: ``v_ref = R(q) v_body``. The kinematics with body rates
``ω`` (rad/s) are

.. math::

    \dot q = \tfrac12\, q \otimes [0, \omega] = \tfrac12\, \Xi(q)\, \omega,
    \qquad
    \Xi(q) = \begin{bmatrix} -x & -y & -z \\ w & -z & y \\ z & w & -x \\ -y & x & w \end{bmatrix}.

Every conversion to or from :class:`scipy.spatial.transform.Rotation` passes
``scalar_first=True`` explicitly, so scipy's own scalar-last default never
leaks in. Reference: Markley & Crassidis, *Fundamentals of Spacecraft
Attitude Determination and Control*, 2014, section 2.9 (their book uses the
scalar-last, "natural order" product; the formulas here are the Hamilton
scalar-first ones of the workshop model).

All functions take 1-D ``(4,)`` arrays or stacks ``(..., 4)`` and return the
same.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:     # scipy is imported where a Rotation is made: the command line starts without it
    from scipy.spatial.transform import Rotation


def quat_multiply(q_a: np.ndarray, q_b: np.ndarray) -> np.ndarray:
    """Hamilton product ``q_a ⊗ q_b`` of scalar-first quaternions (stacks along
    the last axis; two single quaternions take a float path, ten times
    faster and the same numbers: the filters call it for every sigma point)."""
    if np.ndim(q_a) == 1 and np.ndim(q_b) == 1:
        aw, ax, ay, az = np.asarray(q_a, dtype=float).tolist()
        bw, bx, by, bz = np.asarray(q_b, dtype=float).tolist()
        return np.array([aw * bw - ax * bx - ay * by - az * bz,
                         aw * bx + ax * bw + ay * bz - az * by,
                         aw * by - ax * bz + ay * bw + az * bx,
                         aw * bz + ax * by - ay * bx + az * bw])
    aw, ax, ay, az = np.moveaxis(np.asarray(q_a, dtype=float), -1, 0)
    bw, bx, by, bz = np.moveaxis(np.asarray(q_b, dtype=float), -1, 0)
    return np.stack([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ], axis=-1)


#: The identity rotation, scalar-first.
IDENTITY = (1.0, 0.0, 0.0, 0.0)


def relative_rotation(q_from: np.ndarray, q_to: np.ndarray) -> np.ndarray:
    r""":math:`q_\text{from}^{-1} \otimes q_\text{to}`: the rotation, in the body frame
    of ``q_from``, that takes attitude ``q_from`` to ``q_to`` (unit quaternions)."""
    return quat_multiply(quat_conjugate(q_from), q_to)


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """Conjugate ``[w, -x, -y, -z]``: the inverse rotation of a unit quaternion."""
    q = np.asarray(q, dtype=float)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def normalize(q: np.ndarray) -> np.ndarray:
    """Scale to unit norm along the last axis."""
    q = np.asarray(q, dtype=float)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def kinematics_matrix(q: np.ndarray) -> np.ndarray:
    r"""The 4x3 matrix :math:`\Xi(q)` with :math:`\dot q = \tfrac12 \Xi(q)\omega`.

    For a stack ``(..., 4)`` returns ``(..., 4, 3)``.
    """
    w, x, y, z = np.moveaxis(np.asarray(q, dtype=float), -1, 0)
    return np.stack([
        np.stack([-x, -y, -z], axis=-1),
        np.stack([w, -z, y], axis=-1),
        np.stack([z, w, -x], axis=-1),
        np.stack([-y, x, w], axis=-1),
    ], axis=-2)


def rotation_matrix(q: np.ndarray) -> np.ndarray:
    """Direction-cosine matrix ``R(q)`` taking body vectors to the reference frame.

    ``q`` need not be exactly unit; it is normalised first.
    """
    w, x, y, z = np.moveaxis(normalize(q), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=-2)


def to_rotation(q: np.ndarray) -> Rotation:
    """The :class:`~scipy.spatial.transform.Rotation` of a scalar-first quaternion."""
    from scipy.spatial.transform import Rotation
    return Rotation.from_quat(np.asarray(q, dtype=float), scalar_first=True)


def from_rotation(rotation: Rotation) -> np.ndarray:
    """Scalar-first quaternion(s) of a :class:`~scipy.spatial.transform.Rotation`.

    scipy returns the representative with ``w >= 0``; ``q`` and ``-q`` are the
    same attitude.
    """
    return rotation.as_quat(canonical=True, scalar_first=True)


def attitude_error_rad(q_true: np.ndarray, q_est: np.ndarray) -> np.ndarray:
    r"""Angle of the rotation between two attitudes, in radians.

    .. math:: e = 2 \arccos\bigl(\min(1, |q_\text{true} \cdot \hat q|)\bigr)

    Sign-invariant: ``q`` and ``-q`` give zero error; NaN where an estimate
    is not finite. Both inputs are taken as
    unit quaternions (the workshop metric; see the workshop model, "What is measured").
    Being an arccos near 1, it cannot resolve angles below about 1e-7 rad
    (6e-6 degrees): identical attitudes can show an error of that size.
    """
    dot = np.abs(np.sum(np.asarray(q_true, dtype=float) * np.asarray(q_est, dtype=float), axis=-1))
    # A non-finite estimate has no error angle: NaN, never the 0 of min(1, inf).
    return np.where(np.isfinite(dot), 2.0 * np.arccos(np.minimum(1.0, dot)), np.nan)


def skew(v: np.ndarray) -> np.ndarray:
    r"""The cross-product matrix :math:`[v\times]` with :math:`[v\times] u = v \times u`."""
    x, y, z = v
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def quat_from_rotvec(theta_rad: np.ndarray) -> np.ndarray:
    r"""The unit quaternion of the rotation vector :math:`\theta` (the exponential map).

    .. math:: \delta q(\theta) = \bigl[\cos\tfrac{|\theta|}2,\
              \tfrac{\theta}{|\theta|}\sin\tfrac{|\theta|}2\bigr]

    For ``(..., 3)`` returns ``(..., 4)``. Exact at ``θ = 0`` (the series
    ``sin(x/2)/x = ½ - x²/48`` below 1e-4 rad, where it is exact in floating point).
    """
    theta = np.asarray(theta_rad, dtype=float)
    angle = np.linalg.norm(theta, axis=-1, keepdims=True)
    small = angle < 1e-4
    half_sinc = np.where(small, 0.5 - angle * angle / 48.0,
                         np.sin(0.5 * angle) / np.where(small, 1.0, angle))
    return np.concatenate([np.cos(0.5 * angle), half_sinc * theta], axis=-1)


def rotvec_from_quat(q: np.ndarray) -> np.ndarray:
    r"""The rotation vector of a unit quaternion (the logarithm map), angle in [0, π].

    ``q`` and ``-q`` give the same vector: the sign is aligned to ``w >= 0``
    first. For ``(..., 4)`` returns ``(..., 3)``.
    """
    q = np.asarray(q, dtype=float)
    q = np.where(q[..., :1] < 0, -q, q)
    vector_norm = np.linalg.norm(q[..., 1:], axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(vector_norm, q[..., :1])
    # angle / |v| → 2 / w as |v| → 0 (q unit, so w → 1).
    scale = np.where(vector_norm < 1e-12, 2.0 / np.maximum(q[..., :1], 1e-300),
                     angle / np.where(vector_norm < 1e-12, 1.0, vector_norm))
    return scale * q[..., 1:]


def attitude_error_vector_rad(q_true: np.ndarray, q_est: np.ndarray) -> np.ndarray:
    r"""The body-frame small-angle error :math:`\delta\theta` of an estimate, radians.

    The rotation vector of :math:`\hat q^{-1} \otimes q`, so that
    :math:`q = \hat q \otimes \delta q(\delta\theta)` (the error state of the
    multiplicative EKF). Its norm is :func:`attitude_error_rad`; its components
    are the roll, pitch and yaw errors about the body axes.
    """
    return rotvec_from_quat(relative_rotation(q_est, q_true))


#: The generalised Rodrigues parameters of Crassidis & Markley (2003):
#: a = 1, f = 2 (a + 1) = 4 make |p| = 4 tan(θ/4), the rotation angle θ to first order.
GRP_A = 1.0
GRP_F = 4.0


def grp_from_quat(dq: np.ndarray, a: float = GRP_A, f: float = GRP_F) -> np.ndarray:
    r"""Generalised Rodrigues parameters :math:`p = f\,\varrho / (a + w)` of a unit
    quaternion ``[w, ϱ]`` (Crassidis & Markley 2003, eq. 31), sign-aligned to
    ``w >= 0`` first (``q`` and ``-q`` are one rotation). ``(..., 4)`` → ``(..., 3)``."""
    dq = np.asarray(dq, dtype=float)
    dq = np.where(dq[..., :1] < 0, -dq, dq)
    return f * dq[..., 1:] / (a + dq[..., :1])


def quat_from_grp(p: np.ndarray, a: float = GRP_A, f: float = GRP_F) -> np.ndarray:
    r"""The unit quaternion of generalised Rodrigues parameters (Crassidis &
    Markley 2003, eq. 32):

    .. math:: w = \frac{-a|p|^2 + f\sqrt{f^2 + (1 - a^2)|p|^2}}{f^2 + |p|^2},
              \qquad \varrho = \frac{a + w}{f}\,p.
    """
    p = np.asarray(p, dtype=float)
    if p.shape == (3,):         # one point: floats, the same numbers, five times faster
        x, y, z = p.tolist()
        n2 = x * x + y * y + z * z
        w = (-a * n2 + f * math.sqrt(f * f + (1.0 - a * a) * n2)) / (f * f + n2)
        scale = (a + w) / f
        return np.array([w, scale * x, scale * y, scale * z])
    norm2 = np.sum(p * p, axis=-1, keepdims=True)
    w = (-a * norm2 + f * np.sqrt(f * f + (1.0 - a * a) * norm2)) / (f * f + norm2)
    return np.concatenate([w, (a + w) / f * p], axis=-1)


def to_body_frame(q: np.ndarray, vector: np.ndarray) -> np.ndarray:
    r"""A reference-frame vector in the body frame of the unit quaternion ``q``:
    :math:`R(q)^\mathsf{T} v = v - 2w\,(u \times v) + 2\,u \times (u \times v)`
    with :math:`q = (w, u)` (one vector, ``(3,)``; for stacks use
    :func:`rotation_matrix`). Written out in floats: the filters call it for
    every vector reading and sigma point, where ``np.cross`` costs 40 µs."""
    w, x, y, z = q.tolist()
    a, b, c = vector.tolist()
    tx, ty, tz = y * c - z * b, z * a - x * c, x * b - y * a
    return np.array([a - 2.0 * w * tx + 2.0 * (y * tz - z * ty),
                     b - 2.0 * w * ty + 2.0 * (z * tx - x * tz),
                     c - 2.0 * w * tz + 2.0 * (x * ty - y * tx)])
