"""The whole exercise in one command: the workshop's steps 1–9 and a Markdown report.

Each step calls the same function as its command-line counterpart and
writes into its own folder under ``out``; ``report.md`` tells the story
with every figure embedded and the numbers in place.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchmarks import experiments
from benchmarks.experiments.landscape import compute_landscape, pc_grid, write_landscape
from benchmarks.metrics import STAT_COLUMNS
from benchmarks.output import write_json, write_text
from benchmarks.bounds import check_bound_inputs
from benchmarks.output import progress
from benchmarks.scenario import Scenario
from benchmarks.experiments.tuning import (
    DEFAULT_BOUNDS,
    DEFAULT_XTOL,
    format_iteration_table,
    tune_pc_exponent,
)
from dynamics.validation import InvalidParameterError

#: The exercise's values for its activities.
ACTIVITY_1_GYRO_NOISE = (1e-5, 1e-4)
ACTIVITY_2_INTERVALS = (0.2, 1.0, 5.0)
ACTIVITY_3A_PC = (-8.7, -10.9)
LANDSCAPE_GRID = (-18.0, 0.0, 0.25)
SEED = 0


def _markdown_table(rows: dict, first: str, columns=STAT_COLUMNS) -> str:
    header = f"| {first} | " + " | ".join(columns) + " |"
    rule = "|---" * (len(columns) + 1) + "|"
    lines = [header, rule]
    for name, row in rows.items():
        lines.append(f"| {name} | " + " | ".join(f"{row[c]:.4f}" for c in columns) + " |")
    return "\n".join(lines)


def _sweep_table(rows, param) -> str:
    return _markdown_table({f"{row['value']:g}": row for row in rows}, param)


def check_activities(scenario: Scenario) -> None:
    """Every activity's scenario and the landscape grid, validated before step 1
    writes anything (e.g. a dt that the activities' intervals are not multiples of)."""
    for step, param, values in ((3, "gyro-noise", ACTIVITY_1_GYRO_NOISE),
                                (5, "time-between-measurements", ACTIVITY_2_INTERVALS),
                                (7, "pc-exponent", ACTIVITY_3A_PC)):
        try:
            experiments.sweep_scenarios(scenario, param, values)
        except InvalidParameterError as err:
            raise InvalidParameterError(err.name, err.value,
                                        f"{err.rule} (the workshop's step {step})") from None
    pc_grid(*LANDSCAPE_GRID)


def tumble_description(scenario: Scenario) -> str:
    """How the body moves, from its energy and momentum: the angular velocity
    circles the axis of least or greatest inertia, whichever its momentum's
    polhode encloses (2T·I_mid against |H|²), or spins about one of them."""
    moments, axes = np.linalg.eigh(scenario.inertia_tensor_kg_m2)
    omega = axes.T @ scenario.initial_rate_radps            # principal frame
    momentum2 = float(np.sum((moments * omega) ** 2))
    energy2 = float(np.sum(moments * omega ** 2))           # 2T
    if momentum2 == 0.0:
        return "and at rest, it stays at rest"
    on_axis = np.isclose(np.abs(omega), np.linalg.norm(omega), rtol=1e-9)
    if on_axis.any():
        return f"it spins steadily about the principal axis of {moments[on_axis.argmax()]:g} kg m²"
    middle = energy2 * moments[1] - momentum2
    if abs(middle) <= 1e-12 * momentum2:
        return "it moves on the separatrix of the intermediate axis, its flips slowing"
    axis = "minor" if middle > 0 else "major"
    return (f"its rate vector circles the {axis} axis of inertia while the rates trade "
            "energy between the other two")


def reading_error_rms_deg(scenario: Scenario) -> float:
    """RMS attitude error of one star tracker reading, degrees."""
    covariance = scenario.star_tracker_attitude_covariance_rad2
    return float(np.degrees(np.sqrt(np.trace(covariance))))


def reading_error_text(scenario: Scenario) -> str:
    if scenario.star_tracker_model == "workshop":
        sigma = (scenario.star_tracker_noise / scenario.dt) ** 0.5
        return (f"a per-component standard deviation of {sigma:.3g} is an attitude error "
                f"of about 2√3 × that")
    return (f"σ = {', '.join(f'{v:g}' for v in scenario.star_tracker_sigma_arcsec)} arcsec "
            "about the sensor's axes is an attitude error of")


def _against(value: float, reference: float) -> str:
    ratio = value / reference
    if 0.8 <= ratio <= 1.25:
        return "comparable to"
    return f"{ratio:.2g} times" if ratio > 1 else f"{1 / ratio:.2g} times smaller than"


def matrix_text(matrix) -> str:
    matrix = np.asarray(matrix)
    if np.array_equal(matrix, matrix[0, 0] * np.eye(len(matrix))):
        return "I₄" if matrix[0, 0] == 1 else f"{matrix[0, 0]:g} I₄"
    return "diag(" + ", ".join(f"{v:g}" for v in matrix.diagonal()) + ")" \
        if np.array_equal(matrix, np.diag(matrix.diagonal())) else "the scenario's 4×4 R"


def ranking_text(stats: dict) -> str:
    """Which estimator had the lowest mean error in this run, in words."""
    lost = [name for name in stats if not np.isfinite(stats[name]["mean_deg"])]
    scored = [name for name in stats if name not in lost]
    diverged = f" ({', '.join(lost)} diverged: no error to rank)" if lost else ""
    if not scored:
        return f"Every estimator diverged{diverged}."
    best = min(scored, key=lambda name: stats[name]["mean_deg"])
    label = "The EKF" if best == "ekf" else f"Here {best}, not the EKF,"
    return (f"{label} has the lowest mean error of the {len(scored)} that ran to the end "
            f"({stats[best]['mean_deg']:.3g}°){diverged}." if lost else
            f"{label} has the lowest mean error of the three ({stats[best]['mean_deg']:.3g}°).")


def _count(divergence, stats: dict) -> None:
    """Add the runs of ``stats`` ({name: statistics}) to ``divergence`` if kept."""
    if divergence is not None:
        for name, row in stats.items():
            divergence.add(name, row["diverged_step"])


@dataclass
class _Run:
    """What the workshop's steps share: the scenario, and what a step leaves
    for a later one (the tuned exponent, for the landscape)."""

    scenario: Scenario
    divergence: object = None
    tuned_pc_exponent: float = float("nan")

    def count(self, stats: dict) -> None:
        _count(self.divergence, stats)


def _truth(run: _Run, folder: Path) -> str:
    """1. The tumbling spacecraft."""
    experiments.animate(run.scenario, None, SEED, folder, quiet=True)
    return f"""## 1. The tumbling spacecraft

A rigid body with principal moments {", ".join(f"{m:g}" for m in
np.linalg.eigvalsh(run.scenario.inertia_tensor_kg_m2))} kg m² spins freely from
ω₀ = {run.scenario.initial_rate_radps.tolist()} rad/s. With no torque
{tumble_description(run.scenario)} (the truth is integrated to 1e-12 relative
accuracy and checked against the Jacobi-elliptic closed form).

![The true attitude](01-truth/attitude_truth.gif)
"""


def _dead_reckoning(run: _Run, folder: Path) -> str:
    """2. Dead reckoning: the gyro alone."""
    dr_stats = experiments.run_one(run.scenario, "dead-reckoning", SEED, folder)
    run.count({"dead-reckoning": dr_stats})
    experiments.animate(run.scenario, "dead-reckoning", SEED, folder, quiet=True)
    return f"""## 2. Dead reckoning

Integrating the gyro alone, the estimate drifts: white rate noise of power
p = {run.scenario.gyro_noise:g} rad²/s becomes an angle random walk whose variance
grows as p·t per axis, so the error wanders upward with time (final error
{dr_stats['final_deg']:.3f}°, maximum {dr_stats['max_deg']:.3f}°).

![Dead reckoning error](02-dead-reckoning/dead-reckoning.png)

![True and dead-reckoned attitude](02-dead-reckoning/attitude_dead-reckoning.gif)
"""


def _activity_1(run: _Run, folder: Path) -> str:
    """3. Activity 1: a noisier gyro."""
    rows = experiments.sweep(run.scenario, "dead-reckoning", "gyro-noise", ACTIVITY_1_GYRO_NOISE,
                             SEED, folder, quiet=True)
    ratio = ACTIVITY_1_GYRO_NOISE[1] / ACTIVITY_1_GYRO_NOISE[0]
    return f"""## 3. Activity 1 — a noisier gyro

{ratio:g} times the noise power means √{ratio:g} ≈ {ratio ** 0.5:.1f} times the
drift on average (here, one noise realisation: {rows[1]['mean_deg'] / rows[0]['mean_deg']:.1f}
times the mean error).

![Dead reckoning for two gyro noise powers](03-activity-1/sweep.png)

{_sweep_table(rows, "gyro noise")}
"""


def _resets(run: _Run, folder: Path) -> str:
    """4. Dead reckoning with star-tracker resets."""
    _, stats = experiments.compare(run.scenario, SEED, folder,
                                   estimators=("dead-reckoning", "dead-reckoning-resets"))
    reading_rms = reading_error_rms_deg(run.scenario)
    run.count(stats)
    dead_rms, resets_rms = stats["dead-reckoning"]["rms_deg"], \
        stats["dead-reckoning-resets"]["rms_deg"]
    return f"""## 4. Dead reckoning with star-tracker resets

Replacing the estimate with each star tracker reading
(every {run.scenario.time_between_measurements:g} s) stops the drift, but the error
now sits at the star tracker's own noise level: {reading_error_text(run.scenario)}
≈ {reading_rms:.3g}° RMS at each reading. Over this run the resets' RMS error is
{resets_rms:.3g}°, {_against(resets_rms, dead_rms)} dead reckoning's {dead_rms:.3g}°.

![Dead reckoning with and without resets](04-resets/compare.png)

{_markdown_table(stats, "estimator")}
"""


def _activity_2(run: _Run, folder: Path) -> str:
    """5. Activity 2: fewer star tracker readings."""
    rows = experiments.sweep(run.scenario, "dead-reckoning-resets", "time-between-measurements",
                             ACTIVITY_2_INTERVALS, SEED, folder, quiet=True)
    return f"""## 5. Activity 2 — fewer star tracker readings

With readings further apart the estimate dead-reckons for longer between
resets, so the gyro's drift adds to each reading's error; right after a reset
the error is still the star tracker's own.

![Resets every {", ".join(f"{v:g}" for v in ACTIVITY_2_INTERVALS)} s](05-activity-2/sweep.png)

{_sweep_table(rows, "interval (s)")}
"""


def _ekf(run: _Run, folder: Path) -> str:
    """6. The extended Kalman filter."""
    _, ekf_stats = experiments.compare(run.scenario, SEED, folder)
    run.count(ekf_stats)
    return f"""## 6. The extended Kalman filter

The EKF blends both sensors, weighting the gyro's prediction by the process
covariance Q = exp({run.scenario.pc_exponent:g}) I₄ and the star tracker by
R = {matrix_text(run.scenario.measurement_covariance)}. {ranking_text(ekf_stats)}

![Dead reckoning, resets and the EKF](06-ekf/compare.png)

{_markdown_table(ekf_stats, "estimator")}
"""


def _activity_3a(run: _Run, folder: Path) -> str:
    """7. Activity 3a: tuning by hand."""
    rows = experiments.sweep(run.scenario, "ekf", "pc-exponent", ACTIVITY_3A_PC, SEED, folder,
                             quiet=True)
    return f"""## 7. Activity 3a — tuning by hand

A smaller process covariance trusts the gyro more and the star tracker less.

![EKF at two process covariance exponents](07-activity-3a/sweep.png)

{_sweep_table(rows, "pc exponent")}
"""


def _activity_3b(run: _Run, folder: Path) -> str:
    """8. Activity 3b: the bounded minimiser."""
    tune = tune_pc_exponent(run.scenario, (SEED,), quiet=True)
    run.tuned_pc_exponent = tune.pc_exponent
    write_json(folder / "tune.json", tune.as_json())
    _, tuned = experiments.compare(run.scenario.replace(pc_exponent=tune.pc_exponent), SEED,
                                   folder, figure_name="tune.png", summary_name="summary.csv")
    run.count(tuned)
    return f"""## 8. Activity 3b — tuning with a bounded minimiser

Brent's bounded method (MATLAB's `fminbnd`, scipy's
`minimize_scalar(method="bounded")`) searches [{DEFAULT_BOUNDS[0]:g}, {DEFAULT_BOUNDS[1]:g}]
for the exponent minimising the loss, the standard deviation of the error, to
an x tolerance of {DEFAULT_XTOL:g}:

```text
{format_iteration_table(tune.iterations)}

{tune.message}
```

It settles at **pc_exponent = {tune.pc_exponent:.4f}** with a loss of
**{tune.loss_deg:.6f}°** after {tune.evaluations} evaluations. Rerun there:

![The comparison at the tuned exponent](08-activity-3b/tune.png)

{_markdown_table(tuned, "estimator")}

This optimum fits one noise realisation (seed {SEED}); `attitude-bench tune
--seeds 0-19` tunes on the mean loss of many runs instead.
"""


def _landscape(run: _Run, folder: Path) -> str:
    """9. The loss landscape."""
    grid = pc_grid(*LANDSCAPE_GRID)
    landscape = compute_landscape(run.scenario, grid, (SEED,), quiet=True)
    write_landscape(landscape, folder)
    best = landscape.table.iloc[landscape.best_index]
    return f"""## 9. The loss landscape

Sweeping the exponent from {grid[0]:g} to {grid[-1]:g} in steps of
{LANDSCAPE_GRID[2]:g} shows the whole trade-off: too small a Q ignores the star
tracker and drifts like dead reckoning, too large a Q follows every noisy
reading. The lowest error standard deviation on this grid is
{best['std_deg']:.6f}° at pc_exponent = {landscape.best_pc_exponent:g}
(mean error {best['mean_deg']:.4f}°), next to the bounded minimiser's
{run.tuned_pc_exponent:.4f}.

![The landscape](09-landscape/landscape.png)

![The landscape, animated over the sweep](09-landscape/landscape.gif)

The numbers are in [landscape.csv](09-landscape/landscape.csv).
"""


#: The exercise, in order: each step's folder and the function that fills it
#: and returns its section of the report.
WORKSHOP_STEPS = (("01-truth", _truth), ("02-dead-reckoning", _dead_reckoning),
                  ("03-activity-1", _activity_1), ("04-resets", _resets),
                  ("05-activity-2", _activity_2), ("06-ekf", _ekf),
                  ("07-activity-3a", _activity_3a), ("08-activity-3b", _activity_3b),
                  ("09-landscape", _landscape))


def run_workshop(scenario: Scenario | None = None, out: Path = Path("results"),
                 quiet: bool = False, divergence=None) -> Path:
    """Run the exercise and write ``out/report.md``; returns its path.
    ``divergence`` (a :class:`~benchmarks.divergence.DivergenceReport`), if
    given, counts every estimator run of the comparisons that diverged."""
    scenario = scenario or Scenario()
    out = Path(out)
    check_activities(scenario)
    check_bound_inputs(scenario)      # step 9 draws the bound: refuse before step 1
    started = time.perf_counter()
    run, sections = _Run(scenario, divergence), []
    with progress(total=len(WORKSHOP_STEPS), desc="workshop", unit="step", quiet=quiet) as bar:
        for folder, step in WORKSHOP_STEPS:
            bar.update()
            sections.append(step(run, out / folder))
    elapsed = time.perf_counter() - started
    report = out / "report.md"
    write_text(report, f"""# The attitude estimation workshop

The Kalman-filter workshop's spacecraft attitude exercise, reproduced with
attitude-bench: a tumbling spacecraft, a {1 / scenario.dt:g} Hz gyro and a
{1 / scenario.time_between_measurements:g} Hz star tracker, and three ways to
estimate the attitude. Every run uses sensor noise seed {SEED}; every figure
and table below was produced by this run ({elapsed:.0f} s).

""" + "\n".join(sections))
    return report
