r"""What a tuner minimises: an estimator's score over a set of *cases* —
simulated seeds of a scenario, or recordings — for one choice of its settings.

Objectives (:data:`OBJECTIVES`):

* with the truth: ``rms``, ``mean``, ``std`` (the workshop's loss) and
  ``max`` of the attitude error, degrees, averaged over the cases (on a
  recording, over its movement samples with a reference: the BROAD authors'
  scoring);
* consistency, with the truth: ``anees``, :math:`|\ln(\overline{\text{NEES}}/3)|`,
  the distance of the average attitude NEES from its expected value 3 on a
  log scale (over the samples after the first tenth of each run, where the
  prior has settled);
* without the truth: ``nis``, :math:`|\ln(\overline{\text{NIS}}/m)|` for the
  star tracker's NIS of dimension m, and ``likelihood``, the innovations'
  negative log-likelihood per update,
  :math:`\frac{1}{n}\sum_k (\ln\det S_k + y_k^\mathsf{T} S_k^{-1} y_k)` over
  every reading that reaches the gate, tracker and vector readings alike,
  a rejected one's NIS at the gate's threshold (:mod:`estimators.gating`; the classical
  maximum-likelihood criterion of adaptive filtering: Mehra 1970; twice the
  negative log-likelihood per update, less :math:`m\ln 2\pi`). These two need
  no reference.

A run that diverges scores infinity: never a number a minimiser could prefer.
The same seeds serve every candidate (common random numbers): differences
between candidates are the settings', not the noise's. On seeds, the
objectives with the truth and ``nis`` run on the batched engine where the
estimator has a kernel (:func:`benchmarks.engine.run_many`); ``likelihood``
and recordings run each case on the per-run path, from sensor data made once.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from benchmarks.engine import ENGINE_ESTIMATORS, make_runs, run_many
from benchmarks.engine.batch import engine_limitation
from benchmarks.metrics import attitude_error_deg, error_statistics, nees
from benchmarks.scenario import Scenario
from benchmarks.sensor_use import present_sensors, refuse_unreadable
from benchmarks.simulation import SensorData, simulate_sensors, simulate_truth, vectors_for
from dynamics.quaternion import attitude_error_vector_rad
from dynamics.validation import InvalidParameterError
from estimators import resolve_estimator

#: Objective name → what it reads (the error statistic, or the kind).
OBJECTIVES = {"rms": "rms_deg", "mean": "mean_deg", "std": "std_deg", "max": "max_deg",
              "anees": "anees", "nis": "nis", "likelihood": "likelihood"}
#: The objectives that need a reference attitude.
NEEDS_TRUTH = ("rms", "mean", "std", "max", "anees")
#: The NEES average starts after this fraction of each run.
SETTLE_FRACTION = 0.1


def checked_objective(objective: str) -> str:
    if objective not in OBJECTIVES:
        raise InvalidParameterError("objective", objective,
                                    f"must be one of {', '.join(OBJECTIVES)}")
    return objective


@dataclass(frozen=True)
class Case:
    """One run's data: the scenario that configures the estimator, its
    sensor data, the reference attitude (NaN in its gaps) and the samples
    the scores with the truth read."""

    label: str
    scenario: Scenario
    sensors: SensorData
    q_reference: np.ndarray      # (N, 4)
    scored: np.ndarray           # (N,) bool
    seed: int | None = None      # a simulated case's seed
    #: What the case is made of, by content: ``("seed", n)`` or
    #: ``("recording", digest)`` (:func:`benchmarks.experiments.replay.dataset_source`),
    #: so that a test set is kept apart from a training set by what it holds.
    source: tuple = ()

    @property
    def has_reference(self) -> bool:
        return bool(self.scored.any())

    @property
    def time_s(self) -> np.ndarray:
        """Seconds from the case's first sample."""
        return np.arange(len(self.q_reference)) * self.scenario.dt


def seed_cases(scenario: Scenario, seeds) -> list[Case]:
    """The simulated cases of ``seeds`` (their sensor data made once)."""
    truth = simulate_truth(scenario)
    scored = np.ones(scenario.n_steps, dtype=bool)
    return [Case(f"seed {seed}", scenario, simulate_sensors(scenario, truth, int(seed)),
                 truth.q_true, scored, int(seed), ("seed", int(seed))) for seed in seeds]


def recording_case(data, label: str, source: tuple = ()) -> Case:
    """A recording made ready by :func:`benchmarks.experiments.replay.load_replay`
    (``source``: what it is made of, :attr:`Case.source`)."""
    recording = data.recording
    return Case(label, data.scenario, data.sensors, data.truth.q_true,
                recording.has_reference & recording.movement, source=source)


def with_settings(scenario: Scenario, name: str, settings: dict) -> Scenario:
    """``scenario`` with estimator ``name`` set to ``settings`` (constructor
    keywords): its own fields (the EKF's ``pc_exponent``…) on the scenario,
    the rest in its ``[estimators.NAME]`` section."""
    cls = resolve_estimator(name)
    owned = {cls.scenario_defaults[key]: value for key, value in settings.items()
             if key in cls.owned_fields}
    options = {key: dict(section) for key, section in scenario.estimator_options.items()}
    rest = {key: value for key, value in settings.items() if key not in cls.owned_fields}
    if rest:
        options.setdefault(name, {}).update(rest)
    return scenario.replace(**owned, estimator_options=options)


class Objective:
    """``objective(settings)``: the score of estimator ``name`` with
    ``settings`` (constructor keywords over the scenario's, or a function of
    a case's scenario giving them: a scale multiplies each case's own
    default) on ``cases``."""

    def __init__(self, name: str, objective: str, cases: list[Case], *, threads=None):
        self.name, self.objective, self.cases = name, checked_objective(objective), cases
        self.threads = threads
        for case in cases:
            refuse_unreadable([name], present_sensors(case.sensors), case.label)
        if objective in NEEDS_TRUTH:
            for case in cases:
                if not case.has_reference:
                    raise InvalidParameterError("objective", objective,
                                                f"needs a reference attitude, and {case.label} "
                                                "has none: use nis or likelihood")
        seeds = [case.seed for case in cases]
        one_scenario = all(case.scenario is cases[0].scenario for case in cases)
        # The likelihood's sums come from the kernels only (not from the per-run fallback).
        self.on_engine = None not in seeds and one_scenario and (
            objective != "likelihood" or (name in ENGINE_ESTIMATORS and engine_limitation(
                cases[0].scenario, None, name) is None))

    def __call__(self, settings) -> float:
        chosen = settings if callable(settings) else (lambda scenario: settings)
        scores = self.engine_scores(chosen) if self.on_engine else self.case_scores(chosen)
        return _combined(self.objective, scores)

    def engine_scores(self, settings) -> dict:
        """Every case's numbers from one batch (the engine where there is a kernel)."""
        scenario = with_settings(self.cases[0].scenario, self.name,
                                 settings(self.cases[0].scenario))
        if self.objective == "likelihood" and engine_limitation(scenario, None,
                                                                self.name) is not None:
            # A setting the kernel does not model (a gate, for the EKF): the
            # likelihood's sums come from the per-run path.
            return self.case_scores(settings)
        runs = make_runs(scenario, [case.seed for case in self.cases])
        consistency = self.objective in ("anees", "nis", "likelihood")
        settle = int(SETTLE_FRACTION * scenario.n_steps)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")     # a per-run fallback is said once, by the caller
            batch = run_many(scenario, runs, [self.name], consistency=consistency,
                             settle_steps=settle, threads=self.threads)
        diverged = batch.diverged_step[self.name] >= 0
        if self.objective == "likelihood":
            checked = (batch.consistency or {}).get(self.name)
            if checked is None or "likelihood_sum" not in checked:
                return {"values": np.full(len(runs), np.nan)}     # not a filter
            return {"values": np.where(diverged, np.inf, 0.0),
                    "sums": {"updates": float(np.sum(checked["updates"])),
                             "total": float(np.sum(checked["likelihood_sum"]))}}
        if self.objective in ("anees", "nis"):
            checked = (batch.consistency or {}).get(self.name) or {}
            key = "nees_time_average" if self.objective == "anees" else "nis_mean"
            values = checked.get(key, np.full(len(runs), np.nan))
            return {"values": np.where(diverged, np.inf, values),
                    "dof": checked.get("nis_dof", 3)}
        return {"values": np.where(diverged, np.inf,
                                   batch.statistics[self.name][OBJECTIVES[self.objective]])}

    def case_scores(self, settings) -> dict:
        """Every case run on the per-run path."""
        values, nis_dof, sums = [], 3, {"updates": 0, "total": 0.0}
        for case in self.cases:
            estimator, trace = run_case(self.name, case, settings(case.scenario),
                                        log_innovations=self.objective == "likelihood")
            if estimator.diverged_step is not None:
                values.append(math.inf)
                continue
            values.append(self._case_value(case, trace, estimator, sums))
            nis_dof = trace.nis_dof or nis_dof
        return {"values": np.array(values), "dof": nis_dof, "sums": sums}

    def _case_value(self, case: Case, trace, estimator, sums: dict) -> float:
        if self.objective == "likelihood":
            logged = getattr(estimator, "innovation_sums", None)
            if logged is None:
                return math.nan         # not a filter: no innovations
            sums["updates"] += logged["updates"]
            sums["total"] += logged["log_det"] + logged["nis"]
            return 0.0
        if self.objective == "nis":
            return float(np.nanmean(trace.nis)) if trace.nis is not None else math.nan
        if self.objective == "anees":
            if trace.attitude_covariance is None:
                return math.nan
            values = nees(attitude_error_vector_rad(case.q_reference, trace.quat),
                          trace.attitude_covariance)
            settled = case.scored.copy()
            settled[:int(SETTLE_FRACTION * len(settled))] = False
            return float(np.mean(values[settled]))
        error = attitude_error_deg(case.q_reference, trace.quat)[case.scored]
        return error_statistics(error)[OBJECTIVES[self.objective]]


def run_case(name: str, case: Case, settings: dict, log_innovations: bool = False):
    """Estimator ``name`` with ``settings`` tracked through ``case`` on the
    per-run path: the estimator after the run, and its trace."""
    estimator = resolve_estimator(name).from_scenario(
        with_settings(case.scenario, name, settings))
    estimator.log_innovations = log_innovations
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # a class that ignores vectors is said once
        vectors = vectors_for(estimator, name, case.sensors.vectors)
    return estimator, estimator.track(*case.sensors.record, vectors=vectors)


def _combined(objective: str, scores: dict) -> float:
    """The cases' numbers as one score (infinite if any run diverged)."""
    values = np.asarray(scores["values"], dtype=float)
    if np.any(np.isinf(values)):
        return math.inf
    if np.any(np.isnan(values)):
        raise InvalidParameterError("objective", objective, "is not defined for this "
                                    "estimator (it reports no covariance or no NIS)")
    if objective == "anees":
        return abs(math.log(float(np.mean(values)) / 3.0))
    if objective == "nis":
        return abs(math.log(float(np.mean(values)) / scores["dof"]))
    if objective == "likelihood":
        sums = scores["sums"]
        if not sums["updates"]:
            raise InvalidParameterError("objective", objective, "needs updates to score, "
                                        "and no reading was applied")
        return sums["total"] / sums["updates"]
    return float(np.mean(values))
