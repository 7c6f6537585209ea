"""The vector sensors in the engine: each run's magnetometer, sun sensor and
accelerometer readings, block by block, for the kernels that apply them.

The readings are made on the host, by the per-run path's own sensor classes
(:mod:`sensors.vector`: ``measure(q_true, references, rng, first_step)``),
from each run's own streams (:func:`benchmarks.simulation.vector_generators`)
over the block's steps: a block's call draws the numbers the per-run path's
single call draws for those steps, in the same order, so the kernels read the
per-run path's readings exactly. Each sensor measures all the runs of a
block in one call (:meth:`sensors.vector.VectorSensor.measure_runs`: the
truth's part once, each run's noise from its own generator). Unlike the
gyro's and the tracker's, these readings are not remade inside the kernels:
a coarse sun sensor's least-squares solution picks its lit faces by rank
tests, and one definition of it is worth more than a compiled copy. The
readings are packed dense, one slot per sensor and step (``Block.vector_*``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from benchmarks.simulation import scenario_references, vector_generators
from dynamics.environment import References

#: The vector buffers of a block (body vectors, variances and flags of every
#: run, sensor and step) are kept below this many floats (64 MB): a block of
#: a vector scenario has at most that many steps.
MAX_VECTOR_FLOATS = 8_000_000
#: Floats per run, sensor and step in the buffers: the 3-vector, σ², the flag.
_FLOATS_PER_READING = 5


@dataclass
class VectorStreams:
    """What the engine draws vector readings from: the scenario's vector
    sensors, their reference vectors over the whole run (cached, shared by
    the runs) and one generator per run and sensor."""

    sensors: tuple
    references: References
    generators: list

    @property
    def dof(self) -> np.ndarray:
        """``(S,)`` each sensor's degrees of freedom (its gate's χ²)."""
        return np.array([sensor.dof for sensor in self.sensors], dtype=np.int64)


def vector_streams(scenario, seeds) -> VectorStreams:
    """The vector streams of the runs of ``seeds`` (no sensors if the
    scenario has none, or is None: no kernel of the batch applies them)."""
    if scenario is None or not scenario.has_vector_sensors:
        return VectorStreams(sensors=(), references=None, generators=[])
    sensors = tuple(scenario.build_vector_sensors())
    return VectorStreams(sensors=sensors, references=scenario_references(scenario),
                         generators=[vector_generators(int(seed), len(sensors))
                                     for seed in seeds])


def max_block_steps(n_runs: int, n_sensors: int) -> int | None:
    """The longest block whose vector buffers stay under
    :data:`MAX_VECTOR_FLOATS` (None without vector sensors)."""
    if not n_sensors:
        return None
    return max(1, MAX_VECTOR_FLOATS // (n_runs * n_sensors * _FLOATS_PER_READING))


def references_between(references: References, start: int, stop: int) -> References:
    """The reference vectors of steps ``start`` to ``stop``."""
    def part(array):
        return None if array is None else array[start:stop]
    return References(magnetic_field_nT=part(references.magnetic_field_nT),
                      sun_unit=part(references.sun_unit),
                      illumination=part(references.illumination),
                      position_km=part(references.position_km))


def vector_block(streams: VectorStreams, n_runs: int, k0: int, q_true: np.ndarray) -> dict:
    """The ``Block.vector_*`` arrays of the block of steps from ``k0`` whose
    truth is ``q_true`` ``(T, 4)``: every run's readings, each sensor's made
    for all runs at once (:meth:`sensors.vector.VectorSensor.measure_runs`)."""
    steps, count = len(q_true), len(streams.sensors)
    arrays = dict(vector_body=np.zeros((n_runs, steps, count, 3)),
                  vector_reference=np.zeros((steps, count, 3)),
                  vector_variance=np.zeros((n_runs, steps, count)),
                  vector_available=np.zeros((n_runs, steps, count), dtype=bool),
                  vector_dof=streams.dof,
                  vector_magnetic=np.array([sensor.name == "magnetometer"
                                            for sensor in streams.sensors], dtype=bool),
                  vector_gravity=np.array([sensor.name == "accelerometer"
                                           for sensor in streams.sensors], dtype=bool),
                  vector_known=np.ones(count, dtype=bool))
    if not count:
        return arrays
    references = references_between(streams.references, k0, k0 + steps)
    for s, sensor in enumerate(streams.sensors):
        readings = sensor.measure_runs(q_true, references,
                                       [generators[s] for generators in streams.generators],
                                       first_step=k0)
        arrays["vector_body"][:, :, s] = readings.body
        arrays["vector_variance"][:, :, s] = readings.variance
        arrays["vector_available"][:, :, s] = readings.available
        arrays["vector_reference"][:, s] = readings.reference
    return arrays
