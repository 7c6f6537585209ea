"""The workshop's experiments as functions: one run, a comparison, a sweep.

Each function simulates, writes its files into ``out`` (atomically) and
returns the numbers, so the command line, the workshop report and users'
own scripts share one implementation.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from benchmarks.metrics import STAT_COLUMNS, error_statistics
from benchmarks.output import figure_bytes, write_bytes, write_csv
from benchmarks.figures.flight import flight_figure
from benchmarks.figures.plots import comparison_figure
from benchmarks.output import progress
from benchmarks.scenario import Scenario
from benchmarks.experiments.sweep_parameters import SWEEP_PARAMETERS
from benchmarks.simulation import WORKSHOP_ESTIMATORS, RunResult, simulate
from dynamics.quaternion import attitude_error_vector_rad
from dynamics.validation import InvalidParameterError
from estimators import resolve_estimator
from sensors.noise import radps_to_deg_per_hr

TRACE_COLUMNS = ("time_s", "q_true_w", "q_true_x", "q_true_y", "q_true_z",
                 "q_est_w", "q_est_x", "q_est_y", "q_est_z", "error_deg")


SWEEP_COLUMNS = ("param", "value") + STAT_COLUMNS


def run_statistics(result: RunResult, name: str) -> dict:
    """``name``'s error statistics in ``result`` (NaN if it diverged),
    ``diverged_step`` (-1 if it did not) and its ``note`` ("" when its
    numbers are the plain attitude error of a working estimator;
    :attr:`~benchmarks.simulation.RunResult.notes`)."""
    return {**error_statistics(result.error_deg[name]),
            "diverged_step": result.diverged_step[name], "note": result.notes.get(name, "")}


def run_one(scenario: Scenario, estimator: str, seed: int, out: Path,
            quiet: bool = True) -> dict:
    """Run one estimator; write ``NAME.csv`` (the trace) and ``NAME.png``
    (a progress bar on a terminal unless ``quiet``)."""
    with progress(total=scenario.n_steps, desc=estimator, unit="step", quiet=quiet) as bar:
        result = simulate(scenario, [estimator], seed=seed, progress_bar=bar)
    error = result.error_deg[estimator]
    q_true, q_est = result.truth.q_true, result.estimates[estimator]
    table = np.column_stack([result.time_s, q_true, q_est, error])
    drawn = figure_bytes(out / f"{estimator}.png",
                         comparison_figure(result.time_s, {result.labels[estimator]: error}))
    write_csv(out / f"{estimator}.csv", TRACE_COLUMNS, (list(map(float, row)) for row in table))
    write_bytes(out / f"{estimator}.png", drawn)
    return run_statistics(result, estimator)


def compare(scenario: Scenario, seed: int, out: Path, estimators=WORKSHOP_ESTIMATORS,
            figure_name: str = "compare.png",
            summary_name: str | None = "summary.csv", quiet: bool = True) -> tuple[RunResult, dict]:
    """Run several estimators on the same data; write the comparison figure and
    (unless ``summary_name`` is None) the summary table.

    With the workshop's sensors the figure is the workshop's (total error of
    each estimator); with flight sensors (a gyro bias model or the rotation
    star tracker) it is :func:`~benchmarks.figures.flight.flight_figure`: per-axis error
    with each filter's ±3σ envelope, and the bias estimates against the truth.
    """
    workshop = scenario.is_workshop_sensors
    with progress(total=scenario.n_steps * len(estimators), desc="compare", unit="step",
                  quiet=quiet) as bar:
        result = simulate(scenario, estimators, seed=seed, traces=not workshop, progress_bar=bar)
    stats = {name: run_statistics(result, name) for name in result.error_deg}
    if workshop:
        curves = {result.labels[name]: error for name, error in result.error_deg.items()}
        figure = comparison_figure(result.time_s, curves)
    else:
        figure = flight_comparison_figure(result)
    drawn = figure_bytes(out / figure_name, figure)      # drawn before anything is written
    if summary_name:
        write_summary(out / summary_name, stats)
    write_bytes(out / figure_name, drawn)
    return result, stats


def flight_comparison_figure(result: RunResult):
    """The per-axis figure of a run simulated with ``traces=True``."""
    errors, sigmas, biases = {}, {}, {}
    for name, trace in result.traces.items():
        errors[name] = np.degrees(attitude_error_vector_rad(result.truth.q_true, trace.quat))
        sigmas[name] = (None if trace.attitude_covariance is None else np.degrees(
            np.sqrt(np.diagonal(trace.attitude_covariance, axis1=1, axis2=2))))
        if trace.bias_radps is not None:
            biases[name] = (radps_to_deg_per_hr(trace.bias_radps), radps_to_deg_per_hr(
                np.sqrt(np.diagonal(trace.bias_covariance, axis1=1, axis2=2))))
    scenario = result.scenario
    references = result.sensors.references
    rejected = {name: np.unique(np.concatenate(list(trace.rejected.values())))
                for name, trace in result.traces.items() if trace.rejected}
    return flight_figure(result.time_s, errors, sigmas,
                         radps_to_deg_per_hr(result.sensors.gyro_bias_radps), biases,
                         result.labels, envelope_steps=reading_window(scenario),
                         eclipse=None if references is None or references.sun_unit is None
                         else references.eclipse, rejected=rejected)


def reading_window(scenario) -> int:
    """Steps spanning one star tracker interval and the step after it: the
    window over which an envelope is drawn through its peaks."""
    return int(np.ceil(scenario.time_between_measurements / scenario.dt - 1e-9)) + 1


#: ``summary.csv``'s columns: the statistics, and what they are where not plain.
SUMMARY_COLUMNS = ("estimator",) + STAT_COLUMNS + ("note",)


def write_summary(path: Path, stats: dict) -> None:
    write_csv(path, SUMMARY_COLUMNS, ([name, *(row[c] for c in STAT_COLUMNS),
                                       row.get("note", "")] for name, row in stats.items()))


def sweep_scenarios(scenario: Scenario, param: str, values) -> list[Scenario]:
    """One validated scenario per value of ``param`` (a :data:`SWEEP_PARAMETERS` key)."""
    spec = SWEEP_PARAMETERS[param]
    values = [float(value) for value in values]
    repeated = [value for value in values if values.count(value) > 1]
    if repeated:
        raise InvalidParameterError("values", values, f"names {repeated[0]:g} more than once; "
                                    "give each value once")
    convert = spec.convert or (lambda value: value)
    return [scenario.replace(**{spec.field: convert(value)}) for value in values]


def sweep(scenario: Scenario, estimator: str, param: str, values, seed: int, out: Path,
          quiet: bool = False) -> list[dict]:
    """One run of ``estimator`` per value of ``param``, all with the same seed.

    Writes ``sweep.png`` (one error curve per value) and ``sweep.csv`` (one
    row per value); returns those rows.
    """
    resolve_estimator(estimator)                 # a registry name or module:Class
    spec = SWEEP_PARAMETERS[param]
    scenarios = sweep_scenarios(scenario, param, values)
    rows, curves, time_s = [], {}, None
    for value, case in progress(list(zip(values, scenarios)), desc=f"sweep {param}",
                                quiet=quiet):
        result = simulate(case, [estimator], seed=seed)
        error = result.error_deg[estimator]
        rows.append({"param": param, "value": float(value), **run_statistics(result, estimator)})
        legend = spec.legend.format(value=value, label=result.labels[estimator])
        curves[f"{legend} {spec.unit}".rstrip()] = error
        time_s, label = result.time_s, result.labels[estimator]
    drawn = figure_bytes(out / "sweep.png", comparison_figure(
        time_s, curves, ekf_labels=(), title=f"{label}: attitude error as {param} varies "
        f"(seed {seed})"))
    write_csv(out / "sweep.csv", SWEEP_COLUMNS, ([row[c] for c in SWEEP_COLUMNS] for row in rows))
    write_bytes(out / "sweep.png", drawn)
    return rows


def animate(scenario: Scenario, estimator: str | None, seed: int, out: Path, every: int = 50,
            quiet: bool = False) -> tuple[Path, int]:
    """The 3-D attitude animation ``attitude_NAME.gif`` (``attitude_truth.gif``
    without an estimator) and its last frame as PNG; returns the GIF's path
    and the step where the estimator diverged (-1: it did not, or none ran)."""
    from benchmarks.figures.animation import frame_indices, write_attitude_animation
    frames = len(frame_indices(scenario.n_steps, every))   # validates every before writing
    result = simulate(scenario, [estimator] if estimator else [], seed=seed)
    q_est = result.estimates[estimator] if estimator else None
    gif = out / f"attitude_{estimator or 'truth'}.gif"
    with progress(total=frames, desc=f"animate {estimator or 'truth'}", unit="frame",
                  quiet=quiet) as bar:
        write_attitude_animation(result.time_s, result.truth.q_true, q_est, gif,
                                 gif.with_suffix(".png"), every=every, progress_bar=bar)
    return gif, result.diverged_step[estimator] if estimator else -1
