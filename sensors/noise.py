r"""Unit helpers for white noise given as a Simulink "noise power".

Simulink's Band-Limited White Noise block with power ``p`` sampled every
``Ts`` seconds emits independent Gaussian samples of variance ``p / Ts``.
For a rate gyro (``p`` in rad²/s), integrating that noise over a time ``t``
gives an angle error of variance ``p t`` per axis: an angle random walk (ARW)
of ``√p`` rad/√s, which datasheets quote in deg/√h:

.. math:: \sigma = \sqrt{p / T_s}, \qquad
          \text{ARW} = \sqrt{p}\;\frac{180}{\pi}\;60\ \ \text{deg}/\sqrt{\text{h}}

(``60`` because ``√h = 60 √s``). Reference: IEEE Std 952-1997, Annex C.
"""
from __future__ import annotations

import math

# 1/√s expressed per √h: √(3600 s/h) = 60.
_RT_SECONDS_PER_RT_HOUR = 60.0
_DEG_PER_RAD = 180.0 / math.pi


def noise_power_to_std(noise_power: float, sample_time_s: float) -> float:
    """Per-sample standard deviation ``√(p / Ts)`` of white noise of power ``p``.

    Example: the workshop gyro, power 1e-5 rad²/s sampled at 100 Hz, has a
    standard deviation of about 0.0316 rad/s per axis.

    >>> round(noise_power_to_std(1e-5, 0.01), 6)
    0.031623
    """
    return math.sqrt(noise_power / sample_time_s)


def std_to_noise_power(std: float, sample_time_s: float) -> float:
    """Noise power ``σ² Ts`` that gives per-sample standard deviation ``σ``.

    Example: a star tracker with 0.01 per quaternion component at 100 Hz is
    the workshop's power 1e-6.

    >>> f"{std_to_noise_power(0.01, 0.01):.3g}"
    '1e-06'
    """
    return std * std * sample_time_s


def noise_power_to_arw_deg_per_rthr(noise_power: float) -> float:
    """Angle random walk in deg/√h of a rate gyro with noise power ``p`` (rad²/s).

    Example: the workshop gyro (1e-5) is a poor one, about 10.9 deg/√h; a
    tactical-grade gyro is nearer 0.1 deg/√h.

    >>> round(noise_power_to_arw_deg_per_rthr(1e-5), 3)
    10.871
    """
    return math.sqrt(noise_power) * _DEG_PER_RAD * _RT_SECONDS_PER_RT_HOUR


def arw_deg_per_rthr_to_noise_power(arw_deg_per_rthr: float) -> float:
    """Noise power (rad²/s) of a rate gyro whose datasheet ARW is given in deg/√h.

    Example: a 0.1 deg/√h gyro has power of about 8.5e-10 rad²/s.

    >>> f"{arw_deg_per_rthr_to_noise_power(0.1):.3g}"
    '8.46e-10'
    """
    return (arw_deg_per_rthr / (_DEG_PER_RAD * _RT_SECONDS_PER_RT_HOUR)) ** 2
