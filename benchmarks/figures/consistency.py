"""The consistency figure: does each filter know its own error?

One row per estimator with a covariance. On the left, its ANEES (average
normalised estimation error squared over the campaign's runs) over time, on
a log axis, against the χ² band a consistent filter's ANEES falls in; on the
right, one run's error per body axis (:mod:`benchmarks.figures.panels`)
against the filter's own ±3σ and the ±3σ of the bound, the best any filter
could achieve (dashed).
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
from benchmarks.figures.plots import X_LABEL, new_figure
from benchmarks.figures.style import (coincidence_note, estimator_styles, finite_max,
                                      legend_outside, log_axis, symlog_axis, upper_envelope)

#: The height (inches) of each estimator's row in the consistency figure.
CONSISTENCY_ROW_HEIGHT = 1.8
#: An ANEES panel spans at least the band shrunk and stretched by this
#: factor, and always the whole of the estimator's ANEES.
ANEES_MARGIN = 2.5


def consistency_figure(time_s, anees: dict, bands: dict, sample_errors_deg: dict,
                       sample_sigmas_deg: dict, bound_sigma_deg: np.ndarray, sample_time_s,
                       labels: dict, runs: dict | None = None, envelope_steps: int = 1,
                       level: float = 0.95, *, settle_s: float | None = None,
                       averages: dict | None = None) -> Figure:
    """One row per estimator with a covariance: its ANEES over time against
    its χ² band (left), and one run's error per body axis with the filter's
    ±3σ and the bound's ±3σ ("best achievable", dashed).

    Parameters
    ----------
    time_s : (S,) the ANEES sample times
    anees : {name: (S,) or None}; bands : {name: (low, high)}
    sample_errors_deg : {name: (N, 3)}; sample_sigmas_deg : {name: (N, 3) or None}
    bound_sigma_deg : (N, 3) the bound's 1σ per axis; sample_time_s : (N,)
    labels : {name: label}, every estimator of the campaign (those without a
        covariance are named in the legend's title)
    runs : {name: runs} behind each ANEES
    envelope_steps : the bound's ±3σ is drawn through its peaks over this
        many steps (one reading interval), not as a sawtooth
    settle_s : the start of the time averages, marked on every ANEES panel
    averages : {name: (time-averaged ANEES, verdict)} as the campaign's
        table gives them (default: the mean of ``anees`` from ``settle_s`` on)

    Each ANEES panel is a log axis holding the band and the whole of the
    estimator's ANEES (an estimator far off its band is drawn, not clipped),
    its value and verdict written above it; the error panels share one
    symmetric-log scale.
    """
    runs, averages = runs or {}, averages or {}
    rows = [name for name in labels
            if anees.get(name) is not None or name in sample_errors_deg]
    if not rows:
        return _without_covariance()
    styles = estimator_styles(labels)
    steady = max(3 * float(np.median(bound_sigma_deg[len(bound_sigma_deg) // 2:])), 1e-12)
    scaled, scale, unit, under = scale_errors(sample_errors_deg, steady)
    envelopes = three_sigma_envelopes(sample_sigmas_deg, scaled, scale, envelope_steps)
    bound = upper_envelope(3 * bound_sigma_deg * scale, envelope_steps)
    figure, anees_axes, cells = _consistency_grid(len(rows))
    for row, name in enumerate(rows):
        color = styles[name]["color"]
        _anees_strip(anees_axes[row], time_s, anees.get(name), bands.get(name), name,
                     labels[name], color, runs.get(name), averages.get(name), settle_s)
        _sample_row(cells[row], sample_time_s, scaled.get(name), envelopes.get(name), bound,
                    name, color)
        row_label(anees_axes[row], labels, name, under, "ANEES", color)
        cells[row, 0].set_ylabel(unit, fontsize="small")
    symlog_axis(cells[0, 0], steady * scale, finite_max([*scaled.values(), bound]),
                most_decades=ROW_DECADES)
    cells[0, 0].set_xlim(sample_time_s[0], sample_time_s[-1])
    _title_consistency(figure, anees_axes, cells, unit,
                       sorted({runs[name] for name in rows if name in runs}))
    _consistency_legend(figure, [*anees_axes, *cells.ravel()], labels, rows, under=under,
                        unit=unit, level=level)
    return figure


def _without_covariance() -> Figure:
    """The figure of a campaign in which no estimator reports a covariance."""
    figure, (ax,) = new_figure()
    ax.text(0.5, 0.5, "no estimator reports a covariance", ha="center",
            transform=ax.transAxes)
    return figure


def _consistency_grid(rows: int):
    """``(figure, ANEES axes, (rows, 3) per-axis cells)``: each row an ANEES
    panel beside one panel per body axis, all on one time axis, labelled on
    the bottom row only."""
    with sns.axes_style("whitegrid"):
        figure = Figure(figsize=(16.0, CONSISTENCY_ROW_HEIGHT * rows + 1.9),
                        layout="constrained")
        grid = figure.add_gridspec(rows, 4, width_ratios=(1.3, 1, 1, 1))
        cells = cell_grid(figure, grid, range(rows), range(1, 4))
        anees_axes = [figure.add_subplot(grid[row, 0], sharex=cells[0, 0])
                      for row in range(rows)]
    for ax in anees_axes[:-1]:
        ax.tick_params(labelbottom=False)
    return figure, anees_axes, cells


def _sample_row(cells, time_s, errors, envelope, bound, name: str, color) -> None:
    """One estimator's sample run, its error ``(N, 3)`` (None: there is no
    sample run) on each body axis over its own ±3σ ``envelope``, and the
    bound's ±3σ ``bound`` dashed."""
    for axis, ax in enumerate(cells):
        if errors is not None:
            error_cell(ax, time_s, errors[:, axis], envelope, axis, color,
                       gid=f"error {name} {axis}")
        else:
            ax.text(0.5, 0.5, "no sample run", ha="center", transform=ax.transAxes)
        for sign, label in ((1, "best achievable ±3σ (the bound)"), (-1, None)):
            ax.plot(time_s, sign * bound[:, axis], color="black", linestyle="--",
                    linewidth=1.0, zorder=4, label=label)


def _title_consistency(figure, anees_axes, cells, unit: str, counts) -> None:
    """The error columns' titles, the time axis labelled on the bottom row,
    and the figure's title naming the runs ``counts`` behind the ANEES."""
    for axis, ax in enumerate(cells[0]):
        ax.set_title(f"One run: {AXIS_NAMES[axis]} error and ±3σ ({unit})", fontsize="medium")
    for ax in [anees_axes[-1], *cells[-1]]:
        ax.set_xlabel(X_LABEL)
    figure.suptitle("Does each filter know its own error? Its average NEES over "
                    f"{' / '.join(map(str, counts)) or 'its'} runs (left) and one run's error "
                    "against its own ±3σ and the bound's")


def _consistency_legend(figure, axes, labels: dict, rows: list, *, under: dict, unit: str,
                        level: float) -> None:
    """One legend for ``axes``, below them; its title names the estimators
    drawn under others and those without a covariance (not in ``rows``), and
    the χ² band of ``level`` and the ±3σ shading have entries of their own."""
    without = [labels[name] for name in labels if name not in rows]
    notes = [coincidence_note(under, labels, UNIT_SYMBOLS[unit])]
    if without:
        notes.append(f"no covariance, so no ANEES and no ±3σ: {', '.join(without)}")
    extra = [(Patch(color="0.45", alpha=0.3, linewidth=0),
              f"{100 * level:.0f} % χ² band of a consistent filter's ANEES"),
             (Patch(color="0.45", alpha=2 * ENVELOPE_ALPHA, linewidth=0), ENVELOPE_LABEL)]
    legend_outside(figure, axes, columns=3, note="\n".join(note for note in notes if note),
                   extra=extra)


def _anees_strip(ax, time_s, series, band, name: str, label: str, color, runs,
                 average, settle_s) -> None:
    """One estimator's ANEES over time on a log axis holding its band and all
    of its values; its time average and verdict above it; the settle time,
    where the averages start, marked."""
    if settle_s is not None:
        ax.axvline(settle_s, color="0.2", linestyle="-.", linewidth=1.2, zorder=4,
                   label=f"settle time ({settle_s:g} s): the averages start", gid="settle")
    if series is None or band is None or not np.all(np.isfinite(band)):
        ax.text(0.5, 0.5, "no ANEES", ha="center", va="center", transform=ax.transAxes)
        ax.set_yticks([])
        return
    series = np.asarray(series, dtype=float)
    ax.axhspan(*band, color=color, alpha=0.18, linewidth=0, zorder=1)
    ax.axhline(3.0, color="black", linewidth=0.8, linestyle=":", zorder=2,
               label="3 (a consistent filter's mean)")
    ax.plot(time_s, series, color=color, linewidth=0.9, zorder=3, gid=f"anees {name}")
    positive = series[np.isfinite(series) & (series > 0)]
    low = min(band[0] / ANEES_MARGIN, positive.min() / 1.3 if positive.size else math.inf)
    high = max(band[1] * ANEES_MARGIN, positive.max() * 1.3 if positive.size else 0.0)
    log_axis(ax, low, high, most_ticks=5)
    if average is None:
        after = series[time_s >= (settle_s or 0.0)]
        average = (float(np.nanmean(after)) if np.isfinite(after).any() else math.nan, "")
    value, verdict = average
    ax.set_title(f"{label}: ANEES {value:.3g}{', ' + verdict if verdict else ''} "
                 f"(band [{band[0]:.2f}, {band[1]:.2f}], {runs if runs else '?'} runs)",
                 fontsize="small", loc="left", color=color)
