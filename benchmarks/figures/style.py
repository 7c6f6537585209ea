"""What every figure shares so that a reader can read it: one style per
estimator (colour and line style, so that curves that coincide stay
distinguishable and are named as coinciding), symmetric-log axes whose tick
labels do not collide at zero, legends outside the data, and envelopes
drawn through their upper values.
"""
from __future__ import annotations

import math

import numpy as np
import seaborn as sns
from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator
from scipy.ndimage import maximum_filter1d

#: Line styles in turn, so that estimators drawn on top of each other differ
#: in more than colour.
LINE_STYLES = ("-", "--", "-.", ":")
#: Two curves whose largest difference is below this fraction of the axis's
#: linear range are drawn as one, the later named as "under" the earlier.
COINCIDE_FRACTION = 1e-3


def estimator_styles(names) -> dict:
    """``{name: {"color", "linestyle"}}``: seaborn's "deep" colours and the
    :data:`LINE_STYLES` in turn."""
    names = list(names)
    colors = sns.color_palette("deep", max(len(names), 1))
    return {name: {"color": colors[i], "linestyle": LINE_STYLES[i % len(LINE_STYLES)]}
            for i, name in enumerate(names)}


def coinciding(curves: dict, tolerance: float) -> dict:
    """``{later: (earlier, largest difference)}`` for curves (arrays of one
    shape) that an earlier one matches within ``tolerance`` everywhere (NaN
    where either is NaN is ignored)."""
    under = {}
    names = list(curves)
    for i, later in enumerate(names):
        for earlier in names[:i]:
            if earlier in under or np.shape(curves[earlier]) != np.shape(curves[later]):
                continue
            gap = np.abs(np.asarray(curves[later], dtype=float) -
                         np.asarray(curves[earlier], dtype=float))
            gap = gap[np.isfinite(gap)]
            difference = float(gap.max()) if gap.size else math.nan
            if np.isfinite(difference) and difference <= tolerance:
                under[later] = (earlier, float(difference))
                break
    return under


#: How a curve drawn over one it coincides with looks: thin, dashed, on top,
#: so that the one beneath (drawn solid) shows between its dashes.
OVER_STYLE = {"linestyle": (0, (3, 3)), "linewidth": 0.9, "zorder": 3}


def with_coincidences(styles: dict, under: dict) -> dict:
    """``styles`` with each curve that another coincides with drawn solid,
    and each coinciding one in :data:`OVER_STYLE`."""
    styles = {name: dict(style) for name, style in styles.items()}
    for later, (earlier, _) in under.items():
        styles[earlier]["linestyle"] = "-"
        styles[later].update(OVER_STYLE)
    return styles


def coincidence_note(under: dict, labels: dict, unit: str) -> str:
    """One line naming the curves drawn under others, and by how much at most
    they differ (rounded up to one significant digit), or that they are the same."""
    return "; ".join(f"{labels[later]} under {labels[earlier]}: " + (
        f"differ by < {_round_up(difference):g}{unit}" if difference > 0 else "the same")
        for later, (earlier, difference) in under.items())


def _round_up(value: float) -> float:
    """``value`` rounded up to one significant digit (a bound stays a bound)."""
    value = max(float(value), 1e-300)
    power = 10.0 ** math.floor(math.log10(value))
    return math.ceil(value / power * (1 - 1e-12)) * power


def symlog_axis(ax, linthresh: float, largest: float, *, most_decades: int = 4) -> None:
    """A symmetric-log y axis, linear within ``±linthresh`` (rounded down to a
    power of ten), with ticks at 0 and at powers of ten out to ``largest``:
    every decade, or every second, third, … so that at most ``most_decades``
    are labelled on each side, and no two labels crowd (in particular none
    beside the 0; a short panel asks for fewer)."""
    threshold = 10.0 ** math.floor(math.log10(max(linthresh, 1e-300)))
    ax.set_yscale("symlog", linthresh=threshold, linscale=1.0)
    top = max(largest, threshold * 10) if math.isfinite(largest) else threshold * 10
    decades = list(range(int(math.log10(threshold)), int(math.ceil(math.log10(top))) + 1))
    stride = max(1, math.ceil(len(decades) / max(most_decades, 1)))
    kept = decades[::stride]
    ticks = [0.0] + [sign * 10.0 ** d for d in kept for sign in (1, -1)]
    ax.yaxis.set_major_locator(FixedLocator(sorted(ticks)))
    ax.yaxis.set_minor_locator(NullLocator())
    ax.yaxis.set_major_formatter(FuncFormatter(_power_label))
    ax.set_ylim(-top * 1.2, top * 1.2)


def log_axis(ax, low: float, high: float, *, most_ticks: int = 7) -> None:
    """A log y axis from ``low`` to ``high`` (both > 0) with round tick values
    (:func:`round_values`) written out plainly: every 1, 2, 5 per decade, or
    finer on a range of less than a decade, or coarser on a wide one, so that
    at most about ``most_ticks`` labels show."""
    ax.set_yscale("log")
    ax.set_ylim(low, high)
    for mantissas in ((1, 1.5, 2, 3, 4, 5, 6, 7, 8, 9), (1, 2, 3, 5), (1, 2, 5), (1, 3), (1,)):
        ticks = round_values(low, high, mantissas)
        if len(ticks) <= most_ticks:
            break
    if len(ticks) > most_ticks:                      # many decades: every second, third, …
        ticks = ticks[::math.ceil(len(ticks) / most_ticks)]
    ax.yaxis.set_major_locator(FixedLocator(ticks))
    ax.yaxis.set_minor_locator(NullLocator())
    ax.yaxis.set_major_formatter(FuncFormatter(_plain_label))


def _plain_label(value: float, _position=None) -> str:
    if value == 0:
        return "0"
    exponent = math.floor(math.log10(abs(value)))
    if -3 <= exponent <= 4:
        return f"{value:g}"
    mantissa = value / 10.0 ** exponent
    return (f"$10^{{{exponent}}}$" if math.isclose(mantissa, 1.0)
            else f"${mantissa:g}\\times10^{{{exponent}}}$")


def finite_max(arrays) -> float:
    """The largest finite absolute value in ``arrays`` (0 if none: a
    diverged run's curve is all NaN)."""
    values = [np.abs(np.asarray(a, dtype=float)) for a in arrays]
    finite = [v[np.isfinite(v)] for v in values]
    return max((float(v.max()) for v in finite if v.size), default=0.0)


def round_values(low: float, high: float, mantissas=(1, 2, 5)) -> list[float]:
    """The round numbers ``m × 10^e`` (``m`` in ``mantissas``) from ``low`` to
    ``high``: tick positions for a log axis that a reader reads at a glance."""
    first, last = math.floor(math.log10(low)), math.ceil(math.log10(high))
    return [m * 10.0 ** e for e in range(first, last + 1) for m in mantissas
            if low <= m * 10.0 ** e <= high]


def _power_label(value: float, _position=None) -> str:
    if value == 0:
        return "0"
    exponent = round(math.log10(abs(value)))
    sign = "−" if value < 0 else ""
    if -2 <= exponent <= 3:
        return f"{sign}{10.0 ** exponent:g}"
    return f"{sign}$10^{{{exponent}}}$"


def legend_outside(figure, axes, columns: int = 4, note: str = "",
                   where: str = "lower center", extra=()) -> None:
    """One legend for ``axes`` (their labelled artists, each label once, then
    the ``(handle, label)`` pairs of ``extra``: entries that stand for many
    artists) outside the panels (below them, or ``where``), off the data;
    ``note`` as its title."""
    handles, labels = [], []
    pairs = [pair for ax in np.ravel(axes) for pair in zip(*ax.get_legend_handles_labels())]
    for handle, label in [*pairs, *extra]:
        if label not in labels and not label.startswith("_"):
            handles.append(handle)
            labels.append(label)
    if handles:
        figure.legend(handles, labels, loc=f"outside {where}", ncols=columns,
                      fontsize="small", title=note or None, title_fontsize="small")


def upper_envelope(values: np.ndarray, window: int) -> np.ndarray:
    """The running maximum of ``values`` ``(N,)`` or ``(N, k)`` over ``window``
    steps centred on each: a covariance that grows between readings and drops
    at each is drawn through its peaks, not as a sawtooth."""
    window = max(int(window), 1)
    return maximum_filter1d(np.asarray(values, dtype=float), size=window, axis=0,
                            mode="nearest")
