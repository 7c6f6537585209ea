"""Figures in the workshop's style.

Figures are built with :class:`matplotlib.figure.Figure` directly (no
pyplot), so plotting never touches a global backend or opens a window.
"""
from __future__ import annotations

import textwrap

import numpy as np
import seaborn as sns
from matplotlib.animation import PillowWriter
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
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


def comparison_figure(time_s: np.ndarray, curves: dict, ekf_labels=("EKF",)) -> Figure:
    """The workshop's comparison figure of error curves ``{label: degrees}``."""
    figure, (ax,) = new_figure()
    plot_errors(ax, time_s, curves, ekf_labels=ekf_labels)
    return figure


def freeze_layout(figure: Figure) -> None:
    """Lay the figure out once and keep that layout.

    Animations redraw the same figure for every frame; re-running the
    constrained layout each time costs about as much as drawing it.
    """
    figure.draw_without_rendering()   # runs the layout engine with the artists in place
    figure.set_layout_engine("none")


#: Statistics shown in the Monte Carlo distribution figure: (column, title).
DISTRIBUTION_PANELS = (("mean_deg", "Mean error"), ("std_deg", "Error std (the loss)"),
                       ("max_deg", "Maximum error"))


def distribution_figure(frame, labels: dict | None = None) -> Figure:
    """Per-estimator distributions over runs of a tidy per-run frame (one
    violin per estimator and statistic, seaborn)."""
    import pandas as pd   # seaborn's own dependency; imported where it is used

    data = frame.copy()
    labels = labels or {}
    data["estimator"] = data["estimator"].map(
        lambda name: textwrap.fill(labels.get(name, name), 20))
    figure, axes = new_figure(ncols=len(DISTRIBUTION_PANELS), width=4.5, height=4.5)
    for ax, (column, title) in zip(axes, DISTRIBUTION_PANELS):
        sns.violinplot(data=data, x="estimator", y=column, hue="estimator", ax=ax,
                       cut=0, inner="quartile", legend=False)
        ax.set_title(title)
        ax.set_xlabel("")
        ax.set_ylabel("Degrees")
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


#: Body axes as the per-axis figure names them.
AXIS_NAMES = ("Roll (x)", "Pitch (y)", "Yaw (z)")
_ARCSEC_PER_DEG = 3600.0
#: Below this steady-state size per-axis errors are shown in arcsec, above in degrees.
ARCSEC_BELOW_DEG = 0.1


def flight_figure(time_s, error_vectors_deg: dict, sigmas_deg: dict, bias_true_deg_per_hr,
                  bias_estimates: dict, labels: dict) -> Figure:
    """Per-axis attitude error with ±3σ envelopes (left), bias estimates against
    the true bias (right).

    Parameters
    ----------
    time_s : (N,) seconds
    error_vectors_deg : {name: (N, 3)} body-frame error δθ per axis, degrees
    sigmas_deg : {name: (N, 3) or None} each filter's own 1σ per axis, degrees
    bias_true_deg_per_hr : (N, 3) the gyro's true bias, deg/h
    bias_estimates : {name: ((N, 3) estimate, (N, 3) 1σ)} in deg/h, for
        estimators that estimate a bias
    labels : {name: legend label}

    The error axes are symmetric-log: linear within the best filter's
    steady-state 3σ, logarithmic beyond, so a converged filter, a drifting
    dead reckoning and a start tens of degrees off are all readable. The unit
    (arcsec or degrees) follows the size of the steady-state errors.
    """
    with sns.axes_style("whitegrid"):
        figure = Figure(figsize=(14.0, 9.0), layout="constrained")
        axes = figure.subplots(3, 2, sharex=True, squeeze=False)
    colors = dict(zip(error_vectors_deg, sns.color_palette("deep", len(error_vectors_deg))))
    second_half = slice(len(time_s) // 2, None)
    steady = [3 * np.median(sigma[second_half]) for sigma in sigmas_deg.values()
              if sigma is not None]
    if not steady:
        steady = [np.median(np.abs(e[second_half])) for e in error_vectors_deg.values()]
    typical_deg = max(min(steady), 1e-12)
    in_arcsec = typical_deg < ARCSEC_BELOW_DEG
    scale, unit = (_ARCSEC_PER_DEG, "arcsec") if in_arcsec else (1.0, "deg")
    for axis in range(3):
        ax = axes[axis, 0]
        for name, error in error_vectors_deg.items():
            color = colors[name]
            ax.plot(time_s, error[:, axis] * scale, color=color, linewidth=0.8,
                    label=labels[name])
            sigma = sigmas_deg.get(name)
            if sigma is not None:
                envelope = 3 * sigma[:, axis] * scale
                ax.fill_between(time_s, -envelope, envelope, color=color, alpha=0.15,
                                linewidth=0, label=f"{labels[name]} ±3σ")
        ax.set_yscale("symlog", linthresh=typical_deg * scale)
        ax.set_ylabel(f"{AXIS_NAMES[axis]} error ({unit})")
        ax.set_xlim(time_s[0], time_s[-1])
        ax = axes[axis, 1]
        ax.plot(time_s, bias_true_deg_per_hr[:, axis], color="black", linestyle="--",
                linewidth=1.5, label="True bias")
        for name, (estimate, sigma) in bias_estimates.items():
            ax.plot(time_s, estimate[:, axis], color=colors[name], linewidth=1.2,
                    label=labels[name])
            ax.fill_between(time_s, estimate[:, axis] - 3 * sigma[:, axis],
                            estimate[:, axis] + 3 * sigma[:, axis], color=colors[name],
                            alpha=0.15, linewidth=0, label=f"{labels[name]} ±3σ")
        truth = bias_true_deg_per_hr[:, axis]
        span = max(np.ptp(truth), np.abs(truth).max(), 1e-6)
        ax.set_ylim(truth.min() - 1.5 * span, truth.max() + 1.5 * span)
        ax.set_ylabel(f"{AXIS_NAMES[axis]} gyro bias (deg/h)")
    axes[0, 0].set_title("Attitude error per body axis (symmetric log scale)")
    axes[0, 1].set_title("Gyro bias: estimate against the truth")
    axes[2, 0].set_xlabel(X_LABEL)
    axes[2, 1].set_xlabel(X_LABEL)
    axes[0, 0].legend(loc="upper right", fontsize="small", ncols=2)
    axes[0, 1].legend(loc="upper right", fontsize="small")
    return figure


def consistency_figure(time_s, anees: dict, bands: dict, sample_errors_deg: dict,
                       sample_sigmas_deg: dict, bound_sigma_deg: np.ndarray, sample_time_s,
                       labels: dict) -> Figure:
    """ANEES over time against its χ² band per estimator (top left), and the
    per-axis error of a sample run with each filter's ±3σ and the bound's ±3σ
    ("best achievable", dashed) on the other three panels.

    Parameters
    ----------
    time_s : (S,) the ANEES sample times
    anees : {name: (S,) or None}; bands : {name: (low, high)}
    sample_errors_deg : {name: (N, 3)}; sample_sigmas_deg : {name: (N, 3) or None}
    bound_sigma_deg : (N, 3) the bound's 1σ per axis; sample_time_s : (N,)
    """
    with sns.axes_style("whitegrid"):
        figure = Figure(figsize=(14.0, 8.5), layout="constrained")
        axes = figure.subplots(2, 2, squeeze=False).ravel()
    colors = dict(zip(labels, sns.color_palette("deep", len(labels))))
    ax = axes[0]
    for name, series in anees.items():
        if series is None:
            continue
        ax.plot(time_s, series, color=colors[name], linewidth=1.0, label=labels[name])
        low, high = bands[name]
        ax.axhspan(low, high, color=colors[name], alpha=0.12, linewidth=0)
    ax.axhline(3.0, color="black", linewidth=0.8, linestyle=":", label="3 (consistent mean)")
    ax.set_yscale("log")
    ax.set_xlim(time_s[0], time_s[-1])
    ax.set_xlabel(X_LABEL)
    ax.set_ylabel("ANEES (3 degrees of freedom)")
    ax.set_title("Average NEES over runs, with its 95 % χ² band")
    ax.legend(loc="upper right", fontsize="small")
    steady = max(3 * float(np.median(bound_sigma_deg[len(bound_sigma_deg) // 2:])), 1e-12)
    scale, unit = ((_ARCSEC_PER_DEG, "arcsec") if steady < ARCSEC_BELOW_DEG else (1.0, "deg"))
    for axis, ax in enumerate(axes[1:]):
        for name, error in sample_errors_deg.items():
            ax.plot(sample_time_s, error[:, axis] * scale, color=colors[name], linewidth=0.7,
                    label=labels[name])
            sigma = sample_sigmas_deg.get(name)
            if sigma is not None:
                ax.fill_between(sample_time_s, -3 * sigma[:, axis] * scale,
                                3 * sigma[:, axis] * scale, color=colors[name], alpha=0.12,
                                linewidth=0)
        envelope = 3 * bound_sigma_deg[:, axis] * scale
        ax.plot(sample_time_s, envelope, color="black", linestyle="--", linewidth=1.0,
                label="best achievable ±3σ")
        ax.plot(sample_time_s, -envelope, color="black", linestyle="--", linewidth=1.0)
        ax.set_yscale("symlog", linthresh=steady * scale)
        ax.set_xlim(sample_time_s[0], sample_time_s[-1])
        ax.set_xlabel(X_LABEL)
        ax.set_ylabel(f"{AXIS_NAMES[axis]} error ({unit})")
    axes[1].set_title("One run's per-axis error, each filter's ±3σ (shaded)")
    axes[1].legend(loc="upper right", fontsize="small", ncols=2)
    return figure


def replay_figure(result) -> Figure:
    """A replayed recording (:class:`benchmarks.experiments.replay.Replay`):
    each estimator's error against the reference over the trial, log scale,
    the movement phase shaded and the reference's gaps left blank (left); the
    bias estimates against the gyro's mean over the initial rest (right)."""
    run, time_s = result.run, result.time_s
    names = list(run.error_deg)
    colors = dict(zip(names, sns.color_palette("deep", len(names))))
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
    floor = 1e-3   # degrees: the log axis's bottom (an error of 0 at the start)
    for name in names:
        style = {"color": "black", "linewidth": 1.2, "zorder": 3} if name == "ekf" \
            else {"color": colors[name], "linewidth": 1.0}
        error_ax.plot(time_s, np.maximum(run.error_deg[name], floor), label=run.labels[name],
                      alpha=0.85, **style)
    error_ax.set_yscale("log")
    error_ax.set_ylim(bottom=floor)
    error_ax.set_xlim(time_s[0], time_s[-1])
    error_ax.set_title(f"Attitude error against the optical reference: {result.recording.name}")
    error_ax.set_xlabel(X_LABEL)
    error_ax.set_ylabel("Error (degrees, log scale)")
    error_ax.legend(loc="upper left", fontsize="small")
    rest = np.degrees(result.rest_bias_radps)
    for axis, ax in enumerate(bias_axes):
        ax.axhline(rest[axis], color="black", linestyle="--", linewidth=1.5,
                   label="Gyro mean over the initial rest")
        for name in with_bias:
            trace = run.traces[name]
            estimate = np.degrees(trace.bias_radps[:, axis])
            sigma = np.degrees(np.sqrt(trace.bias_covariance[:, axis, axis]))
            ax.plot(time_s, estimate, color=colors[name], linewidth=1.2, label=run.labels[name])
            ax.fill_between(time_s, estimate - 3 * sigma, estimate + 3 * sigma,
                            color=colors[name], alpha=0.15, linewidth=0)
        # Show the rest mean and where the estimates spend 98 % of the time.
        values = [rest[axis]] + [np.degrees(run.traces[n].bias_radps[:, axis]) for n in with_bias]
        low, high = np.percentile(np.hstack(values), [1, 99])
        low, high = min(low, rest[axis]), max(high, rest[axis])
        margin = max(0.2 * (high - low), 0.05)
        ax.set_ylim(low - margin, high + margin)
        ax.set_ylabel(f"{AXIS_NAMES[axis]} bias (deg/s)")
    bias_axes[0].set_title("Gyro bias estimates (±3σ) against the rest-phase mean")
    bias_axes[0].legend(loc="upper right", fontsize="small")
    bias_axes[-1].set_xlabel(X_LABEL)
    if result.attribution:
        figure.supxlabel(textwrap.fill(result.attribution, 200), fontsize="x-small",
                         color="0.3")
    return figure
