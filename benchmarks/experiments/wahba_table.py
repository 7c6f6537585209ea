"""The static solvers side by side: accuracy and time per solution on the
test cases of Markley & Mortari (2000).

Markley & Mortari, "Quaternion Attitude Estimation Using Vector
Observations", *J. Astronautical Sciences* 48(2–3), 2000, compare the
solvers of Wahba's problem on seven cases (also used by Cheng & Shuster,
"Robustness and Accuracy of the QUEST Algorithm", AAS 07-102, 2007): three
orthogonal observations or two, equally accurate or of widely differing
accuracy, and two nearly parallel ones. We could not retrieve the paper's
table itself; the cases below are as those papers describe them, and the
table gives our numbers, not theirs.

For each case, ``trials`` random true attitudes (uniform on the rotation
group) and noisy observations (each :math:`b_i` tilted across itself by
:math:`\\sigma_i` per axis); each solver's error is the angle to the truth,
and its *excess* the angle to the q-method's solution (the eigenvector, the
exact optimum; from the rotation vector, which resolves angles down to
rounding where the arccos of the error stops near 0.1 µrad), which shows
where a fast solver loses digits; *fallbacks*
counts the trials where QUEST's, ESOQ2's or FOAM's own answer failed its
optimality check and the q-method's was returned (:func:`estimators.wahba.solution`).
The time per solution is the median wall time of one call, in microseconds
(Python on this machine: the ranking, not the absolute numbers, is what
carries over).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from dynamics.quaternion import attitude_error_rad, attitude_error_vector_rad, rotation_matrix
from estimators.wahba import SOLVERS, solution

_X, _Y, _Z = np.eye(3)
_NEAR_X = np.array([1.0, 0.01, 0.0]) / math.hypot(1.0, 0.01)


@dataclass(frozen=True)
class WahbaCase:
    """One test case: the reference directions and their σ, rad."""

    number: int
    description: str
    reference: np.ndarray
    sigma_rad: np.ndarray


#: The seven cases (module docstring).
CASES = (
    WahbaCase(1, "3 orthogonal, all 1e-6", np.array([_X, _Y, _Z]), np.array([1e-6] * 3)),
    WahbaCase(2, "3 orthogonal, 1e-6, 0.01, 0.01", np.array([_X, _Y, _Z]),
              np.array([1e-6, 0.01, 0.01])),
    WahbaCase(3, "3 orthogonal, all 0.01", np.array([_X, _Y, _Z]), np.array([0.01] * 3)),
    WahbaCase(4, "2 orthogonal, 1e-6 and 0.01", np.array([_X, _Y]), np.array([1e-6, 0.01])),
    WahbaCase(5, "2 orthogonal, both 0.01", np.array([_X, _Y]), np.array([0.01, 0.01])),
    WahbaCase(6, "2 at 0.57 deg, 1e-6 and 0.01", np.array([_X, _NEAR_X]),
              np.array([1e-6, 0.01])),
    WahbaCase(7, "2 at 0.57 deg, both 0.01", np.array([_X, _NEAR_X]), np.array([0.01, 0.01])),
)


def noisy_body_vectors(case: WahbaCase, q_true: np.ndarray, rng: np.random.Generator
                       ) -> np.ndarray:
    """The case's observations in the body frame of ``q_true``, each tilted
    across itself by its σ per axis."""
    body = case.reference @ rotation_matrix(q_true)
    tilt = case.sigma_rad[:, None] * rng.standard_normal(body.shape)
    tilt -= np.sum(tilt * body, axis=1, keepdims=True) * body
    return Rotation.from_rotvec(tilt).apply(body)


def solver_table(trials: int = 1000, seed: int = 0, timing_calls: int = 200,
                 quiet: bool = True) -> pd.DataFrame:
    """One row per case and solver: RMS and maximum error (µrad), the
    maximum excess over the q-method (µrad), the fallbacks to the q-method
    (trials), and the median time per call (µs); a progress bar over the
    cases unless ``quiet``."""
    from benchmarks.output import progress
    rng = np.random.default_rng(seed)
    rows = []
    for case in progress(CASES, desc="wahba", unit="case", quiet=quiet):
        weights = case.sigma_rad ** -2.0
        errors = {name: np.empty(trials) for name in SOLVERS}
        excess = {name: np.empty(trials) for name in SOLVERS}
        fallbacks = dict.fromkeys(SOLVERS, 0)
        for trial in range(trials):
            q_true = Rotation.random(random_state=rng).as_quat(scalar_first=True)
            body = noisy_body_vectors(case, q_true, rng)
            optimum = SOLVERS["q-method"](body, case.reference, weights)
            for name in SOLVERS:
                q, fell_back = solution(name, body, case.reference, weights)
                fallbacks[name] += fell_back
                errors[name][trial] = attitude_error_rad(q_true, q)
                excess[name][trial] = np.linalg.norm(attitude_error_vector_rad(optimum, q))
        body = noisy_body_vectors(case, np.array([1.0, 0.0, 0.0, 0.0]), rng)
        for name, solver in SOLVERS.items():
            rows.append({"case": case.number, "description": case.description, "solver": name,
                         "rms_error_urad": 1e6 * math.sqrt(np.mean(errors[name] ** 2)),
                         "max_error_urad": 1e6 * errors[name].max(),
                         "max_excess_urad": 1e6 * excess[name].max(),
                         "fallbacks": fallbacks[name],
                         "time_us": _median_time_us(solver, body, case.reference, weights,
                                                    timing_calls)})
    return pd.DataFrame(rows)


def _median_time_us(solver, body, reference, weights, calls: int) -> float:
    times = np.empty(calls)
    for i in range(calls):
        start = time.perf_counter()
        solver(body, reference, weights)
        times[i] = time.perf_counter() - start
    return float(np.median(times) * 1e6)


def format_table(table: pd.DataFrame) -> str:
    """The table as the README prints it: a block per case."""
    lines = [f"{'case':<4} {'solver':<9} {'RMS err µrad':>13} {'max err µrad':>13} "
             f"{'excess µrad':>12} {'fallbacks':>9} {'µs/solution':>12}"]
    for case, rows in table.groupby("case", sort=True):
        lines.append(f"-- case {case}: {rows['description'].iloc[0]}")
        for _, row in rows.iterrows():
            lines.append(f"{case:<4} {row['solver']:<9} {row['rms_error_urad']:>13.4g} "
                         f"{row['max_error_urad']:>13.4g} {row['max_excess_urad']:>12.3g} "
                         f"{row['fallbacks']:>9d} {row['time_us']:>12.1f}")
    return "\n".join(lines)
