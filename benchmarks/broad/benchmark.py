"""Every estimator on every BROAD trial, scored by the authors' metric
(:mod:`benchmarks.broad.metric`): a tidy table of one row per trial and
estimator, the group means as ``trials.json`` defines the groups, the bar
figure of the groups and one trial's errors over time.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import pandas as pd

from benchmarks.broad.dataset import BroadDataset
from benchmarks.broad.inputs import imu_inputs
from benchmarks.broad.metric import METRICS, errors_deg, rmse_of
from benchmarks.engine.recorded import path_of, run_recorded
from benchmarks.progress import progress
from estimators import resolve_estimator

#: ``broad`` without ``--estimators``: the textbook filter, a static
#: solution, dead reckoning and the complementary filters; the peers when
#: installed (:func:`default_estimators`).
DEFAULT_ESTIMATORS = ("dead-reckoning", "triad", "mekf", "usque", "madgwick", "madgwick-broad",
                      "mahony")
PEERS = ("vqf", "vqf-6d", "fusion")
TRIAL_COLUMNS = ("trial", "estimator", *METRICS, "us_per_sample", "samples",
                 "rejected_accelerometer", "rejected_magnetometer", "diverged_step", "path")


def default_estimators() -> tuple:
    """:data:`DEFAULT_ESTIMATORS`, and :data:`PEERS` whose packages are installed."""
    import importlib.util
    modules = {"vqf": "vqf", "vqf-6d": "vqf", "fusion": "imufusion"}
    return DEFAULT_ESTIMATORS + tuple(name for name in PEERS
                                      if importlib.util.find_spec(modules[name]) is not None)


@dataclass(frozen=True)
class BroadResult:
    trials: pd.DataFrame         # TRIAL_COLUMNS
    groups: pd.DataFrame         # group, level, estimator, trials, METRICS
    labels: dict                 # estimator → label
    curves: dict                 # the first trial's: estimator → (time_s, total error °)
    curve_trial: str
    tuning: str = "none"         # how the settings were chosen (benchmarks.broad.tuning.MODES)

    @property
    def dt(self) -> float:
        """The first trial's sample interval, s (for the divergence report)."""
        time_s = next(iter(self.curves.values()))[0]
        return float(time_s[1] - time_s[0])


def run_trial(dataset: BroadDataset, trial: str, estimators, gyro_delay_s: float = 0.0,
              sigmas=None, options=None) -> tuple[list, dict, dict]:
    """Each of ``estimators`` on ``trial`` (:func:`benchmarks.broad.inputs.imu_inputs`
    with ``gyro_delay_s`` and ``sigmas``; ``options``: estimator → settings
    over its defaults, a tuned set for this trial), through the engine where it can
    (:func:`benchmarks.engine.recorded.run_recorded`): its rows (a diverged
    estimator's scores NaN, its step in ``diverged_step``, else -1), total
    errors over time, labels."""
    recording = dataset.load(trial)
    inputs = imu_inputs(recording, gyro_delay_s, sigmas)
    sensors = inputs.sensors
    rows, curves, labels = [], {}, {}
    for name in estimators:
        estimator = resolve_estimator(name).from_scenario(inputs.scenario,
                                                          **(options or {}).get(name, {}))
        _warm_up(estimator, sensors)
        start = time.perf_counter()
        run = run_recorded(estimator, sensors.omega_meas_radps, sensors.vectors)
        seconds = time.perf_counter() - start
        errors = errors_deg(run.estimates, recording.reference_quat)
        scores = rmse_of(errors, run.estimates, recording.reference_quat, recording.movement)
        rows.append({"trial": trial, "estimator": name, **scores,
                     "us_per_sample": 1e6 * seconds / recording.n_samples,
                     "samples": recording.n_samples,
                     "rejected_accelerometer": run.rejected.get("accelerometer", 0),
                     "rejected_magnetometer": run.rejected.get("magnetometer", 0),
                     "diverged_step": -1 if run.diverged_step is None else run.diverged_step,
                     "path": run.path})
        curves[name] = (recording.time_s, errors["total"])
        labels[name] = estimator.label
    return rows, curves, labels


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


def group_means(dataset: BroadDataset, trials: pd.DataFrame) -> pd.DataFrame:
    """Each group's plain mean over its trials present, per estimator (the
    authors' group score); groups with none of the trials run are left out."""
    rows = []
    for group in dataset.groups:
        members = [t for t in dataset.members(group.name) if t in set(trials["trial"])]
        if not members:
            continue
        part = trials[trials["trial"].isin(members)]
        for name, scores in part.groupby("estimator", sort=False):
            rows.append({"group": group.name, "level": group.level, "estimator": name,
                         "trials": len(members),
                         **{metric: scores[metric].mean() for metric in METRICS}})
    return pd.DataFrame(rows)


def run_broad(dataset: BroadDataset, trials, estimators, gyro_delay_s: float = 0.0,
              sigmas=None, quiet: bool = False, workers: int = 0,
              options=None, tuning: str = "none") -> BroadResult:
    """:func:`run_trial` over ``trials`` (on a local Dask cluster of
    ``workers`` processes, one trial per task, if ``workers``), with
    ``options``: trial → its estimators' settings
    (:func:`benchmarks.broad.tuning.tuned_options` under ``tuning``, a
    :data:`~benchmarks.broad.tuning.MODES` name); the tidy table and the
    group means."""
    from benchmarks.engine.runner import map_tasks
    rows, labels = [], {}
    arguments = [(dataset, trial, tuple(estimators), gyro_delay_s, sigmas,
                  (options or {}).get(trial)) for trial in trials]
    with progress(total=len(trials), desc="broad", unit="trial", quiet=quiet) as bar:
        results = map_tasks(run_trial, arguments, workers, bar)
    for found, _, names in results:
        rows += found
        labels.update(names)
    first = results[0][1]
    frame = pd.DataFrame(rows, columns=list(TRIAL_COLUMNS))
    return BroadResult(trials=frame, groups=group_means(dataset, frame), labels=labels,
                       curves=first, curve_trial=trials[0], tuning=tuning)


def format_groups(result: BroadResult, metric: str = "total_rmse_deg") -> str:
    """Estimators × groups of ``metric`` (degrees), with the number of trials."""
    table = result.groups.pivot_table(index="estimator", columns="group", values=metric,
                                      sort=False)
    counts = result.groups.drop_duplicates("group").set_index("group")["trials"]
    table.columns = [f"{group} ({counts[group]})" for group in table.columns]
    return table.to_string(float_format=lambda v: f"{v:.3f}")


def format_trials(result: BroadResult) -> str:
    shown = result.trials[["trial", "estimator", *METRICS, "us_per_sample"]].copy()
    shown["trial"] = shown["trial"].str.split("_", n=1).str[0]
    return shown.to_string(index=False, float_format=lambda v: f"{v:.3f}")


def groups_figure(result: BroadResult):
    """The groups' total, heading and inclination RMSE per estimator (bars)."""
    import matplotlib.pyplot as plt
    import seaborn as sns
    tidy = result.groups.melt(id_vars=["group", "estimator"], value_vars=list(METRICS),
                              var_name="metric", value_name="rmse_deg")
    tidy["estimator"] = tidy["estimator"].map(result.labels)
    grid = sns.catplot(data=tidy, kind="bar", x="group", y="rmse_deg", hue="estimator",
                       row="metric", height=2.6, aspect=4.0, sharey=False)
    grid.set_axis_labels("", "RMSE (°)")
    grid.set_titles("{row_name}")
    for axis in grid.axes.flat:
        plt.setp(axis.get_xticklabels(), rotation=30, ha="right")
    grid.figure.suptitle("BROAD: error during the movement, per group (mean over trials)")
    grid.figure.tight_layout(rect=(0, 0, 0.80, 1))   # title, names and legend inside
    plt.close(grid.figure)
    return grid.figure


def trial_figure(result: BroadResult):
    """The first trial's total error over time, every estimator."""
    import matplotlib.pyplot as plt
    figure, axis = plt.subplots(figsize=(11, 4.5))
    for name, (time_s, error) in result.curves.items():
        axis.plot(time_s, error, linewidth=0.8, label=result.labels[name])
    axis.set_yscale("log")
    axis.set_xlabel("time (s)")
    axis.set_ylabel("total error (°)")
    axis.set_title(f"BROAD {result.curve_trial}: total error (the reference's gaps blank)")
    axis.legend(ncol=3, fontsize="small")
    plt.close(figure)
    return figure
