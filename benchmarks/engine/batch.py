"""Run many realisations of the workshop estimators at once.

A batch is a table of runs that share the scenario's truth and time grid and
may differ in their seed, their sensor noise powers, their star tracker
interval and their EKF ``pc_exponent``. For each run the engine draws the
same random numbers as the per-run path draws for that run's seed
(:func:`benchmarks.simulation.sensor_generators`), in time blocks (the truth
too, see :func:`benchmarks.simulation.truth_blocks`), so the
results are the per-run path's to rounding (checked to 1e-9 in the tests),
and memory does not grow with the run's length.

Statistics are accumulated as the runs advance, in the record of
:mod:`benchmarks.engine.results`, which also reports them
(:class:`~benchmarks.engine.results.BatchResult`).
"""
from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from benchmarks.engine.kernels import KERNELS, kernel, settings_limitation
from benchmarks.engine.kernels.sensors import bias_model
from benchmarks.engine.results import BatchResult, batch_result, new_record
from benchmarks.engine.vectors import VectorStreams, max_block_steps, vector_block, vector_streams
from benchmarks.scenario import SETTINGS, Scenario
from benchmarks.sensor_use import scenario_sensors
from benchmarks.simulation import (TRUTH_CACHE_STEPS, WORKSHOP_ESTIMATORS, sensor_generators,
                                   truth_and_rate_blocks)
from dynamics.validation import InvalidParameterError, seed_values
from estimators import ESTIMATORS, sensing
from sensors.star_tracker import on_gyro_grid, steps_between_readings

#: Steps advanced per kernel call. It bounds the noise buffer (B × 2500 × 3
#: floats, 61 MB at B = 1024) whatever the run length; larger blocks mean
#: fewer, longer calls into numpy's generators, which then overlap better on
#: two threads (numpy releases the GIL while it fills).
BLOCK_STEPS = 2500
#: Settings a run may override, besides its seed (declared ``per_run`` in
#: benchmarks.scenario.SETTINGS; :class:`RunTable` has a column for each).
PER_RUN_SETTINGS = tuple(setting.field for setting in SETTINGS if setting.per_run)


@dataclass(frozen=True)
class RunTable:
    """The runs of a batch: a seed and the per-run settings, each ``(B,)``."""

    seeds: np.ndarray
    gyro_noise: np.ndarray
    star_tracker_noise: np.ndarray
    time_between_measurements: np.ndarray
    pc_exponent: np.ndarray

    def __len__(self) -> int:
        return len(self.seeds)

    def slice(self, start: int, stop: int) -> "RunTable":
        return RunTable(*(getattr(self, name)[start:stop] for name in self.__dataclass_fields__))

    def take(self, indices) -> "RunTable":
        return RunTable(*(getattr(self, name)[indices] for name in self.__dataclass_fields__))


def seed_range(first: int, count: int) -> np.ndarray:
    """Seeds ``first, first + 1, …`` (``count`` of them) as int64, exact up to
    2⁶³ - 1 (``np.arange(first, first + count)`` would turn to float64 there)."""
    return np.arange(count, dtype=np.int64) + np.int64(first)


def whole_number(name: str, value, minimum: int) -> int:
    """``value`` as an int if it is a whole number >= ``minimum`` (not a bool)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) \
            or value < minimum:
        raise InvalidParameterError(name, value, f"must be a whole number >= {minimum}")
    return int(value)


def checked_estimators(estimators) -> tuple:
    """The engine estimators named in ``estimators`` (a list of names), in slot order."""
    if isinstance(estimators, str) or not hasattr(estimators, "__iter__"):
        raise InvalidParameterError("estimators", estimators, "must be a list of names, e.g. "
                                    f"[{estimators!r}], not a single string")
    names = list(estimators)
    for name in names:
        if not isinstance(name, str) or name not in KERNELS:
            raise InvalidParameterError("estimators", name,
                                        f"must be one of {', '.join(KERNELS)}")
    if not names or len(set(names)) != len(names):
        raise InvalidParameterError("estimators", names, "must name at least one estimator, "
                                    "each once")
    return tuple(name for name in KERNELS if name in names)


def engine_limitation(scenario: Scenario, runs: RunTable | None = None,
                      name: str | None = None) -> str | None:
    """Why the engine cannot run ``scenario`` (with the intervals of ``runs``,
    if given), for estimator ``name`` if given, or None: a sensor or setting
    its kernels do not model. Those run on the per-run path
    (:func:`benchmarks.engine.runner.run_many` falls back, saying so)."""
    intervals = ([scenario.time_between_measurements] if runs is None
                 else np.unique(runs.time_between_measurements))
    if scenario.star_tracker_model != "none" and \
            not all(on_gyro_grid(float(t), scenario.dt) for t in intervals):
        return "star tracker readings off the gyro's time grid ([star_tracker] interval_s)"
    if name is None or name not in KERNELS:
        return None
    module = kernel(name)
    if scenario.has_vector_sensors and not sensing.heading_observed(
            ESTIMATORS[name], scenario_sensors(scenario)):
        return f"an inclination-only score ({name} has no heading reference here)"
    if scenario.has_vector_sensors and ESTIMATORS[name].uses_vector_readings and \
            not getattr(module, "VECTOR_READINGS", False):
        return f"vector sensors (magnetometer, sun sensors, accelerometer) for {name}"
    if not getattr(module, "GATING", False) and \
            getattr(ESTIMATORS[name].from_scenario(scenario), "gate_probability", None) is not None:
        return f"innovation gating (gate_probability) for {name}"
    return settings_limitation(module, name, ESTIMATORS[name].configured_settings(scenario))


def checked_runs(scenario: Scenario, runs) -> RunTable:
    """``runs`` as the kernel needs it: a :class:`RunTable` of equal-length,
    non-empty 1-D columns, whole seeds, and settings the scenario accepts."""
    if not isinstance(scenario, Scenario):
        raise InvalidParameterError("scenario", type(scenario).__name__,
                                    "must be a benchmarks.scenario.Scenario")
    if not isinstance(runs, RunTable):
        raise InvalidParameterError("runs", type(runs).__name__,
                                    "must be a RunTable (see make_runs)")
    lengths = {name: np.shape(getattr(runs, name)) for name in RunTable.__dataclass_fields__}
    if any(len(shape) != 1 for shape in lengths.values()) or \
            len(set(lengths.values())) != 1 or not lengths["seeds"][0]:
        raise InvalidParameterError("runs", {name: shape for name, shape in lengths.items()},
                                    "every column must be 1-D, of the same length, not empty")
    columns = {}
    for name in PER_RUN_SETTINGS:
        column = np.asarray(getattr(runs, name))
        if column.dtype.kind not in "iuf":
            raise InvalidParameterError(f"runs.{name}", column, "must be real numbers")
        columns[name] = np.ascontiguousarray(column, dtype=float)
        for value in np.unique(columns[name]):
            scenario.replace(**{name: float(value)})     # as the scenario validates it
    return RunTable(np.ascontiguousarray(seed_values("runs.seeds", runs.seeds)), **columns)


def make_runs(scenario: Scenario, seeds, **settings) -> RunTable:
    """A run table: ``seeds`` and any of :data:`PER_RUN_SETTINGS` as scalars or
    arrays (broadcast together); missing settings come from ``scenario``.

    Every distinct value is validated as the scenario would validate it.
    """
    unknown = set(settings) - set(PER_RUN_SETTINGS)
    if unknown:
        name = sorted(unknown)[0]
        raise InvalidParameterError(name, settings[name],
                                    f"is not a per-run setting; known: {', '.join(PER_RUN_SETTINGS)}")
    columns = {name: settings.get(name, getattr(scenario, name)) for name in PER_RUN_SETTINGS}
    seeds = seed_values("seed", seeds)
    try:
        seeds, *values = np.broadcast_arrays(seeds,
                                             *(np.asarray(columns[n]) for n in PER_RUN_SETTINGS))
    except ValueError:
        raise InvalidParameterError("settings", {n: np.shape(columns[n]) for n in columns},
                                    "must broadcast with the seeds") from None
    values = dict(zip(PER_RUN_SETTINGS, values))
    if "pc_exponent" not in settings and "pc_exponent" in scenario.derived_fields:
        # A Q derived from the gyro follows each run's gyro noise, as the
        # per-run path's scenario.replace(gyro_noise=...) derives it.
        derived = {g: scenario.replace(gyro_noise=float(g)).pc_exponent
                   for g in np.unique(values["gyro_noise"])}
        values["pc_exponent"] = np.array([derived[g] for g in values["gyro_noise"]])
    return checked_runs(scenario, RunTable(seeds, *(values[n] for n in PER_RUN_SETTINGS)))


def _fill_normals(generators, gyro_out, star_out, star_counts, uniforms_out, threads):
    """Draw each stream's next block of random numbers, in the per-run path's order."""
    def fill(indices):
        for r in indices:
            gyro_rng, star_rng, dropout_rng = generators[r]
            gyro_rng.standard_normal(out=gyro_out[r])
            if star_counts[r]:
                star_rng.standard_normal(out=star_out[r, :star_counts[r]])
                if uniforms_out.shape[1]:
                    dropout_rng.random(out=uniforms_out[r, :star_counts[r]])

    if threads <= 1 or len(generators) < 2 * threads:
        fill(range(len(generators)))
        return
    with ThreadPoolExecutor(max_workers=threads) as pool:
        list(pool.map(fill, np.array_split(np.arange(len(generators)), threads)))


def _shared_streams(seeds: np.ndarray, steps_between: np.ndarray) -> tuple:
    """``(sources, first)``: each run's index among the batch's distinct
    (seed, tracker interval) pairs, in the order they first come, and the
    first run of each. Runs that share both draw the same numbers (the same
    generators, drawn as often), so a sweep of a filter's settings over
    common seeds (the landscape, a tuning grid) draws each stream once."""
    index = {}
    sources = np.array([index.setdefault(key, len(index))
                        for key in zip(seeds.tolist(), steps_between.tolist())], dtype=np.intp)
    first = np.unique(sources, return_index=True)[1]
    return sources, first


#: Every estimator with a kernel, in the engine's order (the kernel registry's).
ENGINE_ESTIMATORS = tuple(KERNELS)


def per_run_estimators(scenario: Scenario, runs: RunTable, name: str) -> list:
    """Estimator ``name`` as each run's settings build it (``from_scenario``),
    shared where the settings repeat: the kernels read their settings here."""
    cache, built = {}, []
    for i in range(len(runs)):
        key = tuple(float(getattr(runs, setting)[i]) for setting in PER_RUN_SETTINGS)
        if key not in cache:
            case = scenario.replace(**dict(zip(PER_RUN_SETTINGS, key)))
            cache[key] = ESTIMATORS[name].from_scenario(case)
        built.append(cache[key])
    return built


@dataclass
class _Sensors:
    """The sensors' settings for every run (a :class:`Block`'s sensor fields
    but the noise), the generators of their distinct streams and the length of
    a noise block."""

    settings: dict
    tracker: object              # the scenario's star tracker (its outages)
    initial_bias: np.ndarray     # (B, 6) the gyro's true bias at the start: β_0, and b_0
    generators: list             # (U,) of each distinct stream (_shared_streams)
    sources: np.ndarray          # (B,) each run's stream
    first: np.ndarray            # (U,) each stream's first run
    block_steps: int
    threads: int
    vectors: VectorStreams       # the vector sensors' (none, if no kernel applies them)

    def state(self):
        """A fresh :class:`~benchmarks.engine.kernels.sensors.SensorState`
        (each kernel advances its own copy of the true bias)."""
        from benchmarks.engine.kernels.sensors import SensorState
        return SensorState(bias=self.initial_bias.copy(),
                           bias_last=self.initial_bias[:, :3] + self.initial_bias[:, 3:])


def _sensors(scenario: Scenario, runs: RunTable, block_steps: int, threads: int,
             vectors: bool) -> _Sensors:
    """The per-run path's arithmetic, value by value: √(p/dt + σ_u²dt/12) and the
    tracker's σ, its readings' interval, and the generators of each distinct
    stream (:func:`_shared_streams`; and, if ``vectors``, of its vector
    sensors: :mod:`benchmarks.engine.vectors`)."""
    n_runs, dt = len(runs), scenario.dt
    gyro = scenario.build_gyro()
    tracker = scenario.build_star_tracker()
    rotation = tracker.model == "rotation"
    steps_between = np.array([steps_between_readings(t, dt)
                              for t in runs.time_between_measurements], dtype=np.int64)
    sources, first = _shared_streams(runs.seeds, steps_between)
    streams = vector_streams(scenario if vectors else None, runs.seeds[first])
    # Keep the gyro buffer's size whatever its columns (3, and 3 more each for a
    # bias walk and a Gauss–Markov part).
    block_steps = max(1, min(block_steps * 3 // gyro.normals_per_step, scenario.n_steps,
                             max_block_steps(n_runs, len(streams.sensors)) or scenario.n_steps))
    readings = -(-block_steps // int(steps_between.min())) + 1
    dropout = float(tracker.dropout_probability)
    generators = [sensor_generators(int(seed)) for seed in runs.seeds[first]]
    # β_0 and, with a Gauss–Markov part, its stationary start b_0 = σ_b N,
    # drawn from each run's gyro stream before its first step, as sensors.Gyro does.
    initial_bias = np.zeros((len(generators), 6))
    initial_bias[:, :3] = gyro.initial_bias_radps
    if gyro.bias_instability_radps > 0:
        for r, (gyro_rng, _, _) in enumerate(generators):
            initial_bias[r, 3:] = gyro.bias_instability_radps * gyro_rng.standard_normal(3)
    initial_bias = initial_bias[sources]
    settings = dict(
        gyro_std=np.array([gyro.reading_std(p, dt, gyro.bias_random_walk)
                           for p in runs.gyro_noise]),
        gyro_normals=np.empty((n_runs, block_steps, gyro.normals_per_step)),
        bias_model=bias_model(gyro),
        gyro_scale=(np.zeros((3, 3)) if gyro.scale_misalignment is None
                    else np.ascontiguousarray(gyro.scale_misalignment)),
        has_scale=gyro.scale_misalignment is not None, has_bias=gyro.has_bias_model,
        rotation_model=rotation,
        star_std=np.array([math.sqrt(p / dt) for p in runs.star_tracker_noise]),
        steps_between=steps_between,
        star_normals=np.empty((n_runs, readings, 3 if rotation else 4)),
        sigma_rad=np.ascontiguousarray(tracker.sigma_rad) if rotation else np.zeros(3),
        sensor_to_body=np.ascontiguousarray(tracker.sensor_to_body) if rotation else np.eye(3),
        canonical=rotation and tracker.sign == "canonical", dropout_probability=dropout,
        dropout_uniforms=np.empty((n_runs, readings if dropout > 0 else 0)))
    return _Sensors(settings=settings, tracker=tracker, initial_bias=initial_bias,
                    generators=generators, sources=sources, first=first,
                    block_steps=block_steps, threads=threads, vectors=streams)


def _block(sensors: _Sensors, scenario: Scenario, k0: int, truth, rates, vectors: dict):
    """The block of steps from ``k0`` with ``truth`` and the rates the gyro
    reads over it: its normals drawn, in the per-run path's order, the
    tracker's outages over it, and its ``vectors`` (:func:`vector_block`'s)."""
    from benchmarks.engine.kernels.common import Block
    settings = dict(sensors.settings)
    stop = k0 + len(truth.time_s)
    normals = settings["gyro_normals"]
    if stop - k0 != normals.shape[1]:
        # The last, shorter block gets a buffer of its own: a strided view
        # would compile the kernels a second time (about 40 s, cold).
        settings["gyro_normals"] = normals = np.empty((normals.shape[0], stop - k0,
                                                       normals.shape[2]))
    # Readings fall at k ≡ 0 (mod m) in [k0, stop); floor division makes
    # (-1) // m = -1, so the reading at k = 0 is counted too.
    steps_between = settings["steps_between"]
    counts = (stop - 1) // steps_between - (k0 - 1) // steps_between
    if sensors.tracker.model == "none":
        counts = np.zeros_like(counts)      # an outage throughout: nothing drawn
    _draw(sensors, normals, settings["star_normals"], counts, settings["dropout_uniforms"])
    outage = sensors.tracker.in_outage(truth.time_s)
    return Block(k0=k0, steps=stop - k0, last_step=scenario.n_steps - 1, dt=scenario.dt,
                 q_true=np.ascontiguousarray(truth.q_true),
                 omega_true=np.ascontiguousarray(rates), outage=outage, **settings, **vectors)


def _draw(sensors: _Sensors, gyro_out, star_out, counts, uniforms_out) -> None:
    """Each run's block of random numbers: drawn into the buffers where every
    run has a stream of its own, else each distinct stream's drawn once and
    copied to the runs that share it (:func:`_shared_streams`)."""
    if len(sensors.first) == len(sensors.sources):
        _fill_normals(sensors.generators, gyro_out, star_out, counts, uniforms_out,
                      sensors.threads)
        return
    drawn = [np.empty((len(sensors.first),) + out.shape[1:])
             for out in (gyro_out, star_out, uniforms_out)]
    _fill_normals(sensors.generators, *drawn[:2], counts[sensors.first], drawn[2],
                  sensors.threads)
    for out, values in zip((gyro_out, star_out, uniforms_out), drawn):
        np.take(values, sensors.sources, axis=0, out=out)


def _advance(scenario: Scenario, sensors: _Sensors, kernels: dict, states: dict, record,
             cache_steps: int, progress_bar) -> dict:
    """Every run through the whole time grid, block by block (the truth too,
    integrated as it goes for long runs): the block's noise drawn on every
    core, then each kernel advances every run through it (each makes the
    sensors' readings from the noise itself: measured, that costs no more
    than sharing them). The vector sensors' readings of the next block are
    made in threads of their own (a part of the runs each, one a core) while
    the kernels run this one: their streams are their own, and each still
    draws block after block, so the numbers are those made in turn (a
    CubeSat campaign's host work, most of its time, then runs beside its
    kernels, and the kernels' shares even out the cores). Returns each
    kernel's sensor state."""
    readings = {name: sensors.state() for name in kernels}
    blocks = zip(range(0, scenario.n_steps, sensors.block_steps),
                 truth_and_rate_blocks(scenario, sensors.block_steps, cache_steps))
    with ThreadPoolExecutor(max_workers=sensors.threads) as ahead:
        upcoming = _vectors_ahead(ahead, sensors, next(blocks, None))
        while upcoming is not None:
            (k0, (truth, rates)), vectors = upcoming[0], _shared(sensors, upcoming[1].result())
            upcoming = _vectors_ahead(ahead, sensors, next(blocks, None))
            block = _block(sensors, scenario, k0, truth, rates, vectors)
            for row, name in enumerate(kernels):
                kernels[name].advance(block, readings[name], states[name], record, row)
            if progress_bar is not None:
                progress_bar.update(block.steps)
    return readings


def _vectors_ahead(pool, sensors: _Sensors, item):
    """``(item, the future of its vector readings)`` for the block ``item``
    (``(k0, (truth, rates))``): each distinct stream's readings made once, in
    ``pool``'s threads (:func:`vector_block`); None past the last block."""
    if item is None:
        return None
    k0, (truth, _) = item
    return item, vector_block(sensors.vectors, len(sensors.first), k0,
                              np.ascontiguousarray(truth.q_true), pool, sensors.threads)


def _shared(sensors: _Sensors, arrays: dict) -> dict:
    """:func:`vector_block`'s arrays of every run: each distinct stream's
    copied to the runs that share it."""
    if len(sensors.first) < len(sensors.sources):
        for name in ("vector_body", "vector_variance", "vector_available"):
            arrays[name] = np.take(arrays[name], sensors.sources, axis=0)
    return arrays


def run_batch(scenario: Scenario, runs: RunTable, estimators=WORKSHOP_ESTIMATORS,
              keep_traces: bool = False, block_steps: int = BLOCK_STEPS,
              threads: int | None = None, consistency: bool = False,
              nees_every: int = 1, settle_steps: int = 0,
              cache_steps: int = TRUTH_CACHE_STEPS, health: bool = False,
              error_every: int = 0, progress_bar=None) -> BatchResult:
    """Run ``estimators`` (names from :data:`ENGINE_ESTIMATORS`) on every run of ``runs``.

    Parameters
    ----------
    scenario : Scenario
        Truth, time grid, sensor models and every estimator's settings (its
        ``from_scenario``), shared by the runs.
    runs : RunTable
        From :func:`make_runs`.
    estimators : names from :data:`ENGINE_ESTIMATORS`
    keep_traces : bool
        Keep ``(B, N, 4)`` estimates per estimator; the median is then exact.
    block_steps : int
        Steps of noise drawn at a time (results do not depend on it).
    threads : int, optional
        Threads drawing random numbers (default: one per core).
    consistency : bool
        Stream the attitude NEES of the estimators whose kernels report a
        covariance (sampled every ``nees_every`` steps, and its per-run
        average from ``settle_steps`` on), their star-tracker NIS
        (per-run average) and their innovations' likelihood sums (every
        applied update); see ``BatchResult.consistency``. No traces are needed.
    cache_steps : int
        Longest run whose truth is taken whole from the cache; longer runs
        integrate it block by block (the same numbers), so memory stays flat.
    health : bool
        Check every estimator's state inside the kernel, after each update and
        each propagation: |q| = 1, the covariance symmetric, positive definite
        and finite; counted in ``BatchResult.health``. Off by default (it
        costs a Cholesky factorisation per check).
    error_every : int
        If > 0, keep every estimator's error every that many steps
        (``BatchResult.error_samples``): the shape of a long run's error
        without keeping its traces.
    progress_bar : tqdm-like, optional
        Updated with the steps of each block as it is done.
    """
    from numba import get_num_threads
    runs, names = _checked_batch(scenario, runs, estimators)
    block_steps, nees_every, cache_steps, error_every, settle_steps = (
        whole_number("block_steps", block_steps, 1), whole_number("nees_every", nees_every, 1),
        whole_number("cache_steps", cache_steps, 0), whole_number("error_every", error_every, 0),
        whole_number("settle_steps", settle_steps, 0))
    threads = get_num_threads() if threads is None else whole_number("threads", threads, 1)
    kernels, objects, states = _kernels(scenario, runs, names)
    vectors = scenario.has_vector_sensors and any(
        getattr(module, "VECTOR_READINGS", False) for module in kernels.values())
    sensors = _sensors(scenario, runs, block_steps, threads, vectors)
    record = new_record(names, len(runs), scenario.n_steps, keep_traces, consistency,
                        nees_every, settle_steps, health, error_every,
                        len(sensors.vectors.sensors))
    readings = _advance(scenario, sensors, kernels, states, record, cache_steps, progress_bar)
    return batch_result(scenario, runs, kernels, objects, states, record,
                        next(iter(readings.values())))


def _checked_batch(scenario: Scenario, runs: RunTable, estimators) -> tuple:
    """``(runs, names)`` checked before compiled code sees them (the kernels
    trust shapes and lengths, so a bad table would read or write out of
    bounds), each estimator's kernel modelling what the scenario holds."""
    runs = checked_runs(scenario, runs)
    names = checked_estimators(estimators)
    for name in names:
        limitation = engine_limitation(scenario, runs, name)
        if limitation is not None:
            raise InvalidParameterError("scenario", limitation, "is not modelled by the "
                                        "engine's kernels; run it through "
                                        "benchmarks.engine.runner.run_many, which takes the "
                                        "per-run path")
    return runs, names


def _kernels(scenario: Scenario, runs: RunTable, names) -> tuple:
    """``(kernels, objects, states)`` by estimator name: its kernel module,
    its per-run objects (whose settings the kernel reads) and the kernel's
    initial state for every run."""
    kernels = {name: kernel(name) for name in names}
    objects = {name: per_run_estimators(scenario, runs, name) for name in names}
    states = {name: kernels[name].initial_state(objects[name]) for name in names}
    return kernels, objects, states


#: Runs per kernel batch in campaigns: large enough to keep both cores busy,
#: small enough that a batch's buffers stay near 100 MB.
CHUNK_RUNS = 1024
