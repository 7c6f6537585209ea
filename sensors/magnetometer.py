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
from sensors.vector import VectorSensor, normals, times_matrix, to_body

#: The largest field a reading may carry, per axis, nT (ten gauss): beyond
#: the full-scale range of spacecraft and IMU magnetometers (±8 gauss for a
#: Honeywell HMC5883L, ±800 µT for a PNI RM3100) and fifteen times the
#: strongest geomagnetic field (about 67,000 nT). A noise σ or a hard-iron
#: bias beyond it would make every reading saturate, or noise alone.
MAX_FIELD_NT = 1e6
#: The soft-iron matrix's largest condition number (the ratio of its
#: strongest to its weakest axis): beyond it an axis is a million times
#: weaker than another, dead rather than soft, and a calibration could not
#: invert the matrix. The ratio is scale-free, as invertibility is: 0.001·I
#: is as invertible as I (a determinant, 1e-9 there, is not a test of it).
MAX_SOFT_IRON_CONDITION = 1e6
#: The soft-iron matrix's largest gain (its largest singular value): soft iron
#: bends and scales the field by tens of per cent; ten times the strongest
#: geomagnetic field is still within :data:`MAX_FIELD_NT`.
MAX_SOFT_IRON_GAIN = 10.0


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
        if self.sigma_nT > MAX_FIELD_NT:
            raise InvalidParameterError("magnetometer.sigma_nT", sigma_nT, f"must be at most "
                                        f"{MAX_FIELD_NT:g} nT (10 gauss, beyond any "
                                        "magnetometer's range): readings would be noise alone")
        self.bias_nT = finite_vector("magnetometer.bias_nT", bias_nT, 3)
        if np.abs(self.bias_nT).max() > MAX_FIELD_NT:
            raise InvalidParameterError("magnetometer.bias_nT", bias_nT, f"each component must "
                                        f"be within ±{MAX_FIELD_NT:g} nT (10 gauss, beyond any "
                                        "magnetometer's range)")
        self.soft_iron = _soft_iron(soft_iron)

    def measure_into(self, q_true: np.ndarray, references, rngs, first_step: int,
                     body: np.ndarray, variance: np.ndarray,
                     available: np.ndarray) -> np.ndarray:
        """Readings of the field ``references.magnetic_field_nT`` (``(N, 3)``,
        reference frame) at every scheduled step; one 3-vector of noise drawn
        per reading, in time order."""
        from sensors.vector_arithmetic import noisy_rows    # compiled: loaded where used
        field_nT = references.magnetic_field_nT
        steps = np.flatnonzero(self.scheduled(len(q_true), first_step))
        truth = times_matrix(to_body(q_true[steps], field_nT[steps]), self.soft_iron) + \
            self.bias_nT
        noisy_rows(truth, self.sigma_nT, normals(rngs, (len(steps), 3)), steps,
                   self.sigma_nT ** 2, body, variance, available)
        return field_nT


def _soft_iron(value) -> np.ndarray:
    """A soft-iron matrix: finite, 3x3, invertible by its condition number
    (:data:`MAX_SOFT_IRON_CONDITION`), its gain at most :data:`MAX_SOFT_IRON_GAIN`."""
    name = "magnetometer.soft_iron"
    matrix = float_array(name, value, "must be a 3x3 matrix of numbers")
    if matrix.shape != (3, 3) or not np.all(np.isfinite(matrix)):
        raise InvalidParameterError(name, matrix.tolist(), "must be a finite 3x3 matrix")
    # Singular values of a finite matrix of entries up to 1e308 can overflow;
    # those of its scaled copy cannot, and the ratio does not change.
    largest = float(np.abs(matrix).max())
    gains = np.linalg.svd(matrix / largest, compute_uv=False) * largest if largest else \
        np.zeros(3)
    if not gains[-1] > 0 or gains[0] / gains[-1] > MAX_SOFT_IRON_CONDITION:
        condition = gains[0] / gains[-1] if gains[-1] > 0 else float("inf")
        raise InvalidParameterError(name, matrix.tolist(), f"must be invertible: its "
                                    f"condition number is {condition:.3g}, at most "
                                    f"{MAX_SOFT_IRON_CONDITION:g} (its weakest axis a millionth "
                                    "of its strongest)")
    if gains[0] > MAX_SOFT_IRON_GAIN:
        raise InvalidParameterError(name, matrix.tolist(), f"multiplies the field by up to "
                                    f"{gains[0]:.3g}; at most {MAX_SOFT_IRON_GAIN:g} (soft iron "
                                    "scales it by tens of per cent)")
    return matrix
