"""Madgwick's and Mahony's filters in the engine, on recorded readings
(:mod:`benchmarks.engine.recorded`): the per-run classes' own step
functions (:func:`estimators.complementary.madgwick_step`,
:func:`~estimators.complementary.mahony_step`), compiled as they are, in a
loop over the samples. Why compiled: a step is some 150 flops, and the
per-run path spends a hundred times that in Python per sample.

Unlike the Monte Carlo kernels these take no :class:`~benchmarks.engine.
kernels.common.Block`: there is no truth to draw noise about, only the
recording's gyro, accelerometer and magnetometer; they return the NWU
states, which :mod:`benchmarks.engine.recorded` turns to ENU as the
per-run classes' ``attitude`` does.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from estimators.complementary import madgwick_step, mahony_step

#: The registry names these kernels twin.
NAMES = ("madgwick", "madgwick-broad", "mahony")

_madgwick = njit(cache=True, error_model="numpy")(madgwick_step)
_mahony = njit(cache=True, error_model="numpy")(mahony_step)


@njit(cache=True)
def _reading(channel, available, k):
    """Sample ``k`` of a ``(N, 3)`` channel as a tuple, or the per-run
    classes' absent reading (zeros) where it is not available."""
    if not available[k]:
        return 0.0, 0.0, 0.0
    return channel[k, 0], channel[k, 1], channel[k, 2]


@njit(cache=True, error_model="numpy")
def madgwick_run(q, gyro, acc, has_acc, mag, has_mag, beta, dt, halved_field, out):
    """Every sample through :func:`madgwick_step` from state ``q`` (NWU): the
    state after sample ``k`` into ``out[k]``."""
    for k in range(gyro.shape[0]):
        q = _madgwick(q, (gyro[k, 0], gyro[k, 1], gyro[k, 2]), _reading(acc, has_acc, k),
                      _reading(mag, has_mag, k), beta, dt, halved_field)
        out[k, 0], out[k, 1], out[k, 2], out[k, 3] = q


@njit(cache=True, error_model="numpy")
def mahony_run(q, integral, gyro, acc, has_acc, mag, has_mag, kp, ki, dt, out):
    """Every sample through :func:`mahony_step` from ``q`` (NWU) and its
    integral term: the state after sample ``k`` into ``out[k]``."""
    for k in range(gyro.shape[0]):
        q, integral = _mahony(q, integral, (gyro[k, 0], gyro[k, 1], gyro[k, 2]),
                              _reading(acc, has_acc, k), _reading(mag, has_mag, k), kp, ki,
                              dt)
        out[k, 0], out[k, 1], out[k, 2], out[k, 3] = q


def run(estimator, gyro: np.ndarray, acc: np.ndarray, has_acc: np.ndarray, mag: np.ndarray,
        has_mag: np.ndarray) -> np.ndarray:
    """``(N, 4)`` NWU states of ``estimator`` (a per-run :class:`~estimators.
    complementary.Madgwick`, ``MadgwickBROAD`` or ``Mahony``, its settings
    and its state read off it) after each sample."""
    out = np.empty((len(gyro), 4))
    q = tuple(float(x) for x in estimator.q_nwu)
    if not estimator.takes_next_rate and len(gyro):     # rate 0 left out, as the class does
        gyro = gyro.copy()
        gyro[0] = np.where(np.isfinite(gyro[0]), 0.0, gyro[0])    # one not finite still diverges
    if estimator.name == "mahony":
        mahony_run(q, tuple(float(x) for x in estimator.integral), gyro, acc, has_acc, mag,
                   has_mag, float(estimator.kp), float(estimator.ki), float(estimator.dt), out)
    else:
        madgwick_run(q, gyro, acc, has_acc, mag, has_mag, float(estimator.beta),
                     float(estimator.dt), bool(estimator.halved_field), out)
    return out
