r"""Gravity from the accelerometer of an IMU that moves: the specific force
low-passed in an almost-inertial frame.

An accelerometer reads the specific force :math:`f = A^\mathsf{T}(g_\uparrow
+ a)`, gravity's reaction and the body's linear acceleration :math:`a`. Read
as gravity's direction sample by sample, it tilts the estimate by
:math:`|a| / g` whenever the body accelerates; rejected whenever it
accelerates (a χ² gate), it leaves the filter without gravity for most of a
movement. Laidig & Seel (2023, §3.1, "VQF", eq. 6–9) turn the readings into
the frame :math:`\mathcal I` that the gyro's strapdown integration holds
still, :math:`f_{\mathcal I} = R(q_{\mathcal I}) f`, and low-pass them
there (:mod:`estimators.imu.lowpass`, :math:`\tau` = 3 s): gravity is
constant in that frame, while the linear acceleration, the derivative of a
bounded velocity, averages out (its mean over :math:`\tau` is
:math:`\Delta v / \tau`). Turned back into the body frame with the same
strapdown, :math:`z = R(q_{\mathcal I})^\mathsf{T} \bar f_{\mathcal I} /
\lVert\cdot\rVert` is gravity's direction (up) as a measurement for the
filter, the vector reading of :math:`e_z` with

.. math::

    h(q) = A(\hat q)^\mathsf{T} e_z, \qquad
    H = \bigl[\,[A(\hat q)^\mathsf{T} e_z \times]\ \ 0\,\bigr], \qquad
    R = \frac{S_g}{T} I_3,

where :math:`T` is the time between the readings and :math:`S_g` (rad²·s)
the density of the direction's error: the low-passed direction errs slowly
(it is the residual linear acceleration), so its error is given per unit of
time, not per reading, and the filter's behaviour does not depend on the
accelerometer's rate. While the filter still averages its first samples
(for :math:`\tau`), the strapdown frame is the filter's start, and the
reading is that running mean: over :math:`t < \tau` the linear
acceleration's mean is :math:`\Delta v / t`, not :math:`\Delta v / \tau`,
so its variance is :math:`(\tau / t)^2` times the density's
(:func:`reading_variance`). A body that starts at rest loses nothing
measurable by it (BROAD's whole trials score the same to 0.01°); one that
starts in motion is neither tilted by its first accelerations nor taught a
false bias by their mean's drift (``tests/test_imu_models.py``: a bias
error of 15 °/s without it, 2 °/s with it). On BROAD's trials cut at their
first movement, a hand's gentle accelerations, it changes little (the
MEKF 2.93° → 2.94°).

The strapdown is the filter's own propagation, with its bias-corrected rate
(:meth:`estimators.imu.ImuModels.propagate`); it is never corrected, so the
low-pass filter's inputs stay in one frame.

**The bias in the reading.** That frame drifts with the error of the bias
estimate it was built with, :math:`\Delta\beta = \beta - \hat\beta`,
and the low-passed vector lags the drift. With :math:`R_{\mathcal I}(t)`
the strapdown's rotation (body to :math:`\mathcal I`), its error
:math:`\varepsilon_{\mathcal I}` grows as :math:`\dot\varepsilon_{\mathcal I}
= R_{\mathcal I}\Delta\beta`; the filter's output is
:math:`\bar f_{\mathcal I} \approx g + \mathrm{LP}(\varepsilon_{\mathcal I})
\times g`, turned back with today's :math:`R_{\mathcal I}`, so

.. math::

    z \approx h(q) + R_{\mathcal I}^\mathsf{T} [\hat g_{\mathcal I}\times]\, K\,
    \Delta\beta, \qquad K = J - \mathrm{LP}(J), \quad
    J(t) = \int_0^t R_{\mathcal I}\,\mathrm ds,

with :math:`\hat g_{\mathcal I}` the low-passed direction in
:math:`\mathcal I` and LP the same filter (:func:`drift_jacobian`). For a
body that holds still, :math:`K = \tau R_{\mathcal I}` (the filter's delay
times the rotation), and the bias columns of :math:`H` are :math:`\tau\,
[h\times]`; for one that turns, the rotation averages :math:`K` down. (VQF
models the same lag by low-passing its rotation matrix and bias estimate,
Laidig & Seel 2023, §3.2.) Without it, a filter in motion from its first
sample learns its bias from its own strapdown's drift, and runs away.

Every function works on plain arrays, so
that the engine compiles the same arithmetic.
"""
from __future__ import annotations

import math

from estimators.imu import lowpass

#: The low-pass filter's time constant, s: VQF's ``tauAcc``, taken as published.
LOWPASS_TIME_CONSTANT_S = 3.0


def rotate(q, v, out) -> None:
    """``out = A(q) v``: ``v`` from the body to the reference frame (``q``
    scalar-first, body → reference)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    out[0] = (1 - 2 * (y * y + z * z)) * v[0] + 2 * (x * y - w * z) * v[1] \
        + 2 * (x * z + w * y) * v[2]
    out[1] = 2 * (x * y + w * z) * v[0] + (1 - 2 * (x * x + z * z)) * v[1] \
        + 2 * (y * z - w * x) * v[2]
    out[2] = 2 * (x * z - w * y) * v[0] + 2 * (y * z + w * x) * v[1] \
        + (1 - 2 * (x * x + y * y)) * v[2]


def rotate_back(q, v, out) -> None:
    """``out = A(q)ᵀ v``: ``v`` from the reference to the body frame."""
    out[0], out[1], out[2] = rotated_back(q, v[0], v[1], v[2])


def rotated_back(q, a: float, b: float, c: float) -> tuple:
    """``A(q)ᵀ (a, b, c)`` as a tuple (:func:`rotate_back` with no array)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    return ((1 - 2 * (y * y + z * z)) * a + 2 * (x * y + w * z) * b + 2 * (x * z - w * y) * c,
            2 * (x * y - w * z) * a + (1 - 2 * (x * x + z * z)) * b + 2 * (y * z + w * x) * c,
            2 * (x * z + w * y) * a + 2 * (y * z - w * x) * b + (1 - 2 * (x * x + y * y)) * c)


def strapdown_step(q, rotation, out) -> None:
    """``out = q ⊗ exp(rotation / 2)``, normalised: the strapdown by a
    rotation vector (rad)."""
    angle = math.sqrt(rotation[0] ** 2 + rotation[1] ** 2 + rotation[2] ** 2)
    if angle < 1e-12:
        c, s = 1.0, 0.5
    else:
        c, s = math.cos(0.5 * angle), math.sin(0.5 * angle) / angle
    d0, d1, d2, d3 = c, s * rotation[0], s * rotation[1], s * rotation[2]
    q0, q1, q2, q3 = q[0], q[1], q[2], q[3]
    w = q0 * d0 - q1 * d1 - q2 * d2 - q3 * d3
    x = q0 * d1 + q1 * d0 + q2 * d3 - q3 * d2
    y = q0 * d2 - q1 * d3 + q2 * d0 + q3 * d1
    z = q0 * d3 + q1 * d2 - q2 * d1 + q3 * d0
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    out[0], out[1], out[2], out[3] = w / norm, x / norm, y / norm, z / norm


def integrate_rotation(q, dt: float, integral) -> None:
    """``integral += R(q) dt`` (row-major 3x3 in ``(9,)``): :math:`J` of the
    module docstring, one strapdown step."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    integral[0] += (1 - 2 * (y * y + z * z)) * dt
    integral[1] += 2 * (x * y - w * z) * dt
    integral[2] += 2 * (x * z + w * y) * dt
    integral[3] += 2 * (x * y + w * z) * dt
    integral[4] += (1 - 2 * (x * x + z * z)) * dt
    integral[5] += 2 * (y * z - w * x) * dt
    integral[6] += 2 * (x * z - w * y) * dt
    integral[7] += 2 * (y * z + w * x) * dt
    integral[8] += (1 - 2 * (x * x + y * y)) * dt


def drift_jacobian(q_strapdown, gravity_lp, integral, coeffs, tau_s: float, dt: float,
                   state, scratch, out) -> None:
    r"""The bias columns of the reading's :math:`H` (module docstring) into
    ``out`` (3, 3): :math:`R_{\mathcal I}^\mathsf{T}[\hat g_{\mathcal I}\times]
    (J - \mathrm{LP}(J))`, ``gravity_lp`` the low-passed vector in the strapdown
    frame, ``state`` the LP filter's of :math:`J` (4, 9), ``scratch`` (9,)."""
    lowpass.step(integral, coeffs, tau_s, dt, state, scratch)
    norm = math.sqrt(gravity_lp[0] ** 2 + gravity_lp[1] ** 2 + gravity_lp[2] ** 2)
    g0, g1, g2 = gravity_lp[0] / norm, gravity_lp[1] / norm, gravity_lp[2] / norm
    for j in range(3):
        k0 = integral[j] - scratch[j]
        k1 = integral[3 + j] - scratch[3 + j]
        k2 = integral[6 + j] - scratch[6 + j]
        out[0, j], out[1, j], out[2, j] = rotated_back(
            q_strapdown, g1 * k2 - g2 * k1, g2 * k0 - g0 * k2, g0 * k1 - g1 * k0)


def reading_variance(density: float, interval: float, filter_state, tau_s: float) -> float:
    """The variance per axis of the direction :func:`gravity_direction` has
    just given, ``density`` (rad²·s) over the ``interval`` (s) since the last
    reading, times :math:`(\tau / t)^2` while the low-pass filter
    (``filter_state``, :mod:`estimators.imu.lowpass`) still averages its
    first ``t < tau_s`` seconds (module docstring)."""
    variance = density / interval
    averaged = lowpass.samples_averaged(filter_state)
    if averaged >= 0.0:
        ratio = tau_s / (averaged * interval)
        variance *= ratio * ratio
    return variance


def gravity_direction(q_strapdown, specific_force, coeffs, tau_s: float, dt: float,
                      state, scratch, out) -> None:
    """Gravity's direction (up) in the body frame, into ``out``, from one
    accelerometer reading: low-passed in the strapdown frame and turned back
    (module docstring); ``state`` the low-pass filter's, ``scratch`` (2, 3)."""
    rotate(q_strapdown, specific_force, scratch[0])
    lowpass.step(scratch[0], coeffs, tau_s, dt, state, scratch[1])
    rotate_back(q_strapdown, scratch[1], out)
    norm = math.sqrt(out[0] * out[0] + out[1] * out[1] + out[2] * out[2])
    out[0], out[1], out[2] = out[0] / norm, out[1] / norm, out[2] / norm
