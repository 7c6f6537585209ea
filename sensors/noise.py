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

import numpy as np

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


# The datasheet units of the Farrenkopf gyro model (sensors.gyro): ARW σ_v in
# deg/√h, RRW σ_u in deg/h/√h, bias in deg/h.
_SECONDS_PER_HOUR = 3600.0


def arw_deg_per_rthr_to_rad_per_rts(arw_deg_per_rthr: float) -> float:
    """Angle random walk ``σ_v`` in rad/√s from a datasheet figure in deg/√h.

    Example: the gyro of Crassidis & Markley's (2003) simulations,
    ``σ_v = √10 × 1e-7`` rad/√s, is about 0.00109 deg/√h.

    >>> f"{arw_deg_per_rthr_to_rad_per_rts(0.0010871):.4g}"
    '3.162e-07'
    """
    return arw_deg_per_rthr / (_DEG_PER_RAD * _RT_SECONDS_PER_RT_HOUR)


def arw_rad_per_rts_to_deg_per_rthr(sigma_v: float) -> float:
    """Angle random walk in deg/√h of ``σ_v`` in rad/√s.

    >>> round(arw_rad_per_rts_to_deg_per_rthr(10 ** 0.5 * 1e-7), 7)
    0.0010871
    """
    return sigma_v * _DEG_PER_RAD * _RT_SECONDS_PER_RT_HOUR


def rrw_deg_per_hr_rthr_to_rad_per_s1p5(rrw_deg_per_hr_rthr: float) -> float:
    """Bias rate random walk ``σ_u`` in rad/s^{3/2} from a figure in deg/h/√h.

    Example: Crassidis & Markley's ``σ_u = √10 × 1e-10`` rad/s^{3/2} is about
    0.0039 deg/h/√h: deg → rad is π/180, 1/h → 1/s is 1/3600, 1/√h → 1/√s is 1/60.

    >>> f"{rrw_deg_per_hr_rthr_to_rad_per_s1p5(0.0039136):.4g}"
    '3.162e-10'
    """
    return rrw_deg_per_hr_rthr / (_DEG_PER_RAD * _SECONDS_PER_HOUR * _RT_SECONDS_PER_RT_HOUR)


def rrw_rad_per_s1p5_to_deg_per_hr_rthr(sigma_u: float) -> float:
    """Bias rate random walk in deg/h/√h of ``σ_u`` in rad/s^{3/2}.

    >>> round(rrw_rad_per_s1p5_to_deg_per_hr_rthr(10 ** 0.5 * 1e-10), 7)
    0.0039136
    """
    return sigma_u * _DEG_PER_RAD * _SECONDS_PER_HOUR * _RT_SECONDS_PER_RT_HOUR


def noise_density_deg_per_s_rthz_to_rad_per_rts(density_deg_per_s_rthz: float) -> float:
    """Angle random walk ``σ_v`` in rad/√s from a datasheet rate noise density
    in °/s/√Hz (1/√Hz = √s, so only the degrees convert).

    Example: a MEMS gyro of 0.004 °/s/√Hz has σ_v ≈ 7e-5 rad/√s, an ARW of
    0.24 °/√h (×60).

    >>> f"{noise_density_deg_per_s_rthz_to_rad_per_rts(0.004):.4g}"
    '6.981e-05'
    >>> round(arw_rad_per_rts_to_deg_per_rthr(noise_density_deg_per_s_rthz_to_rad_per_rts(0.004)), 3)
    0.24
    """
    return density_deg_per_s_rthz / _DEG_PER_RAD


def deg_per_hr_to_radps(rate_deg_per_hr: float) -> float:
    """A rate (e.g. a gyro bias) in deg/h as rad/s.

    >>> f"{deg_per_hr_to_radps(0.1):.4g}"
    '4.848e-07'
    """
    return rate_deg_per_hr / (_DEG_PER_RAD * _SECONDS_PER_HOUR)


def bias_instability_deg_per_hr_to_radps(instability_deg_per_hr: float) -> float:
    """The Gauss–Markov bias's ``σ_b`` in rad/s from a datasheet bias
    instability in °/h, taken as the process's standard deviation (the usual
    reading of a datasheet; the Allan deviation of such a process peaks near
    0.62 σ_b, so a figure read off an Allan plot's floor is the smaller one).

    Example: a 3 °/h MEMS gyro has σ_b ≈ 1.45e-5 rad/s.

    >>> f"{bias_instability_deg_per_hr_to_radps(3.0):.4g}"
    '1.454e-05'
    """
    return deg_per_hr_to_radps(instability_deg_per_hr)


def radps_to_deg_per_hr(rate_radps: float) -> float:
    """A rate in rad/s as deg/h.

    >>> round(radps_to_deg_per_hr(4.84813681109536e-07), 6)
    0.1
    """
    return rate_radps * _DEG_PER_RAD * _SECONDS_PER_HOUR


def allan_deviation(rate_samples: np.ndarray, dt: float, cluster_sizes) -> np.ndarray:
    r"""Overlapping Allan deviation of a rate record, per axis.

    For a cluster time :math:`\tau = m\,\Delta t` and the integrated angle
    :math:`\theta_k = \Delta t \sum_{j<k} \tilde\omega_j`,

    .. math:: \sigma^2(\tau) = \frac{1}{2\tau^2 (M - 2m)}
              \sum_{k=0}^{M-2m-1} (\theta_{k+2m} - 2\theta_{k+m} + \theta_k)^2

    (IEEE Std 952-1997, Annex C; :math:`M` = samples + 1). For the Farrenkopf
    gyro, :math:`\sigma^2(\tau) = \sigma_v^2/\tau + \sigma_u^2 \tau/3`: slope
    −½ on a log–log plot where the ARW dominates, +½ where the RRW does.

    Parameters
    ----------
    rate_samples : (N,) or (N, axes) array, rad/s
    dt : float, seconds
    cluster_sizes : iterable of int m, with 2m < N

    Returns
    -------
    (len(cluster_sizes),) or (len(cluster_sizes), axes) array, rad/s
    """
    samples = np.asarray(rate_samples, dtype=float)
    theta = np.concatenate([np.zeros((1,) + samples.shape[1:]), np.cumsum(samples, axis=0) * dt])
    result = []
    for m in cluster_sizes:
        m = int(m)
        if m < 1 or 2 * m >= len(theta):
            raise ValueError(f"cluster size m = {m}: must satisfy 1 <= m and 2m < {len(theta)}")
        second_difference = theta[2 * m:] - 2.0 * theta[m:-m] + theta[:-2 * m]
        tau = m * dt
        result.append(np.sqrt(np.mean(second_difference ** 2, axis=0) / (2.0 * tau * tau)))
    return np.array(result)
