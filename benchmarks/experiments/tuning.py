"""Activity 3b: tune the EKF's process covariance exponent, as ``fminbnd`` does.

MATLAB's ``fminbnd`` is Brent's bounded minimisation (golden-section steps
mixed with parabolic interpolation); :func:`scipy.optimize.minimize_scalar`
with ``method="bounded"`` is the same algorithm (Forsythe, Malcolm & Moler,
*Computer Methods for Mathematical Computations*, 1977, ``fmin``). The
iteration table — function count, ``x``, ``f(x)`` and whether the step was
``initial``, ``golden`` or ``parabolic`` — is scipy's own log
(``disp=3``), captured and paired with the evaluations we record, so the
table is exactly what the algorithm did.

The loss of one run is the sample standard deviation of its attitude error
(the workshop model, "What is measured"); over several seeds it is the mean of the runs'
losses, so the tuned value fits the noise statistics rather than one
realisation of the noise.
"""
from __future__ import annotations

import contextlib
import io
import math
import re
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize_scalar

from benchmarks.output import progress
from benchmarks.scenario import Scenario
from benchmarks.engine import make_runs, run_many
from dynamics.validation import InvalidParameterError, finite_number, process_exponent

DEFAULT_BOUNDS = (-16.0, 0.0)
DEFAULT_XTOL = 0.01
PROCEDURES = ("initial", "golden", "parabolic")
_LOG_ROW = re.compile(r"^\s*(\d+)\s+(\S+)\s+(\S+)\s+(initial|golden|parabolic)\s*$")


@dataclass
class MinimizationLog:
    """What a bounded minimisation did, step by step."""

    x: float
    fun: float
    evaluations: int
    iterations: list = field(default_factory=list)   # {count, x, f, procedure}
    message: str = ""


def minimize_bounded(func, bounds=DEFAULT_BOUNDS, xtol: float = DEFAULT_XTOL) -> MinimizationLog:
    """Minimise ``func`` on ``bounds`` with scipy's bounded Brent method.

    Returns the minimiser, the minimum, the number of evaluations, the
    iteration table and scipy's termination message.
    """
    low, high = validate_bounds(bounds)
    xtol = checked_xtol(xtol, high - low)
    evaluations = []

    def recorded(x):
        value = float(func(float(x)))
        evaluations.append((float(x), value))
        return value

    log = io.StringIO()
    with contextlib.redirect_stdout(log):
        result = minimize_scalar(recorded, bounds=(low, high), method="bounded",
                                 options={"xatol": xtol, "disp": 3})
    rows = [match for match in map(_LOG_ROW.match, log.getvalue().splitlines()) if match]
    if len(rows) != len(evaluations):  # pragma: no cover - would mean scipy changed its log
        raise RuntimeError("scipy's bounded-method log does not match its evaluations")
    iterations = [{"count": int(row.group(1)), "x": x, "f": f, "procedure": row.group(4)}
                  for row, (x, f) in zip(rows, evaluations)]
    table_end = log.getvalue().rfind(rows[-1].group(0)) + len(rows[-1].group(0))
    message = " ".join(log.getvalue()[table_end:].split())
    return MinimizationLog(x=float(result.x), fun=float(result.fun),
                           evaluations=len(evaluations), iterations=iterations,
                           message=message or str(result.message))


def checked_xtol(xtol, width: float) -> float:
    """A search's tolerance: finite, > 0 and below the width of the search
    interval (in the searched coordinate), where it would end the search at
    its first evaluation."""
    xtol = finite_number("xtol", xtol, strictly_positive=True)
    if not xtol < width:
        raise InvalidParameterError("xtol", xtol, f"must be below the search interval's width "
                                    f"({width:g} in the searched coordinate): the search would "
                                    "stop at its first evaluation")
    return xtol


def validate_bounds(bounds) -> tuple[float, float]:
    low = process_exponent("bounds", bounds[0])      # exp(bound) must be finite
    high = process_exponent("bounds", bounds[1])
    if not low < high:
        raise InvalidParameterError("bounds", [low, high], "must be LO HI with LO < HI")
    return low, high


def format_iteration_table(iterations) -> str:
    """The iteration table as ``fminbnd`` and scipy print it."""
    lines = [" Func-count     x          f(x)          Procedure"]
    lines += [f"{row['count']:5d}   {row['x']:12.6g} {row['f']:12.6g}        {row['procedure']}"
              for row in iterations]
    return "\n".join(lines)


class EkfLoss:
    """``loss(pc_exponent)``: mean over seeds of each EKF run's error std, degrees.

    Each evaluation runs the EKF for every seed at once on the batched
    engine (:mod:`benchmarks.engine`), which reproduces the filterpy path's
    numbers to rounding.
    """

    def __init__(self, scenario: Scenario, seeds):
        self.scenario = scenario
        self.seeds = tuple(seeds)

    def run_losses(self, pc_exponent: float) -> np.ndarray:
        """Each seed's loss at ``pc_exponent``."""
        runs = make_runs(self.scenario, self.seeds, pc_exponent=pc_exponent)
        return run_many(self.scenario, runs, ["ekf"]).statistics["ekf"]["std_deg"]

    def __call__(self, pc_exponent: float) -> float:
        """The mean loss, or infinity if the EKF diverged in any run (its
        loss is NaN: never a number the minimiser could prefer)."""
        losses = self.run_losses(pc_exponent)
        return float(np.mean(losses)) if np.all(np.isfinite(losses)) else math.inf


@dataclass
class TuneResult:
    pc_exponent: float
    loss_deg: float
    evaluations: int
    seeds: tuple
    iterations: list
    message: str
    single_seed_optima: dict | None = None
    #: Evaluations where the EKF diverged in some run (an infinite loss).
    diverged_evaluations: int = 0

    def as_json(self) -> dict:
        """The result as JSON values: an infinite (diverged) loss is null."""
        def number(value):
            return value if math.isfinite(value) else None
        iterations = [{**row, "f": number(row["f"])} for row in self.iterations]
        data = {"pc_exponent": self.pc_exponent, "loss_deg": number(self.loss_deg),
                "evaluations": self.evaluations, "seeds": list(self.seeds),
                "iterations": iterations, "message": self.message,
                "diverged_evaluations": self.diverged_evaluations}
        if self.single_seed_optima is not None:
            data["single_seed_optima"] = self.single_seed_optima
        return data


def tune_pc_exponent(scenario: Scenario, seeds=(0,), bounds=DEFAULT_BOUNDS,
                     xtol: float = DEFAULT_XTOL, loss_factory=EkfLoss,
                     quiet: bool = False) -> TuneResult:
    """Find the ``pc_exponent`` minimising the EKF loss over ``seeds``.

    With several seeds, each seed is also tuned on its own and the spread of
    those single-seed optima is reported (5th, 50th and 95th percentiles),
    showing how much one noise realisation moves the answer.
    """
    seeds = tuple(seeds)
    objective = loss_factory(scenario, seeds)
    with progress(desc="tune pc_exponent", unit="eval", quiet=quiet) as bar:
        def counted(x):
            bar.update()
            return objective(x)
        log = minimize_bounded(counted, bounds, xtol)
    result = TuneResult(pc_exponent=log.x, loss_deg=log.fun, evaluations=log.evaluations,
                        seeds=seeds, iterations=log.iterations, message=log.message,
                        diverged_evaluations=sum(not math.isfinite(row["f"])
                                                 for row in log.iterations))
    if len(seeds) > 1:
        optima = [minimize_bounded(loss_factory(scenario, (seed,)), bounds, xtol).x
                  for seed in progress(seeds, desc="single-seed optima", quiet=quiet)]
        p5, p50, p95 = np.percentile(optima, [5, 50, 95])
        result.single_seed_optima = {"seeds": list(seeds), "pc_exponent": optima,
                                     "p5": float(p5), "p50": float(p50), "p95": float(p95)}
    return result


# --- Any estimator, any of its declared settings -----------------------------
