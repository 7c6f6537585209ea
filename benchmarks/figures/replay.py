"""The replay figure: a recorded trial replayed through the estimators.

On the left, each estimator's error against the recording's optical
reference over the trial, on a log axis, as its median and range over short
spans (a 285 Hz record drawn point by point is a solid block), the movement
phase shaded and the reference's gaps left blank. On the right, one panel
per body axis, the gyro bias estimates (±3σ) against the gyro's mean over
the initial rest.
"""
from __future__ import annotations

import textwrap

import numpy as np
import seaborn as sns
from matplotlib.figure import Figure

from benchmarks.figures.panels import AXIS_NAMES
from benchmarks.figures.plots import X_LABEL
from benchmarks.figures.style import estimator_styles, finite_max, legend_outside

#: Bins of the replay's error range: a 285 Hz record drawn point by point is a solid block.
REPLAY_BINS = 600


def binned_range(time_s, values, bins: int):
    """``(centres, min, max, median)`` of ``values`` over ``bins`` equal spans
    of ``time_s`` (empty spans dropped; NaN ignored)."""
    values = np.asarray(values, dtype=float)
    edges = np.linspace(time_s[0], time_s[-1], bins + 1)
    index = np.clip(np.searchsorted(edges, time_s, side="right") - 1, 0, bins - 1)
    centres, low, high, median = [], [], [], []
    for b in range(bins):
        chunk = values[index == b]
        chunk = chunk[np.isfinite(chunk)]
        if chunk.size:
            centres.append(0.5 * (edges[b] + edges[b + 1]))
            low.append(chunk.min())
            high.append(chunk.max())
            median.append(np.median(chunk))
    return tuple(np.array(x) for x in (centres, low, high, median))


def replay_figure(result) -> Figure:
    """A replayed recording (:class:`benchmarks.experiments.replay.Replay`):
    each estimator's error against the reference over the trial, log scale,
    the movement phase shaded and the reference's gaps left blank (left); the
    bias estimates against the gyro's mean over the initial rest (right)."""
    with sns.axes_style("whitegrid"):
        figure = Figure(figsize=(14.0, 7.5), layout="constrained")
        grid = figure.add_gridspec(3, 2)
        error_ax = figure.add_subplot(grid[:, 0])
        bias_axes = [figure.add_subplot(grid[axis, 1], sharex=error_ax) for axis in range(3)]
    movement = result.recording.movement
    for ax in [error_ax, *bias_axes]:
        if movement.any():
            first, last = np.flatnonzero(movement)[[0, -1]]
            ax.axvspan(result.time_s[first], result.time_s[last], color="0.85", alpha=0.5,
                       linewidth=0, label="Movement phase" if ax is error_ax else None)
    styles = estimator_styles(list(result.run.error_deg))
    _error_panel(error_ax, result, styles)
    _bias_panels(bias_axes, result, styles)
    legend_outside(figure, [error_ax, *bias_axes], columns=5, where="upper center")
    if result.attribution:
        figure.supxlabel(textwrap.fill(result.attribution, 200), fontsize="x-small",
                         color="0.3")
    return figure


def _error_panel(ax, result, styles: dict) -> None:
    """Each estimator's error against the reference: its median and its range
    (min to max, shaded) over each of :data:`REPLAY_BINS` spans, on a log axis
    from the errors' 1st percentile to their largest value."""
    run, time_s = result.run, result.time_s
    bottoms = []
    for name in run.error_deg:
        style = styles[name]
        centres, low, high, median = binned_range(time_s, run.error_deg[name], REPLAY_BINS)
        ax.fill_between(centres, low, high, color=style["color"], alpha=0.25,
                        linewidth=0, label=f"{run.labels[name]}: min–max")
        ax.plot(centres, median, color=style["color"], linestyle=style["linestyle"],
                linewidth=1.3, label=f"{run.labels[name]}: median")
        positive = run.error_deg[name][run.error_deg[name] > 0]
        if positive.size:
            bottoms.append(np.nanpercentile(positive, 1))
    ax.set_yscale("log")
    # The log axis bounded by the data: from its 1st percentile (an error of
    # 0 at a reset has no place on it) to its largest value.
    top = finite_max(run.error_deg.values()) or 1.0
    ax.set_ylim(0.5 * min(bottoms) if bottoms else 1e-3, 2 * top)
    ax.set_xlim(time_s[0], time_s[-1])
    bin_s = (time_s[-1] - time_s[0]) / REPLAY_BINS
    ax.set_title(f"Attitude error against the optical reference: {result.recording.name}"
                 f"\n(median and range per {bin_s:.2g} s of "
                 f"{1 / np.median(np.diff(time_s)):.0f} Hz samples)", fontsize="medium")
    ax.set_xlabel(X_LABEL)
    ax.set_ylabel("Error (degrees, log scale)")


def _bias_panels(axes, result, styles: dict) -> None:
    """On each body axis, the bias estimates (±3σ, deg/s) of the estimators
    that estimate one against the gyro's mean over the initial rest (none
    where the recording moves from its first sample); the y range holding
    that mean and where the estimates spend 98 % of the time."""
    run, time_s = result.run, result.time_s
    with_bias = [name for name in run.error_deg if run.traces[name].bias_radps is not None]
    rest = np.degrees(result.rest_bias_radps)
    has_rest = bool(np.all(np.isfinite(rest)))
    for axis, ax in enumerate(axes):
        if has_rest:
            ax.axhline(rest[axis], color="black", linestyle="--", linewidth=1.5,
                       label="Gyro mean over the initial rest")
        for name in with_bias:
            trace = run.traces[name]
            every = max(1, len(time_s) // (4 * REPLAY_BINS))     # a bias moves slowly
            estimate = np.degrees(trace.bias_radps[::every, axis])
            sigma = np.degrees(np.sqrt(trace.bias_covariance[::every, axis, axis]))
            ax.plot(time_s[::every], estimate, color=styles[name]["color"],
                    linestyle=styles[name]["linestyle"], linewidth=1.2,
                    label=f"{run.labels[name]} bias")
            ax.fill_between(time_s[::every], estimate - 3 * sigma, estimate + 3 * sigma,
                            color=styles[name]["color"], alpha=0.15, linewidth=0)
        _bias_limits(ax, [rest[axis]] if has_rest else [],
                     [np.degrees(run.traces[n].bias_radps[:, axis]) for n in with_bias])
        ax.set_ylabel(f"{AXIS_NAMES[axis]} bias (deg/s)")
    axes[0].set_title("Gyro bias estimates (±3σ) against the rest-phase mean" if has_rest else
                      "Gyro bias estimates (±3σ); the recording has no initial rest")
    axes[-1].set_xlabel(X_LABEL)


def _bias_limits(ax, marks: list, estimates: list) -> None:
    """The y range holding ``marks`` and where the finite ``estimates`` spend
    98 % of the time (about zero where there is neither)."""
    values = np.hstack([np.asarray(marks, dtype=float)] + estimates)
    values = values[np.isfinite(values)]
    low, high = np.percentile(values, [1, 99]) if values.size else (0.0, 0.0)
    low, high = min([low, *marks]), max([high, *marks])
    margin = max(0.2 * (high - low), 0.05)
    ax.set_ylim(low - margin, high + margin)
