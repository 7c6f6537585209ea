"""Tuned estimators on BROAD, scored on trials their tuning never saw.

``broad --tune`` picks each estimator's settings by the lowest mean total
RMSE (the authors' score, :mod:`benchmarks.broad.metric`) over *training*
trials, then scores them on others:

* ``all-trials``: two-fold cross-validation. The trials, in their order,
  are dealt into two folds (every other one, so each fold holds slow and
  fast, undisturbed and disturbed trials); each fold is scored with the
  settings tuned on the other. Every number in the table then comes from
  trials its settings were not tuned on.
* ``per-trial``: each trial scored with the settings tuned on itself, the
  authors' "each trial's best": optimistic, and the table says so.
* ``other-dataset`` (``broad --train DIR``): tuned on every trial of
  another dataset, scored on this one's — the honest answer to "will these
  settings work on my device?". The two must share no recording
  (:func:`checked_apart`).
* ``halves``: no reference needed. Each trial's first half tunes the
  Kalman filters by their innovations' likelihood
  (:class:`LikelihoodScore`: the classical criterion of adaptive filtering,
  Mehra 1970, as :mod:`benchmarks.experiments.objectives` has it); every
  estimator runs the whole trial and is scored on its second half only (by
  the reference where there is one, else by agreement), and each tuning is
  judged there (:func:`held_out`): tuned without truth on one part of a
  recording, judged on another. The other estimators keep their defaults.
* ``none``: the defaults.

Tuned settings are adopted only where tuning is shown to carry to trials it
did not see (:func:`checked`, in ``all-trials`` and ``other-dataset``):
nested cross-validation, the training trials dealt into two folds again,
the tuning repeated on each and scored on the other. Where the settings so
tuned score worse there than the defaults, the defaults are kept, and the
table says so. On BROAD, the online filters' four settings tuned on
fifteen trials gained there and lost on the held-out half (up to 0.015°)
on three of their four folds; the check, reading no held-out trial, kept
the defaults on all four (Cawley & Talbot 2010, "On over-fitting in model
selection and subsequent selection bias in performance evaluation", JMLR
11, §5). It is conservative: a tuning on a quarter of the trials overfits
more than one on half, and the smoother's gain is kept on one fold of two.

How: on the authors' grid where they used one (Madgwick's β,
:data:`GRIDS`); otherwise the tuning issue's tuner
(:func:`benchmarks.experiments.estimator_tuning.tune_estimator`, bounded Brent or
Nelder–Mead from the defaults, at most :data:`MAX_EVALUATIONS` runs of the
training trials) over the estimator's declared tunable settings
(:data:`PARAMETERS` where the default choice would include ones that do
nothing here). Mahony's (Kp, Ki) grid has 4,100 points, each a run of every
training trial: the tuner finds its minimum in some fifty. Estimators that
declare no tunable settings (dead reckoning, the peers: VQF with its
defaults, as the issue asks) keep their defaults.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from benchmarks.broad.case_study import MADGWICK_BETAS
from benchmarks.broad.dataset import trial_label
from benchmarks.broad.inputs import ImuInputs, imu_inputs, scored_metric
from benchmarks.broad.metric import rmse_deg
from benchmarks.engine.recorded import run_recorded
from benchmarks.experiments.estimator_tuning import keyword_values
from dynamics.validation import InvalidParameterError
from estimators import resolve_estimator

MODES = ("none", "all-trials", "per-trial", "halves", "other-dataset")
FOLDS = 2
#: The authors' grids (``process_data.py``), searched exhaustively.
GRIDS = {"madgwick": {"beta": MADGWICK_BETAS}, "madgwick-broad": {"beta": MADGWICK_BETAS}}
#: The settings tuned where the declared defaults would add one that does
#: nothing on BROAD (the ``measurement_scale`` scales the star tracker's R;
#: there is no tracker here; the gates: the IMU models gate nothing on an
#: IMU recording) or leave out what acts here: the IMU models' densities.
PARAMETERS = {name: ("gyro_noise", "gyro_bias_random_walk", "gravity_density",
                     "heading_density") for name in ("mekf", "mekf-smoother", "usque")}
#: What ``--tune halves`` tunes by the likelihood: the gyro's densities. Not
#: the IMU models': the low-passed gravity's innovations are correlated over
#: seconds, which the likelihood takes as independent readings, so it drives
#: their density to its lower bound (measured on trials 02 and 07: 16–33°
#: scored, against 1.3–1.7° with the gyro's alone).
HALVES_PARAMETERS = {name: ("gyro_noise", "gyro_bias_random_walk") for name in ("mekf", "usque")}
MAX_EVALUATIONS = 60
#: The likelihood per reading compares settings over the same readings:
#: settings that refuse more of them than the defaults do (the gate, a
#: field's norm and dip tests), by more than this share of them, are out of
#: bounds, and a held-out verdict says so. A filter led astray refuses what
#: it no longer fits, and its likelihood per reading used improves (a log
#: tuned on it went from 0.32° to 60°, 44 % of its field readings refused,
#: and the verdict was "better").
REFUSAL_TOLERANCE = 0.01
#: How the table names each mode's numbers.
MODE_LABELS = {"none": "default settings",
               "all-trials": f"settings tuned on the other fold of trials ({FOLDS}-fold "
                             "cross-validation: no trial scored with settings tuned on it; "
                             "the defaults where the tuning's check kept them)",
               "per-trial": "settings tuned on each trial itself (optimistic: the authors' "
                            "each-trial best)",
               "halves": "the second half of each trial, the Kalman filters tuned on its first "
                         "half by their innovations' likelihood (no reference used)",
               "other-dataset": "settings tuned on every trial of another dataset "
                                "(--train): none of these trials was tuned on; the defaults "
                                "where the tuning's check kept them"}


@dataclass(frozen=True)
class TrialCase:
    """A training trial as the tuner takes a case: its label and scenario."""

    label: str
    inputs: ImuInputs

    @property
    def scenario(self):
        return self.inputs.scenario

    @property
    def sensors(self):
        return self.inputs.sensors


class TrialsScore:
    """The mean total RMSE (degrees) of estimator ``name`` over ``cases``
    with the settings asked (infinite if a run diverges): the tuner's loss;
    the inclination's where it has no heading reference (a 6-axis IMU:
    :func:`~benchmarks.broad.inputs.scored_metric`)."""

    def __init__(self, name: str, cases, second_half: bool = False):
        self.cls, self.cases = resolve_estimator(name), list(cases)
        self.second_half = second_half

    def __call__(self, settings_of) -> float:
        totals = []
        for case in self.cases:
            estimator = self.cls.from_scenario(case.scenario, **settings_of(case.scenario))
            sensors, recording = case.inputs.sensors, case.inputs.recording
            run = run_recorded(estimator, sensors.omega_meas_radps, sensors.vectors)
            movement = recording.movement & judged_samples(recording, self.second_half)
            total = rmse_deg(run.estimates, recording.reference_quat,
                             movement)[scored_metric(self.cls, recording)]
            if not math.isfinite(total):
                return math.inf
            totals.append(total)
        return float(np.mean(totals))


class LikelihoodScore:
    """The innovations' negative log-likelihood per reading, ln det S + NIS
    averaged over every reading of estimator ``name`` on ``cases`` that
    reaches the gate (a rejected one's NIS at the gate's threshold:
    :mod:`estimators.gating`; no reference read; infinite if a run diverges
    or none reaches it): the loss of ``--tune halves``."""

    def __init__(self, name: str, cases):
        self.cls, self.cases = resolve_estimator(name), list(cases)
        self.readings = sum(int(np.count_nonzero(vector.available))
                            for case in self.cases for vector in case.sensors.vectors)
        self._default_refused = None

    def __call__(self, settings_of) -> float:
        total, updates, refused = self.sums(settings_of)
        if not updates or not math.isfinite(total):
            return math.inf
        if self._default_refused is None:
            self._default_refused = self.sums(lambda _scenario: {})[2]
        if refused > self._default_refused + REFUSAL_TOLERANCE * self.readings:
            return math.inf               # out of bounds: REFUSAL_TOLERANCE
        return total / updates

    def sums(self, settings_of) -> tuple[float, int, int]:
        """ln det S + NIS summed over every gated reading of the cases, their
        count, and the readings refused (an infinite sum where a run
        diverges or none is gated)."""
        total, updates, refused = 0.0, 0, 0
        for case in self.cases:
            estimator = self.cls.from_scenario(case.scenario, **settings_of(case.scenario))
            sensors = case.inputs.sensors
            run = run_recorded(estimator, sensors.omega_meas_radps, sensors.vectors,
                               innovations=True)
            if run.diverged_step is not None or not run.likelihood or not run.likelihood[1]:
                return math.inf, 0, 0
            total, updates = total + run.likelihood[0], updates + run.likelihood[1]
            refused += sum(run.rejected.values())
        return total, updates, refused


def tunes(name: str, mode: str = "all-trials") -> bool:
    """Whether ``--tune`` in ``mode`` tunes estimator ``name`` (a grid, or
    declared tunables; without a reference, an online Kalman filter's)."""
    from estimators.tunable import tunables
    cls = resolve_estimator(name)
    if mode == "halves":
        return hasattr(cls, "log_innovations") and cls.mode == "online" and bool(tunables(cls))
    return name in GRIDS or bool(tunables(cls))


def tune_on(name: str, cases, quiet: bool = True, mode: str = "all-trials") -> dict:
    """Estimator ``name``'s settings tuned on ``cases`` (by the reference's
    total RMSE, or in mode ``halves`` by the innovations' likelihood):
    ``values`` (setting → value, before any scale is applied), ``loss``,
    ``loss_default``, ``method`` and ``evaluations``."""
    if mode == "halves":
        score, name_of_loss = LikelihoodScore(name, cases), "innovation likelihood"
    else:
        score, name_of_loss = TrialsScore(name, cases), "broad total RMSE"
    if name in GRIDS and mode != "halves":
        grid = GRIDS[name]
        points = [dict(zip(grid, combination))
                  for combination in itertools.product(*grid.values())]
        losses = [score(lambda _scenario, point=point: point) for point in points]
        best = int(np.argmin(losses))
        return {"values": {key: float(value) for key, value in points[best].items()},
                "loss": losses[best], "loss_default": score(lambda _scenario: {}),
                "method": f"the authors' grid ({len(points)} points)",
                "evaluations": len(points) + 1}
    from benchmarks.experiments.estimator_tuning import tune_estimator
    parameters = _acting((HALVES_PARAMETERS if mode == "halves" else PARAMETERS).get(name),
                         name, cases)
    tuning = tune_estimator(name, cases, name_of_loss, parameters=parameters,
                            max_evaluations=MAX_EVALUATIONS, quiet=quiet, score=score)
    return {"values": dict(tuning.tuned), "loss": tuning.loss,
            "loss_default": tuning.loss_default, "method": tuning.method,
            "evaluations": len(tuning.evaluations),
            "objective": "likelihood" if mode == "halves" else "rmse"}


def _acting(parameters, name: str, cases):
    """``parameters`` less those acting on a sensor none of ``cases`` has
    (the heading's density on a 6-axis IMU); None stays None (the defaults)."""
    if parameters is None:
        return None
    from benchmarks.experiments.estimator_tuning import cases_sensors
    from estimators.tunable import tunables
    declared, present = tunables(resolve_estimator(name)), cases_sensors(cases)
    return tuple(p for p in parameters if present is None or declared[p].sensor is None
                 or declared[p].sensor in present)


def training_sets(trials, mode: str) -> list[tuple[list, list]]:
    """``[(training trials, trials scored with their settings)]`` of ``mode``."""
    trials = list(trials)
    if mode in ("per-trial", "halves"):
        return [([trial], [trial]) for trial in trials]
    if len(trials) < FOLDS:
        raise InvalidParameterError("tune", mode, f"needs at least {FOLDS} trials to tune on "
                                    "some and score on the others; use --tune per-trial or "
                                    "more --trials")
    folds = [trials[i::FOLDS] for i in range(FOLDS)]
    return [([t for j, other in enumerate(folds) if j != i for t in other], fold)
            for i, fold in enumerate(folds)]


def checked_apart(train, test, scored_trials) -> None:
    """Refuse a training dataset that holds a recording of the scored
    trials (the same folder, or a trial whose gyro readings are exactly the
    same, in any file format; a trimmed copy is not caught): their scores
    would be of settings tuned on them."""
    import hashlib
    if train.folder.resolve() == test.folder.resolve():
        raise InvalidParameterError("train", str(train.folder), "is the dataset scored (--broad):"
                                    " tune on another, or use --tune all-trials to tune on "
                                    "half of its trials and score the other half")

    def digest(dataset, name):
        gyro = np.ascontiguousarray(dataset.load(name).gyro_radps, dtype=float)
        return hashlib.sha256(gyro.tobytes()).hexdigest()
    scored = {digest(test, name): name for name in scored_trials}
    for name in train.available:
        twin = scored.get(digest(train, name))
        if twin is not None:
            raise InvalidParameterError("train", str(train.folder), f"holds trial {name}, the "
                                        f"same recording as the scored trial {twin}: the two "
                                        "datasets must share no recording")


def first_half_of(recording):
    """The first half of ``recording``, up to its middle sample (``--tune
    halves`` tunes on it)."""
    return recording.until_sample(recording.n_samples // 2)


def judged_samples(recording, second_half: bool = True) -> np.ndarray:
    """``(N,)`` bool: the samples a score reads — from the middle sample on
    (``--tune halves``), or all. The estimators run the whole recording (a
    filter started mid-motion would be judged on its start)."""
    judged = np.zeros(recording.n_samples, dtype=bool)
    judged[recording.n_samples // 2 if second_half else 0:] = True
    return judged


def _tune_task(dataset, training, names, gyro_delay_s, sigmas, mode, checked_on=()) -> dict:
    """The tunings of one training set (a Dask task): each of ``names`` on
    the ``training`` trials, loaded once for all of them; in mode ``halves``
    on their first halves, and judged on their second (:func:`held_out`).
    With ``checked_on`` (an inner fold's other trials, :func:`checked`):
    name → the mean total RMSE there with the defaults and with the settings
    tuned, and the count of those trials."""
    if mode != "halves":
        cases = [TrialCase(trial, imu_inputs(dataset.load(trial), gyro_delay_s, sigmas))
                 for trial in training]
        found = {name: tune_on(name, cases, mode=mode) for name in names}
        if not checked_on:
            return found
        others = [TrialCase(trial, imu_inputs(dataset.load(trial), gyro_delay_s, sigmas))
                  for trial in checked_on]
        return {name: _scored_both(name, result["values"], others)
                for name, result in found.items()}
    halves = [[TrialCase(trial, imu_inputs(part(dataset.load(trial)), gyro_delay_s, sigmas))
               for trial in training] for part in (first_half_of, lambda recording: recording)]
    return {name: held_out(name, tune_on(name, halves[0], mode=mode), *halves)
            for name in names}


def _scored_both(name: str, values: dict, cases) -> tuple[float, float, int]:
    """The mean total RMSE (°) of estimator ``name`` on ``cases`` with its
    defaults and with the tuned ``values``, and the count of cases."""
    cls, score = resolve_estimator(name), TrialsScore(name, cases)
    tuned = score(lambda scenario: _keywords(cls, values, scenario))
    return score(lambda _scenario: {}), tuned, len(cases)


def _scaled(cls, values: dict) -> bool:
    """Whether a tuned value of ``values`` is a scale factor."""
    return any(t.scales for t in cls.tunable if t.name in values)


def _keywords(cls, values: dict, scenario) -> dict:
    """Tuned ``values`` as constructor keywords on ``scenario`` (a scale
    factor as the setting it scales there)."""
    return keyword_values(cls, values, scenario) if _scaled(cls, values) else dict(values)


def inner_sets(training) -> list[tuple[list, list]]:
    """The inner folds of a training set (:func:`checked`): ``[(trials tuned
    on, trials scored)]``, none where it holds fewer than two trials."""
    return training_sets(training, "all-trials") if len(training) >= FOLDS else []


def checked(result: dict, inner: list) -> dict:
    """``result`` (a tuning on a training set) with the verdict of its
    nested cross-validation: ``inner`` holds, per inner fold, the mean total
    RMSE on its scored trials with the defaults and with the settings tuned
    on the others, and their count. The tuned settings are kept where the
    inner folds, pooled over every training trial, score lower with the
    settings tuned than with the defaults; else the defaults are
    (``adopted`` False: the values found stay in the record, unused).
    Without inner folds (one training trial) they are kept, unchecked, and
    the verdict says so."""
    if not inner:
        return {**result, "check": {"check_verdict": "not checked: one training trial"}}
    count = sum(n for _, _, n in inner)
    default = sum(loss * n for loss, _, n in inner) / count
    tuned = sum(loss * n for _, loss, n in inner) / count
    kept = tuned < default
    verdict = ("tuned settings kept: tuning carried to the inner folds' other trials" if kept
               else "defaults kept: settings tuned on part of the training trials scored "
                    "worse on the rest")
    report = {"check_loss_default_deg": default, "check_loss_deg": tuned,
              "check_verdict": verdict, "adopted": kept}
    return {**result, "adopted": kept, "check": report}


def held_out(name: str, result: dict, first_halves, wholes) -> dict:
    """``result`` (a tuning on ``first_halves``) judged on the second halves
    of the ``wholes`` (the whole trials, run whole): the innovations'
    likelihood per update there (the whole run's sums less the first half's:
    a filter is causal) with the defaults and the tuned settings, and where
    the trials have a reference their total RMSE (°) there — what the truth
    says of a tuning that never read it; and the share of the readings
    each refuses there (:data:`REFUSAL_TOLERANCE`)."""
    found, first_score = {}, LikelihoodScore(name, first_halves)
    readings = sum(int(np.count_nonzero(vector.available))
                   for case in wholes for vector in case.sensors.vectors) - first_score.readings
    for label, values in (("_default", {}), ("", result["values"])):
        total, updates, refused, rmse = _whole_runs(name, wholes, values)
        first = first_score.sums(lambda _scenario, v=values: v)
        count = updates - first[1]
        found[f"held_out_loss{label}"] = (total - first[0]) / count if count > 0 else math.inf
        found[f"held_out_refused_share{label}"] = (refused - first[2]) / max(readings, 1)
        if rmse is not None:
            found[f"held_out_rmse{label}_deg"] = rmse
    found["held_out_verdict"] = held_out_verdict(found)
    return {**result, "held_out": found}


def held_out_verdict(found: dict) -> str:
    """Whether a tuning's held-out likelihood is better than the defaults',
    over the same readings (:data:`REFUSAL_TOLERANCE`)."""
    refused, default = found["held_out_refused_share"], found["held_out_refused_share_default"]
    if refused > default + REFUSAL_TOLERANCE:
        return (f"not better: refuses {refused:.0%} of the readings where the defaults refuse "
                f"{default:.0%}; keep the defaults")
    if found["held_out_loss"] < found["held_out_loss_default"]:
        return "better"
    return "not better: keep the defaults"


def _whole_runs(name: str, wholes, values: dict) -> tuple[float, int, int, float | None]:
    """One run of estimator ``name`` with ``values`` over each whole trial:
    its innovations' ln det S + NIS summed and their count, the readings
    refused, and the mean total RMSE (°) of the second halves where every
    trial has a reference (None otherwise); infinite sums and RMSE where a
    run diverges."""
    cls, total, updates, refused, totals = resolve_estimator(name), 0.0, 0, 0, []
    for case in wholes:
        sensors, recording = case.inputs.sensors, case.inputs.recording
        run = run_recorded(cls.from_scenario(case.scenario, **values),
                           sensors.omega_meas_radps, sensors.vectors, innovations=True)
        if run.diverged_step is not None or not run.likelihood or not run.likelihood[1]:
            return math.inf, 0, 0, math.inf
        total, updates = total + run.likelihood[0], updates + run.likelihood[1]
        refused += sum(run.rejected.values())
        if recording.has_reference.any():
            movement = recording.movement & judged_samples(recording)
            totals.append(rmse_deg(run.estimates, recording.reference_quat,
                                   movement)[scored_metric(cls, recording)])
    if len(totals) < len(wholes):
        return total, updates, refused, None
    return total, updates, refused, (float(np.mean(totals)) if np.all(np.isfinite(totals))
                                     else math.inf)


def tuned_options(dataset, trials, estimators, mode: str, gyro_delay_s: float = 0.0,
                  sigmas=None, workers: int = 0, quiet: bool = False, train=None):
    """Per trial, each tuned estimator's settings (``trial → {estimator →
    keyword values}``), and the tidy record of every tuning (estimator,
    training trials, trials scored, values, losses, method); ``train``: the
    other dataset tuned on (mode ``other-dataset``)."""
    from benchmarks.engine.runner import map_tasks
    from benchmarks.output import progress
    if mode == "none":
        return {}, pd.DataFrame()
    source = train if mode == "other-dataset" else dataset
    tuned_on = source.available if mode == "other-dataset" else trials
    for trial in tuned_on:      # a training trial with no score would make every loss infinite
        reason = None if mode == "halves" else source.unscored(trial)
        if reason is not None and mode == "other-dataset":
            raise InvalidParameterError("train trial", trial, f"{reason}: it cannot be tuned "
                                        "on; leave it out of that folder's trials.json")
        if reason is not None:
            raise InvalidParameterError("trials", trial, f"{reason}: it cannot be tuned on or "
                                        "scored; leave it out of --trials to tune")
    sets = ([(tuned_on, list(trials))] if mode == "other-dataset"
            else training_sets(trials, mode))
    names = [name for name in estimators if tunes(name, mode)]
    nested = mode in ("all-trials", "other-dataset")
    inner = [inner_sets(training) if nested else [] for training, _ in sets]
    tasks = [(source, training, names, gyro_delay_s, sigmas, mode) for training, _ in sets]
    tasks += [(source, part, names, gyro_delay_s, sigmas, mode, others)
              for folds in inner for part, others in folds]
    with progress(total=len(tasks), desc=f"tune ({mode})", unit="tuning",
                  quiet=quiet) as bar:
        found = map_tasks(_tune_task, tasks, workers, bar)
    checks = iter(found[len(sets):])
    inner_found = [[next(checks) for _ in folds] for folds in inner]
    options, rows, scenarios = {trial: {} for trial in trials}, [], {}
    for name in names:
        for (training, scored), results, inner_results in zip(sets, found, inner_found):
            result = results[name]
            if nested:
                result = checked(result, [fold[name] for fold in inner_results])
            rows.append(_applied(name, result, training, scored, options, scenarios,
                                 dataset, gyro_delay_s, sigmas))
    table = pd.DataFrame(rows)
    if mode == "other-dataset" and len(table):
        table.insert(1, "training_dataset", str(source.folder))
    return options, table


def _applied(name: str, result: dict, training, scored, options: dict, scenarios: dict, dataset,
             gyro_delay_s, sigmas) -> dict:
    """One tuning's settings put into ``options`` for each trial it scores
    (a scale factor turned into its setting on that trial's scenario, kept
    in ``scenarios``), the defaults where its check kept them
    (:func:`checked`); its row of the record."""
    cls = resolve_estimator(name)
    values = result["values"] if result.get("adopted", True) else {}
    for trial in scored:
        if _scaled(cls, values) and trial not in scenarios:  # a factor finds its default there
            scenarios[trial] = imu_inputs(dataset.load(trial), gyro_delay_s, sigmas).scenario
        options[trial][name] = _keywords(cls, values, scenarios.get(trial))
    unit = "" if result.get("objective") == "likelihood" else "_deg"
    return {"estimator": name, "training": ",".join(trial_label(t) for t in training),
            "scored": ",".join(trial_label(t) for t in scored),
            "method": result["method"], "evaluations": result["evaluations"],
            f"training_loss_default{unit}": result["loss_default"],
            f"training_loss{unit}": result["loss"], **result.get("held_out", {}),
            **result.get("check", {}),
            **{f"tuned_{key}": value for key, value in result["values"].items()}}

