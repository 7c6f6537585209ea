"""Figures in the workshop's style.

Figures are built with :class:`matplotlib.figure.Figure` directly (no
pyplot), so plotting never touches a global backend or opens a window.
"""
from __future__ import annotations

import math
import textwrap

import numpy as np
import seaborn as sns

from benchmarks.figures.style import (COINCIDE_FRACTION, coincidence_note, coinciding,
                                      estimator_styles, legend_outside, symlog_axis,
                                      finite_max, round_values, upper_envelope,
                                      with_coincidences)
from benchmarks.metrics import angle_unit
from matplotlib.animation import PillowWriter
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator
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
        self._frames.append(Image.frombuffer("RGBA", canvas.get_width_height(),
                                             bytes(canvas.buffer_rgba()), "raw", "RGBA", 0, 1))


#: Body axes as the per-axis figures name them (not roll, pitch and yaw,
#: which would clash with a star tracker's roll about its own boresight).
AXIS_NAMES = ("Body x", "Body y", "Body z")
_UNIT_SYMBOLS = {"arcsec": "″", "deg": "°"}


def flight_figure(time_s, error_vectors_deg: dict, sigmas_deg: dict, bias_true_deg_per_hr,
                  bias_estimates: dict, labels: dict, envelope_steps: int = 1,
                  eclipse=None, rejected: dict | None = None) -> Figure:
    """Per-axis attitude error with ±3σ envelopes (left), bias estimates against
    the true bias (right; no bias column when no estimator has a bias).

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
        error curve.

    The error axes are symmetric-log: linear within the best filter's
    steady-state 3σ, logarithmic beyond, so a converged filter, a drifting
    dead reckoning and a start tens of degrees off are all readable. The unit
    (arcsec or degrees) follows the size of the steady-state errors. Curves
    that coincide are drawn in their own line styles and named below the
    legend; one legend, outside the panels, lists every curve and band.
    """
    columns = 2 if bias_estimates else 1
    with sns.axes_style("whitegrid"):
        figure = Figure(figsize=(14.0 if columns == 2 else 9.0, 9.5), layout="constrained")
        axes = figure.subplots(3, columns, sharex=True, squeeze=False)
    styles = estimator_styles(error_vectors_deg)
    second_half = slice(len(time_s) // 2, None)
    steady = [3 * np.nanmedian(sigma[second_half]) for sigma in sigmas_deg.values()
              if sigma is not None and np.isfinite(sigma[second_half]).any()]
    if not steady:
        steady = [np.nanmedian(np.abs(e[second_half])) for e in error_vectors_deg.values()
                  if np.isfinite(e[second_half]).any()] or [1.0]
    typical_deg = max(min(steady), 1e-12)
    scale, unit = angle_unit(typical_deg)
    scaled = {name: error * scale for name, error in error_vectors_deg.items()}
    under = coinciding(scaled, COINCIDE_FRACTION * typical_deg * scale)
    largest = finite_max(scaled.values())
    envelopes = {name: None if sigma is None else upper_envelope(3 * sigma * scale,
                                                                   envelope_steps)
                 for name, sigma in sigmas_deg.items()}
    styles = layered(styles, scaled)
    for axis in range(3):
        _error_panel(axes[axis, 0], time_s, scaled, envelopes, axis, styles, under, labels)
        _events(axes[axis, 0], time_s, scaled, axis, styles, labels, eclipse, rejected or {})
        symlog_axis(axes[axis, 0], typical_deg * scale, largest)
        axes[axis, 0].set_ylabel(f"{AXIS_NAMES[axis]} error ({unit})")
        axes[axis, 0].set_xlim(time_s[0], time_s[-1])
        if bias_estimates:
            _bias_panel(axes[axis, 1], time_s, bias_true_deg_per_hr[:, axis],
                        {name: (estimate[:, axis], sigma[:, axis])
                         for name, (estimate, sigma) in bias_estimates.items()},
                        styles, under, labels)
            axes[axis, 1].set_ylabel(f"{AXIS_NAMES[axis]} gyro bias (deg/h)")
    axes[0, 0].set_title("Attitude error per body axis (symmetric log scale)")
    axes[2, 0].set_xlabel(X_LABEL)
    if bias_estimates:
        axes[0, 1].set_title("Gyro bias: estimate against the truth, from the start")
        axes[2, 1].set_xlabel(X_LABEL)
    legend_outside(figure, axes, note=coincidence_note(under, labels, _UNIT_SYMBOLS[unit]))
    return figure


def _error_panel(ax, time_s, scaled: dict, envelopes: dict, axis: int, styles: dict,
                 under: dict, labels: dict) -> None:
    """One body axis's errors and each filter's ±3σ band (its edges drawn in
    the filter's line style, so that overlapping bands stay legible)."""
    styles = with_coincidences(styles, under)
    for name, error in scaled.items():
        style = styles[name]
        ax.plot(time_s, error[:, axis], color=style["color"], linestyle=style["linestyle"],
                linewidth=style.get("linewidth", 0.9), label=labels[name],
                zorder=style.get("zorder", 2), alpha=style.get("alpha", 1.0))
        envelope = envelopes.get(name)
        if envelope is None or name in under:
            continue
        envelope = envelope[:, axis]
        ax.fill_between(time_s, -envelope, envelope, color=style["color"], alpha=0.10,
                        linewidth=0, zorder=style.get("zorder", 2) - 0.5)
        for sign, label in ((1, f"{labels[name]} ±3σ"), (-1, None)):
            ax.plot(time_s, sign * envelope, color=style["color"],
                    linestyle=style["linestyle"], linewidth=1.6, alpha=0.9, label=label,
                    zorder=style.get("zorder", 2) + 0.1)


#: An estimator whose typical error exceeds the best one's this many times is
#: drawn faint and beneath the others, so that it does not hide them.
FAINT_ABOVE = 5.0


def layered(styles: dict, scaled: dict) -> dict:
    """``styles`` with the curves stacked by their typical error, the
    smallest on top, and those :data:`FAINT_ABOVE` times the best drawn
    faint and thin (static solutions beside filters, dead reckoning's drift)."""
    typical = {name: float(np.nanmedian(np.linalg.norm(error, axis=1)))
               if np.isfinite(error).any() else math.inf for name, error in scaled.items()}
    best = min(typical.values())
    styles = {name: dict(style) for name, style in styles.items()}
    for rank, name in enumerate(sorted(typical, key=typical.get, reverse=True)):
        styles[name].setdefault("zorder", 2 + rank)
        if typical[name] > FAINT_ABOVE * best:
            styles[name].update(alpha=0.45, linewidth=0.6)
    return styles


def _events(ax, time_s, scaled: dict, axis: int, styles: dict, labels: dict, eclipse,
            rejected: dict) -> None:
    """Eclipses shaded grey; readings rejected by gating marked on each filter's curve."""
    if eclipse is not None and np.any(eclipse):
        edges = np.flatnonzero(np.diff(np.concatenate([[0], eclipse.astype(int), [0]])))
        for first, (start, stop) in enumerate(zip(edges[::2], edges[1::2])):
            ax.axvspan(time_s[start], time_s[min(stop, len(time_s) - 1)], color="0.55",
                       alpha=0.18, linewidth=0, label="Eclipse" if first == 0 else None)
    for name, steps in rejected.items():
        if name in scaled and len(steps):
            ax.plot(time_s[steps], scaled[name][steps, axis], linestyle="none", marker="x",
                    markersize=6, color=styles[name]["color"],
                    label=f"{labels[name]}: reading rejected by gating")


def _bias_panel(ax, time_s, truth, estimates: dict, styles: dict, under: dict,
                labels: dict) -> None:
    """One axis's bias estimates (±3σ) against the truth, the y range holding
    every estimate over the whole run (its initial transient included)."""
    ax.plot(time_s, truth, color="black", linestyle="--", linewidth=1.5, label="True bias")
    values = [truth]
    for name, (estimate, sigma) in estimates.items():
        style = styles[name]
        ax.plot(time_s, estimate, color=style["color"], linestyle=style["linestyle"],
                linewidth=1.2, label=labels[name])
        values.append(estimate)
        if name not in under:
            ax.fill_between(time_s, estimate - 3 * sigma, estimate + 3 * sigma,
                            color=style["color"], alpha=0.12, linewidth=0)
    values = np.hstack(values)
    values = values[np.isfinite(values)]
    if values.size:                  # (a diverged estimate is NaN from its step on)
        low, high = float(values.min()), float(values.max())
        margin = max(0.08 * (high - low), 0.05 * max(abs(low), abs(high)), 1e-6)
        ax.set_ylim(low - margin, high + margin)


def consistency_figure(time_s, anees: dict, bands: dict, sample_errors_deg: dict,
                       sample_sigmas_deg: dict, bound_sigma_deg: np.ndarray, sample_time_s,
                       labels: dict, runs: dict | None = None, envelope_steps: int = 1,
                       level: float = 0.95) -> Figure:
    """ANEES over time against its χ² band per estimator (top left), and the
    per-axis error of a sample run with each filter's ±3σ and the bound's ±3σ
    ("best achievable", dashed) on the other three panels.

    Parameters
    ----------
    time_s : (S,) the ANEES sample times
    anees : {name: (S,) or None}; bands : {name: (low, high)}
    sample_errors_deg : {name: (N, 3)}; sample_sigmas_deg : {name: (N, 3) or None}
    bound_sigma_deg : (N, 3) the bound's 1σ per axis; sample_time_s : (N,)
    runs : {name: runs}: the ANEES axis is scaled to the band of the
        estimator with the most runs; one outside it is marked at the edge
        with its time-averaged value, never hidden
    envelope_steps : the bound's ±3σ is drawn through its peaks over this
        many steps (one reading interval), not as a sawtooth
    """
    with sns.axes_style("whitegrid"):
        figure = Figure(figsize=(14.0, 9.0), layout="constrained")
        axes = figure.subplots(2, 2, squeeze=False).ravel()
    styles = estimator_styles(labels)
    steady = max(3 * float(np.median(bound_sigma_deg[len(bound_sigma_deg) // 2:])), 1e-12)
    scale, unit = angle_unit(steady)
    scaled = {name: error * scale for name, error in sample_errors_deg.items()}
    under = coinciding(scaled, COINCIDE_FRACTION * steady * scale)
    _anees_panel(axes[0], time_s, anees, bands, with_coincidences(styles, under), labels,
                 runs or {}, level)
    envelopes = {name: None if sigma is None else upper_envelope(3 * sigma * scale,
                                                                   envelope_steps)
                 for name, sigma in sample_sigmas_deg.items()}
    bound = upper_envelope(3 * bound_sigma_deg * scale, envelope_steps)
    largest = finite_max([*scaled.values(), bound])
    for axis, ax in enumerate(axes[1:]):
        _error_panel(ax, sample_time_s, scaled, envelopes, axis, styles, under, labels)
        ax.plot(sample_time_s, bound[:, axis], color="black", linestyle="--", linewidth=1.2,
                label="best achievable ±3σ (the bound)")
        ax.plot(sample_time_s, -bound[:, axis], color="black", linestyle="--", linewidth=1.2)
        symlog_axis(ax, steady * scale, largest)
        ax.set_xlim(sample_time_s[0], sample_time_s[-1])
        ax.set_xlabel(X_LABEL)
        ax.set_ylabel(f"{AXIS_NAMES[axis]} error ({unit})")
        ax.set_title(f"One run's {AXIS_NAMES[axis]} error, each filter's ±3σ", fontsize="medium")
    legend_outside(figure, axes, note=coincidence_note(under, labels, _UNIT_SYMBOLS[unit]))
    return figure


def _anees_panel(ax, time_s, anees: dict, bands: dict, styles: dict, labels: dict,
                 runs: dict, level: float) -> None:
    """The ANEES of each estimator over time, its band (in the legend); the
    axis holds the band of the estimator with the most runs, and an
    estimator whose ANEES lies outside is marked at the edge with its value."""
    shown = [name for name, series in anees.items() if series is not None]
    if not shown:
        ax.text(0.5, 0.5, "no estimator reports a covariance", ha="center",
                transform=ax.transAxes)
        return
    main = max(shown, key=lambda name: (runs.get(name, 0), -shown.index(name)))
    low, high = bands[main]
    bottom, top = low / 2.5, high * 2.5
    for name in shown:
        style = styles[name]
        series = np.asarray(anees[name], dtype=float)
        ax.plot(time_s, np.clip(series, bottom, top), color=style["color"],
                linestyle=style["linestyle"], linewidth=style.get("linewidth", 1.0),
                zorder=style.get("zorder", 2), label=f"{labels[name]} ANEES")
        band = bands[name]
        ax.axhspan(*band, color=style["color"], alpha=0.15, linewidth=0,
                   label=f"{labels[name]}: {100 * level:.0f} % band "
                   f"[{band[0]:.2f}, {band[1]:.2f}], {runs.get(name, '?')} runs")
        average = float(np.nanmean(series))
        if not bottom <= average <= top:
            edge = top if average > top else bottom
            ax.annotate(f"{labels[name]}: {average:.3g} {'↑' if average > top else '↓'}",
                        xy=(time_s[-1], edge), xytext=(-6, -12 if average > top else 6),
                        textcoords="offset points", ha="right", color=style["color"],
                        fontsize="small")
    ax.axhline(3.0, color="black", linewidth=0.8, linestyle=":", label="3 (a consistent mean)")
    ax.set_yscale("log")
    ax.set_ylim(bottom, top)
    ax.yaxis.set_major_locator(FixedLocator(round_values(bottom, top, (1, 2, 3, 5))))
    ax.yaxis.set_minor_locator(NullLocator())
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _p: f"{v:g}"))
    ax.set_xlim(time_s[0], time_s[-1])
    ax.set_xlabel(X_LABEL)
    ax.set_ylabel("ANEES (3 degrees of freedom)")
    ax.set_title(f"Average NEES over runs, with each estimator's {100 * level:.0f} % χ² band")


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
