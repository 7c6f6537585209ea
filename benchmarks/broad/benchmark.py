"""Every estimator on every BROAD trial, scored by the authors' metric
(:mod:`benchmarks.broad.metric`): a tidy table of one row per trial and
estimator, the group means as ``trials.json`` defines the groups, the bar
figure of the groups and one trial's errors over time.

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

from benchmarks.broad.agreement import AGAINST, AGREEMENT, agreement_scores
from benchmarks.broad.dataset import BroadDataset, trial_label
from benchmarks.broad.inputs import imu_inputs
from benchmarks.broad.tuning import judged_samples
from benchmarks.broad.metric import METRICS, errors_deg, rmse_of, scored_samples, \
    unscored_reason
from dynamics.validation import InvalidParameterError
from benchmarks.engine.recorded import path_of, run_recorded
from benchmarks.output import progress
from estimators import resolve_estimator, sensing

#: ``broad`` without ``--estimators``: the textbook filter and its smoother
#: (offline), a static solution, dead reckoning and the complementary
#: filters; the peers when installed (:func:`default_estimators`).
DEFAULT_ESTIMATORS = ("dead-reckoning", "triad", "mekf", "mekf-smoother", "usque", "madgwick",
                      "madgwick-broad", "mahony")
PEERS = ("vqf", "vqf-6d", "vqf-offline", "fusion")
#: The vector sensors, in the tables' order, and their short names.
SENSORS = {"accelerometer": "acc", "magnetometer": "mag"}
TRIAL_COLUMNS = ("trial", "estimator", "mode", *METRICS, "us_per_sample", "samples",
                 "movement_samples", "scored_samples",
                 "rejected_accelerometer", "rejected_magnetometer",
                 "rejected_accelerometer_share", "rejected_magnetometer_share",
                 "diverged_step", "path", *AGREEMENT)
GROUP_COLUMNS = ("group", "level", "estimator", "trials", "scored_trials", *METRICS,
                 "left_out", "nan_on")
#: The trial figure's curves: the total error's RMS over windows this long, s.
CURVE_WINDOW_S = 1.0
#: What the scores are taken against where a trial has a reference.
REFERENCE = "the reference"
#: The width of a group's bars in the group figure (seaborn's default).
BAR_WIDTH = 0.8


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

    @property
    def by_agreement(self) -> bool:
        """Whether the scores are the estimators' agreement, not accuracy."""
        return self.against != REFERENCE

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
        scores = rmse_of(errors, run.estimates, recording.reference_quat, movement)
        if not sensing.heading_observed(type(estimator), readings):
            # No heading reference (VQF 6D): its heading is the gyro's, and its
            # total would rank a heading that happens to start near the
            # reference's; only its inclination is a score.
            scores.update(total_rmse_deg=math.nan, heading_rmse_deg=math.nan)
        tested = tests_readings(estimator)
        rows.append({"trial": trial, "estimator": name, "mode": estimator.mode, **scores,
                     "us_per_sample": 1e6 * seconds / recording.n_samples,
                     "samples": recording.n_samples,
                     "movement_samples": int(np.count_nonzero(movement)),
                     "scored_samples": scored,
                     **{f"rejected_{sensor}": run.rejected.get(sensor, 0) for sensor in SENSORS},
                     **{f"rejected_{sensor}_share":
                        run.rejected.get(sensor, 0) / readings[sensor]
                        if tested[sensor] and readings[sensor] else math.nan
                        for sensor in SENSORS},
                     "diverged_step": -1 if run.diverged_step is None else run.diverged_step,
                     "path": run.path})
        heading = sensing.heading_observed(type(estimator), readings)
        curves[name] = (recording.time_s, errors["total" if heading else "inclination"])
        labels[name] = estimator.label + ("" if heading else " [inclination only]") + (
            " [offline]" if estimator.mode == "offline" else "")
        estimates[name] = run.estimates[judged]
        if heading:
            observers.add(name)
            if run.diverged_step is None:
                members.append(name)
    unreferenced = not recording.has_reference.any()
    if unreferenced or agreement:
        scores, agreement_curves = agreement_scores(estimates, members, observers)
        for row in rows:
            row.update(scores[row["estimator"]])
        if unreferenced:
            curves = {name: (recording.time_s[judged], curve)
                      for name, curve in agreement_curves.items()}
    return rows, curves, labels


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
    sample counts it."""
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
                       dataset_title=dataset.title)


def _against(result: BroadResult) -> str:
    """A figure title's second line where the scores are not against the
    reference."""
    return f"\nno reference: against {result.against} (agreement, not accuracy)" \
        if result.by_agreement else ""


def _by_agreement(dataset, trials, frame, labels, results, tuning, unscored) -> BroadResult:
    """Nothing to score against a reference: the estimators ranked by their
    agreement with the others (:mod:`benchmarks.broad.agreement`), every
    sample of every trial scored against the others' median, said as such;
    an error if no total could be scored (fewer than two estimators that
    observe the heading ran through)."""
    if not np.isfinite(frame[AGREEMENT[0]].to_numpy(dtype=float)).any():
        raise InvalidParameterError("trials", ",".join(map(trial_label, trials)), "nothing to "
                                    "score: " + "; ".join(f"{t} {why}"
                                                          for t, why in unscored.items()) +
                                    "; and fewer than two estimators observe the heading, so "
                                    "they cannot be ranked by their agreement either")
    scored = frame.copy()
    scored[list(METRICS)] = frame[list(AGREEMENT)].to_numpy()
    scored["movement_samples"] = scored["scored_samples"] = scored["samples"]
    return BroadResult(trials=scored, groups=group_means(dataset, scored), labels=labels,
                       curves=results[0][1], curve_trial=trials[0], tuning=tuning,
                       against=AGAINST, dataset_title=dataset.title)


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
    blind = {name for name, label in result.labels.items()
             if label.endswith("[inclination only]")}
    notes += [f"NaN: {name} has no total or heading score (no heading reference); its "
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
    notes += [f"{name}: scored on its inclination only (it has no heading reference): its "
              "total and heading RMSE are NaN, never ranked" for name, label in
              result.labels.items() if label.endswith("[inclination only]")]
    return "\n".join([text, *notes])


def groups_figure(result: BroadResult):
    """The groups' total, heading and inclination RMSE per estimator (bars),
    on a log axis: the errors span two decades (VQF's 0.4° to TRIAD's 87°
    on the 30 trials), and on a linear axis the two baselines set the scale
    and squash the filters near zero; on a log axis every bar is readable
    and equal ratios look equal, with no clipping rule chosen by hand. Each
    group is labelled with how many trials its mean holds."""
    import seaborn as sns
    from matplotlib.figure import Figure
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator
    from benchmarks.figures.style import estimator_styles, legend_outside, round_values
    groups = result.groups.copy()
    groups["label"] = [group_header(g, int(n), int(k)).replace(" (", "\n(") for g, n, k in
                       zip(groups["group"], groups["trials"], groups["scored_trials"])]
    names = list(dict.fromkeys(groups["estimator"]))
    styles = estimator_styles(names)
    palette = {result.labels[name]: styles[name]["color"] for name in names}
    tidy = groups.melt(id_vars=["label", "estimator"], value_vars=list(METRICS),
                       var_name="metric", value_name="rmse_deg")
    tidy["estimator"] = tidy["estimator"].map(result.labels)
    values = tidy["rmse_deg"].to_numpy(dtype=float)
    positive = values[np.isfinite(values) & (values > 0)]
    # The axis from the round value (1, 2 or 5 × 10ⁿ) just below the smallest bar.
    low = max(round_values(0.08 * positive.min(), 0.8 * positive.min())) if positive.size \
        else 0.1
    high = 1.3 * positive.max() if positive.size else 10.0
    n_groups = groups["label"].nunique()
    with sns.axes_style("whitegrid"):
        figure = Figure(figsize=(max(11.0, 0.9 * n_groups + 3.0), 10.0), layout="constrained")
        axes = figure.subplots(len(METRICS), 1, sharex=True, squeeze=False)[:, 0]
    labels = list(dict.fromkeys(tidy["label"]))
    hues = [result.labels[name] for name in names]
    for ax, metric in zip(axes, METRICS):
        part = tidy[tidy["metric"] == metric]
        sns.barplot(data=part, x="label", y="rmse_deg", hue="estimator", order=labels,
                    hue_order=hues, palette=palette, ax=ax, errorbar=None, width=BAR_WIDTH,
                    legend=ax is axes[0])
        # A missing bar is a NaN mean (module docstring): say so where it would stand.
        for row in part[part["rmse_deg"].isna()].itertuples():
            x = labels.index(row.label) - BAR_WIDTH / 2 + \
                (hues.index(row.estimator) + 0.5) * BAR_WIDTH / len(hues)
            ax.text(x, low * 1.15, "NaN", rotation=90, ha="center", va="bottom",
                    fontsize="x-small", color="0.35")
        ax.set_yscale("log")
        ax.set_ylim(low, high)
        ax.yaxis.set_major_locator(FixedLocator(round_values(low, high)))
        ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        ax.yaxis.set_minor_locator(NullLocator())
        ax.set_xlabel("")
        ax.set_ylabel(f"{metric.split('_')[0]} RMSE (°, log)")
        if ax.get_legend() is not None:
            ax.get_legend().remove()
    for label in axes[-1].get_xticklabels():
        label.set_rotation(30)
        label.set_horizontalalignment("right")
    figure.suptitle(f"{result.dataset_title}: error during the movement per group, the mean "
                    "over the trials counted under its name" + _against(result))
    legend_outside(figure, axes[:1], columns=min(len(names), 5),
                   note="; ".join(group_notes(result)))
    return figure


def curve_windows(time_s: np.ndarray, error_deg: np.ndarray, window_s: float):
    """``(centres, rms)``: the RMS of ``error_deg`` over consecutive windows
    of ``window_s`` (its samples without a value left out; a window with
    none, NaN)."""
    dt = float(time_s[1] - time_s[0])
    size = max(int(round(window_s / dt)), 1)
    count = len(error_deg) // size
    if count == 0:
        return time_s[:1], np.array([math.sqrt(np.nanmean(error_deg ** 2))])
    squares = np.asarray(error_deg[:count * size], dtype=float).reshape(count, size) ** 2
    present = np.isfinite(squares).sum(axis=1)
    total = np.where(np.isfinite(squares), squares, 0.0).sum(axis=1)
    rms = np.sqrt(np.divide(total, present, out=np.full(count, np.nan), where=present > 0))
    return time_s[:count * size].reshape(count, size).mean(axis=1), rms


def _runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """Runs of true ``flags`` as ``[start, stop)`` index pairs."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], flags.astype(np.int8), [0]])))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])]


def trial_figure(result: BroadResult):
    """The first scored trial's total error over time, every estimator: its
    RMS over each :data:`CURVE_WINDOW_S` (the metric's statistic, over the
    samples with a reference), log scale, the movement phases (where the
    metric scores) shaded, the legend below the axes; curves that coincide
    on the log axis (within a thousandth of its decades) drawn dashed over
    each other and named with their largest difference."""
    import seaborn as sns
    from matplotlib.figure import Figure
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator
    from benchmarks.figures.style import (COINCIDE_FRACTION, coincidence_note, coinciding,
                                          estimator_styles, finite_max, legend_outside,
                                          round_values, with_coincidences)
    windows = {name: curve_windows(times, error, CURVE_WINDOW_S)
               for name, (times, error) in result.curves.items()}
    curves = {name: rms for name, (_, rms) in windows.items()}
    bottoms = [np.percentile(rms[np.isfinite(rms) & (rms > 0)], 1) for rms in curves.values()
               if np.any(np.isfinite(rms) & (rms > 0))]
    low = 0.5 * min(bottoms) if bottoms else 1e-2
    high = 2.0 * (finite_max(curves.values()) or 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        logs = {name: np.log10(rms) for name, rms in curves.items()}
    under = {later: (earlier, float(np.nanmax(np.abs(curves[later] - curves[earlier]))))
             for later, (earlier, _) in coinciding(
                 logs, COINCIDE_FRACTION * math.log10(high / low)).items()}
    styles = with_coincidences(estimator_styles(curves), under)
    with sns.axes_style("whitegrid"):
        figure = Figure(figsize=(12.0, 6.0), layout="constrained")
        axis = figure.subplots()
    time_s = next(iter(result.curves.values()))[0]
    if result.curve_movement is not None:
        for i, (start, stop) in enumerate(_runs(np.asarray(result.curve_movement, dtype=bool))):
            axis.axvspan(time_s[start], time_s[stop - 1], color="0.85", alpha=0.6, linewidth=0,
                         label=None if i else "movement (scored where the reference is)")
    for name, (centres, rms) in windows.items():
        axis.plot(centres, rms, label=result.labels[name], **{"linewidth": 1.3, **styles[name]})
    axis.set_yscale("log")
    axis.set_ylim(low, high)
    ticks = round_values(low, high)
    axis.yaxis.set_major_locator(FixedLocator(ticks if len(ticks) <= 12 else
                                              round_values(low, high, (1,))))
    axis.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axis.yaxis.set_minor_locator(NullLocator())
    axis.set_xlim(time_s[0], time_s[-1])
    axis.set_xlabel("time (s)")
    axis.set_ylabel("total error (°, RMS per window, log)")
    axis.set_title(f"{result.dataset_title} {result.curve_trial}: total error, RMS over {CURVE_WINDOW_S:g} s "
                   "windows" + ("" if result.by_agreement else " (the reference's gaps "
                                "blank)") + _against(result))
    legend_outside(figure, [axis], columns=6, note=coincidence_note(under, result.labels, "°"))
    return figure
