"""An IMU in the hand of :mod:`dynamics.handheld`: a simulated recording.

The readings are what a MEMS IMU gives of that motion, in the units and
frames of a recorded trial (:class:`sensors.recording.Recording`), with the
truth as its reference attitude and no gap in it:

- the gyro: the body rate over the interval before each sample (an IMU
  reads its rate averaged since its last reading, as the filters take it,
  ``rate_interpolation = "end"``; the truth's rate is held over the
  interval after each sample, :mod:`dynamics.handheld`), through a matrix
  ``I + M`` (``M``'s diagonal the scale factors' errors, drawn uniformly
  within ``±gyro_scale_percent``; off it the axes' misalignments, within
  ``±gyro_misalignment_deg``), plus a constant bias drawn per axis
  uniformly within ``±gyro_bias_dps``, plus white noise of density
  ``gyro_noise_density`` (rad/√s): the errors a MEMS gyro keeps after a
  factory calibration, which no filter here models;
- the accelerometer: the specific force in the body frame (the linear
  acceleration minus gravity, so a device at rest reads +9.81 m/s² up),
  plus white noise of σ ``accelerometer_sigma_mps2``;
- the magnetometer: a uniform field of norm ``field_uT`` pointing north
  (+y) and down at ``dip_deg``, in the body frame, plus white noise of σ
  ``magnetometer_sigma_uT``.

The noise levels are those of a good MEMS IMU (BROAD's, Laidig et al. 2021:
a gyro of about 1e-4 rad/√s; an accelerometer's and a magnetometer's
readings scattering by a few hundredths of their units) and the field is
central Europe's (IGRF near Berlin: 49 µT at a dip of 66°).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dynamics.environment import STANDARD_GRAVITY_MPS2
from dynamics.handheld import HandheldMotion, simulate_handheld
from dynamics.quaternion import to_rotation
from dynamics.validation import InvalidParameterError, finite_number, standard_deviation
from sensors.recording import Recording

#: The readings' gravity, m/s²: the standard value (the filters take their own).
GRAVITY_MPS2 = STANDARD_GRAVITY_MPS2


@dataclass(frozen=True)
class HandheldImu:
    """The IMU's errors and the field it reads (module docstring)."""

    gyro_bias_dps: float = 0.5
    gyro_scale_percent: float = 0.5
    gyro_misalignment_deg: float = 0.3
    gyro_noise_density: float = 1.5e-4
    accelerometer_sigma_mps2: float = 0.03
    magnetometer_sigma_uT: float = 0.5
    field_uT: float = 49.0
    dip_deg: float = 66.0

    def __post_init__(self):
        for name in ("gyro_bias_dps", "gyro_scale_percent", "gyro_misalignment_deg",
                     "gyro_noise_density", "accelerometer_sigma_mps2", "magnetometer_sigma_uT"):
            standard_deviation(name, getattr(self, name))
        finite_number("field_uT", self.field_uT, strictly_positive=True)
        if abs(finite_number("dip_deg", self.dip_deg)) > 90.0:
            raise InvalidParameterError("dip_deg", self.dip_deg, "must be within ±90°")

    def gyro_errors(self, rng: np.random.Generator) -> np.ndarray:
        """``M``: the scale factors' errors on the diagonal, the axes'
        misalignments (small angles, rad) off it, drawn from ``rng``."""
        bounds = np.full((3, 3), np.radians(self.gyro_misalignment_deg))
        np.fill_diagonal(bounds, self.gyro_scale_percent / 100.0)
        return bounds * rng.uniform(-1.0, 1.0, (3, 3))

    def field_world(self) -> np.ndarray:
        """The field in the world frame (ENU), µT."""
        dip = np.radians(self.dip_deg)
        return self.field_uT * np.array([0.0, np.cos(dip), -np.sin(dip)])


def rate_before(omega_radps: np.ndarray) -> np.ndarray:
    """``(N, 3)``: at each sample the rate over the interval before it, from
    rates held over the interval after each sample (the truth's); the first
    sample, which has no interval before it, reads its own."""
    return np.concatenate([omega_radps[:1], omega_radps[:-1]])


def simulated_recording(seed: int, motion: HandheldMotion = HandheldMotion(),
                        imu: HandheldImu = HandheldImu()) -> Recording:
    """A recording of ``motion`` by ``imu``, drawn from seed ``seed`` (the
    motion first, then the gyro's bias and its matrix, then each channel's
    noise), named ``handheld-SEED``."""
    rng = np.random.default_rng(seed)
    truth = simulate_handheld(motion, rng)
    n, rate = len(truth.q_true), truth.rate_hz
    to_body = to_rotation(truth.q_true).inv()
    bias = np.radians(imu.gyro_bias_dps) * rng.uniform(-1.0, 1.0, 3)
    errors = imu.gyro_errors(rng)
    gyro = rate_before(truth.omega_radps) @ (np.eye(3) + errors).T + bias \
        + imu.gyro_noise_density * np.sqrt(rate) * rng.standard_normal((n, 3))
    force = to_body.apply(truth.acceleration_mps2 + [0.0, 0.0, GRAVITY_MPS2])
    field = to_body.apply(np.tile(imu.field_world(), (n, 1)))
    return Recording(
        name=f"handheld-{seed}", gyro_radps=gyro, reference_quat=truth.q_true,
        movement=truth.movement, rate_hz=rate,
        info=f"simulated: {motion}, {imu}, seed {seed}",
        accelerometer_mps2=force + imu.accelerometer_sigma_mps2 * rng.standard_normal((n, 3)),
        magnetometer_uT=field + imu.magnetometer_sigma_uT * rng.standard_normal((n, 3)))
