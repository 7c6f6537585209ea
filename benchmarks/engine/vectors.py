"""The vector sensors in the engine: each run's magnetometer, sun sensor and
accelerometer readings, block by block, for the kernels that apply them.

The readings are made on the host, by the per-run path's own sensor classes
(:mod:`sensors.vector`: ``measure(q_true, references, rng, first_step)``),
from each run's own streams (:func:`benchmarks.simulation.vector_generators`)
over the block's steps: a block's call draws the numbers the per-run path's
single call draws for those steps, in the same order, so the kernels read the
per-run path's readings exactly. Each sensor measures the runs of a block
in one call (:meth:`sensors.vector.VectorSensor.measure_into`: the truth's
part once, each run's noise from its own generator, written in the block's
arrays), or in one call per
part of the runs, in threads beside the kernels (:func:`vector_block`). Unlike the
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


def vector_block(streams: VectorStreams, n_runs: int, k0: int, q_true: np.ndarray,
                 pool=None, parts: int = 1):
    """The ``Block.vector_*`` arrays of the block of steps from ``k0`` whose
    truth is ``q_true`` ``(T, 4)``: every run's readings, each sensor's made
    for all runs at once, written where the block keeps them
    (:meth:`sensors.vector.VectorSensor.measure_into`).

    With a ``pool`` (an executor), the runs are measured in ``parts``
    contiguous parts, each in a task of its own, and a future of the arrays
    is returned. Each run's readings are its own generators' (the same bits
    in any part), and a block's tasks are done before the next block's
    begin (the caller waits for them), so each generator still draws block
    after block. Why: in a CubeSat campaign these readings are made beside
    the kernels, and in one thread they were the slower of the two (1024
    runs: about 3.5 s of one core against 3 s of the kernels on two)."""
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
    if pool is None:
        if count:
            _measure_into(arrays, streams, 0, n_runs, k0, q_true)
        return arrays
    bounds = np.linspace(0, n_runs, max(1, min(parts, n_runs)) + 1).round().astype(int)
    tasks = [pool.submit(_measure_into, arrays, streams, first, last, k0, q_true)
             for first, last in zip(bounds[:-1], bounds[1:]) if count and last > first]
    return _Arrays(arrays, tasks)


class _Arrays:
    """A future of :func:`vector_block`'s arrays: ready when its tasks are."""

    def __init__(self, arrays: dict, tasks: list):
        self.arrays, self.tasks = arrays, tasks

    def result(self) -> dict:
        for task in self.tasks:
            task.result()
        return self.arrays


def _measure_into(arrays: dict, streams: VectorStreams, first: int, last: int, k0: int,
                  q_true: np.ndarray) -> None:
    """Runs ``first`` to ``last - 1``'s readings of every sensor, into ``arrays``."""
    references = references_between(streams.references, k0, k0 + len(q_true))
    for s, sensor in enumerate(streams.sensors):
        reference = sensor.measure_into(q_true, references,
                                        [generators[s] for generators in
                                         streams.generators[first:last]], k0,
                                        arrays["vector_body"][first:last, :, s],
                                        arrays["vector_variance"][first:last, :, s],
                                        arrays["vector_available"][first:last, :, s])
        if first == 0:      # the same references in every part: one part writes them
            arrays["vector_reference"][:, s] = reference
