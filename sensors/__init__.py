"""What the spacecraft measures: a rate gyro and a star tracker.

:class:`Gyro` is the standard gyro model (angle random walk, bias random
walk, scale factor and misalignment); the workshop's gyro is its special case
with no bias. :class:`StarTracker` is the workshop's (additive noise on the
quaternion); :class:`RotationStarTracker` a flight-like one (a small error
rotation in arcseconds, dropouts, sign conventions).

Noise is specified as Simulink's band-limited white noise "power" ``p``:
sampled every ``Ts`` seconds it is a zero-mean Gaussian sequence with
variance ``p / Ts`` per component (see :mod:`sensors.noise` for conversions
to per-sample standard deviation and angle random walk).
"""
from dynamics.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    "gyro": ("Gyro",),
    "noise": ("allan_deviation", "arw_deg_per_rthr_to_noise_power",
              "arw_deg_per_rthr_to_rad_per_rts", "arw_rad_per_rts_to_deg_per_rthr",
              "deg_per_hr_to_radps", "noise_power_to_arw_deg_per_rthr", "noise_power_to_std",
              "radps_to_deg_per_hr", "rrw_deg_per_hr_rthr_to_rad_per_s1p5",
              "rrw_rad_per_s1p5_to_deg_per_hr_rthr", "std_to_noise_power"),
    "star_tracker": ("ARCSEC_PER_RAD", "RotationStarTracker", "StarTracker",
                     "StarTrackerReadings"),
})
