"""Every estimator on every BROAD trial, scored by the authors' metric
(:mod:`benchmarks.broad.metric`): a tidy table of one row per trial and
estimator, and the group means as ``trials.json`` defines the groups (their
figures: :mod:`benchmarks.broad.figures`).

Every number says what it was taken on. A trial's row counts its samples,
those of its movement and those scored (with a reference), and, for the
filters that test their readings, the share of each sensor's readings they
rejected. A group's mean names how many of its trials it holds: a trial
with nothing to score is left out of every mean by name (``all_trials (1
of 2 scored)`` and a note saying why), and an estimator whose score is NaN
on one of a group's scored trials (it diverged there) has a NaN mean for
that group, as the metric's own RMSE is NaN when an estimate is not
finite on one scored sample: a mean over the trials it survived would
flatter exactly the estimator that failed. A selection with nothing to
score at all is an error.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import pandas as pd

from benchmarks.broad.agreement import AGAINST, AGAINST_LEVELLED, AGREEMENT, agreement_scores
from benchmarks.broad.dataset import BroadDataset, trial_label
from benchmarks.broad.inputs import heading_scored, imu_inputs
from benchmarks.broad.trial_notes import note_magnetometer_delay
from benchmarks.broad.tuning import judged_samples
from benchmarks.broad.metric import CLAIMED, METRICS, claimed_deg, errors_deg, rmse_of, \
    scored_samples, unscored_reason, without_heading
from dynamics.validation import InvalidParameterError
from benchmarks.engine.recorded import field_timed, path_of, run_recorded
from benchmarks.output import progress
from estimators import resolve_estimator

#: ``broad`` without ``--estimators``: the textbook filter and its smoother
#: (offline), a static solution, dead reckoning and the complementary
#: filters; the peers when installed (:func:`default_estimators`).
DEFAULT_ESTIMATORS = ("dead-reckoning", "triad", "mekf", "mekf-smoother", "usque", "madgwick",
                      "madgwick-broad", "mahony")
PEERS = ("vqf", "vqf-6d", "vqf-offline", "fusion")
#: The vector sensors, in the tables' order, and their short names.
SENSORS = {"accelerometer": "acc", "magnetometer": "mag"}
TRIAL_COLUMNS = ("trial", "estimator", "mode", *METRICS, *CLAIMED, "us_per_sample",
                 "samples", "movement_samples", "scored_samples",
                 "rejected_accelerometer", "rejected_magnetometer",
                 "rejected_accelerometer_share", "rejected_magnetometer_share",
                 "diverged_step", "path", "magnetometer_delay_ms", *AGREEMENT)
GROUP_COLUMNS = ("group", "level", "estimator", "trials", "scored_trials", *METRICS,
                 "left_out", "nan_on")
#: What the scores are taken against where a trial has a reference.
REFERENCE = "the reference"


def default_estimators() -> tuple:
    """:data:`DEFAULT_ESTIMATORS`, and :data:`PEERS` whose packages are installed."""
    import importlib.util
    modules = {"vqf": "vqf", "vqf-6d": "vqf", "vqf-offline": "vqf", "fusion": "imufusion"}
    return DEFAULT_ESTIMATORS + tuple(name for name in PEERS
                                      if importlib.util.find_spec(modules[name]) is not None)


@dataclass(frozen=True)
class BroadResult:
    trials: pd.DataFrame         # TRIAL_COLUMNS
    groups: pd.DataFrame         # GROUP_COLUMNS
    labels: dict                 # estimator → label
    curves: dict                 # the first scored trial's: estimator → (time_s, total error °)
    curve_trial: str
    tuning: str = "none"         # how the settings were chosen (benchmarks.broad.tuning.MODES)
    curve_movement: np.ndarray | None = None     # that trial's movement flags (N,)
    #: What the scores are taken against: the reference, or (no trial has
    #: one) :data:`benchmarks.broad.agreement.AGAINST`.
    against: str = REFERENCE
    #: The data's name in titles (:attr:`BroadDataset.title`).
    dataset_title: str = "BROAD"
    #: Whether no trial has a magnetometer (a 6-axis IMU's): every score
    #: is then the inclination's (:meth:`BroadDataset.sensors`).
    headless: bool = False

    @property
    def by_agreement(self) -> bool:
        """Whether the scores are the estimators' agreement, not accuracy."""
        return self.against != REFERENCE

    @property
    def metric(self) -> str:
        """The score the group table ranks by: the total RMSE, or the
        inclination's where :attr:`headless`."""
        return "inclination_rmse_deg" if self.headless else "total_rmse_deg"

    @property
    def dt(self) -> float:
        """The first trial's sample interval, s (for the divergence report)."""
        time_s = next(iter(self.curves.values()))[0]
        return float(time_s[1] - time_s[0])


def run_trial(dataset: BroadDataset, trial: str, estimators, gyro_delay_s: float = 0.0,
              sigmas=None, options=None, agreement: bool = False,
              second_half: bool = False) -> tuple[list, dict, dict]:
    """Each of ``estimators`` on ``trial`` (:func:`benchmarks.broad.inputs.imu_inputs`
    with ``gyro_delay_s`` and ``sigmas``; ``options``: estimator → settings
    over its defaults, a tuned set for this trial), through the engine where it can
    (:func:`benchmarks.engine.recorded.run_recorded`): its rows (a diverged
    estimator's scores NaN, its step in ``diverged_step``, else -1), total
    errors over time, labels. The estimators' agreement
    (:mod:`benchmarks.broad.agreement`) is scored where the trial has no
    reference, and on every trial with ``agreement`` (NaN where not). With
    ``second_half``, every estimator runs the whole trial and is scored on its
    second half only (``--tune halves`` tuned on the first)."""
    recording = dataset.load(trial)
    inputs = imu_inputs(recording, gyro_delay_s, sigmas)
    # after the inputs' checks: a refusal is one line
    note_magnetometer_delay(recording, dataset.files[trial], dataset.magnetometer_delay)
    sensors = inputs.sensors
    readings = {v.sensor: int(np.count_nonzero(v.available)) for v in sensors.vectors}
    judged = judged_samples(recording, second_half)
    movement = recording.movement & judged
    scored = int(np.count_nonzero(scored_samples(recording.reference_quat, movement)))
    rows, curves, labels, estimates, members, observers = [], {}, {}, {}, [], set()
    for name in estimators:
        estimator = resolve_estimator(name).from_scenario(inputs.scenario,
                                                          **(options or {}).get(name, {}))
        _warm_up(estimator, sensors)
        start = time.perf_counter()
        run = run_recorded(estimator, sensors.omega_meas_radps, sensors.vectors)
        seconds = time.perf_counter() - start
        errors = errors_deg(run.estimates, recording.reference_quat)
        heading = heading_scored(type(estimator), recording)
        scores = _scores(errors, run, recording.reference_quat, movement, heading)
        rows.append({"trial": trial, "estimator": name, "mode": estimator.mode, **scores,
                     "us_per_sample": 1e6 * seconds / recording.n_samples,
                     "samples": recording.n_samples,
                     "movement_samples": int(np.count_nonzero(movement)),
                     "scored_samples": scored, **_rejections(estimator, run, readings),
                     **_run_columns(run)})
        curves[name] = (recording.time_s, errors["total" if heading else "inclination"])
        labels[name] = estimator.label + ("" if heading else f" {INCLINATION_ONLY}") + (
            " [offline]" if estimator.mode == "offline" else "")
        estimates[name] = run.estimates[judged]
        if heading:
            observers.add(name)
            if run.diverged_step is None:
                members.append(name)
    unreferenced = not recording.has_reference.any()
    if not observers:       # a 6-axis IMU: the inclinations agree or not, the headings apart
        members = [row["estimator"] for row in rows if row["diverged_step"] == -1]
        estimates = {name: without_heading(q) for name, q in estimates.items()}
    if unreferenced or agreement:
        scores, agreement_curves = agreement_scores(estimates, members, observers)
        for row in rows:
            row.update(scores[row["estimator"]])
        if unreferenced:
            curves = {name: (recording.time_s[judged], curve)
                      for name, curve in agreement_curves.items()}
    return rows, curves, labels


def _run_columns(run) -> dict:
    """A run's own columns: where it diverged (-1: never), the path it took,
    and the delay an offline estimator took out of its field's timing (ms;
    NaN: none)."""
    return {"diverged_step": -1 if run.diverged_step is None else run.diverged_step,
            "path": run.path,
            "magnetometer_delay_ms": math.nan if run.magnetometer_delay_s is None
            else 1e3 * run.magnetometer_delay_s}


#: A label's mark for an estimator scored on its inclination alone.
INCLINATION_ONLY = "[inclination only]"
#: The notes' one line where no estimator has a heading reference.
HEADLESS = ("no magnetometer: every filter is scored on its inclination alone (its heading is "
            "its gyro's, from an arbitrary start); the total and heading RMSE are NaN")


def shown_labels(result) -> dict:
    """Estimator → its label in figures: :attr:`BroadResult.labels`, less
    the inclination mark where every estimator carries it (:data:`HEADLESS`
    says so once)."""
    if not result.headless:
        return dict(result.labels)
    return {name: label.replace(f" {INCLINATION_ONLY}", "") for name, label in
            result.labels.items()}


def inclination_only(result) -> set:
    """The estimators of ``result`` scored on their inclination alone."""
    return {name for name, label in result.labels.items() if INCLINATION_ONLY in label}


def _scores(errors: dict, run, reference: np.ndarray, movement: np.ndarray,
            heading: bool) -> dict:
    """:data:`METRICS` of ``run`` (its ``errors``) and :data:`CLAIMED`. Without
    a ``heading`` reference (VQF 6D) its heading is the gyro's, and its total
    would rank a heading that happens to start near the reference's: only its
    inclination is a score."""
    scores = {**rmse_of(errors, run.estimates, reference, movement),
              **claimed_deg(run.estimates, run.attitude_covariance, reference, movement)}
    if not heading:
        scores.update(total_rmse_deg=math.nan, heading_rmse_deg=math.nan,
                      heading_sd_deg=math.nan)
    return scores


def _rejections(estimator, run, readings: dict) -> dict:
    """Per sensor, the readings ``run`` rejected and their share of the
    ``readings`` (NaN for a sensor the estimator does not test, or that the
    recording has not)."""
    tested = tests_readings(estimator)
    return {**{f"rejected_{sensor}": run.rejected.get(sensor, 0) if sensor in readings
               else math.nan for sensor in SENSORS},
            **{f"rejected_{sensor}_share":
               run.rejected.get(sensor, 0) / readings[sensor]
               if tested[sensor] and readings.get(sensor) else math.nan
               for sensor in SENSORS}}


def tests_readings(estimator) -> dict:
    """``sensor → bool``: whether ``estimator`` tests that sensor's readings
    and counts those it rejects (a χ² gate, ``gate_probability``; for the
    magnetometer also a test of the field's magnitude,
    ``magnetic_norm_tolerance``, or the heading model's trust,
    :mod:`estimators.imu.heading`); the low-passed gravity model
    (:mod:`estimators.imu.gravity`) takes every reading it is not gated on, a
    known 0. The others take every reading, or weigh or reject them inside
    a library that does not say (VQF): their share of rejected readings is
    unknown, NaN, not 0."""
    if not getattr(estimator, "uses_vector_readings", False):
        return {sensor: False for sensor in SENSORS}
    gated = getattr(estimator, "gate_probability", None) is not None
    normed = getattr(estimator, "magnetic_norm_tolerance", None) is not None
    lowpass = getattr(estimator, "gravity_model", None) == "lowpass"
    heading = getattr(estimator, "magnetometer_model", None) == "heading"
    return {"accelerometer": gated or lowpass, "magnetometer": gated or normed or heading}


_WARM = set()


def _warm_up(estimator, sensors) -> None:
    """The first run of a compiled path in a process loads (or compiles) its
    machine code: done once on a few samples, so that no trial's time per
    sample counts it; nor the field's timing, the trial's, shared by the
    offline estimators (:func:`sensors.delay.timed_readings` keeps it)."""
    field_timed(estimator, sensors.omega_meas_radps, sensors.vectors)
    key = (type(estimator), path_of(estimator, sensors.vectors))
    if key[1] in ("kernel", "compiled") and key not in _WARM:
        run_recorded(estimator, sensors.omega_meas_radps[:4],
                     [v.steps(slice(4)) for v in sensors.vectors])
        _WARM.add(key)


def unscored_trials(trials: pd.DataFrame) -> dict:
    """``trial → why`` for the trials of the tidy table with nothing to
    score (:func:`benchmarks.broad.metric.unscored_reason`)."""
    first = trials.drop_duplicates("trial")
    return {row.trial: why for row in first.itertuples()
            if (why := unscored_reason(int(row.movement_samples), int(row.scored_samples)))}


def group_means(dataset: BroadDataset, trials: pd.DataFrame) -> pd.DataFrame:
    """Each group's plain mean over its trials run that have something to
    score (the authors' group score), per estimator (:data:`GROUP_COLUMNS`):
    ``trials`` the group's trials run, ``scored_trials`` those in the mean,
    ``left_out`` the others and why; an estimator's mean is NaN where its
    score on one of the scored trials is (``nan_on`` names them: module
    docstring). Groups with none of the trials run are left out."""
    rows = []
    run = set(trials["trial"])
    unscored = unscored_trials(trials)
    for group in dataset.groups:
        members = [t for t in dataset.members(group.name) if t in run]
        if not members:
            continue
        scored = [t for t in members if t not in unscored]
        left_out = "; ".join(f"{trial_label(t)} {unscored[t]}" for t in members if t in unscored)
        part = trials[trials["trial"].isin(scored)]
        for name in dict.fromkeys(trials["estimator"]):
            scores = part[part["estimator"] == name]
            missing = scores[scores[list(METRICS)].isna().any(axis=1)]["trial"]
            means = {metric: (scores[metric].mean(skipna=False) if scored else math.nan)
                     for metric in METRICS}
            rows.append({"group": group.name, "level": group.level, "estimator": name,
                         "trials": len(members), "scored_trials": len(scored), **means,
                         "left_out": left_out, "nan_on": ",".join(map(trial_label, missing))})
    return pd.DataFrame(rows, columns=list(GROUP_COLUMNS))


def run_broad(dataset: BroadDataset, trials, estimators, gyro_delay_s: float = 0.0,
              sigmas=None, quiet: bool = False, workers: int = 0,
              options=None, tuning: str = "none", agreement: bool = False) -> BroadResult:
    """:func:`run_trial` over ``trials`` (on a local Dask cluster of
    ``workers`` processes, one trial per task, if ``workers``), with
    ``options``: trial → its estimators' settings
    (:func:`benchmarks.broad.tuning.tuned_options` under ``tuning``, a
    :data:`~benchmarks.broad.tuning.MODES` name); the tidy table and the
    group means."""
    from benchmarks.engine.runner import map_tasks
    repeated = [trial for i, trial in enumerate(trials) if trial in trials[:i]]
    if repeated:        # it would count twice in every mean (BroadDataset.selected says so first)
        raise InvalidParameterError("trials", trial_label(repeated[0]), f"names trial "
                                    f"{repeated[0]} a second time; each trial may be named once")
    rows, labels = [], {}
    arguments = [(dataset, trial, tuple(estimators), gyro_delay_s, sigmas,
                  (options or {}).get(trial), agreement, tuning == "halves") for trial in trials]
    with progress(total=len(trials), desc="broad", unit="trial", quiet=quiet) as bar:
        results = map_tasks(run_trial, arguments, workers, bar)
    for found, _, names in results:
        rows += found
        labels.update(names)
    frame = pd.DataFrame(rows, columns=list(TRIAL_COLUMNS))
    unscored = unscored_trials(frame)
    if len(unscored) == len(trials):
        return _by_agreement(dataset, trials, frame, labels, results, tuning, unscored)
    shown = next(i for i, trial in enumerate(trials) if trial not in unscored)
    return BroadResult(trials=frame, groups=group_means(dataset, frame), labels=labels,
                       curves=results[shown][1], curve_trial=trials[shown], tuning=tuning,
                       curve_movement=dataset.load(trials[shown]).movement,
                       dataset_title=dataset.title,
                       headless="magnetometer" not in dataset.sensors(trials))


def _by_agreement(dataset, trials, frame, labels, results, tuning, unscored) -> BroadResult:
    """Nothing to score against a reference: the estimators ranked by their
    agreement with the others (:mod:`benchmarks.broad.agreement`), every
    sample of every trial scored against the others' median, said as such;
    an error if no total could be scored (fewer than two estimators that
    observe the heading ran through)."""
    headless = "magnetometer" not in dataset.sensors(trials)
    if not np.isfinite(frame[list(AGREEMENT)].to_numpy(dtype=float)).any():
        raise InvalidParameterError("trials", ",".join(map(trial_label, trials)), "nothing to "
                                    "score: " + "; ".join(f"{t} {why}"
                                                          for t, why in unscored.items()) +
                                    "; and fewer than two estimators " +
                                    ("ran through" if headless else "observe the heading") +
                                    ", so they cannot be ranked by their agreement either")
    scored = frame.copy()
    scored[list(METRICS)] = frame[list(AGREEMENT)].to_numpy()
    scored["movement_samples"] = scored["scored_samples"] = scored["samples"]
    return BroadResult(trials=scored, groups=group_means(dataset, scored), labels=labels,
                       curves=results[0][1], curve_trial=trials[0], tuning=tuning,
                       against=AGAINST_LEVELLED if headless else AGAINST,
                       dataset_title=dataset.title, headless=headless)


#: The CSVs' word for what every score in them was taken against.
SCORED_AGAINST = {REFERENCE: "reference", AGAINST: "others' median",
                  AGAINST_LEVELLED: "others' median"}


def with_scored_against(frame: pd.DataFrame, result: BroadResult) -> pd.DataFrame:
    """``frame`` (trials or groups) with a ``scored_against`` column beside
    its estimator: ``reference``, or ``others' median`` where no trial has
    a reference and every score under the RMSE columns is agreement; in a
    folder mixing trials with and without one, ``none`` on the rows of a
    trial with nothing scored (its RMSE columns NaN, its agreement columns
    filled where it has no reference)."""
    marked = frame.copy()
    against = np.full(len(marked), SCORED_AGAINST[result.against], dtype=object)
    if result.against == REFERENCE and "scored_samples" in marked:
        against[marked["scored_samples"].to_numpy() == 0] = "none"
    marked.insert(marked.columns.get_loc("estimator") + 1, "scored_against", against)
    return marked


def group_header(group: str, trials: int, scored: int) -> str:
    """A group's name and how many trials its mean holds: ``rotation (2)``,
    or ``rotation (1 of 2 scored)``."""
    return f"{group} ({trials})" if scored == trials else f"{group} ({scored} of {trials} scored)"


def group_notes(result: BroadResult) -> list[str]:
    """What the group table leaves out, and where it is NaN, and why."""
    notes = [f"left out of the means: {trial} {why}"
             for trial, why in unscored_trials(result.trials).items()]
    failed = result.groups.drop_duplicates(["estimator", "nan_on"])
    failed = failed[failed["nan_on"].astype(str).str.len() > 0]
    blind = inclination_only(result)
    notes += [HEADLESS] if result.headless else [
        f"NaN: {name} has no total or heading score (no heading reference); its "
        "inclination RMSE is scored (broad_groups.csv; broad.png's inclination panel)"
        for name in sorted(blind)]
    failed = failed[~failed["estimator"].isin(blind)]
    for row in failed.drop_duplicates("estimator").itertuples():
        trials = sorted(set(",".join(failed[failed.estimator == row.estimator]["nan_on"])
                            .split(",")))
        notes.append(f"NaN: {row.estimator} has no score on trial {', '.join(trials)} (it "
                     "diverged there), so neither has it on the groups that hold it")
    return notes


def format_groups(result: BroadResult, metric: str = "total_rmse_deg") -> str:
    """Estimators × groups of ``metric`` (degrees), each group headed by
    how many trials its mean holds (:func:`group_header`), and the notes
    (:func:`group_notes`)."""
    groups = result.groups
    columns = {}
    for group, part in groups.groupby("group", sort=False):
        first = part.iloc[0]
        columns[group_header(group, int(first["trials"]), int(first["scored_trials"]))] = \
            part.set_index("estimator")[metric]
    table = pd.DataFrame(columns)
    table.index.name = "estimator"
    modes = result.trials.get("mode")
    offline = set() if modes is None else set(result.trials.loc[modes == "offline", "estimator"])
    table.index = [f"{name} (offline)" if name in offline else name for name in table.index]
    table.index.name = "estimator"
    text = table.to_string(float_format=lambda v: f"{v:.3f}", na_rep="NaN")
    notes = ["(offline): a smoother, each estimate from the whole recording, before and after "
             "it; the others are online, each from the readings up to it"] if offline else []
    timed = result.trials.get("magnetometer_delay_ms")
    if timed is not None and timed.notna().any():
        names = ", ".join(sorted(set(result.trials.loc[timed.notna(), "estimator"])))
        low, high = f"{timed.min():.1f}", f"{timed.max():.1f}"
        fitted = timed.notna().groupby(result.trials["trial"]).any()
        where = "" if fitted.all() else \
            f" where it was clear ({fitted.sum()} of {len(fitted)} trials)"
        span = low if low == high else f"{low} to {high}"
        notes.append(f"{names}: the magnetometer taken at its samples' times{where}, its delay "
                     f"against the gyro fitted per trial ({span} ms, late where positive; "
                     "magnetometer_delay_ms in broad_trials.csv)")
    return "\n".join([text, *group_notes(result), *notes])


def _share(value: float) -> str:
    return "-" if math.isnan(value) else f"{100 * value:.1f}"


def format_trials(result: BroadResult) -> str:
    """The per-trial table: the metrics, the time per sample and the share
    of each sensor's readings the estimator rejected (``-``: it does not
    test them, :func:`tests_readings`); a trial with nothing to score named
    below it."""
    trials = result.trials
    shown = trials[["trial", "estimator", "mode", *METRICS, "us_per_sample"]].copy()
    shown["trial"] = shown["trial"].map(trial_label)
    shown["rejected acc/mag %"] = [
        f"{_share(a)}/{_share(m)}" for a, m in zip(trials["rejected_accelerometer_share"],
                                                   trials["rejected_magnetometer_share"])]
    text = shown.to_string(index=False, float_format=lambda v: f"{v:.3f}", na_rep="NaN")
    notes = [f"trial {trial} {why}: nothing scored, its scores are NaN"
             for trial, why in unscored_trials(trials).items()]
    notes += [HEADLESS] if result.headless else [
        f"{name}: scored on its inclination only (it has no heading reference): its total "
        "and heading RMSE are NaN, never ranked" for name in inclination_only(result)]
    return "\n".join([text, *notes, *rejection_notes(trials)])


#: A note says where an estimator rejected more than this share of a
#: sensor's readings on a trial (the MEKF: 29 % at most on BROAD's 30
#: trials, a magnetometer beside magnets): its estimate there rests on the
#: gyro alone, and the table's share alone is easily missed.
MOSTLY_REJECTED = 0.5
#: What each sensor's rejection leaves to the gyro, and what commonly causes it.
REJECTION_CAUSES = {
    "accelerometer": ("inclination", "readings far from gravity: a sustained acceleration, "
                      "vibration, or the accelerometer's unit or axes"),
    "magnetometer": ("heading", "a field far from the Earth's: iron or a magnet near, the "
                     "sensor's own hard iron, or its axes"),
}


def rejection_notes(trials: pd.DataFrame) -> list[str]:
    """One line per trial and sensor where estimators rejected more than
    :data:`MOSTLY_REJECTED` of the readings."""
    notes = []
    for sensor, (angle, causes) in REJECTION_CAUSES.items():
        mostly = trials[trials[f"rejected_{sensor}_share"] > MOSTLY_REJECTED]
        for trial, rows in mostly.groupby("trial", sort=False):
            share = rows[f"rejected_{sensor}_share"].max()
            notes.append(f"trial {trial_label(trial)}: {', '.join(rows['estimator'])} rejected "
                         f"up to {100 * share:.3g} % of the {sensor}'s readings: their {angle} "
                         f"there rests on the gyro alone ({causes})")
    return notes
