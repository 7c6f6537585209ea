r"""Rate gyro: true body rate plus white noise, every step.

.. math:: \tilde\omega_k = \omega_k + n_k, \qquad
          n_k \sim \mathcal N\!\left(0, \tfrac{p_g}{\Delta t} I_3\right)

with ``p_g`` the gyro noise power (rad²/s) and ``Δt`` the step (workshop
model, SPEC "Sensors"). No bias, scale factor or misalignment: the workshop
gyro has none.
"""
from __future__ import annotations

import numpy as np

from dynamics.validation import finite_number
from sensors.noise import noise_power_to_std


class Gyro:
    """A three-axis rate gyro sampled every ``dt`` seconds.

    Parameters
    ----------
    noise_power : float
        Noise power ``p_g`` in rad²/s (Simulink band-limited white noise).
    dt : float
        Sample time in seconds.
    """

    def __init__(self, noise_power: float, dt: float):
        self.noise_power = finite_number("gyro_noise", noise_power, minimum=0.0)
        self.dt = finite_number("dt", dt, strictly_positive=True)
        self.std_radps = noise_power_to_std(self.noise_power, self.dt)

    def measure(self, omega_true_radps: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Noisy rates ``(N, 3)`` in rad/s for true rates ``(N, 3)``.

        Draws ``N × 3`` standard normals from ``rng`` in row order, so the
        same generator state gives the same noise whatever else is simulated.
        """
        omega_true = np.asarray(omega_true_radps, dtype=float)
        return omega_true + self.std_radps * rng.standard_normal(omega_true.shape)
