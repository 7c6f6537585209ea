"""One runner for many runs: every campaign of the toolkit goes through
:func:`run_many`, which owns the choices they share.

* **Engine or per-run path.** An estimator with a kernel
  (:data:`~benchmarks.engine.batch.ENGINE_ESTIMATORS`) runs on the engine; any
  other (a user's ``package.module:Class``) runs per run, on at most
  ``per_run_limit`` of the runs if asked, each run a full per-run simulation.
* **Chunking.** The engine's runs go through :func:`~benchmarks.engine.batch.run_batch`
  ``chunk_runs`` at a time, which bounds memory and never changes a number.
* **Dask.** With ``workers``, the per-run simulations are mapped over a local
  Dask cluster of that many processes (:func:`dask_client`).
* **Progress.** ``progress_bar`` advances by one per estimator run.

``montecarlo`` (each of its resumable chunks), ``consistency``, ``tune`` and
``landscape`` call it.
"""
from __future__ import annotations

import logging
import re
import warnings

import numpy as np

from benchmarks.engine.batch import (CHUNK_RUNS, ENGINE_ESTIMATORS, PER_RUN_SETTINGS, RunTable,
                                     checked_runs, engine_limitation, run_batch, whole_number)
from benchmarks.engine.results import BatchResult
from benchmarks.metrics import STAT_COLUMNS, error_statistics, nees
from benchmarks.scenario import Scenario
from benchmarks.sensor_use import Usage, refuse_unreadable, scenario_sensors, warn_unmodelled
from benchmarks.simulation import simulate
from dynamics.quaternion import attitude_error_vector_rad
from dynamics.validation import InvalidParameterError

#: How long to try a scheduler before saying it cannot be reached, seconds.
SCHEDULER_TIMEOUT_S = 10
_ADDRESS = re.compile(r"^([a-z]+://)?[\w.\-\[\]:]+:\d+$")


def run_many(scenario: Scenario, runs: RunTable, estimators, *, per_run_limit: int | None = None,
             consistency: bool = False, nees_every: int = 1, settle_steps: int = 0,
             keep_traces: bool = False, error_every: int = 0, workers: int = 0,
             threads: int | None = None,
             chunk_runs: int = CHUNK_RUNS, progress_bar=None) -> BatchResult:
    """Every estimator of ``estimators`` over ``runs``: their statistics,
    diverged steps and, with ``consistency``, their NEES and NIS figures
    (:attr:`BatchResult.consistency`, for estimators that report a
    covariance); with ``keep_traces``, their estimates and attitude
    variances at every step (:attr:`BatchResult.estimates`,
    :attr:`BatchResult.attitude_variances`); with ``error_every`` m > 0,
    their errors at steps 0, m, 2m, … (:attr:`BatchResult.error_samples`).
    An estimator that runs per run
    covers the first ``per_run_limit`` runs only (all if None); its arrays
    are that long."""
    chunk_runs = whole_number("chunk_runs", chunk_runs, 1)
    if per_run_limit is not None:
        per_run_limit = whole_number("per_run_limit", per_run_limit, 1)
    runs = checked_runs(scenario, runs)
    refuse_unreadable(estimators, scenario_sensors(scenario), "the scenario")
    warn_unmodelled(scenario, estimators)
    kept = {"consistency": consistency, "nees_every": nees_every,
            "settle_steps": settle_steps, "keep_traces": keep_traces,
            "error_every": whole_number("error_every", error_every, 0)}
    engine = []
    for name in estimators:
        if name not in ENGINE_ESTIMATORS:
            continue
        limitation = engine_limitation(scenario, runs, name)
        if limitation is None:
            engine.append(name)
        else:
            warnings.warn(f"the engine does not model {limitation}; {name} takes the "
                          "per-run path on every run (slower, the same numbers)", stacklevel=2)
    results = {}
    if engine:
        results.update(_on_the_engine(scenario, runs, engine, kept, threads, chunk_runs,
                                      progress_bar))
    for name in estimators:
        if name not in results:
            limited = per_run_limit is not None      # every estimator on the per-run path
            count = min(len(runs), per_run_limit) if limited else len(runs)
            arguments = [(scenario, runs, i, name, kept) for i in range(count)]
            results[name] = _concatenated(map_tasks(_one_run, arguments, workers, progress_bar))

    def each(key):
        return {name: results[name][key] for name in estimators if key in results[name]}
    return BatchResult(runs=runs, estimators=tuple(estimators), statistics=each("statistics"),
                       usage={name: Usage.combined(results[name]["usage"])
                              for name in estimators},
                       diverged_step=each("diverged_step"),
                       estimates=each("estimates") if keep_traces else None,
                       attitude_variances=each("variances") if keep_traces else None,
                       error_samples=each("error_samples") if error_every else None,
                       sample_time_s=(np.arange(0, scenario.n_steps, error_every) * scenario.dt
                                      if error_every else None),
                       consistency=each("consistency") if consistency else None)


#: What a run's record joins over chunks or runs, besides its statistics.
_PER_RUN_ARRAYS = ("diverged_step", "estimates", "variances", "error_samples")
_CONSISTENCY_ARRAYS = ("nees_samples", "nees_time_average", "nis_mean", "likelihood_sum",
                       "updates")


def _on_the_engine(scenario, runs, names, kept: dict, threads, chunk_runs,
                   progress_bar) -> dict:
    """The engine's estimators over ``runs``, ``chunk_runs`` at a time, joined."""
    parts = []
    for start in range(0, len(runs), chunk_runs):
        part = run_batch(scenario, runs.slice(start, start + chunk_runs), names,
                         threads=threads, **kept)
        parts.append(part)
        if progress_bar is not None:
            progress_bar.update(len(part.runs) * len(names))
    sensors = [sensor.name for sensor in scenario.build_vector_sensors()]
    records = [{name: _engine_record(part, name, sensors) for name in names} for part in parts]
    return {name: _concatenated([record[name] for record in records]) for name in names}


def _engine_record(part: BatchResult, name: str, sensors=()) -> dict:
    """One estimator's arrays in one engine batch, as :func:`_one_run` gives
    them (``sensors``: the names of the scenario's vector sensors, in order)."""
    record = {"statistics": part.statistics[name], "diverged_step": part.diverged_step[name],
              "usage": _engine_usage((part.rejected or {}).get(name), sensors, len(part.runs))}
    if part.error_samples is not None:
        record["error_samples"] = part.error_samples[name]
    if part.estimates is not None:
        record["estimates"] = part.estimates[name]
        if name in part.attitude_variances:
            record["variances"] = part.attitude_variances[name]
    if part.consistency and name in part.consistency:
        record["consistency"] = part.consistency[name]
    return record


def _engine_usage(rejected, sensors, runs: int) -> list:
    """The engine's runs' usage: the vector readings each rejected (the engine
    does not count those offered, nor the star tracker's)."""
    if rejected is None:
        return [Usage(runs=runs, offered=None)]
    return [Usage(runs=runs, offered=None,
                  rejected={sensor: int(rejected[:, s].sum()) for s, sensor in enumerate(sensors)})]


def _one_run(scenario: Scenario, runs: RunTable, i: int, name: str, kept: dict) -> dict:
    """Run ``i`` of ``runs`` of estimator ``name`` on the per-run path, with
    that run's settings: its statistics and, if asked, its NEES and NIS and
    its traces, each with a leading axis of one run."""
    case = scenario.replace(**{setting: float(getattr(runs, setting)[i])
                               for setting in PER_RUN_SETTINGS})
    traced = kept["consistency"] or kept["keep_traces"]
    result = simulate(case, [name], seed=int(runs.seeds[i]), traces=traced)
    record = {"statistics": {column: np.array([value]) for column, value in
                             error_statistics(result.error_deg[name]).items()},
              "diverged_step": np.array([result.diverged_step[name]], dtype=np.int64),
              "usage": [result.usage[name]]}
    if kept["error_every"]:
        record["error_samples"] = result.error_deg[name][::kept["error_every"]][None]
    if not traced:
        return record
    trace = result.traces[name]
    covariance = trace.attitude_covariance
    if kept["keep_traces"]:
        record["estimates"] = trace.quat[None]
        if covariance is not None:
            record["variances"] = np.diagonal(covariance, axis1=1, axis2=2)[None]
    if kept["consistency"]:
        record["consistency"] = _run_consistency(result, trace, kept)
    return record


def _run_consistency(result, trace, kept: dict) -> dict:
    """One per-run simulation's NEES samples and time average, and its mean NIS."""
    every, checked = kept["nees_every"], {}
    if trace.attitude_covariance is not None:
        values = nees(attitude_error_vector_rad(result.truth.q_true, trace.quat),
                      trace.attitude_covariance)
        checked.update(nees_samples=values[::every][None],
                       nees_time_average=np.array([values[kept["settle_steps"]:].mean()]),
                       time_s=result.time_s[::every])
    if trace.nis is not None:
        checked.update(nis_mean=np.array([np.nanmean(trace.nis)]), nis_dof=trace.nis_dof)
    return checked


def _concatenated(records: list) -> dict:
    """Records of the same estimator (chunks, or single runs) joined along the runs."""
    first = records[0]
    joined = {"statistics": {column: np.concatenate([r["statistics"][column] for r in records])
                             for column in STAT_COLUMNS}}
    joined.update({key: np.concatenate([r[key] for r in records])
                   for key in _PER_RUN_ARRAYS if key in first})
    joined["usage"] = [usage for r in records for usage in r["usage"]]
    if first.get("consistency"):
        checked = first["consistency"]
        joined["consistency"] = {key: np.concatenate([r["consistency"][key] for r in records])
                                 for key in _CONSISTENCY_ARRAYS if key in checked}
        joined["consistency"].update({key: checked[key] for key in ("time_s", "nis_dof")
                                      if key in checked})
    return joined


def map_tasks(function, arguments, workers: int, progress_bar) -> list:
    """``function(*a)`` for each ``a``, in order; on a local Dask cluster with ``workers``."""
    if not workers:
        out = []
        for args in arguments:
            out.append(function(*args))
            if progress_bar is not None:
                progress_bar.update(1)
        return out
    client, cluster = dask_client(workers, None)
    try:
        futures = [client.submit(_with_warnings, function, *args, pure=False)
                   for args in arguments]
        out = []
        for future in futures:
            result, caught = future.result()
            for message, category in caught:     # said here, as the command says its notes
                warnings.warn(message, category, stacklevel=2)
            out.append(result)
            if progress_bar is not None:
                progress_bar.update(1)
        return out
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _with_warnings(function, *args):
    """``function(*args)`` in a worker, and the warnings it gave (message,
    category), for :func:`map_tasks` to give again where the results are
    read: in the worker's own process they would print raw, file and line
    first, past the command's notes."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = function(*args)
    return result, [(str(warning.message), warning.category) for warning in caught]


def dask_client(workers: int, scheduler: str | None):
    """A Dask client: on the ``scheduler`` at that address, or on a local
    cluster of ``workers`` single-threaded processes (then also the cluster,
    to close; else None)."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise InvalidParameterError(
            "workers" if workers else "scheduler", workers or scheduler,
            "needs Dask; install it with pip install '.[distributed]'") from None
    logging.getLogger("distributed").setLevel(logging.ERROR)
    if scheduler is not None:
        if not _ADDRESS.match(scheduler):
            raise InvalidParameterError("scheduler", scheduler,
                                        "must be an address such as tcp://host:8786")
        try:
            return Client(scheduler, timeout=SCHEDULER_TIMEOUT_S), None
        except (OSError, TimeoutError) as err:
            raise InvalidParameterError("scheduler", scheduler, f"cannot be reached "
                                        f"({type(err).__name__}: {err})") from None
    import dask
    with dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_MMAP_THRESHOLD_":
                          WORKER_MMAP_THRESHOLD}):
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=None, silence_logs=logging.ERROR)
    return Client(cluster), cluster


#: glibc's size from which an allocation is a mapping of its own, bytes, in
#: a local cluster's workers. Dask sets their MALLOC_TRIM_THRESHOLD_ (to hand
#: memory back to the system), which in glibc also freezes this threshold at
#: 128 kB: every larger numpy temporary is then mapped and faulted in anew.
#: ``broad`` on BROAD's 30 trials, two workers: 14 million page faults and
#: 35 s of system time, 60 s in all; at 32 MB, 1.2 million, 5 s and 42 s.
#: The arithmetic is the same: every number is.
WORKER_MMAP_THRESHOLD = 32 << 20
