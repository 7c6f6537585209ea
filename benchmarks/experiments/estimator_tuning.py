"""Tuning any estimator's declared settings (:mod:`estimators.tunable`) on
simulated seeds or recordings, against the truth or without it
(:mod:`benchmarks.experiments.objectives`): the search
(:func:`tune_estimator`: scipy's bounded Brent method for one setting,
Nelder–Mead with bounds for several), its cases, its scores, the tuned
settings as an ``[estimators.NAME]`` section, and its figure. The
workshop's own tuning of the EKF's process covariance exponent is
:mod:`benchmarks.experiments.tuning`; every estimator tuned and scored side
by side is :mod:`benchmarks.experiments.fair_comparison`.
"""
from __future__ import annotations

import math
import re
import time
from dataclasses import dataclass, field

import numpy as np

from benchmarks.experiments.tuning import checked_xtol, minimize_bounded
from benchmarks.output import progress
from benchmarks.scenario import Scenario
from dynamics.validation import InvalidParameterError

#: Nelder–Mead's stopping rule, in the scaled coordinates (decades, or the
#: linear unit): the simplex within ``XATOL`` and its losses within ``FATOL``
#: (absolute), or ``MAX_EVALUATIONS`` evaluations.
XATOL = 0.01
FATOL = 1e-4
MAX_EVALUATIONS = 200


@dataclass
class EstimatorTuning:
    """What :func:`tune_estimator` found, and every evaluation it made."""

    estimator: str
    objective: str
    parameters: list             # names
    scales: list                 # "log" or "linear", per parameter
    ranges: list                 # (low, high) per parameter, in its units
    default: dict                # name → value (None where it has none)
    tuned: dict                  # name → value
    loss_default: float | None
    loss: float
    method: str
    evaluations: list            # {count, values: {name: value}, loss}
    iterations: list             # {iteration, count, loss, values}
    message: str
    cases: list                  # the training cases' labels
    seconds: float = 0.0
    #: The settings tuned to an end of their range (within twice the
    #: search's tolerance, in its coordinates): the optimum may lie beyond.
    at_bound: list = field(default_factory=list)

    def as_json(self) -> dict:
        def number(value):
            return value if value is not None and math.isfinite(value) else None
        data = {key: getattr(self, key) for key in
                ("estimator", "objective", "parameters", "scales", "default", "tuned", "method",
                 "message", "cases", "seconds", "at_bound")}
        data.update(ranges=[list(r) for r in self.ranges], loss=number(self.loss),
                    loss_default=number(self.loss_default),
                    evaluations=[{**row, "loss": number(row["loss"])} for row in self.evaluations],
                    iterations=[{**row, "loss": number(row["loss"])} for row in self.iterations])
        return data


def tuning_plan(estimator_class, settings: dict, parameters=None, ranges=None,
                present=None) -> list:
    """``[(tunable, default, (low, high))]`` for the settings to tune:
    ``parameters`` (names, default: every declared one with a default and
    no fixed search range, and any given a range), each over its range in
    ``ranges`` (name → (low, high)) or its default search range. Unknown names, reversed ranges and
    ranges outside a setting's declared limits are refused, one line each;
    with ``present`` (the data's sensors), so is a setting of a sensor the
    data lacks (:attr:`estimators.tunable.Tunable.sensor`): it changes nothing."""
    declared = _effective_tunables(estimator_class, present, parameters, ranges)
    ranges = dict(ranges or {})
    if parameters is None:      # those with a default, and any given a range
        parameters = [name for name, t in declared.items() if t.search is None
                      and t.default(settings) not in (None, 0.0)] or list(declared)[:1]
        parameters += [name for name in ranges if name not in parameters]
    for name in ranges:
        if name not in parameters:
            raise InvalidParameterError(f"range of {name}", list(ranges[name]),
                                        f"is for a setting not tuned here; add {name} to "
                                        "--parameters, or leave the range out")
    if len(set(parameters)) != len(parameters) or not parameters:
        raise InvalidParameterError("parameters", list(parameters),
                                    "must name at least one setting, each once")
    plan = []
    for name in parameters:
        tunable = declared[name]
        if not tunable.acts(settings):
            keyword, value = tunable.applies_when
            raise InvalidParameterError("parameters", name, f"acts only with {keyword} = "
                                        f"{value!r} (this estimator's is "
                                        f"{settings.get(keyword)!r}): tuning it would change "
                                        "nothing")
        default = tunable.default(settings)
        bounds = (tunable.checked_range(*ranges[name]) if name in ranges
                  else tunable.search_range(default))
        if tunable.scale == "log" and not bounds[0] > 0:
            raise InvalidParameterError(f"range of {name}", list(bounds),
                                        "must be above 0 on a log scale")
        plan.append((tunable, default, bounds))
    return plan


def _effective_tunables(estimator_class, present, parameters, ranges) -> dict:
    """``name → Tunable`` of the class's tunable settings that act on the
    ``present`` sensors (all, if None); a name asked for that is not one of
    them is refused, saying why."""
    from estimators.tunable import tunables
    declared = tunables(estimator_class)
    if not declared:
        raise InvalidParameterError("estimator", estimator_class.name,
                                    "has no tunable settings (it declares none)")
    effective = {name: t for name, t in declared.items()
                 if present is None or t.sensor is None or t.sensor in present}
    for name in list(parameters or ()) + list(ranges or ()):
        if name in declared and name not in effective:
            raise InvalidParameterError("parameters", name, f"acts on the {declared[name].sensor}'s "
                                        "readings, and the data has none: tuning it would "
                                        "change nothing")
        if name not in declared:
            raise InvalidParameterError("parameters", name, f"is not tunable for "
                                        f"{estimator_class.name}; its tunable settings: "
                                        f"{', '.join(declared)}")
    if not effective:
        raise InvalidParameterError("estimator", estimator_class.name, "has no tunable "
                                    "setting that acts on the data's sensors")
    return effective


def cases_sensors(cases):
    """The sensors that read in any of ``cases`` (None if a case carries no sensor data)."""
    from benchmarks.sensor_use import present_sensors
    if not all(hasattr(case, "sensors") for case in cases):
        return None
    return frozenset().union(*(present_sensors(case.sensors) for case in cases))


def tune_estimator(name: str, cases, objective: str, parameters=None, ranges=None, *,
                   xatol: float = XATOL, max_evaluations: int = MAX_EVALUATIONS,
                   quiet: bool = False, score=None) -> EstimatorTuning:
    """Tune estimator ``name``'s declared settings to minimise ``objective``
    over ``cases`` (:mod:`benchmarks.experiments.objectives`), or ``score``
    if given: a callable of ``settings_of(case_scenario) → keyword values``
    returning the loss (each case has a ``scenario`` and a ``label``), as
    the BROAD benchmark scores its trials (:mod:`benchmarks.broad.tuning`).

    The search runs in scaled coordinates (log10 of a log-scale setting), so
    one step means the same in every direction. One parameter: scipy's
    bounded Brent method (``fminbnd``'s, as the workshop's tuning). Several:
    Nelder–Mead with bounds — it needs no gradient (the losses of a max, or
    of gated readings, are not smooth), and with common random numbers the
    loss is a deterministic function of the settings, which it minimises
    reliably in a few dimensions. It starts from the defaults (clipped into
    the ranges) with a simplex a quarter of each range wide.
    """
    from benchmarks.experiments.objectives import Objective
    from estimators import resolve_estimator
    cls = resolve_estimator(name)
    # What the estimator runs with: the scenario's settings over its constructor's defaults.
    plan = tuning_plan(cls, {**cls.constructor_defaults(),
                             **cls.configured_settings(cases[0].scenario)}, parameters, ranges,
                       cases_sensors(cases))
    score = Objective(name, objective, cases) if score is None else score
    low, high, start = _search_box(plan)
    xatol = checked_xtol(xatol, float(np.min(high - low)))
    search = _Search(plan, lambda values: score(
        lambda case_scenario: keyword_values(cls, values, case_scenario)))
    began = time.perf_counter()
    with progress(desc=f"tune {name}", unit="eval", quiet=quiet) as search.bar:
        # The defaults' loss first (the start, unless a default lies outside its range).
        at_default = all(d is not None and np.isclose(t.coordinate(d), c)
                         for (t, d, _), c in zip(plan, start))
        loss_default = search.loss(start) if at_default else None
        if len(plan) == 1:
            iterations, message, method = _brent(search, low, high, xatol, at_default)
        else:
            iterations, message, method = _nelder_mead(search, start, low, high, xatol,
                                                       max_evaluations)
    best = min(search.evaluations, key=lambda row: row["loss"])
    return EstimatorTuning(
        estimator=name, objective=objective, parameters=[t.name for t, _, _ in plan],
        scales=[t.scale for t, _, _ in plan], ranges=[b for _, _, b in plan],
        default={t.name: d for t, d, _ in plan}, tuned=best["values"],
        loss_default=loss_default, loss=best["loss"], method=method,
        evaluations=search.evaluations, iterations=iterations, message=message,
        cases=[case.label for case in cases], seconds=time.perf_counter() - began,
        at_bound=_at_bound(plan, best["values"], low, high, xatol))


def _search_box(plan):
    """``(low, high, start)``: the search's bounds and its start (the
    defaults, clipped into them; a range's middle where there is none), in
    the scaled coordinates of :meth:`~estimators.tunable.Tunable.coordinate`."""
    ends = np.array([[t.coordinate(b[0]), t.coordinate(b[1])] for t, _, b in plan])
    low, high = ends.min(axis=1), ends.max(axis=1)   # log10(1 − p) runs backwards
    start = np.array([t.coordinate(d) if d is not None and (t.scale != "log" or d > 0)
                      else 0.5 * (lo + hi) for (t, d, _), lo, hi in zip(plan, low, high)])
    return low, high, np.clip(start, low, high)


class _Search:
    """The loss at a point of the scaled coordinates, every evaluation
    recorded (and counted on :attr:`bar`, the progress bar)."""

    def __init__(self, plan, loss_of_values):
        self.plan, self.loss_of_values = plan, loss_of_values
        self.evaluations, self.bar = [], None

    def values_at(self, u) -> dict:
        return {t.name: t.value(float(c)) for (t, _, _), c in zip(self.plan, np.atleast_1d(u))}

    def loss(self, u) -> float:
        values = self.values_at(u)
        # A scale multiplies each case's own default.
        value = float(self.loss_of_values(values))
        self.evaluations.append({"count": len(self.evaluations) + 1, "values": values,
                                 "loss": value})
        self.bar.update()
        return value


def _brent(search: _Search, low, high, xatol: float, at_default: bool):
    """One setting: scipy's bounded Brent method; ``(iterations, message,
    method)``, the iterations as ``fminbnd`` logs them."""
    log = minimize_bounded(lambda x: search.loss(np.array([x])), (low[0], high[0]), xatol)
    iterations = [{"iteration": row["count"], "count": row["count"] + int(at_default),
                   "loss": row["f"], "values": search.values_at([row["x"]]),
                   "procedure": row["procedure"]} for row in log.iterations]
    return iterations, log.message, "bounded Brent"


def _nelder_mead(search: _Search, start, low, high, xatol: float, max_evaluations: int):
    """Several settings: Nelder–Mead with bounds from a simplex a quarter of
    each range wide; ``(iterations, message, method)``."""
    from scipy.optimize import minimize
    iterations = []
    simplex = [start] + [_vertex(start, i, low, high) for i in range(len(start))]

    def record(intermediate_result):
        iterations.append({"iteration": len(iterations) + 1,
                           "count": len(search.evaluations),
                           "loss": float(intermediate_result.fun),
                           "values": search.values_at(intermediate_result.x)})

    result = minimize(search.loss, start, method="Nelder-Mead", bounds=list(zip(low, high)),
                      callback=record,
                      options={"initial_simplex": np.array(simplex), "xatol": xatol,
                               "fatol": FATOL, "maxfev": max_evaluations})
    return iterations, str(result.message), "Nelder-Mead"


def _at_bound(plan, values: dict, low, high, xatol: float) -> list:
    """The settings tuned to an end of their range (within twice the
    search's tolerance, in its coordinates)."""
    return [t.name for (t, _, _), lo, hi in zip(plan, low, high)
            if min(abs(t.coordinate(values[t.name]) - lo),
                   abs(t.coordinate(values[t.name]) - hi)) <= 2.0 * xatol]


def _vertex(start, axis: int, low, high) -> np.ndarray:
    """A simplex vertex a quarter of the range from ``start`` along ``axis``,
    toward the farther bound."""
    vertex = start.copy()
    step = 0.25 * (high[axis] - low[axis])
    vertex[axis] += step if high[axis] - start[axis] >= start[axis] - low[axis] else -step
    return vertex


def format_tuning_table(tuning: EstimatorTuning) -> str:
    """The iteration table: Brent's as ``fminbnd`` prints it; Nelder–Mead's
    as one row per iteration with its best loss and settings."""
    names = tuning.parameters
    header = f" {'Iter':>4} {'Func-count':>10} {'f(x)':>13}  " + "  ".join(
        f"{name:>22}" for name in names)
    lines = [header]
    for row in tuning.iterations:
        values = "  ".join(f"{row['values'][name]:>22.6g}" for name in names)
        extra = f"  {row['procedure']}" if "procedure" in row else ""
        lines.append(f" {row['iteration']:>4} {row['count']:>10} {row['loss']:>13.6g}  "
                     f"{values}{extra}")
    return "\n".join(lines)


def cases_of(scenario: Scenario | None, seeds=None, datasets=None, what: str = "training",
             settings=None, allow_imports=(), replay=None) -> list:
    """The cases to tune (or score) on: recordings if ``datasets`` are
    named (``settings``, a file of ``[estimators.NAME]`` sections over what
    each recording derives; ``replay``, keywords of
    :func:`~benchmarks.experiments.replay.load_replay`: the pseudo star
    tracker, the gyro delay), else simulated ``seeds`` of ``scenario``."""
    from benchmarks.experiments.objectives import recording_case, seed_cases
    from benchmarks.experiments.replay import dataset_source, load_replay
    if datasets and seeds:
        raise InvalidParameterError(f"{what} seeds", list(seeds), "are simulated, and the "
                                    f"{what} recordings named beside them are real: give one "
                                    "kind (--dataset files read no --seeds)")
    if datasets:
        sources = [dataset_source(name) for name in datasets]
        for i, source in enumerate(sources):
            if source in sources[:i]:
                twin = datasets[sources.index(source)]
                raise InvalidParameterError(f"{what} datasets", datasets[i], f"holds the same "
                                            f"recording as {twin}: name each recording once")
        # Scored or not by the objective (objectives.Objective: nis and likelihood read no
        # reference), not refused here for having nothing to score.
        return [recording_case(load_replay(name, settings=settings, allow_imports=allow_imports,
                                           scored=False, **(replay or {})), name, source)
                for name, source in zip(datasets, sources)]
    return seed_cases(scenario, seeds)


def disjoint(training: list, test: list) -> None:
    """Refuse a test set that shares a seed or a recording (by content: a
    file named twice, by its name and by a path, is one recording) with the
    training set, or that is of the other kind (a tuning on recordings
    scored on simulated seeds, or the reverse, tests nothing of it)."""
    kinds = ({case.source[0] for case in training if case.source},
             {case.source[0] for case in test if case.source})
    if all(kinds) and kinds[0] != kinds[1]:
        raise InvalidParameterError("test set", [case.label for case in test],
                                    f"must be of the training set's kind ({', '.join(kinds[0])}"
                                    "s): a tuning on one kind scored on the other is no test of "
                                    "it")
    trained = {case.source or case.label: case.label for case in training}
    shared = sorted({trained[case.source or case.label] for case in test
                     if (case.source or case.label) in trained})
    if shared:
        raise InvalidParameterError("test set", shared, "must share no seed or recording "
                                    "with the training set (a score on tuned-on data is not a test)")


def keyword_values(cls, values: dict, scenario: Scenario) -> dict:
    """Tuned ``values`` (setting → value) as the constructor keywords they
    set on ``scenario`` (a scale as the quantity it multiplies, from the
    scenario's own default), as an ``[estimators.NAME]`` section holds them."""
    from estimators.tunable import tunables
    declared, own = tunables(cls), cls.configured_settings(scenario)
    found = {}
    for name, value in values.items():
        found.update(declared[name].overrides(value, own))
    return found


def tuned_settings(tuning: EstimatorTuning, scenario: Scenario) -> dict:
    """:func:`keyword_values` of what ``tuning`` found, on ``scenario``."""
    from estimators import resolve_estimator
    return keyword_values(resolve_estimator(tuning.estimator), tuning.tuned, scenario)


def scores(name: str, objective: str, cases: list, settings: dict) -> dict:
    """The objective, and the RMS error where there is a reference, of
    ``settings`` on ``cases``."""
    from benchmarks.experiments.objectives import Objective
    found = {objective: Objective(name, objective, cases)(settings)}
    if objective != "rms" and all(case.has_reference for case in cases):
        found["rms"] = Objective(name, "rms", cases)(settings)
    return found


def settings_toml(name: str, settings: dict) -> str:
    """``[estimators.NAME]`` with ``settings`` (numbers, or matrices as lists)."""
    key = name if re.fullmatch(r"[A-Za-z0-9_-]+", name) else f'"{name}"'
    lines = [f"[estimators.{key}]"]
    for setting, value in settings.items():
        lines.append(f"{setting} = {_toml_value(np.asarray(value, dtype=float))}")
    return "\n".join(lines) + "\n"


def _toml_value(array: np.ndarray) -> str:
    if array.ndim == 0:
        return repr(float(array))
    return "[" + ", ".join(_toml_value(row) for row in array) + "]"


def tuning_figure(tuning: EstimatorTuning, time_s, curves: dict):
    """The loss at each evaluation, the best so far and the default's loss,
    and the error of the default and tuned settings over time on one case.

    Every evaluation lies inside the loss axis: a log axis when every loss is
    positive (the first wild guesses and the last refinements both read), a
    linear one holding them all otherwise; an evaluation that diverged
    (infinite loss) is drawn at the top edge and named so."""
    from benchmarks.figures.plots import new_figure, plot_errors
    from benchmarks.figures.style import legend_outside, log_axis
    figure, (left, right) = new_figure(ncols=2, width=6.5, height=5.0)
    losses = np.array([row["loss"] for row in tuning.evaluations], dtype=float)
    count = np.arange(1, len(losses) + 1)
    finite = np.isfinite(losses)
    default = tuning.loss_default
    default = default if default is not None and math.isfinite(default) else None
    known = np.concatenate([losses[finite], [default] if default is not None else []])
    low, high = (known.min(), known.max()) if known.size else (1.0, 1.0)
    logarithmic = low > 0
    if logarithmic:         # the top edge (for diverged ones), then a margin beyond it
        pad = max((high / low) ** 0.06, 1.05)
        edge, bottom = high * pad, low / pad
        top = edge * pad
    else:
        pad = 0.06 * ((high - low) or abs(low) or 1.0)
        edge, bottom = high + pad, low - pad
        top = edge + pad
    left.plot(count[finite], losses[finite], "o", markersize=3.5, color="0.45",
              label="evaluation", gid="evaluations")
    if not finite.all():
        left.plot(count[~finite], np.full((~finite).sum(), edge), "^", markersize=6,
                  color="tab:red", label="diverged (infinite loss), at the top edge",
                  gid="diverged")
    best = np.fmin.accumulate(np.where(finite, losses, np.inf))
    left.step(count, np.where(np.isfinite(best), best, np.nan), where="post", color="black",
              linewidth=1.2, label="best so far")
    if default is not None:
        left.axhline(default, color="C0", linestyle="--", linewidth=1.2, gid="default",
                     label=f"default settings: {default:.4g}")
    if math.isfinite(tuning.loss):
        left.plot(int(np.argmin(np.where(finite, losses, np.inf))) + 1, tuning.loss, "*",
                  markersize=13, color="C1", zorder=5, label=f"tuned: {tuning.loss:.4g}")
    if logarithmic:
        log_axis(left, bottom, top)
    else:
        left.set_ylim(bottom, top)
    left.set_xlim(0, len(losses) + 1)
    left.set_xlabel("evaluation")
    left.set_ylabel(f"{tuning.objective} loss{' (log scale)' if logarithmic else ''}")
    left.set_title(f"Tuning {tuning.estimator} ({tuning.method}): every evaluation")
    plot_errors(right, time_s, curves, ekf_labels=())
    right.get_legend().remove()
    right.set_title(f"{tuning.estimator}: default and tuned, {tuning.cases[0]}")
    legend_outside(figure, [left, right], columns=4)
    return figure


def plain(settings: dict) -> dict:
    """Settings as JSON values (matrices as lists)."""
    return {key: np.asarray(value, dtype=float).tolist() for key, value in settings.items()}


def case_error(name: str, case, settings: dict) -> np.ndarray:
    """Estimator ``name``'s error (degrees) on ``case`` with ``settings``,
    NaN where the case has no reference."""
    from benchmarks.experiments.objectives import run_case
    from benchmarks.metrics import attitude_error_deg
    _, trace = run_case(name, case, settings)
    return attitude_error_deg(case.q_reference, trace.quat)
