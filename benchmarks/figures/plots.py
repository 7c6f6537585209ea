"""Figures in the workshop's style, and what the other figures build on.

The workshop's comparison of error curves, the Monte Carlo distributions,
a new figure in the project's look, and the GIF writer of the animations.
The flight, consistency and replay figures have modules of their own
(:mod:`benchmarks.figures.flight`, :mod:`benchmarks.figures.consistency`,
:mod:`benchmarks.figures.replay`), their shared per-axis panels are in
:mod:`benchmarks.figures.panels`.

Figures are built with :class:`matplotlib.figure.Figure` directly (no
pyplot), so plotting never touches a global backend or opens a window.
"""
from __future__ import annotations

import textwrap
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import seaborn as sns

from benchmarks.figures.style import round_values
from benchmarks.metrics import angle_unit
from matplotlib.animation import PillowWriter
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
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
