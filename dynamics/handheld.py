"""A hand-held device's motion, as a truth to score IMU filters against.

BROAD's trials (Laidig et al. 2021) are a hand turning and carrying an IMU
between rests, scored against motion capture. A filter's score there mixes
what the filter models with what the room does: a field that is not uniform,
a reference whose north is the field where the trial rests. This motion is
that hand's in a world that is exactly what the filters assume, so that what
a filter loses (without its rest, say) is the filter's own.

The body rate and the linear acceleration are each white Gaussian noise
low-passed to a hand's bandwidth (second-order Butterworth, forward and
backward: zero phase), scaled to a given RMS per axis and tapered linearly
into and out of a rest at each end. The attitude is the rate integrated
exactly, sample to sample, as a rotation about the rate held over the step:
``q[k+1] = q[k] ⊗ exp(ω[k] Δt / 2)``. The world frame is ENU (z up), as
BROAD's reference.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from scipy.signal import butter, sosfiltfilt
from scipy.spatial.transform import Rotation

from dynamics.quaternion import from_rotation
from dynamics.validation import InvalidParameterError, finite_number


@dataclass(frozen=True)
class HandheldMotion:
    """How the hand moves. Durations in s, rates in Hz.

    Attributes
    ----------
    rate_hz : the samples' rate
    rest_s, moving_s, final_rest_s : the rest before the movement, the
        movement (tapers included), the rest after it
    rate_rms_dps : RMS of each axis's body rate over the movement, °/s
    acceleration_rms_mps2 : RMS of each axis's linear acceleration, m/s²
    bandwidth_hz : the low-pass's cut-off (a hand's motion: about 1 Hz)
    taper_s : the ramp from rest to full motion and back
    """

    rate_hz: float = 200.0
    rest_s: float = 10.0
    moving_s: float = 110.0
    final_rest_s: float = 5.0
    rate_rms_dps: float = 60.0
    acceleration_rms_mps2: float = 0.5
    bandwidth_hz: float = 1.0
    taper_s: float = 1.0

    def __post_init__(self):
        for field in fields(self):
            finite_number(field.name, getattr(self, field.name), minimum=0.0,
                          strictly_positive=field.name in ("rate_hz", "moving_s", "bandwidth_hz"))
        if self.bandwidth_hz >= self.rate_hz / 2:
            raise InvalidParameterError("bandwidth_hz", self.bandwidth_hz,
                                        f"must be below half rate_hz ({self.rate_hz / 2:g} Hz)")
        if 2 * self.taper_s > self.moving_s:
            raise InvalidParameterError("taper_s", self.taper_s,
                                        f"must be at most half moving_s ({self.moving_s:g} s)")

    def samples(self) -> tuple[int, int, int]:
        """The samples of the first rest, the movement and the final rest."""
        return tuple(int(round(s * self.rate_hz))
                     for s in (self.rest_s, self.moving_s, self.final_rest_s))


@dataclass(frozen=True)
class HandheldTruth:
    """The motion's truth, one row per sample.

    Attributes
    ----------
    q_true : (N, 4) attitude, body → world (ENU), scalar first
    omega_radps : (N, 3) body rate, body frame, held over each step
    acceleration_mps2 : (N, 3) linear acceleration, world frame
    movement : (N,) bool, the movement phase
    rate_hz : float
    """

    q_true: np.ndarray
    omega_radps: np.ndarray
    acceleration_mps2: np.ndarray
    movement: np.ndarray
    rate_hz: float


def _hand_noise(motion: HandheldMotion, rms: float, n: int, rng) -> np.ndarray:
    """``(n, 3)`` white noise low-passed (zero phase), each axis at ``rms``,
    tapered from and to zero over ``motion.taper_s``."""
    sos = butter(2, motion.bandwidth_hz, fs=motion.rate_hz, output="sos")
    noise = sosfiltfilt(sos, rng.standard_normal((n, 3)), axis=0)
    noise *= rms / noise.std(axis=0)
    ramp = motion.taper_s * motion.rate_hz
    if ramp < 1.0:          # no taper: the motion starts and stops at once
        return noise
    from_ends = np.minimum(np.arange(n), np.arange(n)[::-1])
    return noise * np.minimum(1.0, from_ends / ramp)[:, None]


def simulate_handheld(motion: HandheldMotion, rng: np.random.Generator) -> HandheldTruth:
    """A motion of ``motion``'s kind drawn from ``rng``, from a random heading
    and a tilt of up to 0.3 rad about each horizontal axis."""
    rest, moving, final = motion.samples()
    n = rest + moving + final
    omega, acceleration = np.zeros((n, 3)), np.zeros((n, 3))
    omega[rest:rest + moving] = _hand_noise(motion, np.radians(motion.rate_rms_dps), moving, rng)
    acceleration[rest:rest + moving] = _hand_noise(motion, motion.acceleration_rms_mps2, moving,
                                                   rng)
    start = Rotation.from_euler("zyx", rng.uniform(-1.0, 1.0, 3) * [np.pi, 0.3, 0.3])
    steps = Rotation.from_rotvec(omega[:-1] / motion.rate_hz)
    attitudes = [start]
    for step in steps:
        attitudes.append(attitudes[-1] * step)
    movement = np.zeros(n, dtype=bool)
    movement[rest:rest + moving] = True
    return HandheldTruth(q_true=from_rotation(Rotation.concatenate(attitudes)),
                         omega_radps=omega, acceleration_mps2=acceleration, movement=movement,
                         rate_hz=float(motion.rate_hz))
