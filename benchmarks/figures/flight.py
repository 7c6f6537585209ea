"""The flight figure: every estimator's attitude error, one row each.

The top panel compares them all, each one's total error (the rotation angle)
as its RMS over short spans on a log axis. Below it each estimator has its
own row of per-axis panels (:mod:`benchmarks.figures.panels`): its error,
its ±3σ, the readings its gating rejected and the Earth's shadow. A last row
holds the gyro bias estimates against the true bias. Curves that look alike
are drawn dashed over solid and named in the one legend below the panels.
"""
from __future__ import annotations

import math

import numpy as np
import seaborn as sns
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from benchmarks.figures.panels import (AXIS_NAMES, ENVELOPE_ALPHA, ENVELOPE_LABEL, ROW_DECADES,
                                       UNIT_SYMBOLS, cell_grid, error_cell, row_label,
                                       scale_errors, three_sigma_envelopes)
from benchmarks.figures.plots import X_LABEL
from benchmarks.figures.style import (coincidence_note, coinciding, estimator_styles, finite_max,
                                      legend_outside, log_axis, symlog_axis, with_coincidences)
from sensors.recording import true_runs

#: Heights (inches) of the per-axis figures' rows: the panel comparing every
#: estimator, each estimator's own row, the bias row, and room for the legend.
COMPARISON_HEIGHT = 2.6
ESTIMATOR_ROW_HEIGHT = 1.55
BIAS_ROW_HEIGHT = 2.2
LEGEND_HEIGHT = 0.9
#: Spans over which the comparison panel takes each estimator's RMS error: a
#: static solution's step-to-step noise drawn point by point fills a band
#: that hides every curve beneath it; its RMS over a span is one line.
COMPARISON_BINS = 300
#: Curves closer than this (in decades, on a log axis) or this fraction of a
#: panel's range (on a linear one) look like one: the later is drawn dashed
#: over the earlier and the pair named, whatever the tolerance of
#: :data:`~benchmarks.figures.style.COINCIDE_FRACTION` says.
LOOK_ALIKE_DECADES = 0.01
LOOK_ALIKE_FRACTION = 0.01
REJECTED_LABEL = "reading rejected by gating (✕ on the filter's curve)"


def flight_figure(time_s, error_vectors_deg: dict, sigmas_deg: dict, bias_true_deg_per_hr,
                  bias_estimates: dict, labels: dict, envelope_steps: int = 1,
                  eclipse=None, rejected: dict | None = None) -> Figure:
    """Every estimator's attitude error, one row each, beside the others.

    The top panel compares them all: each one's total error (the rotation
    angle), as its RMS over short spans, on a log axis. Below it each
    estimator has its own row, one panel per body axis, with its error and
    its own ±3σ envelope; the rows share one symmetric-log scale, so a glance
    down a column compares them. The last row (when any estimator has a
    bias) holds the gyro bias estimates against the true bias, one panel per
    axis.

    Parameters
    ----------
    time_s : (N,) seconds
    error_vectors_deg : {name: (N, 3)} body-frame error δθ per axis, degrees
    sigmas_deg : {name: (N, 3) or None} each filter's own 1σ per axis, degrees
    bias_true_deg_per_hr : (N, 3) the gyro's true bias, deg/h
    bias_estimates : {name: ((N, 3) estimate, (N, 3) 1σ)} in deg/h, for
        estimators that estimate a bias
    labels : {name: legend label}
    envelope_steps : int
        The ±3σ bands are drawn through their peaks over this many steps (one
        reading interval: a σ that drops at each reading is not a sawtooth).
    eclipse : (N,) bool, optional
        The steps in the Earth's shadow, shaded grey in every panel.
    rejected : {name: (steps,)}, optional
        Each filter's readings rejected by innovation gating, marked ✕ on its
        error curve in its row.

    The symmetric-log scale is linear within the best filter's steady-state
    3σ and logarithmic beyond, so a converged filter, a drifting dead
    reckoning and a start tens of degrees off are all readable. The unit
    (arcsec or degrees) follows the size of the steady-state errors.
    Estimators whose errors coincide are drawn dashed over solid in the
    comparison panel and named, with their largest difference, in the
    legend's title; one legend, below the panels, lists every curve.
    """
    names = list(error_vectors_deg)
    styles = estimator_styles(names)
    typical_deg = _steady_three_sigma(time_s, error_vectors_deg, sigmas_deg)
    scaled, scale, unit, under = scale_errors(error_vectors_deg, typical_deg)
    envelopes = three_sigma_envelopes(sigmas_deg, names, scale, envelope_steps)
    figure, total_ax, cells, bias_axes = _flight_grid(len(names), bias=bool(bias_estimates))
    _shade_eclipses([total_ax, *cells.ravel(), *bias_axes], time_s, eclipse)
    alike = {**_total_panel(total_ax, time_s, scaled, styles, labels, unit), **under}
    for row, name in enumerate(names):
        _error_row(cells[row], time_s, scaled[name], envelopes[name], name,
                   styles[name]["color"], rejected=(rejected or {}).get(name, ()))
        row_label(cells[row, 0], labels, name, under, unit, styles[name]["color"])
    symlog_axis(cells[0, 0], typical_deg * scale, finite_max(scaled.values()),
                most_decades=ROW_DECADES)
    if bias_estimates:
        _bias_row(bias_axes, time_s, bias_true_deg_per_hr, bias_estimates, styles, labels)
    _finish_flight(figure, time_s, total_ax, cells, bias_axes, unit=unit,
                   note=coincidence_note(alike, labels, UNIT_SYMBOLS[unit]))
    return figure


def _steady_three_sigma(time_s, error_vectors_deg: dict, sigmas_deg: dict) -> float:
    """The best filter's steady-state 3σ (median over the second half of the
    run), degrees; without any σ, the smallest median absolute error."""
    second_half = slice(len(time_s) // 2, None)
    steady = [3 * np.nanmedian(sigma[second_half]) for sigma in sigmas_deg.values()
              if sigma is not None and np.isfinite(sigma[second_half]).any()]
    if not steady:
        steady = [np.nanmedian(np.abs(e[second_half])) for e in error_vectors_deg.values()
                  if np.isfinite(e[second_half]).any()] or [1.0]
    return max(min(steady), 1e-12)


def _flight_grid(rows: int, *, bias: bool):
    """``(figure, comparison axes, (rows, 3) per-axis cells, bias axes)``:
    the comparison panel across the top, ``rows`` estimator rows of one panel
    per body axis, and (if ``bias``) the bias row, all on the comparison's
    time axis."""
    heights = ([COMPARISON_HEIGHT] + [ESTIMATOR_ROW_HEIGHT] * rows
               + ([BIAS_ROW_HEIGHT] if bias else []))
    with sns.axes_style("whitegrid"):
        figure = Figure(figsize=(14.0, sum(heights) + LEGEND_HEIGHT), layout="constrained")
        grid = figure.add_gridspec(len(heights), 3, height_ratios=heights)
        total_ax = figure.add_subplot(grid[0, :])
        cells = cell_grid(figure, grid, range(1, rows + 1), range(3), sharex=total_ax)
        bias_axes = [figure.add_subplot(grid[-1, axis], sharex=total_ax)
                     for axis in range(3)] if bias else []
    return figure, total_ax, cells, bias_axes


def _error_row(cells, time_s, errors, envelope, name: str, color, rejected) -> None:
    """One estimator's row: its error ``(N, 3)`` on each body axis over its
    ±3σ ``envelope``, and the readings its gating rejected (the steps
    ``rejected``) marked ✕ on its curve."""
    for axis, ax in enumerate(cells):
        error_cell(ax, time_s, errors[:, axis], envelope, axis, color,
                   gid=f"error {name} {axis}")
        if len(rejected):
            ax.plot(time_s[rejected], errors[rejected, axis], linestyle="none",
                    marker="x", markersize=4, markeredgewidth=0.8, color="black",
                    zorder=4, label=REJECTED_LABEL)


def _bias_row(axes, time_s, truth_deg_per_hr, estimates: dict, styles: dict,
              labels: dict) -> None:
    """The gyro bias row: on each body axis, the estimates ``{name: (estimate,
    1σ)}`` (deg/h, (N, 3) each) against the truth."""
    for axis, ax in enumerate(axes):
        _bias_panel(ax, time_s, truth_deg_per_hr[:, axis],
                    {name: (estimate[:, axis], sigma[:, axis])
                     for name, (estimate, sigma) in estimates.items()},
                    styles, labels, axis)
        ax.set_title(f"{AXIS_NAMES[axis]} gyro bias: estimate (±3σ) and truth",
                     fontsize="medium")
    axes[0].set_ylabel("Gyro bias (deg/h)")


def _finish_flight(figure, time_s, total_ax, cells, bias_axes, *, unit: str,
                   note: str) -> None:
    """The columns' titles, the time axis (labelled on the bottom row) and
    the one legend below the panels, ``note`` as its title."""
    for axis, ax in enumerate(cells[0]):
        ax.set_title(f"{AXIS_NAMES[axis]} error and the filter's ±3σ ({unit})",
                     fontsize="medium")
    for ax in bias_axes or cells[-1]:
        ax.set_xlabel(X_LABEL)
    total_ax.set_xlim(time_s[0], time_s[-1])
    extra = [(Patch(color="0.45", alpha=2 * ENVELOPE_ALPHA, linewidth=0), ENVELOPE_LABEL)]
    legend_outside(figure, [total_ax, *cells.ravel(), *bias_axes], columns=5, note=note,
                   extra=extra)


def _total_panel(ax, time_s, scaled: dict, styles: dict, labels: dict, unit: str) -> dict:
    """Every estimator's total error (the rotation angle), its RMS over each
    of :data:`COMPARISON_BINS` spans, on a log axis, the smallest on top.
    Returns ``{later: (earlier, largest difference of their per-axis
    errors)}`` for the curves that look alike (within
    :data:`LOOK_ALIKE_DECADES`): the later drawn dashed over the earlier."""
    bins = min(COMPARISON_BINS, len(time_s))
    curves = {name: binned_rms(time_s, np.linalg.norm(error, axis=1), bins)
              for name, error in scaled.items()}
    with np.errstate(divide="ignore", invalid="ignore"):
        alike = coinciding({name: np.log10(rms) for name, (_, rms) in curves.items()},
                           LOOK_ALIKE_DECADES)
    under = {later: (earlier, finite_max([scaled[later] - scaled[earlier]]))
             for later, (earlier, _) in alike.items()}
    typical = {name: float(np.nanmedian(rms)) if np.isfinite(rms).any() else math.inf
               for name, (_, rms) in curves.items()}
    order = {name: 2 + rank for rank, name in
             enumerate(sorted(curves, key=typical.get, reverse=True))}
    for later, (earlier, _) in under.items():
        order[later] = order[earlier] + 0.5          # over the one it hides
    styles = with_coincidences(styles, under)
    for name, (centres, rms) in curves.items():
        style = styles[name]
        ax.plot(centres, rms, color=style["color"], linestyle=style["linestyle"],
                linewidth=style.get("linewidth", 1.6), zorder=order[name],
                label=labels[name], gid=f"total {name}")
    values = np.concatenate([rms for _, rms in curves.values()])
    values = values[np.isfinite(values) & (values > 0)]
    low, high = (values.min() / 1.5, values.max() * 1.5) if values.size else (0.1, 10.0)
    log_axis(ax, low, high)
    span_s = (time_s[-1] - time_s[0]) / bins
    ax.set_ylabel(unit)
    ax.set_title(f"Total attitude error of every estimator: its RMS over each {span_s:.2g} s "
                 f"({unit}, log scale)", fontsize="medium")
    return under


def binned_rms(time_s, values, bins: int):
    """``(centres, rms)`` of ``values`` over ``bins`` equal spans of
    ``time_s``; NaN where a span holds no finite value (a diverged run's
    curve stops)."""
    values = np.asarray(values, dtype=float)
    edges = np.linspace(time_s[0], time_s[-1], bins + 1)
    index = np.clip(np.searchsorted(edges, time_s, side="right") - 1, 0, bins - 1)
    finite = np.isfinite(values)
    counts = np.bincount(index[finite], minlength=bins)
    sums = np.bincount(index[finite], weights=values[finite] ** 2, minlength=bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.sqrt(sums / counts)
    return 0.5 * (edges[:-1] + edges[1:]), np.where(counts > 0, rms, np.nan)


def _shade_eclipses(axes, time_s, eclipse) -> None:
    """The Earth's shadow, shaded grey in each of ``axes``."""
    if eclipse is None or not np.any(eclipse):
        return
    for ax in axes:
        for first, (start, stop) in enumerate(true_runs(eclipse)):
            ax.axvspan(time_s[start], time_s[min(stop, len(time_s) - 1)], color="0.55",
                       alpha=0.18, linewidth=0, zorder=0,
                       label="Eclipse" if first == 0 else None)


def _bias_panel(ax, time_s, truth, estimates: dict, styles: dict, labels: dict,
                axis: int) -> None:
    """One axis's bias estimates (±3σ) against the truth, the y range holding
    every estimate over the whole run (its initial transient included); an
    estimate that looks like another (within :data:`LOOK_ALIKE_FRACTION` of
    the range) drawn dashed over it."""
    values = np.hstack([truth, *(estimate for estimate, _ in estimates.values())])
    values = values[np.isfinite(values)]
    low, high = (float(values.min()), float(values.max())) if values.size else (-1.0, 1.0)
    under = coinciding({name: estimate for name, (estimate, _) in estimates.items()},
                       LOOK_ALIKE_FRACTION * (high - low))
    styles = with_coincidences(styles, under)
    ax.plot(time_s, truth, color="black", linestyle="--", linewidth=1.5, label="True bias")
    # Each estimate thinner than the one before and drawn over it: estimates
    # that nearly agree show as a thin line with its predecessor's edges.
    widths = np.linspace(2.6, 1.0, len(estimates)) if len(estimates) > 1 else [1.4]
    for rank, (name, (estimate, sigma)) in enumerate(estimates.items()):
        style = styles[name]
        ax.plot(time_s, estimate, color=style["color"], linestyle=style["linestyle"],
                linewidth=style.get("linewidth", widths[rank]), zorder=3 + rank,
                label=labels[name], gid=f"bias {name} {axis}")
        if name not in under:
            ax.fill_between(time_s, estimate - 3 * sigma, estimate + 3 * sigma,
                            color=style["color"], alpha=0.12, linewidth=0)
    # (a diverged estimate is NaN from its step on)
    margin = max(0.08 * (high - low), 0.05 * max(abs(low), abs(high)), 1e-6)
    ax.set_ylim(low - margin, high + margin)
