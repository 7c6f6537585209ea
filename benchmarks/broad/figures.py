"""The BROAD benchmark's figures (:mod:`benchmarks.broad.benchmark`): the
groups' RMSE per estimator as bars, and one trial's errors over time.
"""
from __future__ import annotations

import math

import numpy as np

from benchmarks.broad.benchmark import BroadResult, group_header, group_notes, shown_labels
from benchmarks.broad.metric import METRICS
from sensors.recording import true_runs

#: The trial figure's curves: the total error's RMS over windows this long, s.
CURVE_WINDOW_S = 1.0
#: The width of a group's bars in the group figure (seaborn's default).
BAR_WIDTH = 0.8


def _against(result: BroadResult) -> str:
    """A figure title's second line where the scores are not against the
    reference."""
    return f"\nno reference: against {result.against} (agreement, not accuracy)" \
        if result.by_agreement else ""


def groups_figure(result: BroadResult):
    """The groups' total, heading and inclination RMSE per estimator (bars),
    on a log axis: the errors span two decades (VQF's 0.4° to TRIAD's 87°
    on the 30 trials), and on a linear axis the two baselines set the scale
    and squash the filters near zero; on a log axis every bar is readable
    and equal ratios look equal, with no clipping rule chosen by hand. Each
    group is labelled with how many trials its mean holds."""
    import seaborn as sns
    from matplotlib.figure import Figure
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator
    from benchmarks.figures.style import estimator_styles, legend_outside, round_values
    groups = result.groups.copy()
    groups["label"] = [group_header(g, int(n), int(k)).replace(" (", "\n(") for g, n, k in
                       zip(groups["group"], groups["trials"], groups["scored_trials"])]
    names = list(dict.fromkeys(groups["estimator"]))
    styles, shown = estimator_styles(names), shown_labels(result)
    palette = {shown[name]: styles[name]["color"] for name in names}
    metrics = (result.metric,) if result.headless else METRICS
    tidy = groups.melt(id_vars=["label", "estimator"], value_vars=list(metrics),
                       var_name="metric", value_name="rmse_deg")
    tidy["estimator"] = tidy["estimator"].map(shown)
    values = tidy["rmse_deg"].to_numpy(dtype=float)
    positive = values[np.isfinite(values) & (values > 0)]
    # The axis from the round value (1, 2 or 5 × 10ⁿ) just below the smallest bar.
    low = max(round_values(0.08 * positive.min(), 0.8 * positive.min())) if positive.size \
        else 0.1
    high = 1.3 * positive.max() if positive.size else 10.0
    n_groups = groups["label"].nunique()
    with sns.axes_style("whitegrid"):
        figure = Figure(figsize=(max(11.0, 0.9 * n_groups + 3.0), 2.0 + 8.0 * len(metrics) / 3),
                        layout="constrained")
        axes = figure.subplots(len(metrics), 1, sharex=True, squeeze=False)[:, 0]
    labels = list(dict.fromkeys(tidy["label"]))
    hues = [shown[name] for name in names]
    for ax, metric in zip(axes, metrics):
        part = tidy[tidy["metric"] == metric]
        sns.barplot(data=part, x="label", y="rmse_deg", hue="estimator", order=labels,
                    hue_order=hues, palette=palette, ax=ax, errorbar=None, width=BAR_WIDTH,
                    legend=ax is axes[0])
        _mark_nan(ax, part, labels, hues, low)
        ax.set_yscale("log")
        ax.set_ylim(low, high)
        ax.yaxis.set_major_locator(FixedLocator(round_values(low, high)))
        ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        ax.yaxis.set_minor_locator(NullLocator())
        ax.set_xlabel("")
        ax.set_ylabel(f"{metric.split('_')[0]} RMSE (°, log)")
        if ax.get_legend() is not None:
            ax.get_legend().remove()
    for label in axes[-1].get_xticklabels():
        label.set_rotation(30)
        label.set_horizontalalignment("right")
    figure.suptitle(f"{result.dataset_title}: error during the movement per group, the mean "
                    "over the trials counted under its name" + _against(result))
    legend_outside(figure, axes[:1], columns=min(len(names), 5),
                   note="; ".join(group_notes(result)))
    return figure


def _mark_nan(ax, part, labels: list, hues: list, low: float) -> None:
    """A missing bar is a NaN mean (:func:`benchmarks.broad.benchmark.group_means`):
    say so where it would stand."""
    for row in part[part["rmse_deg"].isna()].itertuples():
        x = labels.index(row.label) - BAR_WIDTH / 2 + \
            (hues.index(row.estimator) + 0.5) * BAR_WIDTH / len(hues)
        ax.text(x, low * 1.15, "NaN", rotation=90, ha="center", va="bottom",
                fontsize="x-small", color="0.35")


def curve_windows(time_s: np.ndarray, error_deg: np.ndarray, window_s: float):
    """``(centres, rms)``: the RMS of ``error_deg`` over consecutive windows
    of ``window_s`` (its samples without a value left out; a window with
    none, NaN)."""
    dt = float(time_s[1] - time_s[0])
    size = max(int(round(window_s / dt)), 1)
    count = len(error_deg) // size
    if count == 0:
        return time_s[:1], np.array([math.sqrt(np.nanmean(error_deg ** 2))])
    squares = np.asarray(error_deg[:count * size], dtype=float).reshape(count, size) ** 2
    present = np.isfinite(squares).sum(axis=1)
    total = np.where(np.isfinite(squares), squares, 0.0).sum(axis=1)
    rms = np.sqrt(np.divide(total, present, out=np.full(count, np.nan), where=present > 0))
    return time_s[:count * size].reshape(count, size).mean(axis=1), rms


def trial_figure(result: BroadResult):
    """The first scored trial's total error over time, every estimator: its
    RMS over each :data:`CURVE_WINDOW_S` (the metric's statistic, over the
    samples with a reference), log scale, the movement phases (where the
    metric scores) shaded, the legend below the axes; curves that coincide
    on the log axis (within a thousandth of its decades) drawn dashed over
    each other and named with their largest difference."""
    import seaborn as sns
    from matplotlib.figure import Figure
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator
    from benchmarks.figures.style import (COINCIDE_FRACTION, coincidence_note, coinciding,
                                          estimator_styles, finite_max, legend_outside,
                                          round_values, with_coincidences)
    windows = {name: curve_windows(times, error, CURVE_WINDOW_S)
               for name, (times, error) in result.curves.items()}
    curves = {name: rms for name, (_, rms) in windows.items()}
    bottoms = [np.percentile(rms[np.isfinite(rms) & (rms > 0)], 1) for rms in curves.values()
               if np.any(np.isfinite(rms) & (rms > 0))]
    low = 0.5 * min(bottoms) if bottoms else 1e-2
    high = 2.0 * (finite_max(curves.values()) or 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        logs = {name: np.log10(rms) for name, rms in curves.items()}
    under = {later: (earlier, float(np.nanmax(np.abs(curves[later] - curves[earlier]))))
             for later, (earlier, _) in coinciding(
                 logs, COINCIDE_FRACTION * math.log10(high / low)).items()}
    styles = with_coincidences(estimator_styles(curves), under)
    with sns.axes_style("whitegrid"):
        figure = Figure(figsize=(12.0, 6.0), layout="constrained")
        axis = figure.subplots()
    time_s = next(iter(result.curves.values()))[0]
    if result.curve_movement is not None:
        for i, (start, stop) in enumerate(true_runs(result.curve_movement)):
            axis.axvspan(time_s[start], time_s[stop - 1], color="0.85", alpha=0.6, linewidth=0,
                         label=None if i else "movement (scored where the reference is)")
    shown, part = shown_labels(result), result.metric.split("_")[0]
    for name, (centres, rms) in windows.items():
        axis.plot(centres, rms, label=shown[name], **{"linewidth": 1.3, **styles[name]})
    axis.set_yscale("log")
    axis.set_ylim(low, high)
    ticks = round_values(low, high)
    axis.yaxis.set_major_locator(FixedLocator(ticks if len(ticks) <= 12 else
                                              round_values(low, high, (1,))))
    axis.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axis.yaxis.set_minor_locator(NullLocator())
    axis.set_xlim(time_s[0], time_s[-1])
    axis.set_xlabel("time (s)")
    axis.set_ylabel(f"{part} error (°, RMS per window, log)")
    axis.set_title(f"{result.dataset_title} {result.curve_trial}: {part} error, RMS over "
                   f"{CURVE_WINDOW_S:g} s "
                   "windows" + ("" if result.by_agreement else " (the reference's gaps "
                                "blank)") + _against(result))
    legend_outside(figure, [axis], columns=6, note=coincidence_note(under, shown, "°"))
    return figure
