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
* the initial attitude, TRIAD on the first sample's two readings
  (:func:`estimators.wahba.triad`, gravity first).

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
from estimators import wahba
from sensors.recording import Recording
from sensors.vector import VectorReadings

#: The smallest σ per axis the filters take for each sensor: m/s², µT.
MOTION_SIGMAS = {"accelerometer": 0.3, "magnetometer": 4.0}
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


def rest_references(recording: Recording, sigmas=None) -> tuple[dict, dict]:
    """The gravity and field reference vectors (ENU) and each sensor's σ²,
    from the initial rest, at least ``sigmas`` (default
    :data:`MOTION_SIGMAS`) squared (module docstring)."""
    sigmas = {**MOTION_SIGMAS, **(sigmas or {})}
    rest = recording.rest_samples
    acc, mag = recording.accelerometer_mps2[rest], recording.magnetometer_uT[rest]
    a, m = acc.mean(axis=0), mag.mean(axis=0)
    cosine = float(np.clip(a @ m / (np.linalg.norm(a) * np.linalg.norm(m)), -1.0, 1.0))
    sine = math.sqrt(1.0 - cosine ** 2)
    references = {"accelerometer": np.array([0.0, 0.0, np.linalg.norm(a)]),
                  "magnetometer": np.linalg.norm(m) * np.array([0.0, sine, cosine])}
    variances = {name: max(float(np.mean(channel.var(axis=0))), sigmas[name] ** 2)
                 for name, channel in (("accelerometer", acc), ("magnetometer", mag))}
    return references, variances


def initial_attitude(acc: np.ndarray, mag: np.ndarray, references: dict) -> np.ndarray:
    """Body → ENU from one accelerometer and magnetometer sample (TRIAD, gravity first)."""
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
    start = initial_attitude(recording.accelerometer_mps2[0], recording.magnetometer_uT[0],
                             references)
    vectors = tuple(
        VectorReadings(sensor=name, body=channel, reference=np.tile(references[name], (n, 1)),
                       available=np.ones(n, dtype=bool), variance=np.full(n, variances[name]),
                       unit=unit)
        for name, channel, unit in (("accelerometer", recording.accelerometer_mps2, "m/s^2"),
                                    ("magnetometer", recording.magnetometer_uT, "uT")))
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
