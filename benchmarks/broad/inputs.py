r"""A recorded IMU trial as the estimators' sensor data: the gyro, the
accelerometer as a gravity reading and the magnetometer as a field reading
(:class:`sensors.vector.VectorReadings`), with nothing taken from a rest the
recording may not have, and nothing from its reference attitude. What is
assumed instead, and where it comes from, :attr:`ImuInputs.assumptions`
says, and ``broad`` prints:

* gravity: the standard :math:`g_0` = 9.80665 m/s², up (a recording
  declares no site);
* the field: for the filters that read it as a vector, its median norm and
  dip over the trial's first :data:`FIELD_WINDOW_S` (the angle between the
  accelerometer and the magnetometer, gravity up; its heading is magnetic
  north, as the complementary filters and VQF take it). The MEKF does not
  take them: it reads the field as a heading only and learns its norm and
  dip online from the readings it trusts (:mod:`estimators.imu.heading`);
* the noise: :data:`MOTION_SIGMAS` per axis for the readings' σ (in motion
  the accelerometer also reads the linear acceleration, and the magnetometer
  the room's disturbances), the gyro's σ_v :data:`GYRO_NOISE_DENSITY`;
* the start attitude: TRIAD on the first sample whose two readings are
  usable (:func:`start_sample`), gravity first (:func:`estimators.triad.triad`):
  its linear acceleration, if the body moves there, is the start's error,
  which the filters' prior holds.

The MEKF and USQUE run the IMU models (:mod:`estimators.imu`, by their
``[estimators.mekf]`` and ``[estimators.usque]`` settings:
:data:`IMU_MODELS`): gravity low-passed in its strapdown frame, the
heading-only magnetometer with its hard iron fitted online, rest detection
with the zero-rate update of its bias, and the gyro's own error along the
rate (:data:`estimators.imu.GYRO_SCALE_DENSITY`). Every estimator with a setting for
it takes the gyro's reading as the rate over the interval before it (an
IMU's output is filtered inside the sensor:
:data:`benchmarks.experiments.replay.RECORDED_GYRO`).

A reading of exactly zero on all three axes is a dropout (no accelerometer
reads no gravity, no magnetometer no field): it is no reading (``available``
false), and is left out of the share of readings a filter rejected. What a
trial needs to be run (:func:`runnable_rule`): at least
:data:`MIN_SAMPLES` samples, and a sample to start from.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from benchmarks.experiments.replay import checked_gyro_delay, delayed_gyro, recorded_options
from benchmarks.scenario import Scenario
from benchmarks.simulation import SensorData
from dynamics.environment import STANDARD_GRAVITY_MPS2
from dynamics.quaternion import from_rotation
from dynamics.validation import InvalidParameterError, standard_deviation
from estimators import sensing, wahba
from estimators.imu import GYRO_NOISE_DENSITY, GYRO_SCALE_DENSITY
from estimators.imu.heading import NORM_TOLERANCE
from sensors.recording import Recording, reading_interval_s
from sensors.turning import held_readings
from sensors.vector import VectorReadings, readings_taken

#: The smallest σ per axis the filters that read the vectors take: m/s², µT.
MOTION_SIGMAS = {"accelerometer": 0.3, "magnetometer": 4.0}
#: The bias's rate random walk they take, rad/s^1.5: a MEMS gyro's bias
#: drifts by about 0.01 °/s over a minute.
GYRO_BIAS_RANDOM_WALK = 1e-5
#: Their prior on the bias, rad/s: a MEMS gyro's switch-on bias, 0.5 °/s
#: (VQF's ``biasSigmaInit``).
INITIAL_BIAS_SIGMA_RADPS = math.radians(0.5)
#: Their prior on the attitude from one TRIAD sample, rad.
INITIAL_ATTITUDE_SIGMA_RAD = 0.1
#: The time over which the field's norm and dip are taken for the filters
#: that read the field as a vector, s.
FIELD_WINDOW_S = 1.0
#: The fewest samples a trial must have.
MIN_SAMPLES = 50
#: Two directions closer than this to parallel (or antiparallel) fix no
#: attitude: the start's two readings must be at least this far apart.
MIN_SEPARATION_DEG = 1.0
#: The χ² gate of the filters that read acc/mag as vectors (the workshop's
#: EKF here; the textbook MEKF of :mod:`benchmarks.broad.ablation`).
GATE_PROBABILITY = 0.9999
#: The textbook MEKF's magnetic disturbance test: a field reading more than
#: 10 % off the reference's magnitude is rejected (VQF's ``magNormTh``, as the
#: heading model's own test, :data:`estimators.imu.heading.NORM_TOLERANCE`).
MAGNETIC_NORM_TOLERANCE = NORM_TOLERANCE
#: The MEKF's and USQUE's settings on an IMU recording (module docstring).
IMU_MODELS = {"gravity_model": "lowpass", "magnetometer_model": "heading",
              "rest_updates": True, "hard_iron_fit": True,
              "gyro_scale_density": GYRO_SCALE_DENSITY}


@dataclass(frozen=True)
class ImuInputs:
    """A trial ready for any estimator: its scenario, its sensor data (gyro
    and the two vector sensors, no star tracker), the reference vectors and
    variances the vector filters take, and what was assumed to make them."""

    recording: Recording
    scenario: Scenario
    sensors: SensorData
    references: dict             # sensor → (3,) reference vector, ENU
    variances: dict              # sensor → σ² per axis
    assumptions: tuple = ()      # one line each: what was assumed, and from what


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


#: Each vector channel's unit, as the estimators take it.
UNITS = {"accelerometer": "m/s^2", "magnetometer": "uT"}


def channels(recording: Recording) -> dict:
    """``sensor → (N, 3)`` readings: the accelerometer's, m/s², and the
    magnetometer's, µT, where the recording has one (a 6-axis IMU has not)."""
    return {name: channel for name, channel in (("accelerometer", recording.accelerometer_mps2),
                                                ("magnetometer", recording.magnetometer_uT))
            if channel is not None}


def heading_reference(recording: Recording) -> bool:
    """Whether ``recording`` reads a heading reference (a magnetometer): a
    6-axis IMU's heading is its gyro's, and every filter is scored on its
    inclination (:func:`estimators.sensing.heading_observed`)."""
    return recording.magnetometer_uT is not None


def usable_readings(recording: Recording) -> dict:
    """``sensor → (N,)`` bool: the readings that are not exactly zero (a
    dropout, module docstring)."""
    return {name: readings_taken(channel) for name, channel in channels(recording).items()}


#: The VQF estimators told their channels' intervals (the offline one
#: takes every channel at the gyro's rate, a slower one held).
TOLD_INTERVALS = ("vqf", "vqf-6d")


def _vqf_options(usable: dict, dt: float) -> dict:
    """VQF's ``accTs`` and ``magTs`` (``accelerometer_interval_s``,
    ``magnetometer_interval_s``) where the accelerometer or the
    magnetometer reads slower than the gyro: its coefficients are set for
    them, and at the gyro's step (its default) its corrections would be
    that many times too slow. The MEKF reads each reading's interval as it
    comes."""
    intervals = {f"{sensor}_interval_s": reading_interval_s(usable[sensor], dt)
                 for sensor in ("accelerometer", "magnetometer") if sensor in usable}
    told = {key: interval for key, interval in intervals.items() if interval > dt}
    return {name: dict(told) for name in TOLD_INTERVALS} if told else {}


def _sine_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The sine of the angle between rows of ``a`` and ``b`` (0 where either is zero)."""
    norms = np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1)
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    return np.divide(cross, norms, out=np.zeros_like(cross), where=norms > 0)


def _timed_already(recording: Recording) -> dict:
    """The estimators that time their own field (``fit_magnetometer_delay``:
    the offline ones) told not to where the recording's was timed already
    (``--magnetometer-delay``, a delay given or fitted): a delay is never
    taken out twice, and a delay given is the one every estimator reads."""
    if not recording.magnetometer_timed:
        return {}
    from estimators import ESTIMATORS
    return {name: {"fit_magnetometer_delay": False} for name in ESTIMATORS
            if "fit_magnetometer_delay" in ESTIMATORS[name].option_names()}


def heading_scored(cls, recording: Recording) -> bool:
    """Whether estimator class ``cls`` is scored on its heading on
    ``recording``: it has a heading reference there
    (:func:`heading_reference`, :func:`estimators.sensing.heading_observed`)."""
    return heading_reference(recording) and sensing.heading_observed(cls, channels(recording))


def scored_metric(cls, recording: Recording) -> str:
    """The RMSE that scores estimator class ``cls`` on ``recording``: the
    total, or the inclination's where its heading is not scored
    (:func:`heading_scored`)."""
    return "total_rmse_deg" if heading_scored(cls, recording) else "inclination_rmse_deg"


def start_pair(recording: Recording) -> tuple | None:
    """``(sample, accelerometer, magnetometer)``: the first sample where both
    sensors have read and their latest readings are at least
    :data:`MIN_SEPARATION_DEG` apart, and those readings, the start
    attitude's (None if the trial has none). Sensors that read on the same
    samples start on one sample's pair; sensors on their own clocks on the
    later one's reading and the other's last before it. Without a
    magnetometer, the first accelerometer reading, and None for the field."""
    acc = held_readings(recording.accelerometer_mps2)
    if not heading_reference(recording):
        found = np.flatnonzero(readings_taken(acc))
        return (int(found[0]), acc[found[0]], None) if len(found) else None
    mag = held_readings(recording.magnetometer_uT)
    found = np.flatnonzero(_sine_between(acc, mag) >= math.sin(math.radians(MIN_SEPARATION_DEG)))
    return (int(found[0]), acc[found[0]], mag[found[0]]) if len(found) else None


def start_sample(recording: Recording) -> int | None:
    """The sample the start attitude is taken at (:func:`start_pair`; None
    if the trial has none)."""
    pair = start_pair(recording)
    return None if pair is None else pair[0]


def runnable_rule(recording: Recording) -> str | None:
    """The rule ``recording`` (with its accelerometer) breaks for the
    estimators to be started on it (module docstring), in words; None if it
    breaks none."""
    if recording.n_samples < MIN_SAMPLES:
        return (f"has {recording.n_samples} sample{'s' * (recording.n_samples != 1)}; a trial "
                f"needs at least {MIN_SAMPLES} to be run and scored")
    if start_sample(recording) is not None:
        return None
    if not heading_reference(recording):
        return "has no accelerometer reading that is not zero, which the start attitude's " \
            "inclination is taken from"
    return ("no accelerometer reading and magnetometer reading, the latest of each at a "
            f"sample, are both non-zero and at least {MIN_SEPARATION_DEG:g}° apart, which the "
            "start attitude is taken from")


def _checked_runnable(recording: Recording) -> None:
    rule = runnable_rule(recording)
    if rule:
        raise InvalidParameterError("trial", recording.name, rule)


def field_reference(recording: Recording) -> np.ndarray:
    """The field's reference vector (ENU, µT) for the filters that read it as
    a vector: its median norm, and its median dip against the accelerometer,
    over the first :data:`FIELD_WINDOW_S` of usable readings of both on one
    sample, or where the two never read on one sample each field reading's
    against the latest accelerometer reading (module docstring)."""
    window = max(1, round(FIELD_WINDOW_S / recording.dt))
    usable = usable_readings(recording)
    acc = recording.accelerometer_mps2
    if not np.any(usable["accelerometer"] & usable["magnetometer"]):
        # sensors on their own clocks: each field reading with the latest
        # accelerometer reading before it
        acc = held_readings(np.where(usable["accelerometer"][:, None], acc, 0.0))
        usable = {**usable, "accelerometer": readings_taken(acc)}
    both = np.flatnonzero(usable["accelerometer"] & usable["magnetometer"])[:window]
    acc, mag = acc[both], recording.magnetometer_uT[both]
    norm = float(np.median(np.linalg.norm(mag, axis=1)))
    cosine = np.sum(acc * mag, axis=1) / (np.linalg.norm(acc, axis=1) * np.linalg.norm(mag, axis=1))
    dip = math.asin(float(np.clip(np.median(-cosine), -1.0, 1.0)))      # positive downward
    return norm * np.array([0.0, math.cos(dip), -math.sin(dip)])


def references_and_variances(recording: Recording, sigmas=None) -> tuple[dict, dict]:
    """The gravity and field reference vectors (ENU) and each sensor's σ²
    (:data:`MOTION_SIGMAS`, or ``sigmas`` over them: :func:`checked_sigmas`)."""
    sigmas = checked_sigmas(sigmas)
    _checked_runnable(recording)
    references = {"accelerometer": np.array([0.0, 0.0, STANDARD_GRAVITY_MPS2])}
    if heading_reference(recording):
        references["magnetometer"] = field_reference(recording)
    return references, {name: sigma ** 2 for name, sigma in sigmas.items()}


def initial_attitude(acc: np.ndarray, mag: np.ndarray | None, references: dict) -> np.ndarray:
    """Body → ENU from one accelerometer and magnetometer sample (TRIAD,
    gravity first); the two readings must be non-zero and not parallel
    (:func:`start_sample` finds such a sample). Without a field (``mag``
    None), the smallest rotation that turns the accelerometer's reading
    up: its heading is arbitrary, as a 6-axis IMU's is."""
    if mag is None:
        return from_rotation(Rotation.align_vectors([references["accelerometer"]], [acc])[0])
    body = np.array([acc / np.linalg.norm(acc), mag / np.linalg.norm(mag)])
    reference = np.array([references[name] / np.linalg.norm(references[name])
                          for name in ("accelerometer", "magnetometer")])
    return wahba.triad(body, reference, np.array([2.0, 1.0]))


def assumptions(recording: Recording, references: dict, sigmas=None) -> tuple:
    """What :func:`imu_inputs` assumed for ``recording``, one line each."""
    field = references.get("magnetometer")
    if field is None:
        field_line = ("no magnetometer: the heading is the gyro's alone, from an arbitrary "
                      "start; every filter is scored on its inclination")
        start = "the smallest rotation that turns the accelerometer's reading up"
    else:
        dip = math.degrees(-math.asin(field[2] / np.linalg.norm(field)))
        field_line = (f"the field for the vector filters: {np.linalg.norm(field):.1f} µT, dip "
                      f"{dip:.1f}°, the medians of the first {FIELD_WINDOW_S:g} s; the MEKF "
                      "learns its own online")
        start = "TRIAD"
    return (f"gravity: the standard {STANDARD_GRAVITY_MPS2} m/s², up (no site given)",
            field_line,
            f"the start: {start} on sample {start_sample(recording)}; noise: "
            f"{noise_words(sigmas, field is not None)}")


def noise_words(sigmas=None, heading: bool = True) -> str:
    """The noise the filters take, in words: the defaults, or ``sigmas``
    (sensor → σ, ``--accelerometer-sigma``, ``--magnetometer-sigma``) where given."""
    given = dict(sigmas or {})
    parts = [f"gyro {GYRO_NOISE_DENSITY:g} rad/√s"] + [
        f"{name} {given.get(name, MOTION_SIGMAS[name]):g} {unit}"
        for name, unit in (("accelerometer", "m/s²"), ("magnetometer", "µT"))
        if heading or name == "accelerometer"]
    which = " and ".join(f"the {name}'s" for name in MOTION_SIGMAS if name in given)
    return f"the defaults{f' but {which} as given' if which else ''} ({', '.join(parts)})"


def assumed(heading: bool = True, sigmas=None) -> str:
    """What every trial's inputs assume, in one line (:func:`assumptions`
    has one trial's numbers); ``heading``: whether the trials have a
    magnetometer (a 6-axis IMU's have not); ``sigmas``: the σ given over
    the defaults (:func:`noise_words`)."""
    start = ("each trial starts on TRIAD of its first usable sample; the vector filters' "
             f"field is the median of its first {FIELD_WINDOW_S:g} s, the MEKF learns its own "
             "online" if heading else "each trial starts level with its first accelerometer "
             "reading, its heading arbitrary (no magnetometer)")
    return (f"nothing is taken from a rest: gravity is the standard {STANDARD_GRAVITY_MPS2} "
            f"m/s² (no site given); {start}; the noise is {noise_words(sigmas, heading)}")


def imu_inputs(recording: Recording, gyro_delay_s: float = 0.0, sigmas=None) -> ImuInputs:
    """``recording`` (with its accelerometer, and its magnetometer if it has one) as an
    :class:`ImuInputs`; ``gyro_delay_s``: how late the gyro's samples are
    (:func:`benchmarks.experiments.replay.delayed_gyro`); ``sigmas``:
    sensor → the σ the vector filters take (:func:`checked_sigmas`)."""
    delay = checked_gyro_delay(recording, gyro_delay_s)
    references, variances = references_and_variances(recording, sigmas)
    n, dt = recording.n_samples, recording.dt
    start = initial_attitude(*start_pair(recording)[1:], references)
    usable = usable_readings(recording)
    vectors = tuple(
        VectorReadings(sensor=name, body=channel, reference=np.tile(references[name], (n, 1)),
                       available=usable[name], variance=np.full(n, variances[name]), unit=UNITS[name],
                       reference_known=name == "accelerometer")
        for name, channel in channels(recording).items())
    priors = {"initial_attitude_sigma_rad": INITIAL_ATTITUDE_SIGMA_RAD,
              "initial_bias_sigma_radps": INITIAL_BIAS_SIGMA_RADPS}
    scenario = Scenario(
        tstop=(n - 1) * dt, dt=dt, initial_state=start, initial_attitude_quat=start,
        gyro_noise=GYRO_NOISE_DENSITY ** 2, gyro_bias_random_walk=GYRO_BIAS_RANDOM_WALK,
        # The estimators see no star tracker; the scenario keeps the workshop's
        # model out of use (an outage throughout) because its own vector
        # sensors are simulated ones, and these readings are recorded.
        star_tracker_model="rotation", star_tracker_outages_s=((0.0, n * dt),),
        estimator_options=recorded_options({"mekf": {**priors, **IMU_MODELS},
                                            "usque": {**priors, **IMU_MODELS},
                                            "ekf": {"gate_probability": GATE_PROBABILITY},
                                            **_vqf_options(usable, dt),
                                            **_timed_already(recording)}))
    sensors = SensorData(omega_meas_radps=delayed_gyro(recording, delay),
                         star_tracker_quat=np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)),
                         available=np.zeros(n, dtype=bool), vectors=vectors)
    return ImuInputs(recording=recording, scenario=scenario, sensors=sensors,
                     references=references, variances=variances,
                     assumptions=assumptions(recording, references, sigmas))
