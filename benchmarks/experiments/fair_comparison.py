"""Every estimator tuned on the same training cases and scored, with its
default and its tuned settings, on those and on disjoint test cases: the
fair comparison of ``tuned`` and ``replay --tuned`` (an estimator is judged
with settings it was tuned to, on data it never saw).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from benchmarks.experiments.estimator_tuning import (disjoint, scores, settings_toml,
                                                     tune_estimator, tuned_settings)
from benchmarks.scenario import Scenario
from dynamics.validation import InvalidParameterError


@dataclass
class FairComparison:
    """Every estimator tuned on the training cases and scored, default and
    tuned, on the training and the test cases; the tuned settings per
    estimator (constructor keywords; empty for one with nothing to tune)."""

    objective: str
    rows: list                   # {estimator, tuned: {name: value}, seconds, scores}
    settings: dict               # estimator → {keyword: value}

    def scenario(self, scenario: Scenario) -> Scenario:
        """``scenario`` with every estimator's tuned settings."""
        from benchmarks.experiments.objectives import with_settings
        for name, settings in self.settings.items():
            if settings:
                scenario = with_settings(scenario, name, settings)
        return scenario

    def toml(self) -> str:
        return "\n".join(settings_toml(name, settings)
                         for name, settings in self.settings.items() if settings)


def tune_all(estimators, objective: str, training: list, test: list,
             quiet: bool = False) -> FairComparison:
    """Tune each of ``estimators`` that declares tunable settings on
    ``training`` (its default settings: :func:`tuning_plan`) and score every
    one, with its default and its tuned settings, on ``training`` and on the
    disjoint ``test``."""
    from estimators import resolve_estimator
    from estimators.tunable import tunables
    disjoint(training, test)
    rows, chosen = [], {}
    for name in estimators:
        row = {"estimator": name, "tuned": {}, "seconds": 0.0}
        settings = {}
        if tunables(resolve_estimator(name)):
            tuning = tune_estimator(name, training, objective, quiet=quiet)
            settings = tuned_settings(tuning, training[0].scenario)
            row.update(tuned=tuning.tuned, seconds=tuning.seconds, at_bound=tuning.at_bound)
        chosen[name] = settings
        row["scores"] = {label: {"default": _scores_or_nan(name, objective, cases, {}),
                                 "tuned": _scores_or_nan(name, objective, cases, settings)}
                         for label, cases in (("training", training), ("test", test))}
        rows.append(row)
    return FairComparison(objective=objective, rows=rows, settings=chosen)


def _scores_or_nan(name: str, objective: str, cases: list, settings: dict) -> dict:
    """:func:`scores`, the objective NaN for an estimator it is not defined
    for (no covariance, no innovations: dead reckoning's likelihood)."""
    try:
        return scores(name, objective, cases, settings)
    except InvalidParameterError:
        found = {objective: math.nan}
        if objective != "rms" and all(case.has_reference for case in cases):
            found["rms"] = scores(name, "rms", cases, settings)["rms"]
        return found


def format_fair_comparison(comparison: FairComparison) -> str:
    """One row per estimator: its objective on the training and the test
    cases, default → tuned, and the tuned values."""
    objective = comparison.objective
    width = max(len("estimator"), *(len(row["estimator"]) for row in comparison.rows))
    columns = [("training", objective), ("test", objective)]
    if objective != "rms" and "rms" in comparison.rows[0]["scores"]["test"]["default"]:
        columns.append(("test", "rms"))
    names = {"training": "train", "test": "test"}
    lines = [f"{'estimator':<{width}}  " + "  ".join(
        f"{key + ' ' + names[label]:>22}" for label, key in columns) + "  tuned settings"]
    for row in comparison.rows:
        cells = []
        for label, key in columns:
            score = row["scores"][label]
            cells.append(f"{score['default'][key]:>10.4g} -> {score['tuned'][key]:<8.4g}")
        values = ", ".join(f"{k} {v:.4g}" + (" (at its bound)" if k in row.get("at_bound", ())
                                              else "")
                           for k, v in row["tuned"].items()) or "(none to tune)"
        lines.append(f"{row['estimator']:<{width}}  " + "  ".join(f"{c:>22}" for c in cells)
                     + f"  {values}")
    return "\n".join(lines)
