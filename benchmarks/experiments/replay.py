r"""Replay a recorded gyro against an optical reference attitude.

The estimators meet a real gyro — its real bias, noise and scale errors —
and are scored against an independent reference: the BROAD dataset's
motion-capture attitude (``datasets/broad/``, CC BY 4.0, attribution in its
README) or a user's recording with the same keys
(:func:`sensors.recording.load_recording`).

The star tracker is a *pseudo* star tracker made from that same reference:
the optical attitude every ``interval_s`` (default 1 s), rotated by a small
random error of ``noise_deg`` per axis (default 0.1°, drawn from the seed's
star-tracker stream, :func:`benchmarks.simulation.sensor_generators`), with
the reference's real gaps as outages — :class:`sensors.RotationStarTracker`
applied to the record. So one optical record is both the source of the
readings and the truth they are scored against. The comparison is still
fair: the readings are sparse (one in 286 samples at 1 s) and noisy, and
between them — where nearly every scored sample lies — every estimator runs
on the real gyro alone. (Copying the readings is
:class:`~estimators.DeadReckoningWithResets`, which is scored like the rest.)

Everything else is the simulation's: a :class:`~benchmarks.Scenario` built
from the recording (:func:`replay_scenario`) configures every estimator
through its ``from_scenario``, and :func:`replay` hands back the same
:class:`~benchmarks.simulation.RunResult` that :func:`benchmarks.simulate`
does, so every metric and figure works on it unchanged.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.broad.metric import recording_unscored
from benchmarks.metrics import ARCSEC_PER_DEG, attitude_error_deg
from benchmarks.output import write_csv, write_figure, write_text
from benchmarks.output import progress
from benchmarks.scenario import Scenario
from benchmarks.shipped import shipped_file
from benchmarks.sensor_use import refuse_unreadable
from benchmarks.simulation import RunResult, SensorData, build_estimator, sensor_generators
from dynamics.rigid_body import RigidBodyTruth
from dynamics.validation import InvalidParameterError, finite_number
from estimators.imu import GYRO_NOISE_DENSITY
from sensors.recording import Recording, load_recording
from sensors.vector import readings_taken

#: ``--dataset`` name → the shipped file.
DATASETS = {"broad-02": "datasets/broad/02_undisturbed_slow_rotation_B.npz",
            "broad-07": "datasets/broad/07_undisturbed_fast_rotation_B.npz"}
ATTRIBUTION = ("Data: BROAD, D. Laidig, M. Caruso, A. Cereatti, T. Seel, \"BROAD - A "
               "Benchmark for Robust Inertial Orientation Estimation\", Data 6(7), 2021, "
               "doi:10.3390/data6070072; CC BY 4.0 (converted to .npz, unused channels "
               "dropped).")
DEFAULT_ESTIMATORS = ("dead-reckoning", "ekf", "mekf")
DEFAULT_INTERVAL_S = 1.0
DEFAULT_NOISE_DEG = 0.1
#: The filters' gyro bias model: a random walk of this σ_u (rad/s^1.5), a
#: MEMS gyro's bias instability over minutes; and the prior σ of the bias at
#: switch-on, 0.01 rad/s ≈ 0.6 °/s, which covers a MEMS gyro's turn-on bias.
BIAS_RANDOM_WALK = 1e-4
INITIAL_BIAS_SIGMA_RADPS = 0.01
#: How the estimators take a recorded IMU's gyro: each reading the mean rate
#: over the interval before its sample (an IMU filters its rate inside the
#: sensor), reading 0 the time before the start: the filters'
#: ``rate_interpolation = "end"``, dead reckoning's, Madgwick's and Mahony's
#: ``rate_timing = "end"`` (``broad --case-study`` runs the BROAD authors'
#: filters as they ran them, each step's rate integrated). ``broad``'s
#: inputs take them too.
RECORDED_GYRO = {"mekf": {"rate_interpolation": "end"}, "usque": {"rate_interpolation": "end"},
                 "ekf": {"rate_interpolation": "end"}, "dead-reckoning": {"rate_timing": "end"},
                 "dead-reckoning-resets": {"rate_timing": "end"},
                 **{name: {"rate_timing": "end"} for name in ("madgwick", "madgwick-broad",
                                                              "mahony")}}
#: The six-state filters start on the first reference attitude, within this.
INITIAL_ATTITUDE_SIGMA_RAD = math.radians(1.0)
SUMMARY_COLUMNS = ("estimator", "rms_movement_deg", "mean_deg", "max_deg", "final_deg",
                   "final_bias_error_degps")


def recorded_options(sections: dict) -> dict:
    """A recording's ``estimator_options``: :data:`RECORDED_GYRO`'s sections,
    each estimator's settings in ``sections`` (name → settings) added."""
    return {name: {**RECORDED_GYRO.get(name, {}), **sections.get(name, {})}
            for name in {**RECORDED_GYRO, **sections}}


def open_dataset(dataset: str) -> tuple[Recording, str | None]:
    """The recording ``dataset`` names — ``broad-02``, ``broad-07``, a path
    to an ``.npz``, or a ``[recording]`` ``.toml`` declaring a logger's file
    (:mod:`sensors.declared`) — and the attribution it must carry (None for
    a user's)."""
    if dataset in DATASETS:
        try:
            path = shipped_file(DATASETS[dataset])
        except FileNotFoundError as err:
            raise InvalidParameterError("dataset", dataset, str(err)) from None
        return load_recording(path, name=dataset), ATTRIBUTION
    if str(dataset).endswith(".toml"):
        from sensors.declared import load_declared
        recording = load_declared(dataset)
        if not recording.has_reference.any():
            raise InvalidParameterError("dataset", str(dataset), "declares no reference attitude "
                                        "([recording.reference]): replay scores against one; "
                                        "broad ranks a recording without one by agreement")
        return with_found_rest(recording), None
    if not str(dataset).endswith(".npz"):
        raise InvalidParameterError("dataset", dataset, f"must be one of {', '.join(DATASETS)}, "
                                    "a path to a .npz recording or a [recording] .toml")
    return load_recording(dataset), None


def with_found_rest(recording: Recording) -> Recording:
    """A logger's ``recording``, whose every sample with a reference is
    movement (no declaration flags a rest), with the rest it begins with
    taken out of its movement phase: VQF's rest (Laidig & Seel 2023, §3.4;
    :func:`benchmarks.experiments.inspection.rest_periods`: the gyro, and the
    accelerometer where there is one, within their thresholds for at least
    1.5 s) from its first sample. There, as in a BROAD trial's rest, the
    gyro's noise and bias are taken; a note says how long it is. Where none
    is found, it moves from its first sample: no rest, even before its
    reference begins; where the rest lasts to its end, it is still
    throughout, and every sample is scored."""
    import warnings
    from dataclasses import replace
    from benchmarks.experiments.inspection import rest_periods
    from estimators.imu.rest import MIN_DURATION_S
    from sensors.turning import held_readings
    force = (np.zeros_like(recording.gyro_radps) if recording.accelerometer_mps2 is None
             else held_readings(recording.accelerometer_mps2))
    read = np.flatnonzero(readings_taken(force))
    if len(read):                    # before its first reading, the accelerometer's first
        force[:read[0]] = force[read[0]]
    periods = rest_periods(recording.gyro_radps, force, recording.dt)
    if not periods or periods[0][0] > 0.0:   # no rest: it moves from its first sample
        return replace(recording, movement=np.ones(recording.n_samples, dtype=bool))
    end = int(round(periods[0][1] / recording.dt))
    both = " and the accelerometer" if recording.accelerometer_mps2 is not None else ""
    still = f"the gyro{both} still within VQF's thresholds"
    if (recording.n_samples - end) * recording.dt < MIN_DURATION_S:     # no movement after it
        warnings.warn(f"{recording.name}: it is at rest throughout ({still}): nothing moves, "
                      "and every sample is scored, no rest taken out", stacklevel=2)
        return replace(recording, movement=np.ones(recording.n_samples, dtype=bool))
    warnings.warn(f"{recording.name}: its first {end * recording.dt:.1f} s are at rest ({still}): "
                  "the gyro's noise and bias are taken there and the movement is scored after "
                  "it", stacklevel=2)
    # movement from the rest's end on (scored where the reference is): the
    # rest is the samples before it, even where the reference begins later
    return replace(recording, movement=np.arange(recording.n_samples) >= end)


def dataset_source(dataset: str) -> tuple:
    """``("recording", digest)``: what the recording ``dataset`` names holds
    (a SHA-256 of its file), so that one file named two ways (``broad-02``
    and its path, a copy) is known for one recording."""
    import hashlib
    if dataset not in DATASETS and not str(dataset).endswith((".npz", ".toml")):
        open_dataset(dataset)           # its refusal, one line
    try:
        path = shipped_file(DATASETS[dataset]) if dataset in DATASETS else Path(dataset)
        digest = hashlib.sha256(Path(path).read_bytes())
        if str(dataset).endswith(".toml"):      # the declaration and the file it reads
            from sensors.declared import data_files, read_declaration
            for data in data_files(path, read_declaration(path)):
                digest.update(data.read_bytes())
        digest = digest.hexdigest()
    except OSError as err:
        raise InvalidParameterError("dataset", dataset, f"cannot be read "
                                    f"({err.strerror or err})") from None
    return ("recording", digest)


#: The largest σ of the pseudo star tracker per axis, degrees.
MAX_NOISE_DEG = 90.0


def interval_steps(recording: Recording, interval_s: float) -> int:
    """``interval_s`` in whole samples of ``recording``, checked."""
    interval_s = finite_number("star_tracker_interval", interval_s, strictly_positive=True)
    # round(inf) would overflow: the ratio is checked before the steps are counted
    if interval_s / recording.dt < recording.n_samples:
        steps = max(1, round(interval_s / recording.dt))
        if steps < recording.n_samples:
            return steps
    raise InvalidParameterError("star_tracker_interval", interval_s,
                                f"must be shorter than the recording "
                                f"({recording.n_samples * recording.dt:.4g} s; "
                                "--star-tracker-interval, 1 s by default)")


def replay_scenario(recording: Recording, interval_s: float = DEFAULT_INTERVAL_S,
                    noise_deg: float = DEFAULT_NOISE_DEG, rest=None) -> Scenario:
    """The scenario that configures every estimator for ``recording``.

    ``noise_deg`` must be positive: the filters weigh each reading by its
    error covariance, which must be positive definite.

    Its grid is the recording's (``dt`` = 1 / rate), its star tracker the
    pseudo star tracker (``interval_s`` rounded to whole samples, ``noise_deg``
    per axis, the reference's gaps as outages), its gyro noise power the
    variance of the gyro over the initial rest times ``dt`` (without a rest,
    the MEMS gyro's density the IMU filters take,
    :data:`estimators.imu.GYRO_NOISE_DENSITY`, squared), and every filter
    starts on the first reference attitude: the additive EKF with
    R = (σ/2)² I₄ and a Q that covers the gyro's noise and the drift the rest
    bias, which it cannot estimate, causes over a reading interval (derived
    from the rest phase and the interval, not tuned on the movement), the
    six-state filters with a bias prior wide enough for
    a MEMS gyro (:data:`INITIAL_BIAS_SIGMA_RADPS`). ``rest``: the gyro's
    samples at rest, where they are not the recording's own (a rest before
    its reference begins, cut off with it).
    """
    steps = interval_steps(recording, interval_s)
    noise_deg = finite_number("star_tracker_noise_deg", noise_deg, strictly_positive=True)
    if noise_deg > MAX_NOISE_DEG:
        raise InvalidParameterError("star_tracker_noise_deg", noise_deg,
                                    f"must be at most {MAX_NOISE_DEG:g}°: beyond it a reading "
                                    "says nothing of the attitude")
    dt = recording.dt
    rest = recording.rest_gyro_radps() if rest is None else rest
    noise_power = (float(np.mean(rest.var(axis=0)) * dt) if len(rest) > 1
                   else GYRO_NOISE_DENSITY ** 2)
    bias = rest.mean(axis=0) if len(rest) else np.zeros(3)
    sigma_rad = math.radians(noise_deg)
    # The EKF's Q per step on each quaternion component: the gyro noise,
    # (dt/2)² σ_ω², plus the drift of the bias it cannot estimate, as a random
    # walk whose spread over one reading interval T (n = T/dt steps) equals
    # that drift: n Q = (β T / 2)², so Q = (β/2)² T dt.
    interval = steps * dt
    q_variance = (dt / 2) ** 2 * noise_power / dt + float(np.mean(bias ** 2)) / 4 * interval * dt
    six_state = {"initial_attitude_sigma_rad": INITIAL_ATTITUDE_SIGMA_RAD,
                 "initial_bias_sigma_radps": INITIAL_BIAS_SIGMA_RADPS}
    gaps = tuple((start * dt, stop * dt) for start, stop in recording.reference_gaps())
    first = recording.reference_quat[np.argmax(recording.has_reference)]
    return Scenario(
        tstop=(recording.n_samples - 1) * dt, dt=dt, initial_state=first,
        initial_attitude_quat=first,
        gyro_noise=noise_power, gyro_bias_random_walk=BIAS_RANDOM_WALK,
        star_tracker_model="rotation", star_tracker_sigma_arcsec=[noise_deg * ARCSEC_PER_DEG] * 3,
        time_between_measurements=interval, star_tracker_outages_s=gaps,
        measurement_covariance=(sigma_rad / 2) ** 2 * np.eye(4),
        pc_exponent=math.log(max(q_variance, 1e-300)),
        estimator_options=recorded_options({"mekf": six_state, "usque": six_state}))


#: What a replay gives the estimators: the gyro, and the pseudo star tracker.
REPLAY_SENSORS = frozenset({"star_tracker"})


def pseudo_star_tracker(recording: Recording, scenario: Scenario, seed: int):
    """The pseudo star tracker's held readings and ``available`` flags."""
    filled = np.where(recording.has_reference[:, None], recording.reference_quat,
                      [1.0, 0.0, 0.0, 0.0])     # never read: the gaps are outages
    return scenario.build_star_tracker().measure(filled, sensor_generators(seed)[1])


@dataclass(frozen=True)
class Replay:
    """A replayed recording: the run (as :func:`benchmarks.simulate` returns
    it, with traces), the recording itself, from its first reference
    attitude on, and the gyro's mean over the initial rest."""

    run: RunResult
    recording: Recording
    start_sample: int
    rest_bias_radps: np.ndarray
    attribution: str | None

    @property
    def time_s(self) -> np.ndarray:
        """Time since the start of the recording, seconds."""
        return (self.start_sample + np.arange(self.recording.n_samples)) * self.recording.dt

    def summary(self) -> pd.DataFrame:
        """Per estimator: RMS error over the movement phase (the dataset authors'
        scoring), mean, max and final error over the samples with a reference,
        and the final bias estimate's largest axis error against the rest
        mean (°/s; NaN without a bias estimate, or without a rest)."""
        scored = self.recording.has_reference
        movement = scored & self.recording.movement
        rows = []
        for name, error in self.run.error_deg.items():
            trace = self.run.traces[name]
            bias_error = (np.nan if trace.bias_radps is None else float(np.degrees(
                np.abs(trace.bias_radps[-1] - self.rest_bias_radps).max())))
            rows.append({"estimator": name,
                         "rms_movement_deg": float(np.sqrt(np.mean(error[movement] ** 2)))
                         if movement.any() else np.nan,
                         "mean_deg": float(error[scored].mean()),
                         "max_deg": float(error[scored].max()),
                         "final_deg": float(error[scored][-1]),
                         "final_bias_error_degps": bias_error})
            if (self.run.diverged_step or {}).get(name, -1) >= 0:     # no number to score
                rows[-1].update({column: np.nan for column in SUMMARY_COLUMNS[1:]})
        return pd.DataFrame(rows, columns=list(SUMMARY_COLUMNS))


@dataclass(frozen=True)
class ReplayData:
    """What the simulation would hand the estimators, made from a recording:
    the scenario that configures them, the truth (the reference attitude,
    NaN in its gaps; the rate is not observed, so NaN too) and the sensor
    data (the real gyro, the pseudo star tracker's readings and flags), on
    the recording from its first reference attitude on."""

    scenario: Scenario
    truth: RigidBodyTruth
    sensors: SensorData
    recording: Recording
    start_sample: int
    rest_bias_radps: np.ndarray
    attribution: str | None


def load_replay(dataset: str, interval_s: float = DEFAULT_INTERVAL_S,
                noise_deg: float = DEFAULT_NOISE_DEG, seed: int = 0,
                settings=None, allow_imports=(), gyro_delay_s: float = 0.0,
                scored: bool = True) -> ReplayData:
    """``dataset`` (see :func:`open_dataset`) made ready for any estimator;
    ``settings``, a TOML file of ``[estimators.NAME]`` sections, overrides
    what :func:`replay_scenario` derives (importing only the users' modules
    named in ``allow_imports``, see :meth:`Scenario.from_toml`);
    ``gyro_delay_s`` is how late the gyro's samples are against the
    reference (:func:`delayed_gyro`). ``scored``: the recording is to be
    scored against its reference, and is refused where it has nothing to
    score (a recording read only by the filters' innovations need not)."""
    recording, attribution = open_dataset(dataset)
    unscored = recording_unscored(recording) if scored else None
    if unscored is not None:
        raise InvalidParameterError("dataset", dataset, f"nothing to score: it {unscored}")
    delay = checked_gyro_delay(recording, gyro_delay_s)
    interval_steps(recording, interval_s)       # named against the whole recording
    rest_bias = recording.rest_gyro_mean_radps()
    whole_rest = recording.rest_gyro_radps()
    start = int(np.argmax(recording.has_reference))
    recording = recording.from_sample(start)
    # the rest within the scored part; where the reference begins after it, the rest before
    own_rest = recording.rest_gyro_radps()
    scenario = replay_scenario(recording, interval_s, noise_deg,
                               own_rest if len(own_rest) > 1 else whole_rest)
    if settings is not None:
        scenario = scenario.with_estimator_settings(settings, allow_imports=allow_imports)
    readings = pseudo_star_tracker(recording, scenario, seed)
    sensors = SensorData(omega_meas_radps=delayed_gyro(recording, delay),
                         star_tracker_quat=readings.quat, available=readings.available)
    truth = RigidBodyTruth(time_s=recording.time_s, q_true=recording.reference_quat,
                           omega_true_radps=np.full((recording.n_samples, 3), np.nan))
    return ReplayData(scenario=scenario, truth=truth, sensors=sensors, recording=recording,
                      start_sample=start, rest_bias_radps=rest_bias, attribution=attribution)


#: The largest gyro delay :func:`load_replay` takes, in samples.
MAX_GYRO_DELAY_SAMPLES = 50


def checked_gyro_delay(recording: Recording, delay_s) -> float:
    """``delay_s`` as a number within ±:data:`MAX_GYRO_DELAY_SAMPLES` samples."""
    delay = finite_number("gyro_delay", delay_s)
    if abs(delay) > MAX_GYRO_DELAY_SAMPLES * recording.dt:
        raise InvalidParameterError("gyro_delay", delay_s, f"must be within "
                                    f"±{MAX_GYRO_DELAY_SAMPLES} samples "
                                    f"(±{MAX_GYRO_DELAY_SAMPLES * recording.dt:g} s)")
    return delay


def delayed_gyro(recording: Recording, delay_s: float) -> np.ndarray:
    r"""The gyro as the estimators take it when its samples come ``delay_s``
    late against the reference: the reading of sample :math:`k` is the
    recording's at :math:`t_k + \text{delay}`, linearly
    interpolated (the first and last samples held at the ends). An IMU's
    internal low-pass filters and its clock against the motion capture's
    delay its rate by a few milliseconds; the estimators take each sample
    as the rate over the step before it (:data:`RECORDED_GYRO`), so a delay
    is an attitude error of the rate times the delay (at 1,400 °/s, 7° per
    5 ms)."""
    if not delay_s:
        return recording.gyro_radps
    time_s = recording.time_s
    return np.column_stack([np.interp(time_s + delay_s, time_s, recording.gyro_radps[:, axis])
                            for axis in range(3)])


def replay(dataset: str, estimators=DEFAULT_ESTIMATORS, interval_s: float = DEFAULT_INTERVAL_S,
           noise_deg: float = DEFAULT_NOISE_DEG, seed: int = 0, quiet: bool = True,
           settings=None) -> Replay:
    """Replay ``dataset`` (see :func:`open_dataset`) through ``estimators``
    (registry names, ``package.module:Class`` specs); ``settings`` as for
    :func:`load_replay`."""
    return run_replay(load_replay(dataset, interval_s, noise_deg, seed, settings), estimators,
                      seed, quiet)


def run_replay(data: ReplayData, estimators=DEFAULT_ESTIMATORS, seed: int = 0,
               quiet: bool = True) -> Replay:
    """Run ``estimators`` on data from :func:`load_replay` (made with ``seed``)."""
    sensors = data.sensors
    refuse_unreadable(estimators, REPLAY_SENSORS, "the replay")
    estimates, errors, labels, traces, diverged = {}, {}, {}, {}, {}
    for name in progress(estimators, desc="replay", unit="estimator", quiet=quiet):
        estimator = build_estimator(name, data.scenario)
        traces[name] = estimator.track(sensors.omega_meas_radps, sensors.star_tracker_quat,
                                       sensors.available)
        estimates[name] = traces[name].quat
        errors[name] = attitude_error_deg(data.truth.q_true, estimates[name])
        labels[name] = estimator.label
        diverged[name] = -1 if estimator.diverged_step is None else estimator.diverged_step
    run = RunResult(scenario=data.scenario, seed=seed, truth=data.truth, sensors=sensors,
                    estimates=estimates, error_deg=errors, labels=labels, traces=traces,
                    diverged_step=diverged)
    return Replay(run=run, recording=data.recording, start_sample=data.start_sample,
                  rest_bias_radps=data.rest_bias_radps, attribution=data.attribution)


def write_replay(result: Replay, out: Path) -> pd.DataFrame:
    """Write ``replay.png``, ``summary.csv`` and, for a shipped dataset,
    ``ATTRIBUTION.txt`` (CC BY 4.0 asks it of derived material)."""
    from benchmarks.figures.replay import replay_figure
    out = Path(out)
    summary = result.summary()
    write_figure(out / "replay.png", replay_figure(result))
    write_csv(out / "summary.csv", SUMMARY_COLUMNS,
              (list(row) for row in summary.itertuples(index=False)))
    if result.attribution:
        write_text(out / "ATTRIBUTION.txt", "replay.png and summary.csv derive from:\n"
                   + result.attribution + "\n")
    return summary
