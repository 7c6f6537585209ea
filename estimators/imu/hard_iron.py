r"""The magnetometer's hard iron, fitted online from its readings alone.

A magnet or magnetised steel fixed to the device adds a constant field in
the body frame, the hard iron :math:`h`: the magnetometer reads
:math:`m = B + h + v`, :math:`B` the Earth's field turned into the body
frame (:mod:`sensors.magnetometer_calibration`, without its soft iron).
The heading model (:mod:`estimators.imu.heading`) rejects such a field —
it turns with the body in the strapdown frame — and so holds no heading
while the magnet is on; VQF takes it for a disturbance too (Laidig & Seel
2023, §3.3). But where the field is one field, :math:`|m - h| = |B|` however
the body turns: the readings lie on a sphere about :math:`h`, and the
sphere's centre is the hard iron, found with no attitude and no reference
(the attitude-independent calibration, Alonso & Shuster, "Complete linear
attitude-independent magnetometer calibration", *J. Astronaut. Sci.* 50
(4), 2002, here with the soft iron left out).

**The fit.** With :math:`y = |m|^2`, the sphere is linear in its unknowns:
:math:`y = 2\, m^\mathsf{T} h + c`, :math:`c = |B|^2 - |h|^2`. Least
squares with an intercept gives, from the readings' means and covariances,

.. math::

    h = \tfrac12\, C_{mm}^{-1} C_{my}, \qquad
    c = \bar y - 2\, \bar m^\mathsf{T} h, \qquad |B| = \sqrt{c + |h|^2},

and the residual variance :math:`C_{yy} - 2 h^\mathsf{T} C_{my}`, whose
root over :math:`2|B|` is the RMS of :math:`|m - h| - |B|` to first order.
The means are exponentially weighted, time constant
:data:`TIME_CONSTANT_S` (the readings' sums decay by
:math:`e^{-T/\tau}` for readings :math:`T` apart): the fit follows a magnet
put on or taken off within seconds, where a batch fit
(:func:`sensors.magnetometer_calibration.fit_ellipsoid`) would average the
recording's parts with and without it.

**When it is believed.** A fit is taken only when the readings determine
it: at least :data:`MIN_READINGS` readings since it began (however slow
the magnetometer: the tests below judge what its memory holds), their residual
within :data:`MAX_RESIDUAL` of the field (else the field was not one
field: a magnet that moved relative to the device, a room's steel passed
by), and their spread along the weakest direction,
:math:`s = \sqrt{\lambda_{\min}(C_{mm})}`, at least :data:`MIN_SPREAD` of
the field (a turn about one axis reads a ring, which leaves the centre's
component along the axis to the noise). The hard iron it finds is applied
only where it exceeds the error that the residual alone could put on it
along the weakest direction, :math:`|h| > \rho\, |B| / s` with
:math:`\rho` the residual's RMS (the centre's standard error along that
direction were the residual one systematic error, not averaged down by
the number of readings: the room's field and the soft iron err
systematically); below
it the fit says there is no hard iron worth removing, and none is. Between
fits that are believed, the last is held. Where the residual has stayed
beyond its bound for :data:`RESTART_S`, the fit forgets its readings and
begins anew: the readings of a magnet being put on, far off any sphere,
would otherwise hold every fit off long after the magnet sits still.
Whenever the readings read as if the magnet were gone — their norm less
the hard iron off the field's, their own norm closer to it — for
:data:`MIN_GONE_S`, the hard iron is dropped and the fit forgets the
readings that held it: a magnet taken off before the body comes to rest,
where no new fit can be made, is dropped all the same, and one taken off
in motion does not wait for its readings to leave the fit's memory.
Meanwhile the heading model's own tests reject the readings an old hard
iron spoils.

A fit's state is :func:`new_state`; every function works on plain arrays
and floats, so that the engine compiles the very same ones
(:mod:`benchmarks.engine.kernels.imu`).
"""
from __future__ import annotations

import math

import numpy as np

#: The fit's memory, s: the time a first field takes to be confirmed
#: (:data:`estimators.imu.heading.FIRST_FIELD_S`, VQF's ``magNewFirstTime``),
#: so that a magnet put on or taken off is followed as fast as the heading
#: model takes a new field; a hand-held turn covers the directions in a
#: few seconds. Measured before the rule of MIN_GONE_S, BROAD's 30 trials
#: (the MEKF) score 1.93°, 2.08° and 2.17° whole, 2.95°, 2.99° and 3.01°
#: cut at their first movement, with 5, 10 and 20 s: the shortest is also
#: the best of the three tried.
TIME_CONSTANT_S = 5.0
#: The least spread of the readings along their weakest direction, over the
#: field's norm, of a fit that is believed (module docstring): a ring of
#: readings 0.1 of the field thick leaves the centre's component along its
#: axis to within ten times the residual.
MIN_SPREAD = 0.1
#: The largest RMS of the readings' distance from the sphere, over its
#: radius, of a fit that is believed (the batch fit's bound,
#: :data:`sensors.magnetometer_calibration.MAX_RESIDUAL`: undisturbed
#: hand-held recordings read 1.7 to 3.2 %).
MAX_RESIDUAL = 0.05
#: The fewest readings since the fit began of a fit that is believed.
MIN_READINGS = 50
#: How long the readings must read as if the magnet were gone before its
#: hard iron is dropped without a new fit (s; the heading model's hold,
#: :data:`estimators.imu.heading.MIN_UNDISTURBED_S`, VQF's
#: ``magMinUndisturbedTime``).
MIN_GONE_S = 0.5

#: How long the readings may stay off any one sphere (their residual beyond
#: :data:`MAX_RESIDUAL`) before the fit forgets them and begins anew, s:
#: the fit's memory. A magnet being put on reads far off every sphere for a
#: second or two, and those readings, however faded, held the residual
#: above its bound for 20 s after the magnet sat still (BROAD's trial 33:
#: believed at 70 s, now at 49 s, the magnet on from 41 s); begun anew, the
#: fit is believed as soon as the readings since then spread. BROAD's 30
#: trials: the smoother 1.604° → 1.595° whole, 1.752° → 1.746° cut at their
#: first movement; the MEKF 1.899° → 1.903° whole, 2.893° cut unchanged.
RESTART_S = TIME_CONSTANT_S

#: Entries of a fit's state: the sum of the weights, the weighted sums of
#: m (3), of m mᵀ (xx, xy, xz, yy, yz, zz), of m y (3), of y and of y²
#: (y = |m|²), the hard iron applied (3), the radius of the fit that gave
#: it, how long the readings have read as if it were gone (s), the
#: readings since the fit began, and how long its residual has been beyond
#: its bound (s).
(WEIGHT, M, MM, MY, Y, YY, APPLIED, RADIUS, GONE_S, COUNT, OFF_S) = (
    0, 1, 4, 10, 13, 14, 15, 18, 19, 20, 21)
#: The length of a fit's state.
STATE_SIZE = 22


def new_state() -> np.ndarray:
    """A fit with no readings, and no hard iron applied."""
    return np.zeros(STATE_SIZE)


def step(field, dt: float, state, out) -> None:
    """One reading ``field`` (body frame), ``dt`` s after the last: into the
    fit's sums, the fit refreshed where it is believed, and the reading less
    the hard iron applied into ``out`` (module docstring). A reading that is
    not finite is passed on, less the hard iron, and not fitted."""
    y = field[0] * field[0] + field[1] * field[1] + field[2] * field[2]
    if math.isfinite(y):
        _take(field, y, dt, state)
    for i in range(3):
        out[i] = field[i] - state[APPLIED + i]


def _take(field, y: float, dt: float, state) -> None:
    """A finite reading into the fit's sums, the fit refreshed, and the test
    of a magnet gone."""
    decay = math.exp(-dt / TIME_CONSTANT_S)
    for i in range(APPLIED):
        state[i] *= decay
    state[WEIGHT] += 1.0
    state[COUNT] += 1.0
    k = MM
    for i in range(3):
        state[M + i] += field[i]
        state[MY + i] += field[i] * y
        for j in range(i, 3):
            state[k] += field[i] * field[j]
            k += 1
    state[Y] += y
    state[YY] += y * y
    if state[COUNT] >= MIN_READINGS and not _refit(state):
        state[OFF_S] += dt
        if state[OFF_S] >= RESTART_S:          # begun anew: the sums forgotten
            for i in range(APPLIED):
                state[i] = 0.0
            state[COUNT] = state[OFF_S] = 0.0
    else:
        state[OFF_S] = 0.0
    _gone_step(field, dt, state)


def _refit(state) -> bool:
    """The sphere fitted to the sums; where it is believed, its hard iron
    applied (or none). False where the readings lie off the sphere by more
    than :data:`MAX_RESIDUAL`, else True. (Scalars and tuples, not arrays:
    it runs at every reading, in the kernel too.)"""
    w = state[WEIGHT]
    m0, m1, m2, y_mean = state[M] / w, state[M + 1] / w, state[M + 2] / w, state[Y] / w
    c = (state[MM] / w - m0 * m0, state[MM + 1] / w - m0 * m1, state[MM + 2] / w - m0 * m2,
         state[MM + 3] / w - m1 * m1, state[MM + 4] / w - m1 * m2, state[MM + 5] / w - m2 * m2)
    cmy = (state[MY] / w - m0 * y_mean, state[MY + 1] / w - m1 * y_mean,
           state[MY + 2] / w - m2 * y_mean)
    det, x0, x1, x2 = _solve_symmetric(c, cmy)
    if not det > 0.0:                              # readings in a plane or fewer
        return True
    h0, h1, h2 = 0.5 * x0, 0.5 * x1, 0.5 * x2
    residual_variance = state[YY] / w - y_mean * y_mean - 2.0 * (h0 * cmy[0] + h1 * cmy[1]
                                                                 + h2 * cmy[2])
    squared_norm = h0 * h0 + h1 * h1 + h2 * h2
    radius_squared = y_mean - 2.0 * (m0 * h0 + m1 * h1 + m2 * h2) + squared_norm
    if radius_squared <= 0.0:
        return True
    radius = math.sqrt(radius_squared)
    residual = math.sqrt(max(residual_variance, 0.0)) / (2.0 * radius)   # RMS, the unit of m
    if residual > MAX_RESIDUAL * radius:
        return False
    spread = math.sqrt(max(smallest_eigenvalue(c), 0.0))
    if spread < MIN_SPREAD * radius:
        return True
    if not math.sqrt(squared_norm) * spread > residual * radius:
        h0 = h1 = h2 = 0.0                         # none worth removing
    state[APPLIED], state[APPLIED + 1], state[APPLIED + 2] = h0, h1, h2
    state[RADIUS] = radius
    return True


def _gone_step(field, dt: float, state) -> None:
    """The hard iron applied dropped, and the fit begun anew, once the
    readings have read for :data:`MIN_GONE_S` as if it were gone: their norm
    less the hard iron off the fit's radius (the field's) by more than
    :data:`MAX_RESIDUAL` of it, their own norm closer to it (module
    docstring)."""
    h0, h1, h2 = state[APPLIED], state[APPLIED + 1], state[APPLIED + 2]
    if h0 == 0.0 and h1 == 0.0 and h2 == 0.0:
        state[GONE_S] = 0.0
        return
    radius = state[RADIUS]
    plain = math.sqrt(field[0] * field[0] + field[1] * field[1] + field[2] * field[2])
    corrected = math.sqrt((field[0] - h0) ** 2 + (field[1] - h1) ** 2 + (field[2] - h2) ** 2)
    off = abs(corrected - radius)
    if abs(plain - radius) < off and off > MAX_RESIDUAL * radius:
        state[GONE_S] += dt
    else:
        state[GONE_S] = 0.0
    if state[GONE_S] >= MIN_GONE_S:
        for i in range(STATE_SIZE):
            state[i] = 0.0


def _solve_symmetric(c, v) -> tuple:
    """``(det C, C⁻¹ v)`` for the symmetric ``C`` of entries ``c`` (xx, xy,
    xz, yy, yz, zz), by its adjugate; the solution is meaningless unless
    ``det C > 0``."""
    a, b, d, e, f, g = c
    A, B, D = e * g - f * f, d * f - b * g, b * f - d * e
    det = a * A + b * B + d * D
    if not det > 0.0:
        return det, 0.0, 0.0, 0.0
    E, F, G = a * g - d * d, b * d - a * f, a * e - b * b
    return (det, (A * v[0] + B * v[1] + D * v[2]) / det, (B * v[0] + E * v[1] + F * v[2]) / det,
            (D * v[0] + F * v[1] + G * v[2]) / det)


def smallest_eigenvalue(c) -> float:
    """The smallest eigenvalue of the symmetric 3x3 matrix of entries ``c``
    (xx, xy, xz, yy, yz, zz), in closed form (Smith, "Eigenvalues of a
    symmetric 3 × 3 matrix", *Commun. ACM* 4 (4), 1961)."""
    q = (c[0] + c[3] + c[5]) / 3.0
    off = c[1] * c[1] + c[2] * c[2] + c[4] * c[4]
    p2 = (c[0] - q) ** 2 + (c[3] - q) ** 2 + (c[5] - q) ** 2 + 2.0 * off
    if p2 <= 0.0:
        return q
    p = math.sqrt(p2 / 6.0)
    b0, b3, b5 = (c[0] - q) / p, (c[3] - q) / p, (c[5] - q) / p
    b1, b2, b4 = c[1] / p, c[2] / p, c[4] / p
    half_det = 0.5 * (b0 * (b3 * b5 - b4 * b4) - b1 * (b1 * b5 - b4 * b2)
                      + b2 * (b1 * b4 - b3 * b2))
    phi = math.acos(max(-1.0, min(1.0, half_det))) / 3.0
    return q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)


def applied(state) -> np.ndarray:
    """The hard iron applied now (zeros: none)."""
    return state[APPLIED:APPLIED + 3].copy()
