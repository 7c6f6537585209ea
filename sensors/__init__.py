"""What the spacecraft measures: a rate gyro and a star tracker.

Noise is specified as Simulink's band-limited white noise "power" ``p``:
sampled every ``Ts`` seconds it is a zero-mean Gaussian sequence with
variance ``p / Ts`` per component (see :mod:`sensors.noise` for conversions
to per-sample standard deviation and angle random walk).
"""
from sensors.gyro import Gyro
from sensors.noise import (
    arw_deg_per_rthr_to_noise_power,
    noise_power_to_arw_deg_per_rthr,
    noise_power_to_std,
    std_to_noise_power,
)
from sensors.star_tracker import StarTracker, StarTrackerReadings

__all__ = [
    "Gyro",
    "StarTracker",
    "StarTrackerReadings",
    "arw_deg_per_rthr_to_noise_power",
    "noise_power_to_arw_deg_per_rthr",
    "noise_power_to_std",
    "std_to_noise_power",
]
