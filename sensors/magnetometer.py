r"""A three-axis magnetometer.

.. math:: b_k = S\,A(q_k)^\mathsf{T} r_k + b_\text{hard} + v_k, \qquad
          v_k \sim \mathcal N(0, \sigma^2 I_3),

with :math:`r_k` the geomagnetic field at the spacecraft in the reference
frame (nT, :func:`dynamics.environment.geomagnetic_field_nT`), :math:`\sigma`
the noise per axis in nT (a datasheet's RMS noise; e.g. the PNI RM3100 reads
about 15 nT at its 200-cycle setting, a Honeywell HMC5883L about 200 nT),
:math:`b_\text{hard}` the constant hard-iron bias (nT) and :math:`S` the
soft-iron (and scale) matrix, :math:`I_3` for a calibrated magnetometer.

The filters take the reading as a full vector in nT with :math:`R = \sigma^2
I_3` (3 degrees of freedom), as Crassidis & Markley (2003, §V) do; they know
neither :math:`S` nor :math:`b_\text{hard}`, which a calibration removes (a
scenario that sets them shows what an uncalibrated magnetometer costs).
"""
from __future__ import annotations

import numpy as np

from dynamics.validation import (InvalidParameterError, finite_vector, float_array,
                                 standard_deviation)
from sensors.vector import VectorReadings, VectorSensor, normals, times_matrix, to_body


class Magnetometer(VectorSensor):
    """A three-axis magnetometer reading every ``interval_s`` seconds.

    Parameters
    ----------
    sigma_nT : float
        Noise σ per axis, nT (> 0).
    interval_s, dt : float
        See :class:`sensors.vector.VectorSensor`.
    bias_nT : (3,)
        Hard-iron bias, nT.
    soft_iron : (3, 3)
        Soft-iron and scale matrix :math:`S` (identity: none).
    """

    name = "magnetometer"
    unit = "nT"
    dof = 3

    def __init__(self, sigma_nT: float, interval_s: float, dt: float, *,
                 bias_nT=(0.0, 0.0, 0.0), soft_iron=np.eye(3)):
        super().__init__(interval_s, dt)
        self.sigma_nT = standard_deviation("magnetometer.sigma_nT", sigma_nT,
                                           strictly_positive=True)
        self.bias_nT = finite_vector("magnetometer.bias_nT", bias_nT, 3)
        rule = "must be a finite, invertible 3x3 matrix"
        matrix = float_array("magnetometer.soft_iron", soft_iron, rule)
        if matrix.shape != (3, 3) or not np.all(np.isfinite(matrix)) or \
                abs(np.linalg.det(matrix)) < 1e-6:
            raise InvalidParameterError("magnetometer.soft_iron", matrix.tolist(), rule)
        self.soft_iron = matrix

    def measure_runs(self, q_true: np.ndarray, references, rngs,
                     first_step: int = 0) -> VectorReadings:
        """Readings of the field ``references.magnetic_field_nT`` (``(N, 3)``,
        reference frame) at every scheduled step; one 3-vector of noise drawn
        per reading, in time order."""
        field_nT = references.magnetic_field_nT
        available = self.scheduled(len(q_true), first_step)
        steps = np.flatnonzero(available)
        truth = times_matrix(to_body(q_true[steps], field_nT[steps]), self.soft_iron) + \
            self.bias_nT
        body = np.zeros((len(rngs), len(q_true), 3))
        body[:, steps] = truth + self.sigma_nT * normals(rngs, (len(steps), 3))
        return self.readings(body, field_nT, available, self.sigma_nT ** 2)
