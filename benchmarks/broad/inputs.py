r"""A recorded IMU trial as the estimators' sensor data: the gyro, the
accelerometer as a gravity-direction reading and the magnetometer as a
field-direction reading (:class:`sensors.vector.VectorReadings`), with
everything the filters need taken from the trial's initial rest, never from
its reference attitude:

* the references, in the recording's ENU frame: gravity's specific force
  :math:`[0, 0, |\bar a|]` (up), and the field :math:`|\bar m|[0, \sin\theta,
  \cos\theta]` with :math:`\theta` the measured angle between the mean
  accelerometer and magnetometer readings at rest (the field's inclination;
  its heading is magnetic north, as the complementary filters and VQF take it);
* each sensor's σ² per axis: the mean of its three variances at rest,
  which is its noise, but at least :data:`MOTION_SIGMAS` squared: in motion
  the accelerometer also reads the linear acceleration, and the
  magnetometer the disturbances of the room, which the rest does not show
  (the values were chosen on trial 02, the training trial, with the MEKF:
  the rest's σ alone, 0.055 m/s² and 0.7 µT, made its gate reject three
  accelerometer readings in four during the movement);
* the gyro's noise power, its mean variance at rest times dt;
* the initial attitude, TRIAD on the first sample of the rest whose two
  readings are usable (:func:`start_sample`; on BROAD's trials the first
  sample), gravity first (:func:`estimators.wahba.triad`): the sensor rests,
  so the attitude there is the attitude at the first sample.

A reading of exactly zero on all three axes is a dropout (no accelerometer
at rest reads no gravity, no magnetometer no field): it is no reading
(``available`` false), left out of the rest's means and variances and of
the share of readings a filter rejected. What a trial needs to be run
(:func:`runnable_rule`): at least :data:`MIN_REST_SAMPLES` usable readings
of each sensor at rest, their means at least :data:`MIN_SEPARATION_DEG`
apart, and a sample of the rest to start from.

In motion the accelerometer also reads the linear acceleration and the
magnetometer any disturbance: the filters' χ² gate
(``gate_probability``) keeps such readings out, and for the field a test
of its magnitude against the rest's (``magnetic_norm_tolerance``): a
disturbed field can keep a plausible direction, never its magnitude.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from benchmarks.experiments.replay import BIAS_RANDOM_WALK, INITIAL_BIAS_SIGMA_RADPS, \
    checked_gyro_delay, delayed_gyro
from benchmarks.scenario import Scenario
from benchmarks.simulation import SensorData
from dynamics.validation import InvalidParameterError, standard_deviation
from estimators import wahba
from sensors.recording import Recording
from sensors.vector import VectorReadings

#: The smallest σ per axis the filters take for each sensor: m/s², µT.
MOTION_SIGMAS = {"accelerometer": 0.3, "magnetometer": 4.0}
#: The fewest usable readings of each sensor a trial's rest must hold: its
#: reference and σ are taken from them (from 50 samples a variance is known
#: to about ±20 %, √(2/49)).
MIN_REST_SAMPLES = 50
#: Two directions closer than this to parallel (or antiparallel) fix no
#: attitude: the start's two readings and the rest's two means must be at
#: least this far apart (the static estimators' ``min_separation_deg``).
MIN_SEPARATION_DEG = 1.0
#: The six-state filters' prior on the attitude from one TRIAD sample, rad.
INITIAL_ATTITUDE_SIGMA_RAD = math.radians(5.0)
#: The filters' χ² gate on the acc/mag readings unless a section sets one.
GATE_PROBABILITY = 0.9999
#: Their magnetic disturbance test: a field reading more than 10 % off the
#: rest's magnitude is rejected (VQF's default threshold, ``magNormTh``,
#: taken as published, not tuned here).
MAGNETIC_NORM_TOLERANCE = 0.1


@dataclass(frozen=True)
class ImuInputs:
    """A trial ready for any estimator: its scenario, its sensor data (gyro
    and the two vector sensors, no star tracker) and the reference to score."""

    recording: Recording
    scenario: Scenario
    sensors: SensorData
    references: dict             # sensor → (3,) reference vector, ENU
    variances: dict              # sensor → σ² per axis


def checked_sigmas(sigmas=None) -> dict:
    """:data:`MOTION_SIGMAS` with ``sigmas`` (sensor → σ) over them, each a
    standard deviation > 0 whose square, a variance, is finite (the error
    names ``accelerometer_sigma`` or ``magnetometer_sigma``)."""
    sigmas = dict(sigmas or {})
    for name in sigmas:
        if name not in MOTION_SIGMAS:
            raise InvalidParameterError("sigmas", name, f"must name one of "
                                        f"{', '.join(MOTION_SIGMAS)}")
    return {name: standard_deviation(f"{name}_sigma", value, strictly_positive=True)
            for name, value in {**MOTION_SIGMAS, **sigmas}.items()}


def channels(recording: Recording) -> dict:
    """``sensor → (N, 3)`` readings: the accelerometer's, m/s², and the magnetometer's, µT."""
    return {"accelerometer": recording.accelerometer_mps2,
            "magnetometer": recording.magnetometer_uT}


def usable_readings(recording: Recording) -> dict:
    """``sensor → (N,)`` bool: the readings that are not exactly zero (a
    dropout, module docstring)."""
    return {name: np.any(channel != 0.0, axis=1) for name, channel in channels(recording).items()}


def _rest_readings(recording: Recording) -> dict:
    """``sensor → (M, 3)``: its usable readings of the initial rest."""
    rest, found = recording.rest_samples, {}
    for (name, channel), usable in zip(channels(recording).items(),
                                       usable_readings(recording).values()):
        # Every reading usable (a real trial): the rest itself, not a copy,
        # whose sums numpy orders differently in the last bits.
        kept = usable[rest]
        found[name] = channel[rest] if kept.all() else channel[rest][kept]
    return found


def _sine_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The sine of the angle between rows of ``a`` and ``b`` (0 where either is zero)."""
    norms = np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1)
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    return np.divide(cross, norms, out=np.zeros_like(cross), where=norms > 0)


def start_sample(recording: Recording) -> int | None:
    """The first sample of the rest whose accelerometer and magnetometer
    readings are both non-zero and at least :data:`MIN_SEPARATION_DEG`
    apart: the start attitude's (None if the rest has none)."""
    rest = recording.rest_samples
    sine = _sine_between(recording.accelerometer_mps2[rest], recording.magnetometer_uT[rest])
    found = np.flatnonzero(sine >= math.sin(math.radians(MIN_SEPARATION_DEG)))
    return int(found[0]) if len(found) else None


def runnable_rule(recording: Recording) -> str | None:
    """The rule ``recording`` (with both vector channels) breaks for the
    estimators to be started and configured from its rest (module
    docstring), in words; None if it breaks none."""
    rest = recording.rest_samples
    where = (f"samples 0 to {rest.stop - 1}" if rest.stop else "none: it moves from sample 0")
    usable = usable_readings(recording)
    for name, flags in usable.items():
        count = int(np.count_nonzero(flags[rest]))
        if count < MIN_REST_SAMPLES:
            return (f"has {count} usable {name} reading{'s' * (count != 1)} at rest before "
                    f"its movement ({where}); a trial needs at least {MIN_REST_SAMPLES}: each "
                    "sensor's reference and noise are taken from its rest")
    means = [readings.mean(axis=0) for readings in _rest_readings(recording).values()]
    angle = math.degrees(math.asin(min(float(_sine_between(*means)), 1.0)))
    if angle < MIN_SEPARATION_DEG:
        return (f"its mean accelerometer and magnetometer readings at rest are {angle:.3g}° "
                f"from parallel; they must be at least {MIN_SEPARATION_DEG:g}° apart to give "
                "the field's inclination and an attitude")
    if start_sample(recording) is None:
        return (f"no sample of its rest ({where}) has accelerometer and magnetometer readings "
                f"both non-zero and at least {MIN_SEPARATION_DEG:g}° apart, which the start "
                "attitude is taken from")
    return None


def _checked_runnable(recording: Recording) -> None:
    rule = runnable_rule(recording)
    if rule:
        raise InvalidParameterError("trial", recording.name, rule)


def rest_references(recording: Recording, sigmas=None) -> tuple[dict, dict]:
    """The gravity and field reference vectors (ENU) and each sensor's σ²,
    from the usable readings of the initial rest, at least ``sigmas``
    (default :data:`MOTION_SIGMAS`, :func:`checked_sigmas`) squared (module
    docstring)."""
    sigmas = checked_sigmas(sigmas)
    _checked_runnable(recording)
    acc, mag = _rest_readings(recording).values()
    a, m = acc.mean(axis=0), mag.mean(axis=0)
    cosine = float(np.clip(a @ m / (np.linalg.norm(a) * np.linalg.norm(m)), -1.0, 1.0))
    sine = math.sqrt(1.0 - cosine ** 2)
    references = {"accelerometer": np.array([0.0, 0.0, np.linalg.norm(a)]),
                  "magnetometer": np.linalg.norm(m) * np.array([0.0, sine, cosine])}
    variances = {name: max(float(np.mean(channel.var(axis=0))), sigmas[name] ** 2)
                 for name, channel in (("accelerometer", acc), ("magnetometer", mag))}
    return references, variances


def initial_attitude(acc: np.ndarray, mag: np.ndarray, references: dict) -> np.ndarray:
    """Body → ENU from one accelerometer and magnetometer sample (TRIAD,
    gravity first); the two readings must be non-zero and not parallel
    (:func:`start_sample` finds such a sample)."""
    body = np.array([acc / np.linalg.norm(acc), mag / np.linalg.norm(mag)])
    reference = np.array([references[name] / np.linalg.norm(references[name])
                          for name in ("accelerometer", "magnetometer")])
    return wahba.triad(body, reference, np.array([2.0, 1.0]))


def imu_inputs(recording: Recording, gyro_delay_s: float = 0.0, sigmas=None) -> ImuInputs:
    """``recording`` (with its accelerometer and magnetometer) as an
    :class:`ImuInputs`; ``gyro_delay_s``: how late the gyro's samples are
    (:func:`benchmarks.experiments.replay.delayed_gyro`); ``sigmas``:
    sensor → the smallest σ the filters take (:func:`rest_references`)."""
    delay = checked_gyro_delay(recording, gyro_delay_s)
    references, variances = rest_references(recording, sigmas)
    n, dt = recording.n_samples, recording.dt
    rest_gyro = recording.gyro_radps[recording.rest_samples]
    noise_power = float(np.mean(rest_gyro.var(axis=0)) * dt)
    first = start_sample(recording)
    start = initial_attitude(recording.accelerometer_mps2[first],
                             recording.magnetometer_uT[first], references)
    usable = usable_readings(recording)
    vectors = tuple(
        VectorReadings(sensor=name, body=channel, reference=np.tile(references[name], (n, 1)),
                       available=usable[name], variance=np.full(n, variances[name]), unit=unit)
        for (name, channel), unit in zip(channels(recording).items(), ("m/s^2", "uT")))
    six_state = {"initial_attitude_sigma_rad": INITIAL_ATTITUDE_SIGMA_RAD,
                 "initial_bias_sigma_radps": INITIAL_BIAS_SIGMA_RADPS,
                 "gate_probability": GATE_PROBABILITY,
                 "magnetic_norm_tolerance": MAGNETIC_NORM_TOLERANCE}
    scenario = Scenario(
        tstop=(n - 1) * dt, dt=dt, initial_state=start, initial_attitude_quat=start,
        gyro_noise=noise_power, gyro_bias_random_walk=BIAS_RANDOM_WALK,
        # The estimators see no star tracker; the scenario keeps the workshop's
        # model out of use (an outage throughout) because its own vector
        # sensors are simulated ones, and these readings are recorded.
        star_tracker_model="rotation", star_tracker_outages_s=((0.0, n * dt),),
        estimator_options={"mekf": dict(six_state), "usque": dict(six_state),
                           "ekf": {"gate_probability": GATE_PROBABILITY}})
    sensors = SensorData(omega_meas_radps=delayed_gyro(recording, delay),
                         star_tracker_quat=np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)),
                         available=np.zeros(n, dtype=bool), vectors=vectors)
    return ImuInputs(recording=recording, scenario=scenario, sensors=sensors,
                     references=references, variances=variances)
