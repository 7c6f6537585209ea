"""The BROAD authors' case study (their ``example_code/process_data.py``):
Madgwick's filter over β and Mahony's over (Kp, Ki), each started from the
first accelerometer and magnetometer sample, turned to ENU and scored by
:mod:`benchmarks.broad.metric`; per trial and group, the value at the one
setting chosen for all trials (the lowest average total RMSE over their 39
trials) and each trial's own best. Their Madgwick is Madgwick's C code with
the halved field reference (``madgwick-broad``,
:mod:`estimators.complementary`).
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from dynamics.quaternion import quat_multiply
from dynamics.validation import InvalidParameterError
from estimators.complementary import NWU_TO_ENU

if TYPE_CHECKING:              # pandas is imported where the tables are made
    import pandas as pd

#: The authors' grids (``process_data.py``).
MADGWICK_BETAS = np.round(np.arange(0.01, 0.300001, 0.01), 8)
MAHONY_KPS = np.round(np.arange(0.02, 2.000001, 0.02), 8)
MAHONY_KIS = np.round(np.arange(0.0, 0.0040001, 0.0001), 8)
#: The settings they chose for all trials (``case_study/*.json``, ``tagp_parameters``).
CHOSEN = {"madgwick-broad": {"beta": 0.12}, "mahony": {"kp": 0.74, "ki": 0.0012}}
#: Their result files, in a BROAD folder.
RESULT_FILES = {"madgwick-broad": "case_study/results_madgwick_average_rmse.json",
                "mahony": "case_study/results_mahony_average_rmse.json"}


#: Where the authors' result files hold their numbers: per trial, at the
#: chosen setting and at each trial's best.
RESULT_KINDS = ("tagp_parameters", "minimum_value")


def authors_initial_state(acc: np.ndarray, mag: np.ndarray) -> np.ndarray:
    """The authors' ``quatFromAccMag`` (``broad_utils.py``), verbatim, as
    their filters' NWU state, turned to ENU as this toolkit's estimators take
    it. It is exact only for a level sensor with x east or west (BROAD's
    trials start so): :func:`benchmarks.broad.inputs.initial_attitude` is
    the general one. The two readings must be non-zero and not parallel
    (:func:`start_readings` gives such a pair)."""
    z = np.asarray(acc, dtype=float)
    x = np.cross(np.cross(z, -np.asarray(mag, dtype=float)), z)
    y = np.cross(z, x)
    r = np.column_stack([x / np.linalg.norm(x), y / np.linalg.norm(y), z / np.linalg.norm(z)])
    squares = np.array([1 + r[0, 0] + r[1, 1] + r[2, 2], 1 + r[0, 0] - r[1, 1] - r[2, 2],
                        1 - r[0, 0] + r[1, 1] - r[2, 2], 1 - r[0, 0] - r[1, 1] + r[2, 2]]) / 4
    q = np.sqrt(squares)
    q[1] = np.copysign(q[1], r[2, 1] - r[1, 2])
    q[2] = np.copysign(q[2], r[0, 2] - r[2, 0])
    q[3] = np.copysign(q[3], r[1, 0] - r[0, 1])
    return quat_multiply(NWU_TO_ENU, q)


def start_readings(recording) -> tuple[np.ndarray, np.ndarray]:
    """The accelerometer and magnetometer readings the authors' filters
    start from: the first sample's, as theirs, or where that pair is
    unusable (a dropout, two parallel readings) the first usable pair of
    the rest (:func:`benchmarks.broad.inputs.start_pair`)."""
    from benchmarks.broad.inputs import start_pair
    return start_pair(recording)[1:]


def published_results(folder: Path) -> dict:
    """``estimator → the authors' JSON`` for the result files present in
    ``folder``, each checked (:func:`checked_results`)."""
    found = {}
    for name, relative in RESULT_FILES.items():
        path = Path(folder) / relative
        if path.is_file():
            found[name] = checked_results(path, relative)
    return found


def checked_results(path: Path, shown: str | None = None) -> dict:
    """An authors' result file read and checked where it is read: an
    object whose ``trials`` (if any) map each trial to an object whose
    :data:`RESULT_KINDS` (if any) map metrics to numbers. Anything else is
    one line naming the file (as ``shown``, its path in the BROAD folder),
    the entry and the rule."""
    def refuse(rule: str):
        raise InvalidParameterError("case_study", shown or str(path), rule)
    try:
        results = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, ValueError) as err:
        refuse(f"cannot be read as JSON ({type(err).__name__}: {err})")
    if not isinstance(results, dict):
        refuse(f"holds {type(results).__name__}; must be an object with the authors' trials "
               "({\"trials\": {name: {\"tagp_parameters\": {metric: number}, ...}}})")
    trials = results.get("trials", {})
    if not isinstance(trials, dict):
        refuse(f"trials is {type(trials).__name__}; must be an object of trials by name")
    for trial, entry in trials.items():
        if not isinstance(entry, dict):
            refuse(f"trial {trial} is {type(entry).__name__}; must be an object of "
                   f"{' and '.join(RESULT_KINDS)}")
        for kind in RESULT_KINDS:
            values = entry.get(kind, {})
            if not isinstance(values, dict):
                refuse(f"trial {trial}'s {kind} is {type(values).__name__}; must be an object "
                       "of metrics")
            for metric, value in values.items():
                if isinstance(value, bool) or not isinstance(value, (int, float)):
                    refuse(f"trial {trial}'s {kind} {metric} = {value!r}; must be a number")
    return results


def reproduce(dataset, trials, published: dict, quiet: bool = False) -> "pd.DataFrame":
    """The authors' Madgwick and Mahony at their chosen settings, started as
    they start them, on ``trials``: per trial and metric, the published
    value (NaN where ``published`` has none), ours and the difference."""
    import pandas as pd
    from benchmarks.broad.metric import METRICS, rmse_deg
    from benchmarks.broad.inputs import imu_inputs
    from benchmarks.engine.recorded import run_recorded
    from benchmarks.output import progress
    from estimators import resolve_estimator
    rows = []
    with progress(total=len(trials) * len(CHOSEN), desc="case study", unit="run",
                  quiet=quiet) as bar:
        for trial in trials:
            recording = dataset.load(trial)
            sensors = imu_inputs(recording).sensors
            start = authors_initial_state(*start_readings(recording))
            for name, settings in CHOSEN.items():
                estimator = resolve_estimator(name)(dt=recording.dt, initial_attitude=start,
                                                    **settings)
                estimate = run_recorded(estimator, sensors.omega_meas_radps,
                                        sensors.vectors).estimates
                ours = rmse_deg(estimate, recording.reference_quat, recording.movement)
                theirs = published.get(name, {}).get("trials", {}).get(trial, {}).get(
                    "tagp_parameters", {})
                for metric in METRICS:
                    value = theirs.get(metric, float("nan"))
                    rows.append({"trial": trial, "estimator": name, "metric": metric,
                                 "published": value, "ours": ours[metric],
                                 "difference": ours[metric] - value})
                bar.update()
    return pd.DataFrame(rows)


def grid_points(name: str) -> list[dict]:
    """The authors' grid of ``name`` (``madgwick-broad``: β; ``mahony``: Kp × Ki)."""
    if name == "mahony":
        return [{"kp": float(kp), "ki": float(ki)} for kp in MAHONY_KPS for ki in MAHONY_KIS]
    return [{"beta": float(beta)} for beta in MADGWICK_BETAS]


def trial_grid(dataset, trial: str, name: str) -> np.ndarray:
    """``(points, 3)``: :data:`~benchmarks.broad.metric.METRICS` of ``name``
    at every point of its grid on ``trial``, started as the authors start
    (a Dask task of :func:`grid_study`; the compiled filters make the 4,100
    Mahony runs of a trial take about a minute)."""
    from benchmarks.broad.inputs import imu_inputs
    from benchmarks.broad.metric import METRICS, rmse_deg
    from benchmarks.engine.recorded import run_recorded
    from estimators import resolve_estimator
    recording = dataset.load(trial)
    sensors = imu_inputs(recording).sensors
    start = authors_initial_state(*start_readings(recording))
    cls, scores = resolve_estimator(name), []
    for point in grid_points(name):
        run = run_recorded(cls(dt=recording.dt, initial_attitude=start, **point),
                           sensors.omega_meas_radps, sensors.vectors)
        found = rmse_deg(run.estimates, recording.reference_quat, recording.movement)
        scores.append([found[metric] for metric in METRICS])
    return np.array(scores)


def grid_study(dataset, trials, published: dict, workers: int = 0, quiet: bool = False):
    """The authors' grid search over ``trials``, per filter: the setting of
    the lowest mean total RMSE over these trials (theirs was chosen over all
    39 of theirs), and per trial and metric each trial's best (the grid's
    minimum) beside their published ``minimum_value``. Returns ``(chosen,
    frame)``: filter → setting, and the tidy comparison."""
    import pandas as pd
    from benchmarks.broad.metric import METRICS
    from benchmarks.engine.runner import map_tasks
    from benchmarks.output import progress
    chosen, rows = {}, []
    for name in CHOSEN:
        with progress(total=len(trials), desc=f"grid {name}", unit="trial",
                      quiet=quiet) as bar:
            grids = map_tasks(trial_grid, [(dataset, trial, name) for trial in trials],
                              workers, bar)
        points = grid_points(name)
        chosen[name] = points[int(np.argmin(np.mean([g[:, 0] for g in grids], axis=0)))]
        for trial, grid in zip(trials, grids):
            theirs = published.get(name, {}).get("trials", {}).get(trial, {}).get(
                "minimum_value", {})
            for m, metric in enumerate(METRICS):
                value = theirs.get(metric, float("nan"))
                ours = float(np.min(grid[:, m]))
                rows.append({"trial": trial, "estimator": name, "metric": metric,
                             "published_best": value, "ours_best": ours,
                             "difference": ours - value,
                             "our_best_setting": points[int(np.argmin(grid[:, m]))]})
    return chosen, pd.DataFrame(rows)
