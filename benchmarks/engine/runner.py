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

import numpy as np

from benchmarks.engine.batch import (CHUNK_RUNS, ENGINE_ESTIMATORS, PER_RUN_SETTINGS,
                                     BatchResult, RunTable, checked_runs, run_batch,
                                     whole_number)
from benchmarks.metrics import STAT_COLUMNS, error_statistics, nees
from benchmarks.scenario import Scenario
from benchmarks.simulation import simulate
from dynamics.quaternion import attitude_error_vector_rad
from dynamics.validation import InvalidParameterError

#: How long to try a scheduler before saying it cannot be reached, seconds.
SCHEDULER_TIMEOUT_S = 10
_ADDRESS = re.compile(r"^([a-z]+://)?[\w.\-\[\]:]+:\d+$")


def run_many(scenario: Scenario, runs: RunTable, estimators, *, per_run_limit: int | None = None,
             consistency: bool = False, nees_every: int = 1, settle_steps: int = 0,
             workers: int = 0, threads: int | None = None, chunk_runs: int = CHUNK_RUNS,
             progress_bar=None) -> BatchResult:
    """Every estimator of ``estimators`` over ``runs``: their statistics,
    diverged steps and, with ``consistency``, their NEES and NIS figures
    (:attr:`BatchResult.consistency`, for estimators that report a
    covariance). An estimator that runs per run covers the first
    ``per_run_limit`` runs only (all if None); its arrays are that long."""
    chunk_runs = whole_number("chunk_runs", chunk_runs, 1)
    runs = checked_runs(scenario, runs)
    engine = [name for name in estimators if name in ENGINE_ESTIMATORS]
    results = {}
    if engine:
        results.update(_on_the_engine(scenario, runs, engine, consistency, nees_every,
                                      settle_steps, threads, chunk_runs, progress_bar))
    for name in estimators:
        if name not in results:
            count = len(runs) if per_run_limit is None else min(len(runs), per_run_limit)
            arguments = [(scenario, runs, i, name, consistency, nees_every, settle_steps)
                         for i in range(count)]
            results[name] = _joined(_map(_one_run, arguments, workers, progress_bar))
    statistics = {name: results[name]["statistics"] for name in estimators}
    checked = {name: results[name]["consistency"] for name in estimators
               if results[name].get("consistency")}
    return BatchResult(runs=runs, estimators=tuple(estimators), statistics=statistics,
                       diverged_step={name: results[name]["diverged_step"]
                                      for name in estimators},
                       consistency=checked if consistency else None)


def _on_the_engine(scenario, runs, names, consistency, nees_every, settle_steps, threads,
                   chunk_runs, progress_bar) -> dict:
    """The engine's estimators over ``runs``, ``chunk_runs`` at a time, joined."""
    parts = []
    for start in range(0, len(runs), chunk_runs):
        part = run_batch(scenario, runs.slice(start, start + chunk_runs), names,
                         consistency=consistency, nees_every=nees_every,
                         settle_steps=settle_steps, threads=threads)
        parts.append(part)
        if progress_bar is not None:
            progress_bar.update(len(part.runs) * len(names))
    joined = {}
    for name in names:
        record = {"statistics": {column: np.concatenate([p.statistics[name][column]
                                                         for p in parts])
                                 for column in STAT_COLUMNS},
                  "diverged_step": np.concatenate([p.diverged_step[name] for p in parts])}
        if consistency and name in (parts[0].consistency or {}):
            first = parts[0].consistency[name]
            record["consistency"] = {
                key: np.concatenate([p.consistency[name][key] for p in parts])
                for key in ("nees_samples", "nees_time_average", "nis_mean")}
            record["consistency"].update(time_s=first["time_s"], nis_dof=first["nis_dof"])
        joined[name] = record
    return joined


def _one_run(scenario: Scenario, runs: RunTable, i: int, name: str, consistency: bool,
             nees_every: int, settle_steps: int) -> dict:
    """Run ``i`` of ``runs`` of estimator ``name`` on the per-run path, with
    that run's settings: its statistics and, if asked, its NEES and NIS."""
    case = scenario.replace(**{setting: float(getattr(runs, setting)[i])
                               for setting in PER_RUN_SETTINGS})
    result = simulate(case, [name], seed=int(runs.seeds[i]), traces=consistency)
    out = {"statistics": error_statistics(result.error_deg[name]),
           "diverged_step": result.diverged_step[name]}
    if not consistency:
        return out
    trace = result.traces[name]
    checked = {}
    if trace.attitude_covariance is not None:
        values = nees(attitude_error_vector_rad(result.truth.q_true, trace.quat),
                      trace.attitude_covariance)
        checked.update(nees_samples=values[::nees_every],
                       nees_time_average=float(values[settle_steps:].mean()),
                       time_s=result.time_s[::nees_every])
    if trace.nis is not None:
        checked.update(nis_mean=float(np.nanmean(trace.nis)), nis_dof=trace.nis_dof)
    out["consistency"] = checked
    return out


def _joined(outcomes: list) -> dict:
    """The per-run outcomes of one estimator as arrays, one entry per run."""
    record = {"statistics": {column: np.array([o["statistics"][column] for o in outcomes])
                             for column in STAT_COLUMNS},
              "diverged_step": np.array([o["diverged_step"] for o in outcomes],
                                        dtype=np.int64)}
    checked = outcomes[0].get("consistency") if outcomes else None
    if checked:
        record["consistency"] = {key: np.array([o["consistency"][key] for o in outcomes])
                                 for key in ("nees_samples", "nees_time_average", "nis_mean")
                                 if key in checked}
        record["consistency"].update({key: checked[key] for key in ("time_s", "nis_dof")
                                      if key in checked})
    return record


def _map(function, arguments, workers: int, progress_bar) -> list:
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
        futures = [client.submit(function, *args, pure=False) for args in arguments]
        out = []
        for future in futures:
            out.append(future.result())
            if progress_bar is not None:
                progress_bar.update(1)
        return out
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


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
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                           dashboard_address=None, silence_logs=logging.ERROR)
    return Client(cluster), cluster
