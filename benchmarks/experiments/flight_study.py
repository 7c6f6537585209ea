"""After the workshop: the additive EKF against the multiplicative ones, and all
of them against the best achievable (``attitude-bench workshop --part flight``).

A report for a reader who has just finished the exercise, in three steps,
each a small function that computes its numbers and writes its figure:

1. the workshop's EKF, tuned, against the bound on the workshop scenario;
2. the flight scenario's filters side by side: error, efficiency, and whether
   each knows its error (ANEES against its χ² band);
3. convergence from a large initial error, and the cost of a step.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchmarks import experiments
from benchmarks.shipped import FLIGHT_SCENARIO, shipped_file
from benchmarks.experiments import consistency
from benchmarks.bounds import posterior_crb
from benchmarks.metrics import ARCSEC_PER_DEG
from benchmarks.engine import make_runs, run_batch
from benchmarks.output import write_figure, write_text
from benchmarks.output import progress
from benchmarks.scenario import Scenario
from benchmarks.simulation import build_estimator, simulate, simulate_sensors, simulate_truth

#: The flight scenario is shortened for the study: ten minutes show the
#: convergence, the bias estimate settling and steady state.
STUDY_TSTOP_S = 600.0
WORKSHOP_SEEDS = 400
FLIGHT_ENGINE_RUNS = 200
PC_GRID = np.arange(-11.0, -5.99, 0.25)
FILTERS = ("ekf", "mekf", "usque")
#: An estimate has converged once its error stays below this (arcsec).
CONVERGED_ARCSEC = 60.0


@dataclass
class Section:
    title: str
    body: str


#: An efficiency within this of 1 counts as at the bound: the Monte Carlo
#: uncertainty of the RMS over the study's seeds is a few tenths of a per cent.
AT_BOUND = 0.02


def _verdict(efficiency: float, scenario: Scenario) -> str:
    if efficiency <= 1 + AT_BOUND:
        return (f"So here the additive EKF, well tuned, *is* the best filter: the model is "
                f"nearly linear over a {scenario.time_between_measurements:g} s reading "
                "interval and there is no bias to estimate.")
    return (f"So here even the best-tuned additive EKF stays {100 * (efficiency - 1):.0f} % "
            "above what the best filter could do.")


def workshop_efficiency(scenario: Scenario, seeds: int = WORKSHOP_SEEDS) -> tuple[Section, dict]:
    """The workshop EKF over a pc grid on the engine: its best RMS against the bound."""
    bound = posterior_crb(scenario).rms_deg(build_estimator("ekf", scenario).output)
    rms = []
    for pc in PC_GRID:
        values = run_batch(scenario, make_runs(scenario, np.arange(seeds), pc_exponent=pc),
                           ["ekf"]).statistics["ekf"]["rms_deg"]
        rms.append(float(np.sqrt(np.mean(values ** 2))))
    best = int(np.argmin(rms))
    numbers = {"bound_rms_deg": bound, "best_pc": float(PC_GRID[best]),
               "best_rms_deg": rms[best], "efficiency": rms[best] / bound,
               "default_rms_deg": rms[int(np.argmin(np.abs(PC_GRID - scenario.pc_exponent)))]}
    gap = 100 * (numbers["efficiency"] - 1)
    body = f"""On the workshop's own scenario no filter can do better, on average, than the
posterior Cramér–Rao bound along the true tumble (`benchmarks/bounds.py`):
an RMS error of **{bound:.4f}°** for an estimate made before each step's
reading, as the workshop's EKF makes it. Over {seeds} seeds and
`pc_exponent` from {PC_GRID[0]:g} to {PC_GRID[-1]:g}, the EKF's RMS error is
lowest at **pc = {numbers['best_pc']:g}: {numbers['best_rms_deg']:.4f}°**, an
efficiency of {numbers['efficiency']:.3f} ({gap:+.1f} % from the bound). At the
scenario's own pc = {scenario.pc_exponent:g} it is {numbers['default_rms_deg']:.4f}°.

{_verdict(numbers['efficiency'], scenario)} (The exercise's loss, the error's standard deviation, is not what
the bound limits: a filter can have a smaller spread than the optimal one by
being further off on average.)
"""
    return Section("1. The workshop's EKF against the best achievable", body), numbers


def _mekf_text(efficiency: float) -> str:
    if abs(efficiency - 1) <= 0.1:
        return (f"The MEKF sits at the bound (efficiency {efficiency:.2f}, both taken after "
                "the settle time)")
    return f"The MEKF is {efficiency:.2f} times the bound"


def flight_side_by_side(flight: Scenario, out: Path, quiet: bool) -> tuple[Section, dict]:
    """Error, efficiency and consistency of the three filters on the flight
    scenario: the section, and each estimator's diverged steps per run."""
    names = ("dead-reckoning",) + FILTERS
    with progress(total=FLIGHT_ENGINE_RUNS * len(names), desc="flight study",
                  unit="run", quiet=quiet) as bar:
        result = consistency.run_consistency(flight, names, FLIGHT_ENGINE_RUNS,
                                             progress_bar=bar)
    write_figure(out / "consistency.png", consistency.figure(result))
    experiments.compare(flight, 0, out, estimators=("dead-reckoning", "ekf", "mekf"),
                        figure_name="compare.png", summary_name="summary.csv")
    rows = ["| estimator | runs | RMS error (arcsec) | bound (arcsec) | efficiency | ANEES | 95 % band | verdict |",
            "|---|---|---|---|---|---|---|---|"]
    for name, row in result.summary.items():
        band = ("–" if np.isnan(row["anees"])
                else f"[{row['anees_low']:.2f}, {row['anees_high']:.2f}]")
        anees = "–" if np.isnan(row["anees"]) else f"{row['anees']:.2f}"
        rms, bound = row["rms_deg"] * ARCSEC_PER_DEG, row["bound_rms_deg"] * ARCSEC_PER_DEG
        rows.append(f"| {name} | {row['runs']} | {rms:.2f} | {bound:.2f} | "
                    f"{row['efficiency']:.2f} | {anees} | {band} | {row['verdict']} |")
    summary = result.summary
    body = f"""The flight scenario (`scenarios/flight.toml`, here its first
{flight.tstop:g} s): a spacecraft at orbital rate, a navigation-grade gyro
with a bias of 0.1 deg/h that wanders, a 1 Hz star tracker with 6 arcsec
across its boresight and 40 about it, and filters that start 44° off. The
MEKF and the UKF (USQUE) estimate the bias; the additive EKF cannot.

![The filters on one run](compare.png)

{chr(10).join(rows)}

(The engine runs {FLIGHT_ENGINE_RUNS} seeds of each estimator. Started from the
same prior, the MEKF's RMS error is {summary['mekf']['rms_deg'] * ARCSEC_PER_DEG:.3f} arcsec
and USQUE's {summary['usque']['rms_deg'] * ARCSEC_PER_DEG:.3f}: on a full-attitude reading
the two are the same filter to first order.)

{_mekf_text(summary['mekf']['efficiency'])}, and both multiplicative filters are judged by their ANEES
against the χ² band in the last columns.
The additive EKF is {summary['ekf']['efficiency']:.1f} times the bound: with no
bias state, its `pc_exponent` must be large enough to follow the drifting
bias, and that lets every reading's noise through.

![ANEES over time and one run's errors against their envelopes](consistency.png)
"""
    return (Section("2. The flight scenario: additive against multiplicative", body),
            result.diverged_step)


def convergence_and_cost(flight: Scenario) -> tuple[Section, dict]:
    """Time to converge from the 44° start (seed 0), and seconds per step per run."""
    result = simulate(flight, FILTERS, seed=0)
    times, costs = {}, {}
    for name in FILTERS:
        above = np.flatnonzero(result.error_deg[name] * ARCSEC_PER_DEG > CONVERGED_ARCSEC)
        times[name] = 0.0 if not len(above) else float(result.time_s[min(
            above[-1] + 1, len(result.time_s) - 1)])
    short = flight.replace(tstop=30.0)
    data = simulate_sensors(short, simulate_truth(short), 0)
    for name in FILTERS:
        estimator = build_estimator(name, short)
        start = time.perf_counter()
        estimator.run(data.omega_meas_radps, data.star_tracker_quat, data.available)
        costs[name] = (time.perf_counter() - start) / short.n_steps
    rows = ["| filter | converged below 60 arcsec after | cost per step (per-run path) |",
            "|---|---|---|"]
    for name in FILTERS:
        rows.append(f"| {name} | {times[name]:.1f} s | {costs[name] * 1e6:.0f} µs |")
    body = f"""From the 44° start, each filter's error stays below
{CONVERGED_ARCSEC:g} arcsec from the time in the table on (seed 0). With a
full-attitude reading every second, the MEKF's and USQUE's first update
already lands within the reading's own error; USQUE's sigma points earn their
keep when readings are weaker than the initial error (vector measurements,
sparse or rough readings). The price is in the last column: USQUE propagates
13 sigma points through the kinematics each step.

{chr(10).join(rows)}
"""
    return Section("3. Convergence and cost", body), {"convergence_s": times,
                                                      "seconds_per_step": costs}


def study_scenario() -> Scenario:
    """The flight scenario as the study runs it (its first :data:`STUDY_TSTOP_S`)."""
    return Scenario.from_toml(shipped_file(FLIGHT_SCENARIO)).replace(tstop=STUDY_TSTOP_S)


def run_flight_study(workshop: Scenario | None = None, out: Path = Path("results"),
                     quiet: bool = False, divergence=None) -> Path:
    """Write ``out/report.md`` with the study; returns its path. ``divergence``
    (a :class:`~benchmarks.divergence.DivergenceReport` in the study
    scenario's steps), if given, counts the side-by-side runs that diverged."""
    out = Path(out)
    workshop = workshop or Scenario()
    flight = study_scenario()
    started = time.perf_counter()
    side_by_side, diverged = flight_side_by_side(flight, out, quiet)
    if divergence is not None:
        for name, steps in diverged.items():
            divergence.add(name, steps)
    sections = [workshop_efficiency(workshop)[0], side_by_side, convergence_and_cost(flight)[0]]
    elapsed = time.perf_counter() - started
    report = out / "report.md"
    write_text(report, "# After the workshop: additive against multiplicative, and the best "
               f"achievable\n\nEvery number below was computed by this run ({elapsed:.0f} s).\n\n"
               + "\n".join(f"## {s.title}\n\n{s.body}" for s in sections))
    return report
