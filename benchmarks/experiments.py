"""The workshop's experiments as functions: one run, a comparison, a sweep.

Each function simulates, writes its files into ``out`` (atomically) and
returns the numbers, so the command line, the workshop report and users'
own scripts share one implementation.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchmarks.metrics import STAT_COLUMNS, error_statistics
from benchmarks.output import write_csv, write_figure, write_text
from benchmarks.plots import comparison_figure
from benchmarks.progress import progress
from benchmarks.scenario import Scenario
from benchmarks.simulation import WORKSHOP_ESTIMATORS, RunResult, simulate
from dynamics.validation import InvalidParameterError
from estimators import ESTIMATORS

TRACE_COLUMNS = ("time_s", "q_true_w", "q_true_x", "q_true_y", "q_true_z",
                 "q_est_w", "q_est_x", "q_est_y", "q_est_z", "error_deg")


@dataclass(frozen=True)
class SweepParameter:
    """A scenario setting that ``sweep`` can vary, and how its legend reads."""

    field: str
    legend: str     # format string; {value} and {label} (the estimator's label)


#: Sweepable settings by their command-line name.
SWEEP_PARAMETERS = {
    "gyro-noise": SweepParameter("gyro_noise", "Noise = {value:g}"),
    "star-tracker-noise": SweepParameter("star_tracker_noise", "ST noise = {value:g}"),
    "time-between-measurements": SweepParameter("time_between_measurements",
                                                "ST every {value:.1f} s"),
    "pc-exponent": SweepParameter("pc_exponent", "{label}, pc exponent = {value:g}"),
}

SWEEP_COLUMNS = ("param", "value") + STAT_COLUMNS


def run_one(scenario: Scenario, estimator: str, seed: int, out: Path) -> dict:
    """Run one estimator; write ``NAME.csv`` (the trace) and ``NAME.png``."""
    result = simulate(scenario, [estimator], seed=seed)
    error = result.error_deg[estimator]
    q_true, q_est = result.truth.q_true, result.estimates[estimator]
    table = np.column_stack([result.time_s, q_true, q_est, error])
    write_csv(out / f"{estimator}.csv", TRACE_COLUMNS, (list(map(float, row)) for row in table))
    write_figure(out / f"{estimator}.png",
                 comparison_figure(result.time_s, {result.labels[estimator]: error}))
    return error_statistics(error)


def compare(scenario: Scenario, seed: int, out: Path, estimators=WORKSHOP_ESTIMATORS,
            figure_name: str = "compare.png",
            summary_name: str | None = "summary.csv") -> tuple[RunResult, dict]:
    """Run several estimators on the same data; write the comparison figure and
    (unless ``summary_name`` is None) the summary table."""
    result = simulate(scenario, estimators, seed=seed)
    stats = {name: error_statistics(error) for name, error in result.error_deg.items()}
    if summary_name:
        write_summary(out / summary_name, stats)
    curves = {result.labels[name]: error for name, error in result.error_deg.items()}
    write_figure(out / figure_name, comparison_figure(result.time_s, curves))
    return result, stats


def write_summary(path: Path, stats: dict) -> None:
    write_csv(path, ("estimator",) + STAT_COLUMNS,
              ([name, *(row[c] for c in STAT_COLUMNS)] for name, row in stats.items()))


def sweep_scenarios(scenario: Scenario, param: str, values) -> list[Scenario]:
    """One validated scenario per value of ``param`` (a :data:`SWEEP_PARAMETERS` key)."""
    field = SWEEP_PARAMETERS[param].field
    return [scenario.replace(**{field: value}) for value in values]


def sweep(scenario: Scenario, estimator: str, param: str, values, seed: int, out: Path,
          quiet: bool = False) -> list[dict]:
    """One run of ``estimator`` per value of ``param``, all with the same seed.

    Writes ``sweep.png`` (one error curve per value) and ``sweep.csv`` (one
    row per value); returns those rows.
    """
    if estimator not in ESTIMATORS:
        raise InvalidParameterError("estimator", estimator,
                                    f"must be one of {', '.join(ESTIMATORS)}")
    spec = SWEEP_PARAMETERS[param]
    scenarios = sweep_scenarios(scenario, param, values)
    rows, curves, time_s = [], {}, None
    for value, case in progress(list(zip(values, scenarios)), desc=f"sweep {param}",
                                quiet=quiet):
        result = simulate(case, [estimator], seed=seed)
        error = result.error_deg[estimator]
        rows.append({"param": param, "value": float(value), **error_statistics(error)})
        curves[spec.legend.format(value=value, label=result.labels[estimator])] = error
        time_s = result.time_s
    write_csv(out / "sweep.csv", SWEEP_COLUMNS, ([row[c] for c in SWEEP_COLUMNS] for row in rows))
    write_figure(out / "sweep.png", comparison_figure(time_s, curves, ekf_labels=()))
    return rows


def write_json(path: Path, data: dict) -> None:
    write_text(path, json.dumps(data, indent=2) + "\n")


def animate(scenario: Scenario, estimator: str | None, seed: int, out: Path, every: int = 50,
            quiet: bool = False) -> Path:
    """The 3-D attitude animation ``attitude_NAME.gif`` (``attitude_truth.gif``
    without an estimator) and its last frame as PNG; returns the GIF's path."""
    from benchmarks.animation import frame_indices, write_attitude_animation
    frames = len(frame_indices(scenario.n_steps, every))   # validates every before writing
    result = simulate(scenario, [estimator] if estimator else [], seed=seed)
    q_est = result.estimates[estimator] if estimator else None
    gif = out / f"attitude_{estimator or 'truth'}.gif"
    with progress(total=frames, desc=f"animate {estimator or 'truth'}", unit="frame",
                  quiet=quiet) as bar:
        write_attitude_animation(result.time_s, result.truth.q_true, q_est, gif,
                                 gif.with_suffix(".png"), every=every, progress_bar=bar)
    return gif
