r"""Rest detection, and the gyro's bias measured at rest.

At rest the gyro reads its bias. Laidig & Seel (2023, §3.4, "VQF") call a
body at rest when, for at least :data:`MIN_DURATION_S`, the gyro and the
accelerometer stay close to their own low-passed values (time constant
:data:`FILTER_TIME_CONSTANT_S`):

.. math::

    \lVert \omega - \bar\omega \rVert < 2\ °/\mathrm s, \qquad
    \lVert f - \bar f \rVert < 0.5\ \mathrm{m/s^2}, \qquad
    \max_i |\bar\omega_i| \le 2\ °/\mathrm s

(the last: a gyro turning steadily faster than any bias is not at rest).
The thresholds are VQF's published defaults, taken as published.

At rest the filter applies a zero-rate update of its bias (Markley &
Crassidis 2014, §6.2 for the MEKF's measurement updates): the low-passed rate
measures the bias, :math:`y = \bar\omega - \hat\beta`, :math:`H = [0\ \ I_3]`,
with :math:`R = S_r / T` for readings :math:`T` seconds apart: the
low-passed rate errs slowly, so its error is a density :math:`S_r`
(rad²/s²·s) and the update weighs the same whatever the gyro's rate. The
low-passed rate, not the reading, because the detection declares rest
only after some time, and the first readings of a movement would read as bias.

Every function works on plain arrays: the engine compiles the same
arithmetic. A detector's state is :func:`new_state`.
"""
from __future__ import annotations

import math

import numpy as np

from estimators.imu import lowpass

#: VQF's rest thresholds (``restThGyr``, ``restThAcc``, ``biasClip``,
#: ``restMinT``, ``restFilterTau``): rad/s, m/s², rad/s, s, s.
GYRO_THRESHOLD_RADPS = math.radians(2.0)
ACC_THRESHOLD_MPS2 = 0.5
RATE_LIMIT_RADPS = math.radians(2.0)
MIN_DURATION_S = 1.5
FILTER_TIME_CONSTANT_S = 0.5

#: A detector's state, (9, 3): rows 0–3 the gyro's low-pass filter, 4–7 the
#: accelerometer's, and row 8 [time at rest (s), at rest (1.0) or not (0.0)].
CLOCK = 8


def new_state() -> np.ndarray:
    """A detector's state, nothing seen yet."""
    return np.zeros((9, 3))


def gyro_step(rate, coeffs, dt: float, state, rate_lp) -> None:
    """One gyro reading: its low-passed value into ``rate_lp``; a reading far
    from it, or a steady rate beyond a bias, ends any rest."""
    lowpass.step(rate, coeffs, FILTER_TIME_CONSTANT_S, dt, state[0:4], rate_lp)
    d0, d1, d2 = rate[0] - rate_lp[0], rate[1] - rate_lp[1], rate[2] - rate_lp[2]
    steady = max(abs(rate_lp[0]), abs(rate_lp[1]), abs(rate_lp[2]))
    if d0 * d0 + d1 * d1 + d2 * d2 >= GYRO_THRESHOLD_RADPS ** 2 or steady > RATE_LIMIT_RADPS:
        state[CLOCK, 0] = 0.0
        state[CLOCK, 1] = 0.0


def acc_step(specific_force, coeffs, dt: float, state, scratch) -> bool:
    """One accelerometer reading (``dt`` s after the last): whether the body
    is at rest now (module docstring); ``scratch`` (3,)."""
    lowpass.step(specific_force, coeffs, FILTER_TIME_CONSTANT_S, dt, state[4:8], scratch)
    d0 = specific_force[0] - scratch[0]
    d1 = specific_force[1] - scratch[1]
    d2 = specific_force[2] - scratch[2]
    if d0 * d0 + d1 * d1 + d2 * d2 >= ACC_THRESHOLD_MPS2 ** 2:
        state[CLOCK, 0] = 0.0
        state[CLOCK, 1] = 0.0
    else:
        state[CLOCK, 0] += dt
        if state[CLOCK, 0] >= MIN_DURATION_S:
            state[CLOCK, 1] = 1.0
    return state[CLOCK, 1] > 0.0
