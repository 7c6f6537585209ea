r"""The low-pass filter of the IMU models: a second-order Butterworth filter,
started from the mean of its first samples.

Laidig & Seel, "VQF: Highly accurate IMU orientation estimation with bias
estimation and magnetic disturbance rejection", *Information Fusion* 91,
2023, §3.1 (and their ``filterCoeffs``/``filterVec``): the filter is set by
the time constant :math:`\tau` of the non-oscillating part of its step
response, cutoff :math:`f_c = \sqrt 2 / (2\pi\tau)`; its coefficients by the
bilinear transform,

.. math::

    C = \tan(\pi f_c T_s), \quad D = C^2 + \sqrt 2\, C + 1, \quad
    b = \tfrac{C^2}{D}\,[1,\ 2,\ 1], \quad
    a = \bigl[\tfrac{2 (C^2 - 1)}{D},\ \tfrac{1 - \sqrt 2\, C + C^2}{D}\bigr],

in direct form II transposed (scipy's ``lfilter`` with ``a₀ = 1``). So that
the output does not depend on a single first sample, the filter outputs the
running mean of its inputs for the first :math:`\tau` seconds, and then
starts from that mean as a steady state (``lfilter_zi``'s state). Below
:math:`\tau < T_s / 2` the filter passes its input through.

Every function here works on plain arrays and floats, so that the engine
compiles the very same functions (:mod:`benchmarks.engine.kernels.imu`).
The state of a filter of ``n`` channels is a ``(4, n)`` array:
:func:`new_state`.
"""
from __future__ import annotations

import math

import numpy as np


def coefficients(tau_s: float, dt: float) -> np.ndarray:
    """``[b0, b1, b2, a1, a2]`` of the filter of time constant ``tau_s`` at
    sample time ``dt`` (module docstring)."""
    if tau_s < dt / 2:
        return np.array([1.0, 0.0, 0.0, 0.0, 0.0])
    fc = math.sqrt(2.0) / (2.0 * math.pi * tau_s)
    c = math.tan(math.pi * fc * dt)
    d = c * c + math.sqrt(2.0) * c + 1.0
    b0 = c * c / d
    return np.array([b0, 2.0 * b0, b0, 2.0 * (c * c - 1.0) / d,
                     (1.0 - math.sqrt(2.0) * c + c * c) / d])


#: A reading more than this many times its sensor's last interval after
#: the last one comes after a gap (a logger's dropped packets, a sensor's
#: stall): :func:`reading_steps`.
READING_GAP_FACTOR = 3.0


def reading_steps(since: int, last: int) -> tuple:
    """``(steps, last)``: the steps a reading is filtered over, and the
    sensor's ``last`` interval after it (0: no reading yet; -1: one, no
    interval yet). The steps are those ``since`` the sensor's last reading
    (one at least), or after a gap, its last interval's. The filter's state
    holds its past at the last interval's coefficients; at a gap's, many
    times longer, the direct form's state no longer fits them and its
    output swings (a 1 s gap in a 100 Hz accelerometer halved gravity's
    low-passed norm, then turned it: the MEKF's inclination 1° → 22°): the
    reading after a gap is taken as the next one, which the strapdown frame
    it is filtered in keeps true (:mod:`estimators.imu.gravity`)."""
    since = max(since, 1)
    if last == 0:
        return since, -1
    steps = last if 0 < last and READING_GAP_FACTOR * last < since else since
    return steps, steps


def new_state(channels: int) -> np.ndarray:
    """A fresh filter's state: rows 0–1 the filter's, row 2 the running sum,
    ``[3, 0]`` the number of samples averaged so far (-1 once filtering)."""
    state = np.zeros((4, channels))
    return state


def samples_averaged(state: np.ndarray) -> float:
    """How many samples a filter still averaging has averaged (its output
    their mean); -1 once it filters."""
    return state[3, 0]


def step(x: np.ndarray, coeffs: np.ndarray, tau_s: float, dt: float, state: np.ndarray,
         out: np.ndarray) -> None:
    """Filter one sample ``x`` of every channel into ``out`` (module docstring)."""
    n = x.shape[0]
    if state[3, 0] >= 0.0:                 # still averaging
        count = state[3, 0] + 1.0
        state[3, 0] = count
        for i in range(n):
            state[2, i] += x[i]
            out[i] = state[2, i] / count
        if count * dt >= tau_s:            # the mean becomes the steady state
            for i in range(n):
                state[0, i] = out[i] * (1.0 - coeffs[0])
                state[1, i] = out[i] * (coeffs[2] - coeffs[4])
            state[3, 0] = -1.0
        return
    for i in range(n):
        y = coeffs[0] * x[i] + state[0, i]
        state[0, i] = coeffs[1] * x[i] - coeffs[3] * y + state[1, i]
        state[1, i] = coeffs[2] * x[i] - coeffs[4] * y
        out[i] = y
