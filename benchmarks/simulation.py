"""Run estimators on simulated data: one truth, one set of sensor readings per seed.

Every estimator of a :func:`simulate` call sees *the same* truth and the
same gyro and star tracker readings, so their errors differ only by what the
estimators do with them.

Randomness: ``seed`` feeds :class:`numpy.random.SeedSequence`, which spawns
independent streams for the gyro, the star tracker and the star tracker's
random dropouts (see :func:`sensor_generators`). So a run's numbers depend on
the seed alone, and changing the star tracker's rate does not change the gyro
noise (the star tracker noise is drawn only at its readings).
"""
from __future__ import annotations

import inspect
import warnings
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from benchmarks.metrics import attitude_error_deg, inclination_error_deg
from benchmarks.resources import TRUTH_CACHE_STEPS, check_memory, engine_bytes, per_run_bytes
from benchmarks.scenario import Scenario
from dynamics.rigid_body import RigidBodyTruth, simulate_torque_free, torque_free_blocks
from dynamics.validation import InvalidParameterError, seed_values
from benchmarks.sensor_use import (Usage, present_sensors, refuse_unreadable, scenario_sensors,
                                   tagged_label,
                                   warn_unmodelled)
from estimators import AttitudeEstimator, resolve_estimator

#: The workshop's estimators in the order it introduces them.
WORKSHOP_ESTIMATORS = ("dead-reckoning", "dead-reckoning-resets", "ekf")


@dataclass(frozen=True)
class SensorData:
    """What the estimators are given, on the time grid ``t_k = k dt``.

    Attributes
    ----------
    omega_meas_radps : (N, 3) gyro readings, rad/s, body frame
    star_tracker_quat : (N, 4) held star tracker readings, scalar-first
    available : (N,) bool, True where a new star tracker reading was taken
    gyro_bias_radps : (N, 3) the gyro's true bias β_k, rad/s (zeros for the
        workshop gyro)
    star_tracker_offset_s : (N,) seconds after ``t_k`` that step ``k``'s
        reading was taken (0 on the gyro grid and where there is none; see
        :func:`sensors.star_tracker.reading_schedule`)
    vectors : tuple of :class:`~sensors.vector.VectorReadings`, one per
        vector sensor (magnetometer, sun sensors, accelerometer), or ()
    references : :class:`~dynamics.environment.References` the vector
        sensors saw (eclipses among them), or None
    """

    omega_meas_radps: np.ndarray
    star_tracker_quat: np.ndarray
    available: np.ndarray
    gyro_bias_radps: np.ndarray | None = None
    star_tracker_offset_s: np.ndarray | None = None
    vectors: tuple = ()
    references: object = None

    @property
    def record(self) -> tuple:
        """What an estimator's ``run`` and ``track`` take: rates, readings,
        availability and (off the gyro grid) the readings' offsets."""
        offsets = self.star_tracker_offset_s
        if offsets is None or not np.any(offsets):
            return self.omega_meas_radps, self.star_tracker_quat, self.available
        return self.omega_meas_radps, self.star_tracker_quat, self.available, offsets


@dataclass(frozen=True)
class RunResult:
    """One seed's truth, sensor data and every estimator's output.

    ``estimates[name]`` is ``(N, 4)``; ``error_deg[name]`` is ``(N,)``;
    ``traces[name]`` (when asked for) is the estimator's
    :class:`~estimators.EstimateTrace`, with its covariances and bias estimate.
    """

    scenario: Scenario
    seed: int
    truth: RigidBodyTruth
    sensors: SensorData
    estimates: dict
    error_deg: dict
    labels: dict
    traces: dict | None = None
    #: ``diverged_step[name]``: the step where the estimator's estimate or
    #: covariance stopped being finite (its estimates and errors are NaN from
    #: there on), or -1 where it never did.
    diverged_step: dict | None = None
    #: ``notes[name]``: what its numbers are where they are not the plain
    #: attitude error of a working estimator (scored on its inclination; it
    #: used none of its readings; it rejected some), for every table and
    #: figure to say; from ``usage[name]`` (:class:`benchmarks.sensor_use.Usage`).
    notes: dict = field(default_factory=dict)
    usage: dict = field(default_factory=dict)

    @property
    def time_s(self) -> np.ndarray:
        return self.truth.time_s


def simulate_truth(scenario: Scenario) -> RigidBodyTruth:
    """The torque-free truth of ``scenario`` (cached: it does not depend on the seed)."""
    return _truth_cached(scenario.dt, scenario.n_steps,
                         scenario.inertia_tensor_kg_m2.tobytes(),
                         scenario.initial_attitude_quat.tobytes(),
                         scenario.initial_rate_radps.tobytes())




def truth_blocks(scenario: Scenario, block_steps: int, cache_steps: int = TRUTH_CACHE_STEPS):
    """The truth of ``scenario`` as consecutive blocks of ``block_steps`` steps
    (:class:`~dynamics.rigid_body.RigidBodyTruth` each), the same numbers as
    :func:`simulate_truth`'s, bit for bit, whichever way they are made."""
    if scenario.n_steps <= cache_steps:
        truth = simulate_truth(scenario)
        for k0 in range(0, scenario.n_steps, block_steps):
            block = slice(k0, k0 + block_steps)
            yield RigidBodyTruth(truth.time_s[block], truth.q_true[block],
                                 truth.omega_true_radps[block])
    else:
        yield from torque_free_blocks(scenario.inertia_tensor_kg_m2,
                                      scenario.initial_attitude_quat,
                                      scenario.initial_rate_radps, scenario.dt,
                                      scenario.n_steps, block_steps)


def truth_and_rate_blocks(scenario: Scenario, block_steps: int,
                          cache_steps: int = TRUTH_CACHE_STEPS):
    """:func:`truth_blocks` with the rates the gyro reads over each block
    (:meth:`sensors.Gyro.true_rates`): for an averaging gyro, each block's
    last rate takes the next block's first attitude, so the rates are those
    of the whole run, bit for bit."""
    blocks = truth_blocks(scenario, block_steps, cache_steps)
    gyro = scenario.build_gyro()
    if gyro.sampling == "sample":
        for block in blocks:
            yield block, block.omega_true_radps
        return
    previous = None
    for block in blocks:
        if previous is not None:
            yield previous, gyro.true_rates(previous.q_true, previous.omega_true_radps,
                                            q_after=block.q_true[0])
        previous = block
    yield previous, gyro.true_rates(previous.q_true, previous.omega_true_radps)


@lru_cache(maxsize=8)
def _truth_cached(dt, n_steps, inertia, q0, omega0) -> RigidBodyTruth:
    return simulate_torque_free(np.frombuffer(inertia).reshape(3, 3), np.frombuffer(q0),
                                np.frombuffer(omega0), np.arange(n_steps) * dt)


def vector_generators(seed: int, count: int) -> tuple[np.random.Generator, ...]:
    """One generator per vector sensor for ``seed``: children 3, 4, … of the
    seed's sequence, after :func:`sensor_generators`' three (so adding a
    vector sensor changes no gyro or star tracker draw)."""
    return tuple(np.random.Generator(np.random.SFC64(sequence))
                 for sequence in np.random.SeedSequence(seed).spawn(3 + count)[3:])


def sensor_generators(seed: int) -> tuple[np.random.Generator, ...]:
    """The gyro's, the star tracker's and the star tracker dropouts' random
    generators for ``seed``.

    All use numpy's SFC64 bit generator, which draws normals about 20 %
    faster than the default PCG64 and matters in Monte Carlo campaigns, where
    drawing the noise is half the work. (``SeedSequence.spawn`` numbers its
    children, so adding the third stream left the first two as they were.)
    """
    return tuple(np.random.Generator(np.random.SFC64(sequence))
                 for sequence in np.random.SeedSequence(seed).spawn(3))


def simulate_sensors(scenario: Scenario, truth: RigidBodyTruth, seed: int) -> SensorData:
    """Gyro and star tracker readings of ``truth`` for ``seed``."""
    gyro_rng, star_rng, dropout_rng = sensor_generators(seed)
    star_tracker = scenario.build_star_tracker()
    readings = star_tracker.measure(truth.q_true, star_rng, dropout_rng,
                                    reading_quat=_truth_at_readings(scenario, star_tracker))
    gyro = scenario.build_gyro()
    omega, bias = gyro.measure_with_bias(gyro.true_rates(truth.q_true, truth.omega_true_radps),
                                         gyro_rng)
    references = scenario_references(scenario)
    vectors = vector_readings(scenario, truth.q_true, references, seed)
    return SensorData(omega_meas_radps=omega, star_tracker_quat=readings.quat,
                      available=readings.available, gyro_bias_radps=bias,
                      star_tracker_offset_s=readings.offset_s, vectors=vectors,
                      references=references)


def vector_readings(scenario: Scenario, q_true: np.ndarray, references, seed: int) -> tuple:
    """Each vector sensor's readings of ``q_true`` for ``seed`` (its own stream)."""
    sensors = scenario.build_vector_sensors()
    return tuple(sensor.measure(q_true, references, rng)
                 for sensor, rng in zip(sensors, vector_generators(seed, len(sensors))))


def scenario_references(scenario: Scenario):
    """The reference vectors of ``scenario``'s environment at every step
    (:mod:`dynamics.environment`; cached, they do not depend on the seed),
    or None without vector sensors."""
    if not scenario.has_vector_sensors:
        return None
    return _references_cached(tuple(scenario.orbit_settings.items()), scenario.site,
                              scenario.magnetic_field_model, scenario.shadow_model,
                              scenario.dt, scenario.n_steps)


@lru_cache(maxsize=8)
def _references_cached(orbit_settings, site, field_model, shadow_model, dt, n_steps):
    from dynamics.environment import orbit_references, site_references
    from dynamics.orbit import make_orbit
    settings = dict(orbit_settings)
    if site is not None:
        references = site_references(*site, settings["epoch"], n_steps)
    else:
        references = orbit_references(make_orbit(**settings), settings["epoch"],
                                      np.arange(n_steps) * dt, field_model, shadow_model)
    for array in vars(references).values():     # shared by every run: never to be changed
        if isinstance(array, np.ndarray):
            array.setflags(write=False)
    return references


def _truth_at_readings(scenario: Scenario, star_tracker) -> np.ndarray | None:
    """Off the gyro grid, the true attitude at each scheduled reading's time
    (integrated at those times, as accurately as the grid's truth); on it, None."""
    if scenario.readings_on_gyro_grid:
        return None
    steps, offsets = star_tracker.schedule(scenario.n_steps)
    times = steps * scenario.dt + offsets
    return _reading_truth_cached(scenario.inertia_tensor_kg_m2.tobytes(),
                                 scenario.initial_attitude_quat.tobytes(),
                                 scenario.initial_rate_radps.tobytes(), times.tobytes())


@lru_cache(maxsize=8)
def _reading_truth_cached(inertia, q0, omega0, times) -> np.ndarray:
    """The truth at reading times (cached as the grid's truth is: it does not
    depend on the seed, and every run of a campaign needs it)."""
    q_true = simulate_torque_free(np.frombuffer(inertia).reshape(3, 3), np.frombuffer(q0),
                                  np.frombuffer(omega0), np.frombuffer(times)).q_true
    q_true.setflags(write=False)
    return q_true


def build_estimator(name: str, scenario: Scenario) -> AttitudeEstimator:
    """The estimator ``name`` names (see :func:`estimators.resolve_estimator`),
    built from ``scenario`` (its ``from_scenario``, which also applies a
    user's class's ``[estimators."package.module:ClassName"]`` section)."""
    return resolve_estimator(name).from_scenario(scenario)


def vectors_for(estimator, key: str, vectors: tuple):
    """The vector readings for ``estimator``: all of them if it takes them;
    None (and a warning, for an estimator that does not say) if not."""
    if not vectors:
        return None
    if estimator.uses_vector_readings:
        return vectors
    if estimator.uses_vector_readings is None:
        warnings.warn(f"{key} ignores the scenario's vector sensors (it does not set "
                      "uses_vector_readings; see estimators.AttitudeEstimator.step)", stacklevel=3)
    return None


def _estimates(estimator, record, vectors, traces: bool, progress_bar) -> tuple:
    """``(q_est, trace)``: one estimator's estimates over ``record`` and, with
    ``traces``, its whole trace (:meth:`~estimators.AttitudeEstimator.track`;
    else None), advancing ``progress_bar`` where its run takes one."""
    method = estimator.track if traces else estimator.run
    shown = ({"progress": progress_bar} if progress_bar is not None
             and "progress" in inspect.signature(method).parameters else {})
    made = method(*record, vectors=vectors, **shown)
    return (made.quat, made) if traces else (made, None)


def simulate(scenario: Scenario | None = None, estimators=WORKSHOP_ESTIMATORS,
             seed: int = 0, *, traces: bool = False, progress_bar=None) -> RunResult:
    """Simulate ``scenario`` for ``seed`` and run each estimator on the same data.

    Parameters
    ----------
    scenario : Scenario, optional
        Defaults to the workshop scenario.
    estimators : iterable of str or AttitudeEstimator
        Names from :data:`estimators.ESTIMATORS` or ``module:Class`` specs
        (built from the scenario, keyed by the string given), or ready
        estimator objects (used as they are, keyed by their ``name``).
    seed : int
        Seed of the sensor noise.
    traces : bool
        Also keep each estimator's covariances and bias estimates
        (:meth:`~estimators.AttitudeEstimator.track`), in ``RunResult.traces``.
    progress_bar : optional
        Advanced by one per estimator step (``len(estimators) × N`` in all).
    """
    scenario = scenario or Scenario()
    if isinstance(estimators, str):
        raise InvalidParameterError("estimators", estimators, "must be a list of names, e.g. "
                                    f"[{estimators!r}], not a single string")
    estimators = list(estimators)
    seed = int(seed_values("seed", seed))
    check_memory(scenario, per_run_bytes(scenario.n_steps, len(estimators), traces),
                 streaming_bytes=engine_bytes(scenario.n_steps))
    truth = simulate_truth(scenario)
    sensors = simulate_sensors(scenario, truth, seed)
    # The sensors the scenario declares, as the engine judges them: a run whose
    # random dropouts took every reading is flagged (Usage), not refused, so
    # that both paths run the same runs.
    present = scenario_sensors(scenario) | present_sensors(sensors)
    refuse_unreadable(estimators, present, "the scenario")
    warn_unmodelled(scenario, estimators, sensors.references)
    estimates, errors, labels, kept, diverged, usage = {}, {}, {}, {}, {}, {}
    for item in estimators:
        estimator = build_estimator(item, scenario) if isinstance(item, str) else item
        key = item if isinstance(item, str) else estimator.name
        record = sensors.record
        if len(record) == 4 and not estimator.applies_reading_times:
            warnings.warn(f"{key} applies each star tracker reading at its gyro step, not at "
                          "its own time (it does not override _step_at)", stacklevel=2)
        q_est, kept[key] = _estimates(estimator, record, vectors_for(estimator, key,
                                                                     sensors.vectors),
                                      traces, progress_bar)
        estimates[key] = q_est
        usage[key] = Usage.of(estimator, present)
        errors[key] = (attitude_error_deg if usage[key].heading
                       else inclination_error_deg)(truth.q_true, q_est)
        step = getattr(estimator, "diverged_step", None)
        diverged[key] = -1 if step is None else int(step)
        labels[key] = tagged_label(estimator.label, usage[key].note())
    return RunResult(scenario=scenario, seed=seed, truth=truth, sensors=sensors,
                     estimates=estimates, error_deg=errors, labels=labels,
                     traces=kept if traces else None, diverged_step=diverged,
                     notes={key: u.note() for key, u in usage.items() if u.note()}, usage=usage)

