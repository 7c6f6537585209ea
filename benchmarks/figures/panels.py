"""The per-axis panels the flight and consistency figures share.

Each estimator has a row of three panels, one per body axis, holding its
error δθ on that axis over its own ±3σ band (shaded in its colour); the rows
share one y axis, so a glance down a column compares them. The errors are
written in the unit their steady-state size calls for (arcsec or degrees,
:func:`benchmarks.metrics.angle_unit`), and estimators whose errors coincide
are found here once, for the figures to name.
"""
from __future__ import annotations

import textwrap

import numpy as np

from benchmarks.figures.style import COINCIDE_FRACTION, coinciding, upper_envelope
from benchmarks.metrics import angle_unit

#: Body axes as the per-axis figures name them (not roll, pitch and yaw,
#: which would clash with a star tracker's roll about its own boresight).
AXIS_NAMES = ("Body x", "Body y", "Body z")
#: How a legend's note writes each unit after a number.
UNIT_SYMBOLS = {"arcsec": "″", "deg": "°"}
#: Decades labelled on each side of zero in an estimator's row (a short panel).
ROW_DECADES = 2
ERROR_WIDTH = 0.7
#: Shading of a filter's ±3σ band, in its colour.
ENVELOPE_ALPHA = 0.25
ENVELOPE_LABEL = "±3σ: each filter's own, shaded in its colour"


def scale_errors(errors_deg: dict, typical_deg: float):
    """``(scaled, scale, unit, under)``: the errors ``{name: (N, 3)}`` in the
    unit that ``typical_deg`` (a steady-state error, degrees) calls for,
    ``scale`` (that unit per degree), ``unit`` ("arcsec" or "deg"), and
    ``{later: (earlier, largest difference)}`` for the errors that coincide
    within :data:`~benchmarks.figures.style.COINCIDE_FRACTION` of
    ``typical_deg``."""
    scale, unit = angle_unit(typical_deg)
    scaled = {name: error * scale for name, error in errors_deg.items()}
    return scaled, scale, unit, coinciding(scaled, COINCIDE_FRACTION * typical_deg * scale)


def three_sigma_envelopes(sigmas_deg: dict, names, scale: float, window: int) -> dict:
    """``{name: (N, 3) or None}``: each filter's ±3σ (``sigmas_deg`` times
    ``scale``) drawn through its peaks over ``window`` steps, so that a σ
    that drops at each reading is not a sawtooth; None without a σ."""
    return {name: None if sigmas_deg.get(name) is None
            else upper_envelope(3 * sigmas_deg[name] * scale, window)
            for name in names}


def cell_grid(figure, grid, rows, columns, sharex=None) -> np.ndarray:
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


def error_cell(ax, time_s, error, envelope, axis: int, color, gid: str) -> None:
    """One estimator's error on one body axis over its own ±3σ band (shaded,
    without edge lines: a static solution's σ changes at every step, and
    edges drawn through it would fill the panel and hide the error)."""
    if envelope is not None:
        band = envelope[:, axis]
        ax.fill_between(time_s, -band, band, color=color, alpha=ENVELOPE_ALPHA, linewidth=0,
                        zorder=1)
    ax.plot(time_s, error, color=color, linewidth=ERROR_WIDTH, zorder=3, gid=gid)


def row_label(ax, labels: dict, name: str, under: dict, unit: str, color) -> None:
    """The estimator a row belongs to, in its colour, as the row's y label;
    one whose errors coincide with another's says so."""
    lines = [textwrap.fill(labels[name], 16)]
    if name in under:
        lines.append(f"(as {labels[under[name][0]]})")
    ax.set_ylabel("\n".join([*lines, unit]), color=color, fontsize="small")
