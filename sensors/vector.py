r"""Vector observations: what a magnetometer, a sun sensor or an accelerometer
gives an estimator.

A vector sensor measures, in the body frame, a vector whose direction in the
reference frame is known from a model (the geomagnetic field, the Sun's
ephemeris, gravity: :mod:`dynamics.environment`):

.. math:: b = A(q)^\mathsf{T} r + v, \qquad v \sim \mathcal N(0, \sigma^2 I_3),

with :math:`A(q)` the body-to-reference rotation of the truth (this
toolkit's convention, :mod:`dynamics`). One reading of one sensor is a
:class:`VectorObservation`: the measured ``body`` vector, the model's
``reference`` vector, the noise variance :math:`\sigma^2` per axis (in the
vector's unit squared) and the degrees of freedom of its innovation: 3 for a
full vector (the magnetometer's nT), 2 for a unit vector, whose error lies
across it (a sun sensor's direction; Shuster's QUEST measurement model,
Markley & Crassidis 2014, §5.2.1, where :math:`\sigma^2 I_3` in place of
:math:`\sigma^2 (I_3 - b b^\mathsf{T})` changes no update to first order).

Over a record, each sensor's readings are one :class:`VectorReadings` on the
gyro's grid (each sensor on its own rate, a whole multiple of ``dt``), with
``available`` flags where a reading was taken (none in eclipse for a sun
sensor, none outside its field of view).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from dynamics.quaternion import rotation_matrix
from sensors.star_tracker import steps_between_readings


def readings_taken(vectors: np.ndarray) -> np.ndarray:
    """``(N,)`` bool: which of a recorded sensor's ``(N, 3)`` readings were
    taken. A reading of exactly zero on all three axes is a dropout (no
    accelerometer reads no gravity, no magnetometer no field), not a reading;
    any other is one, a reading that is not finite included (what uses it
    decides)."""
    return np.any(vectors != 0.0, axis=1)


@dataclass(frozen=True)
class VectorObservation:
    """One reading of one vector sensor, as an estimator's step takes it.

    Attributes
    ----------
    body : (3,) the measured vector, body frame
    reference : (3,) the same vector in the reference frame (the model's)
    variance : float, σ² per axis of ``body``'s noise (the vector's unit squared)
    sensor : str, the sensor's name (``"magnetometer"``, ``"sun_sensor"``, …)
    dof : int, the degrees of freedom of its innovation (3, or 2 for a unit vector)
    reference_known : bool, whether ``reference`` is the vector itself (a
        model's, in the reading's unit), or only gives its direction's
        azimuth (a recording's field, whose norm and dip a filter must learn:
        :mod:`estimators.imu.heading`)
    """

    body: np.ndarray
    reference: np.ndarray
    variance: float
    sensor: str
    dof: int = 3
    reference_known: bool = True


@dataclass(frozen=True)
class VectorReadings:
    """One vector sensor's readings over a record of ``N`` gyro steps.

    Attributes
    ----------
    sensor : str
    body : (N, 3) measured vectors (zeros where none was taken)
    reference : (N, 3) the model's reference vectors at every step
    available : (N,) bool, True where a reading was taken
    variance : (N,) σ² per axis of each reading (0 where none was taken)
    dof : int
    unit : str, the vectors' unit ("nT", "m/s^2", or "" for unit vectors)
    reference_known : bool, as :attr:`VectorObservation.reference_known`
    """

    sensor: str
    body: np.ndarray
    reference: np.ndarray
    available: np.ndarray
    variance: np.ndarray
    dof: int = 3
    unit: str = ""
    reference_known: bool = True

    def observation(self, k: int) -> VectorObservation:
        """Step ``k``'s reading (``available[k]`` must be True)."""
        return VectorObservation(self.body[k], self.reference[k], float(self.variance[k]),
                                 self.sensor, self.dof, self.reference_known)

    def steps(self, part: slice) -> "VectorReadings":
        """The readings of the steps ``part`` (a slice of the record)."""
        return dataclasses.replace(self, body=self.body[part], reference=self.reference[part],
                                   available=self.available[part],
                                   variance=self.variance[part])

    def run(self, index: int) -> "VectorReadings":
        """One run's readings of readings made for several
        (:meth:`VectorSensor.measure_runs`: ``body`` ``(R, N, 3)``,
        ``available`` and ``variance`` ``(R, N)``)."""
        return dataclasses.replace(self, body=self.body[index],
                                   available=self.available[index],
                                   variance=self.variance[index])


def to_body(q_true: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``(N, 3)``: :math:`A(q_k)^\\mathsf{T} r_k`, each reference vector in the body frame."""
    return np.einsum("nji,nj->ni", rotation_matrix(q_true), reference)


def times_matrix(vectors: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """``vectors @ matrix.T`` for ``(..., 3)`` vectors, written element by
    element (compiled: :func:`sensors.vector_arithmetic.times_matrix_rows`):
    a row's result is then the same bits wherever it sits in the stack (a
    block of a run, or the whole run), which BLAS does not promise."""
    from sensors.vector_arithmetic import times_matrix_rows   # compiled: loaded where used
    vectors = np.asarray(vectors, dtype=float)
    matrix = np.ascontiguousarray(matrix, dtype=float)
    rows = np.ascontiguousarray(vectors.reshape(-1, 3))
    return times_matrix_rows(rows, matrix).reshape(vectors.shape[:-1] + (len(matrix),))


def normals(rngs, shape: tuple) -> np.ndarray:
    """``(R,) + shape`` standard normals, each run's from its own generator."""
    out = np.empty((len(rngs),) + shape)
    for row, rng in zip(out, rngs):
        rng.standard_normal(out=row)
    return out


class VectorSensor:
    """What the vector sensors share: a name, a rate on the gyro's grid.

    Parameters
    ----------
    interval_s : float
        Seconds between readings: a whole multiple of ``dt``.
    dt : float
        The gyro's step, seconds.
    """

    name = "vector"
    unit = ""
    dof = 3

    def __init__(self, interval_s: float, dt: float):
        self.interval_s = float(interval_s)
        self.dt = float(dt)
        self.steps_between = steps_between_readings(interval_s, dt)

    def scheduled(self, n_steps: int, first_step: int = 0) -> np.ndarray:
        """``(N,)`` bool: the steps at which the sensor reads, every ``m``
        steps from step 0, over ``N`` steps from ``first_step`` (a block of a
        longer run: the engine measures block by block, drawing the same
        numbers in the same order as one call over the whole run)."""
        flags = np.zeros(n_steps, dtype=bool)
        flags[-first_step % self.steps_between::self.steps_between] = True
        return flags

    def measure(self, q_true: np.ndarray, references, rng: np.random.Generator,
                first_step: int = 0) -> VectorReadings:
        """The readings of true attitudes ``q_true`` ``(N, 4)`` with the
        reference vectors ``references`` (:class:`dynamics.environment.References`)
        over ``N`` steps from ``first_step``, the noise drawn from ``rng`` in
        time order (a block's call draws what one call over the run draws
        for those steps)."""
        return self.measure_runs(q_true, references, [rng], first_step).run(0)

    def measure_runs(self, q_true: np.ndarray, references, rngs,
                     first_step: int = 0) -> VectorReadings:
        """:meth:`measure` for several runs of the same truth at once, one
        generator each (the engine's batches): readings with a leading axis
        of runs, ``body`` ``(R, N, 3)``, ``available`` and ``variance``
        ``(R, N)`` (zero where no reading was taken). A run's readings are the
        same bits as :meth:`measure`'s."""
        shape = (len(rngs), len(q_true))
        body, variance = np.zeros(shape + (3,)), np.zeros(shape)
        available = np.zeros(shape, dtype=bool)
        reference = self.measure_into(q_true, references, rngs, first_step, body, variance,
                                      available)
        return VectorReadings(sensor=self.name, body=body, reference=reference,
                              available=available, variance=variance, dof=self.dof,
                              unit=self.unit)

    def measure_into(self, q_true: np.ndarray, references, rngs, first_step: int,
                     body: np.ndarray, variance: np.ndarray,
                     available: np.ndarray) -> np.ndarray:
        """:meth:`measure_runs`' readings written into zeroed arrays ``body``
        ``(R, N, 3)``, ``variance`` and ``available`` ``(R, N)`` (views of
        the engine's block arrays: the readings are written once, where they
        are kept). Returns the reference vectors ``(N, 3)``. Each sensor's
        model is here; :meth:`measure_runs` and :meth:`measure` call it. A
        sensor that defines :meth:`measure_runs` instead has its readings
        copied in."""
        if type(self).measure_runs is VectorSensor.measure_runs:
            raise NotImplementedError(f"{type(self).__name__} defines neither measure_into "
                                      "nor measure_runs")
        readings = self.measure_runs(q_true, references, rngs, first_step)
        body[...] = np.where(readings.available[..., None], readings.body, 0.0)
        variance[...] = np.where(readings.available, readings.variance, 0.0)
        available[...] = readings.available
        return readings.reference
