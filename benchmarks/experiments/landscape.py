"""The loss landscape: EKF error statistics across ``pc_exponent`` (the workshop's step 9).

For each ``pc_exponent`` on a grid and each seed, the EKF runs on that
seed's data; each statistic is averaged over the runs. The figure shows,
side by side, the three estimators' error curves at the best value (left) and
the mean, median and 3σ of the error against ``pc_exponent`` (right, a
vertical line at that value); the animation moves that line across the
sweep, the left panel's EKF curve following it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
import seaborn as sns

from benchmarks.engine import make_runs, run_many
from benchmarks.metrics import attitude_error_deg
from benchmarks.output import atomic_path, write_csv, write_figure
from benchmarks.figures.plots import BlittingPillowWriter, freeze_layout, new_figure, plot_errors
from benchmarks.output import progress
from benchmarks.scenario import Scenario
from benchmarks.simulation import simulate_truth
from dynamics.validation import InvalidParameterError, finite_number
from estimators import ESTIMATORS

LANDSCAPE_COLUMNS = ("pc_exponent", "mean_deg", "median_deg", "std_deg", "three_sigma_deg",
                     "rms_deg", "max_deg", "runs")
#: Statistics drawn on the right-hand panel: (column, legend).
PANEL_STATISTICS = (("mean_deg", "Mean"), ("median_deg", "Median"), ("three_sigma_deg", "3σ"))
#: Refuse grids that would take hours on the per-run path by mistake.
MAX_GRID_POINTS = 10_000


def pc_grid(pc_min: float, pc_max: float, pc_step: float) -> np.ndarray:
    """``pc_min, pc_min + step, …`` up to and including ``pc_max`` (to 1e-9 of a step)."""
    pc_min = finite_number("pc_min", pc_min)
    pc_max = finite_number("pc_max", pc_max)
    pc_step = finite_number("pc_step", pc_step, strictly_positive=True)
    if pc_max < pc_min:
        raise InvalidParameterError("pc_max", pc_max, f"must be >= pc_min = {pc_min:g}")
    if pc_step > pc_max - pc_min > 0:
        raise InvalidParameterError("pc_step", pc_step, f"must be at most pc_max - pc_min = "
                                    f"{pc_max - pc_min:g}, or the grid would stop at pc_min")
    count = int(np.floor((pc_max - pc_min) / pc_step + 1e-9)) + 1
    if count > MAX_GRID_POINTS:
        raise InvalidParameterError("pc_step", pc_step,
                                    f"gives {count} grid points; at most {MAX_GRID_POINTS}")
    return pc_min + pc_step * np.arange(count)


@dataclass
class Landscape:
    """Per-run statistics over a ``pc_exponent`` grid, and the curves to draw.

    Attributes
    ----------
    pc_values : (P,) grid
    seeds : the seeds run at every grid value
    runs : tidy frame, one row per (pc_exponent, seed), a column per statistic
    table : frame with one row per grid value: each statistic's mean over runs
    time_s : (N,) seconds
    ekf_curves : (P, N) EKF error of the first seed at each grid value, degrees
    reference_curves : {label: (N,)} dead reckoning and resets, first seed
    bound_mean_deg : the mean error angle of the best achievable filter
        (:mod:`benchmarks.bounds`), drawn as "best achievable"
    """

    pc_values: np.ndarray
    seeds: tuple
    runs: pd.DataFrame
    table: pd.DataFrame
    time_s: np.ndarray
    ekf_curves: np.ndarray
    reference_curves: dict
    bound_mean_deg: float | None = None

    @property
    def best_index(self) -> int:
        """Grid index of the lowest mean loss (error std), among the values
        where no run diverged."""
        losses = self.table["std_deg"].to_numpy()
        if np.all(np.isnan(losses)):
            raise InvalidParameterError("pc_exponent", [float(self.pc_values[0]),
                                                        float(self.pc_values[-1])],
                                        "the EKF diverged at every grid value; choose "
                                        "another range")
        return int(np.nanargmin(losses))

    @property
    def diverged_step(self) -> np.ndarray:
        """Every run's diverged step (-1: it did not), as in the engine."""
        return self.runs["diverged_step"].to_numpy()

    @property
    def best_pc_exponent(self) -> float:
        return float(self.pc_values[self.best_index])


def compute_landscape(scenario: Scenario, pc_values, seeds=(0,), quiet: bool = False) -> Landscape:
    """Run the EKF at every grid value for every seed on the batched engine,
    plus the curves of the first seed (the EKF at each grid value, the two
    dead reckonings once) for the left panel."""
    seeds = tuple(seeds)
    pc_values = np.asarray(pc_values, dtype=float)
    grid_pc, grid_seed = (column.ravel() for column in np.meshgrid(pc_values, seeds,
                                                                    indexing="ij"))
    runs = make_runs(scenario, grid_seed, pc_exponent=grid_pc)
    with progress(total=len(runs), desc="landscape", unit="run", quiet=quiet) as bar:
        batch = run_many(scenario, runs, ["ekf"], progress_bar=bar)
    records = pd.DataFrame({"pc_exponent": grid_pc, "seed": grid_seed,
                            **batch.statistics["ekf"],
                            "diverged_step": batch.diverged_step["ekf"]})
    first = make_runs(scenario, seeds[0], pc_exponent=pc_values)
    truth = simulate_truth(scenario)
    curves = run_many(scenario, first, ["ekf"], keep_traces=True).estimates["ekf"]
    ekf_curves = attitude_error_deg(truth.q_true, curves)
    references = run_many(scenario, make_runs(scenario, [seeds[0]]),
                          ["dead-reckoning", "dead-reckoning-resets"], keep_traces=True)
    reference_curves = {
        ESTIMATORS[name].label: attitude_error_deg(truth.q_true, references.estimates[name][0])
        for name in ("dead-reckoning", "dead-reckoning-resets")}
    groups = records.groupby("pc_exponent", sort=False)
    table = groups[list(LANDSCAPE_COLUMNS[1:-1])].mean()
    # A grid value where any run diverged has no mean (NaN), not the others' mean.
    table[groups["diverged_step"].max() >= 0] = np.nan
    table["runs"] = groups.size()
    return Landscape(pc_values=pc_values, seeds=seeds, runs=records,
                     table=table.reset_index(), time_s=truth.time_s, ekf_curves=ekf_curves,
                     reference_curves=reference_curves, bound_mean_deg=bound_mean_deg(scenario))


def bound_mean_deg(scenario: Scenario) -> float:
    """The bound's mean error angle for the EKF as the scenario builds it (its
    output, prior or posterior, picks the bound's)."""
    from benchmarks.bounds import posterior_crb
    output = ESTIMATORS["ekf"].from_scenario(scenario).output
    return posterior_crb(scenario).mean_deg(output)


def _draw(landscape: Landscape, index: int):
    """The two-panel figure at grid ``index``; returns (figure, EKF line, vertical line)."""
    figure, (left, right) = new_figure(ncols=2, width=7.0, height=4.5)
    curves = dict(landscape.reference_curves)
    curves["EKF"] = landscape.ekf_curves[index]
    plot_errors(left, landscape.time_s, curves)
    ekf_line = left.get_lines()[-1]
    upper = np.nanmax([np.nanmax(landscape.ekf_curves, initial=0.0),
                       *(np.nanmax(c, initial=0.0) for c in curves.values())])
    left.set_ylim(0, 1.05 * upper)
    left.set_title(f"Absolute Attitude Error, pc exponent = {landscape.pc_values[index]:g}")
    for column, label in PANEL_STATISTICS:
        right.plot(landscape.table["pc_exponent"], landscape.table[column], label=label,
                   linewidth=1.8)
    if landscape.bound_mean_deg is not None:
        right.axhline(landscape.bound_mean_deg, color="grey", linestyle=":", linewidth=1.8,
                      label=f"best achievable mean ({landscape.bound_mean_deg:.3f}°)")
    vertical = right.axvline(landscape.pc_values[index], color="black", linestyle="--",
                             linewidth=1.2, label="pc exponent shown")
    right.set_xlabel("pc exponent (Q = exp(pc) I)")
    right.set_ylabel("Degrees")
    runs = len(landscape.seeds)
    right.set_title("EKF error statistics" + (f" (mean of {runs} runs)" if runs > 1 else ""))
    right.legend(loc="upper left")
    return figure, ekf_line, vertical


def landscape_figure(landscape: Landscape, index: int | None = None):
    index = landscape.best_index if index is None else index
    return _draw(landscape, index)[0]


def spread_figure(landscape: Landscape):
    """seaborn view of the per-run spread: median line and 5–95 % band per statistic."""
    tidy = landscape.runs.melt(id_vars=["pc_exponent", "seed"],
                               value_vars=[c for c, _ in PANEL_STATISTICS],
                               var_name="statistic", value_name="degrees")
    tidy["statistic"] = tidy["statistic"].map(dict(PANEL_STATISTICS))
    figure, (ax,) = new_figure()
    sns.lineplot(data=tidy, x="pc_exponent", y="degrees", hue="statistic",
                 estimator="median", errorbar=("pi", 90), ax=ax)
    ax.axvline(landscape.best_pc_exponent, color="black", linestyle="--", linewidth=1.2)
    ax.set_title(f"Spread over {len(landscape.seeds)} runs (median, 5–95 % band)")
    ax.set_xlabel("pc exponent (Q = exp(pc) I)")
    ax.set_ylabel("Degrees")
    return figure


#: Frames of the landscape animation at most: a finer grid is sampled evenly
#: (thousands of frames exhaust memory when the GIF is quantised, and no one
#: watches them).
MAX_ANIMATION_FRAMES = 400


def animation_indices(n_values: int) -> np.ndarray:
    """Grid indices animated: all of them, or evenly spread ones up to the cap."""
    if n_values <= MAX_ANIMATION_FRAMES:
        return np.arange(n_values)
    return np.unique(np.linspace(0, n_values - 1, MAX_ANIMATION_FRAMES).round().astype(int))


def write_animation(landscape: Landscape, path, fps: int = 8, dpi: int = 80) -> int:
    """The two panels animated over the sweep, as a GIF; returns the frame count."""
    figure, ekf_line, vertical = _draw(landscape, 0)
    left = figure.axes[0]
    # The title's words stay in the background; only the value is drawn
    # again each frame (redrawing the whole title was a quarter of the GIF's time).
    left.set_title("Absolute Attitude Error, pc exponent =")
    value = left.annotate("", xy=(1.0, 1.0), xycoords=left.title, ha="left", va="top",
                          xytext=(3, 0), textcoords="offset points",
                          fontsize=left.title.get_fontsize(), color=left.title.get_color(),
                          fontweight=left.title.get_fontweight())
    freeze_layout(figure)
    writer = BlittingPillowWriter([ekf_line, vertical, value], fps=fps)
    indices = animation_indices(len(landscape.pc_values))
    with atomic_path(path) as temporary, writer.saving(figure, temporary, dpi):
        for index in indices:
            pc = landscape.pc_values[index]
            ekf_line.set_ydata(landscape.ekf_curves[index])
            vertical.set_xdata([pc, pc])
            value.set_text(f"{pc:g}")
            writer.grab_frame()
    return len(indices)


def write_landscape(landscape: Landscape, out, animate: bool = True) -> dict:
    """Write ``landscape.csv``, ``landscape.png`` (and ``landscape.gif``; with
    several seeds ``landscape_spread.png`` and ``landscape_runs.csv``)."""
    table = landscape.table
    write_csv(out / "landscape.csv", LANDSCAPE_COLUMNS,
              ([float(row[c]) if c != "runs" else int(row[c]) for c in LANDSCAPE_COLUMNS]
               for _, row in table.iterrows()))
    write_figure(out / "landscape.png", landscape_figure(landscape))
    files = {"csv": out / "landscape.csv", "png": out / "landscape.png"}
    if animate:
        write_animation(landscape, out / "landscape.gif")
        files["gif"] = out / "landscape.gif"
    if len(landscape.seeds) > 1:
        write_figure(out / "landscape_spread.png", spread_figure(landscape))
        columns = list(landscape.runs.columns)
        write_csv(out / "landscape_runs.csv", columns,
                  (list(row) for row in landscape.runs.itertuples(index=False)))
        files["spread"] = out / "landscape_spread.png"
    return files
