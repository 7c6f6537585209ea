"""Figures in the workshop's style.

Figures are built with :class:`matplotlib.figure.Figure` directly (no
pyplot), so plotting never touches a global backend or opens a window.
"""
from __future__ import annotations

import math
import textwrap
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import seaborn as sns

from benchmarks.figures.style import (COINCIDE_FRACTION, coincidence_note, coinciding,
                                      estimator_styles, finite_max, legend_outside, log_axis,
                                      round_values, symlog_axis, upper_envelope,
                                      with_coincidences)
from benchmarks.metrics import angle_unit
from matplotlib.animation import PillowWriter
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Patch
from matplotlib.ticker import FixedLocator, FuncFormatter
from PIL import Image

TITLE = "Absolute Attitude Error"
Y_LABEL = "Degrees"
X_LABEL = "Time (seconds)"
#: The EKF is drawn as the workshop draws it: a thick black line.
EKF_STYLE = {"color": "black", "linewidth": 3.0, "zorder": 3}


def new_figure(ncols: int = 1, width: float = 8.0, height: float = 4.5):
    """A figure with the project's look (seaborn's white grid, no global state)."""
    with sns.axes_style("whitegrid"):
        figure = Figure(figsize=(width * ncols, height), layout="constrained")
        axes = figure.subplots(1, ncols, squeeze=False)[0]
    return figure, axes


def plot_errors(ax, time_s: np.ndarray, curves: dict, ekf_labels=("EKF",)) -> None:
    """Draw error curves ``{legend label: (N,) degrees}`` on ``ax`` in the workshop style."""
    for label, error_deg in curves.items():
        style = EKF_STYLE if label in ekf_labels else {"linewidth": 1.2}
        ax.plot(time_s, error_deg, label=label, **style)
    ax.set_title(TITLE)
    ax.set_xlabel(X_LABEL)
    ax.set_ylabel(Y_LABEL)
    ax.set_xlim(time_s[0], time_s[-1])
    ax.set_ylim(bottom=0)
    ax.legend(loc="upper left")


def comparison_figure(time_s: np.ndarray, curves: dict, ekf_labels=("EKF",),
                      title: str | None = None) -> Figure:
    """The workshop's comparison figure of error curves ``{label: degrees}``."""
    figure, (ax,) = new_figure()
    plot_errors(ax, time_s, curves, ekf_labels=ekf_labels)
    if title:
        ax.set_title(title)
    return figure


def freeze_layout(figure: Figure) -> None:
    """Lay the figure out once and keep that layout.

    Animations redraw the same figure for every frame; re-running the
    constrained layout each time costs about as much as drawing it.
    """
    figure.draw_without_rendering()   # runs the layout engine with the artists in place
    figure.set_layout_engine("none")


#: Statistics shown in the Monte Carlo distribution figure: (column, title);
#: the RMS error first, the statistic the comparisons quote.
DISTRIBUTION_PANELS = (("rms_deg", "RMS error"), ("std_deg", "Error std (the workshop's loss)"),
                       ("max_deg", "Maximum error"))
#: Estimators whose medians differ by more than this factor share a log axis.
LOG_AXIS_SPREAD = 10.0


def distribution_figure(frame, labels: dict | None = None) -> Figure:
    """Per-estimator distributions over runs of a tidy per-run frame (one
    violin per estimator and statistic, seaborn). Angles are in arcseconds
    when the errors are below 0.1°, and on a log axis when the estimators'
    medians differ by orders of magnitude (the violins then show log values)."""
    import pandas as pd   # seaborn's own dependency; imported where it is used

    data = frame.copy()
    labels = labels or {}
    data["estimator"] = data["estimator"].map(
        lambda name: textwrap.fill(labels.get(name, name), 20))
    columns = [column for column, _ in DISTRIBUTION_PANELS]
    medians = data.groupby("estimator")["rms_deg"].median().to_numpy()
    scale, unit = angle_unit(float(np.nanmedian(data[columns].to_numpy())))
    positive = medians[medians > 0]
    log_axis = positive.size > 1 and positive.max() / positive.min() > LOG_AXIS_SPREAD
    figure, axes = new_figure(ncols=len(DISTRIBUTION_PANELS), width=4.5, height=4.5)
    for ax, (column, title) in zip(axes, DISTRIBUTION_PANELS):
        values = data[column] * scale
        if log_axis:
            values = np.log10(values.where(values > 0))
        plotted = data.assign(value=values)
        sns.violinplot(data=plotted, x="estimator", y="value", hue="estimator", ax=ax,
                       cut=0, inner="quartile", legend=False)
        ax.set_title(title)
        ax.set_xlabel("")
        if log_axis:
            finite = values[np.isfinite(values)]
            low, high = (finite.min(), finite.max()) if finite.size else (0.0, 1.0)
            ax.yaxis.set_major_locator(FixedLocator(
                np.log10(round_values(10.0 ** (low - 0.3), 10.0 ** (high + 0.3)))))
            ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _p: f"{10 ** v:g}"))
            ax.set_ylabel(f"{unit} (log scale)")
        else:
            ax.set_ylabel(unit)
    runs = data["run"].nunique() if isinstance(data, pd.DataFrame) else len(data)
    figure.suptitle(f"Attitude error over {runs} Monte Carlo runs")
    return figure


class BlittingPillowWriter(PillowWriter):
    """matplotlib's GIF writer, grabbing frames by blitting.

    The figure is drawn once without its animated artists; each frame then
    restores that background and draws only those artists. Redrawing the
    whole figure for every frame (as ``FuncAnimation.save`` does) cost about
    0.24 s a frame, mostly laying out the same tick labels again.

    Use it through matplotlib's own ``writer.saving(figure, path, dpi)``,
    calling :meth:`grab_frame` after each update.
    """

    def __init__(self, animated_artists, fps: int):
        super().__init__(fps=fps)
        self._animated = list(animated_artists)
        self._background = None
        self._palettes = None

    def setup(self, fig, outfile, dpi=None):
        super().setup(fig, outfile, dpi)
        # Each frame's palette is chosen (Pillow's GIF writer would do it in
        # finish(), one frame after another) in a worker while the next frame
        # is drawn: Pillow releases the GIL there, so it costs no wall time.
        self._palettes = ThreadPoolExecutor(max_workers=1)

    def finish(self):
        self._frames = [frame.result() for frame in self._frames]
        self._palettes.shutdown()
        super().finish()

    def grab_frame(self, **savefig_kwargs):
        canvas = self.fig.canvas
        if self._background is None:
            if not isinstance(canvas, FigureCanvasAgg):
                canvas = FigureCanvasAgg(self.fig)
            self.fig.set_dpi(self.dpi)
            for artist in self._animated:
                artist.set_animated(True)
            canvas.draw()
            self._background = canvas.copy_from_bbox(self.fig.bbox)
        canvas.restore_region(self._background)
        for artist in self._animated:
            self.fig.draw_artist(artist)
        # PillowWriter keeps its frames in _frames and writes them in finish().
        frame = Image.frombuffer("RGBA", canvas.get_width_height(), bytes(canvas.buffer_rgba()),
                                 "raw", "RGBA", 0, 1)
        self._frames.append(self._palettes.submit(_gif_frame, frame))


def _gif_frame(frame):
    """``frame`` as Pillow's GIF writer would convert it (GifImagePlugin's
    ``_normalize_mode``: an adaptive palette, a fully transparent colour as
    the GIF's transparency), so that it writes the same file."""
    frame = frame.convert("P", palette=Image.Palette.ADAPTIVE)
    if frame.palette.mode == "RGBA":
        for rgba, index in frame.palette.colors.items():
            if rgba[3] == 0:
                frame.info["transparency"] = index
                break
    return frame


#: Body axes as the per-axis figures name them (not roll, pitch and yaw,
#: which would clash with a star tracker's roll about its own boresight).
AXIS_NAMES = ("Body x", "Body y", "Body z")
_UNIT_SYMBOLS = {"arcsec": "″", "deg": "°"}
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
#: Decades labelled on each side of zero in an estimator's row (a short panel).
ROW_DECADES = 2
ERROR_WIDTH = 0.7
#: Shading of a filter's ±3σ band, in its colour.
ENVELOPE_ALPHA = 0.25
#: Curves closer than this (in decades, on a log axis) or this fraction of a
#: panel's range (on a linear one) look like one: the later is drawn dashed
#: over the earlier and the pair named, whatever the tolerance of
#: :data:`~benchmarks.figures.style.COINCIDE_FRACTION` says.
LOOK_ALIKE_DECADES = 0.01
LOOK_ALIKE_FRACTION = 0.01
REJECTED_LABEL = "reading rejected by gating (✕ on the filter's curve)"
ENVELOPE_LABEL = "±3σ: each filter's own, shaded in its colour"


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
    scale, unit = angle_unit(typical_deg)
    scaled = {name: error * scale for name, error in error_vectors_deg.items()}
    under = coinciding(scaled, COINCIDE_FRACTION * typical_deg * scale)
    envelopes = {name: None if sigmas_deg.get(name) is None
                 else upper_envelope(3 * sigmas_deg[name] * scale, envelope_steps)
                 for name in names}
    heights = ([COMPARISON_HEIGHT] + [ESTIMATOR_ROW_HEIGHT] * len(names)
               + ([BIAS_ROW_HEIGHT] if bias_estimates else []))
    with sns.axes_style("whitegrid"):
        figure = Figure(figsize=(14.0, sum(heights) + LEGEND_HEIGHT), layout="constrained")
        grid = figure.add_gridspec(len(heights), 3, height_ratios=heights)
        total_ax = figure.add_subplot(grid[0, :])
        cells = _cell_grid(figure, grid, range(1, len(names) + 1), range(3), sharex=total_ax)
        bias_axes = [figure.add_subplot(grid[-1, axis], sharex=total_ax)
                     for axis in range(3)] if bias_estimates else []
    for ax in [total_ax, *cells.ravel(), *bias_axes]:
        _shade_eclipses(ax, time_s, eclipse)
    alike = {**_total_panel(total_ax, time_s, scaled, styles, labels, unit), **under}
    rejected = rejected or {}
    for row, name in enumerate(names):
        for axis, ax in enumerate(cells[row]):
            _error_cell(ax, time_s, scaled[name][:, axis], envelopes[name], axis,
                        styles[name]["color"], gid=f"error {name} {axis}")
            steps = rejected.get(name, ())
            if len(steps):
                ax.plot(time_s[steps], scaled[name][steps, axis], linestyle="none",
                        marker="x", markersize=4, markeredgewidth=0.8, color="black",
                        zorder=4, label=REJECTED_LABEL)
        _row_label(cells[row, 0], labels, name, under, unit, styles[name]["color"])
    symlog_axis(cells[0, 0], typical_deg * scale, finite_max(scaled.values()),
                most_decades=ROW_DECADES)
    for axis, ax in enumerate(cells[0]):
        ax.set_title(f"{AXIS_NAMES[axis]} error and the filter's ±3σ ({unit})",
                     fontsize="medium")
    if bias_estimates:
        for axis, ax in enumerate(bias_axes):
            _bias_panel(ax, time_s, bias_true_deg_per_hr[:, axis],
                        {name: (estimate[:, axis], sigma[:, axis])
                         for name, (estimate, sigma) in bias_estimates.items()},
                        styles, labels, axis)
            ax.set_title(f"{AXIS_NAMES[axis]} gyro bias: estimate (±3σ) and truth",
                         fontsize="medium")
        bias_axes[0].set_ylabel("Gyro bias (deg/h)")
    for ax in bias_axes or cells[-1]:
        ax.set_xlabel(X_LABEL)
    total_ax.set_xlim(time_s[0], time_s[-1])
    extra = [(Patch(color="0.45", alpha=2 * ENVELOPE_ALPHA, linewidth=0), ENVELOPE_LABEL)]
    legend_outside(figure, [total_ax, *cells.ravel(), *bias_axes], columns=5,
                   note=coincidence_note(alike, labels, _UNIT_SYMBOLS[unit]), extra=extra)
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


def _cell_grid(figure, grid, rows, columns, sharex=None) -> np.ndarray:
    """``(rows, columns)`` panels of ``grid`` sharing one y axis (and the x
    axis of ``sharex``, or of the first panel); tick labels only on the
    outer edges."""
    rows, columns = list(rows), list(columns)
    cells = np.empty((len(rows), len(columns)), dtype=object)
    for i, row in enumerate(rows):
        for j, column in enumerate(columns):
            first = cells[0, 0] if i or j else None
            cells[i, j] = figure.add_subplot(grid[row, column], sharex=sharex or first,
                                             sharey=first)
    for ax in cells[:, 1:].ravel():
        ax.tick_params(labelleft=False)
    for ax in cells[:-1].ravel():
        ax.tick_params(labelbottom=False)
    return cells


def _error_cell(ax, time_s, error, envelope, axis: int, color, gid: str) -> None:
    """One estimator's error on one body axis over its own ±3σ band (shaded,
    without edge lines: a static solution's σ changes at every step, and
    edges drawn through it would fill the panel and hide the error)."""
    if envelope is not None:
        band = envelope[:, axis]
        ax.fill_between(time_s, -band, band, color=color, alpha=ENVELOPE_ALPHA, linewidth=0,
                        zorder=1)
    ax.plot(time_s, error, color=color, linewidth=ERROR_WIDTH, zorder=3, gid=gid)


def _row_label(ax, labels: dict, name: str, under: dict, unit: str, color) -> None:
    """The estimator a row belongs to, in its colour, as the row's y label;
    one whose errors coincide with another's says so."""
    lines = [textwrap.fill(labels[name], 16)]
    if name in under:
        lines.append(f"(as {labels[under[name][0]]})")
    ax.set_ylabel("\n".join([*lines, unit]), color=color, fontsize="small")


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


def _shade_eclipses(ax, time_s, eclipse) -> None:
    """The Earth's shadow, shaded grey."""
    if eclipse is None or not np.any(eclipse):
        return
    edges = np.flatnonzero(np.diff(np.concatenate([[0], np.asarray(eclipse).astype(int), [0]])))
    for first, (start, stop) in enumerate(zip(edges[::2], edges[1::2])):
        ax.axvspan(time_s[start], time_s[min(stop, len(time_s) - 1)], color="0.55",
                   alpha=0.18, linewidth=0, zorder=0, label="Eclipse" if first == 0 else None)


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
        figure, (ax,) = new_figure()
        ax.text(0.5, 0.5, "no estimator reports a covariance", ha="center",
                transform=ax.transAxes)
        return figure
    styles = estimator_styles(labels)
    steady = max(3 * float(np.median(bound_sigma_deg[len(bound_sigma_deg) // 2:])), 1e-12)
    scale, unit = angle_unit(steady)
    scaled = {name: error * scale for name, error in sample_errors_deg.items()}
    under = coinciding(scaled, COINCIDE_FRACTION * steady * scale)
    envelopes = {name: None if sample_sigmas_deg.get(name) is None
                 else upper_envelope(3 * sample_sigmas_deg[name] * scale, envelope_steps)
                 for name in scaled}
    bound = upper_envelope(3 * bound_sigma_deg * scale, envelope_steps)
    with sns.axes_style("whitegrid"):
        figure = Figure(figsize=(16.0, CONSISTENCY_ROW_HEIGHT * len(rows) + 1.9),
                        layout="constrained")
        grid = figure.add_gridspec(len(rows), 4, width_ratios=(1.3, 1, 1, 1))
        cells = _cell_grid(figure, grid, range(len(rows)), range(1, 4))
        anees_axes = [figure.add_subplot(grid[row, 0], sharex=cells[0, 0])
                      for row in range(len(rows))]
    for ax in anees_axes[:-1]:
        ax.tick_params(labelbottom=False)
    for row, name in enumerate(rows):
        color = styles[name]["color"]
        _anees_strip(anees_axes[row], time_s, anees.get(name), bands.get(name), name,
                     labels[name], color, runs.get(name), averages.get(name), settle_s)
        for axis, ax in enumerate(cells[row]):
            if name in scaled:
                _error_cell(ax, sample_time_s, scaled[name][:, axis], envelopes[name], axis,
                            color, gid=f"error {name} {axis}")
            else:
                ax.text(0.5, 0.5, "no sample run", ha="center", transform=ax.transAxes)
            for sign, label in ((1, "best achievable ±3σ (the bound)"), (-1, None)):
                ax.plot(sample_time_s, sign * bound[:, axis], color="black", linestyle="--",
                        linewidth=1.0, zorder=4, label=label)
        _row_label(anees_axes[row], labels, name, under, "ANEES", color)
        cells[row, 0].set_ylabel(unit, fontsize="small")
    symlog_axis(cells[0, 0], steady * scale, finite_max([*scaled.values(), bound]),
                most_decades=ROW_DECADES)
    cells[0, 0].set_xlim(sample_time_s[0], sample_time_s[-1])
    for axis, ax in enumerate(cells[0]):
        ax.set_title(f"One run: {AXIS_NAMES[axis]} error and ±3σ ({unit})", fontsize="medium")
    for ax in [anees_axes[-1], *cells[-1]]:
        ax.set_xlabel(X_LABEL)
    counts = sorted({runs[name] for name in rows if name in runs})
    figure.suptitle("Does each filter know its own error? Its average NEES over "
                    f"{' / '.join(map(str, counts)) or 'its'} runs (left) and one run's error "
                    "against its own ±3σ and the bound's")
    without = [labels[name] for name in labels if name not in rows]
    notes = [coincidence_note(under, labels, _UNIT_SYMBOLS[unit])]
    if without:
        notes.append(f"no covariance, so no ANEES and no ±3σ: {', '.join(without)}")
    extra = [(Patch(color="0.45", alpha=0.3, linewidth=0),
              f"{100 * level:.0f} % χ² band of a consistent filter's ANEES"),
             (Patch(color="0.45", alpha=2 * ENVELOPE_ALPHA, linewidth=0), ENVELOPE_LABEL)]
    legend_outside(figure, [*anees_axes, *cells.ravel()], columns=3,
                   note="\n".join(note for note in notes if note), extra=extra)
    return figure


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
    run, time_s = result.run, result.time_s
    names = list(run.error_deg)
    with_bias = [name for name in names if run.traces[name].bias_radps is not None]
    with sns.axes_style("whitegrid"):
        figure = Figure(figsize=(14.0, 7.5), layout="constrained")
        grid = figure.add_gridspec(3, 2)
        error_ax = figure.add_subplot(grid[:, 0])
        bias_axes = [figure.add_subplot(grid[axis, 1], sharex=error_ax) for axis in range(3)]
    movement = result.recording.movement
    for ax in [error_ax, *bias_axes]:
        if movement.any():
            first, last = np.flatnonzero(movement)[[0, -1]]
            ax.axvspan(time_s[first], time_s[last], color="0.85", alpha=0.5, linewidth=0,
                       label="Movement phase" if ax is error_ax else None)
    styles = estimator_styles(names)
    bottoms = []
    for name in names:
        style = styles[name]
        centres, low, high, median = binned_range(time_s, run.error_deg[name], REPLAY_BINS)
        error_ax.fill_between(centres, low, high, color=style["color"], alpha=0.25,
                              linewidth=0, label=f"{run.labels[name]}: min–max")
        error_ax.plot(centres, median, color=style["color"], linestyle=style["linestyle"],
                      linewidth=1.3, label=f"{run.labels[name]}: median")
        positive = run.error_deg[name][run.error_deg[name] > 0]
        if positive.size:
            bottoms.append(np.nanpercentile(positive, 1))
    error_ax.set_yscale("log")
    # The log axis bounded by the data: from its 1st percentile (an error of
    # 0 at a reset has no place on it) to its largest value.
    top = finite_max(run.error_deg.values()) or 1.0
    error_ax.set_ylim(0.5 * min(bottoms) if bottoms else 1e-3, 2 * top)
    error_ax.set_xlim(time_s[0], time_s[-1])
    bin_s = (time_s[-1] - time_s[0]) / REPLAY_BINS
    error_ax.set_title(f"Attitude error against the optical reference: {result.recording.name}"
                       f"\n(median and range per {bin_s:.2g} s of "
                       f"{1 / np.median(np.diff(time_s)):.0f} Hz samples)", fontsize="medium")
    error_ax.set_xlabel(X_LABEL)
    error_ax.set_ylabel("Error (degrees, log scale)")
    rest = np.degrees(result.rest_bias_radps)
    for axis, ax in enumerate(bias_axes):
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
        # Show the rest mean and where the estimates spend 98 % of the time.
        values = [rest[axis]] + [np.degrees(run.traces[n].bias_radps[:, axis]) for n in with_bias]
        low, high = np.percentile(np.hstack(values), [1, 99])
        low, high = min(low, rest[axis]), max(high, rest[axis])
        margin = max(0.2 * (high - low), 0.05)
        ax.set_ylim(low - margin, high + margin)
        ax.set_ylabel(f"{AXIS_NAMES[axis]} bias (deg/s)")
    bias_axes[0].set_title("Gyro bias estimates (±3σ) against the rest-phase mean")
    bias_axes[-1].set_xlabel(X_LABEL)
    legend_outside(figure, [error_ax, *bias_axes], columns=5, where="upper center")
    if result.attribution:
        figure.supxlabel(textwrap.fill(result.attribution, 200), fontsize="x-small",
                         color="0.3")
    return figure
