r"""An accelerometer used as a gravity sensor, as ground IMUs use it.

At rest, or moving slowly, an accelerometer measures the specific force
:math:`f = a - g`, which is gravity's reaction, pointing up:

.. math:: b_k = A(q_k)^\mathsf{T} r + b_a + v_k, \qquad r = (0, 0, g)
          \ \text{(east-north-up)}, \qquad v_k \sim \mathcal N(0, \sigma^2 I_3),

with :math:`A(q)` the body-to-local-level rotation, :math:`g` standard
gravity (:data:`dynamics.environment.STANDARD_GRAVITY_MPS2`), :math:`b_a` a
constant bias and σ the noise per axis in m/s² (a datasheet's noise density
:math:`N` in µg/√Hz over a bandwidth :math:`B` Hz gives
:math:`\sigma = N \cdot 10^{-6} g \sqrt{B}`). Linear acceleration is what
this model leaves out; innovation gating is how a filter rejects it (and
magnetic disturbances, for the magnetometer beside it).

In orbit an accelerometer reads no gravity (free fall): scenarios with an
orbit refuse it.
"""
from __future__ import annotations

import numpy as np

from dynamics.environment import STANDARD_GRAVITY_MPS2
from dynamics.validation import InvalidParameterError, finite_vector, standard_deviation
from sensors.vector import VectorSensor, normals, to_body

#: The specific force at rest in the east-north-up frame, m/s².
GRAVITY_REACTION_ENU_MPS2 = np.array([0.0, 0.0, STANDARD_GRAVITY_MPS2])
#: The largest noise σ or bias per axis, m/s² (16 g): the widest full-scale
#: range of the MEMS accelerometers in IMUs (±16 g: ADXL345, MPU-6050,
#: BMI160, LSM6DSO). Beyond it a reading saturates; a gravity sensor's
#: 1 g would be lost in it.
MAX_SPECIFIC_FORCE_MPS2 = 16.0 * STANDARD_GRAVITY_MPS2


class Accelerometer(VectorSensor):
    """A three-axis accelerometer as a gravity sensor (module docstring).

    Parameters
    ----------
    sigma_mps2 : float
        Noise σ per axis, m/s² (> 0).
    interval_s, dt : float
    bias_mps2 : (3,)
        Constant bias, m/s².
    """

    name = "accelerometer"
    unit = "m/s^2"
    dof = 3

    def __init__(self, sigma_mps2: float, interval_s: float, dt: float, *,
                 bias_mps2=(0.0, 0.0, 0.0)):
        super().__init__(interval_s, dt)
        self.sigma_mps2 = standard_deviation("accelerometer.sigma_mps2", sigma_mps2,
                                             strictly_positive=True)
        if self.sigma_mps2 > MAX_SPECIFIC_FORCE_MPS2:
            raise InvalidParameterError("accelerometer.sigma_mps2", sigma_mps2, f"must be at "
                                        f"most {MAX_SPECIFIC_FORCE_MPS2:g} m/s^2 (16 g, an IMU "
                                        "accelerometer's widest range)")
        self.bias_mps2 = finite_vector("accelerometer.bias_mps2", bias_mps2, 3)
        if np.abs(self.bias_mps2).max() > MAX_SPECIFIC_FORCE_MPS2:
            raise InvalidParameterError("accelerometer.bias_mps2", bias_mps2, f"each component "
                                        f"must be within ±{MAX_SPECIFIC_FORCE_MPS2:g} m/s^2 "
                                        "(16 g, an IMU accelerometer's widest range)")

    def measure_into(self, q_true: np.ndarray, references, rngs, first_step: int,
                     body: np.ndarray, variance: np.ndarray,
                     available: np.ndarray) -> np.ndarray:
        """Readings of the gravity reaction at every scheduled step; one
        3-vector of noise per reading, in time order (``references`` is not
        read: gravity's reference is the local vertical)."""
        from sensors.vector_arithmetic import noisy_rows    # compiled: loaded where used
        n = len(q_true)
        reference = np.broadcast_to(GRAVITY_REACTION_ENU_MPS2, (n, 3)).copy()
        steps = np.flatnonzero(self.scheduled(n, first_step))
        truth = to_body(q_true[steps], reference[steps]) + self.bias_mps2
        noisy_rows(truth, self.sigma_mps2, normals(rngs, (len(steps), 3)), steps,
                   self.sigma_mps2 ** 2, body, variance, available)
        return reference
