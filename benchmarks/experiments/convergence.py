"""Convergence from a large initial error: the magnetometer-only study of
Crassidis & Markley (2003, §V), over seeds and initial errors.

Their finding: from a large initial attitude error, USQUE converges where
the EKF (their multiplicative EKF with a bias state, this toolkit's MEKF)
takes much longer. ``scenarios/magnetometer_only.toml`` holds the case as we
read it; this study starts each filter from the scenario's initial estimate
and from others at stated angles from the truth, over several seeds, and
reports when each converged.

**Convergence criterion**: a run has converged at the first time after
which its error stays below :data:`CONVERGED_DEG` to the end of the run;
a run whose last error is above it has not converged.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from benchmarks.figures.style import legend_outside
from benchmarks.simulation import simulate
from dynamics.quaternion import attitude_error_rad

#: The error a converged run stays below, degrees.
CONVERGED_DEG = 1.0
#: The axis the study's extra initial errors turn about (the truth's body frame).
ERROR_AXIS = np.array([1.0, 1.0, 1.0]) / math.sqrt(3.0)


def convergence_time_s(time_s: np.ndarray, error_deg: np.ndarray,
                       threshold_deg: float = CONVERGED_DEG) -> float:
    """The first time after which ``error_deg`` stays below ``threshold_deg``
    (NaN if its last value is not below it)."""
    above = np.flatnonzero(~(error_deg < threshold_deg))
    if len(above) == 0:
        return float(time_s[0])
    if above[-1] == len(error_deg) - 1:
        return math.nan
    return float(time_s[above[-1] + 1])


def starts(scenario, angles_deg) -> dict:
    """Initial estimates: the scenario's own, and one at each angle from the
    truth about :data:`ERROR_AXIS` — label → quaternion."""
    truth = Rotation.from_quat(scenario.initial_attitude_quat, scalar_first=True)
    chosen = {}
    own = math.degrees(float(attitude_error_rad(scenario.initial_attitude_quat,
                                                scenario.initial_state)))
    chosen[f"{own:.0f}° (the scenario's)"] = scenario.initial_state
    for angle in angles_deg:
        turned = truth * Rotation.from_rotvec(math.radians(angle) * ERROR_AXIS)
        chosen[f"{angle:g}°"] = turned.as_quat(scalar_first=True)
    return chosen


def convergence_study(scenario, estimators=("mekf", "usque"), seeds=range(5),
                      angles_deg=(90.0, 150.0), quiet: bool = True) -> tuple[pd.DataFrame, dict]:
    """Each estimator from each start over ``seeds``: a table of convergence
    times (minutes, NaN where not converged) and the first seed's error
    curves, ``{(start, name): (N,) degrees}`` (a progress bar on a terminal
    unless ``quiet``)."""
    from benchmarks.output import progress
    rows, curves, cases = [], {}, starts(scenario, angles_deg)
    total = len(cases) * len(seeds) * len(estimators) * scenario.n_steps
    with progress(total=total, desc="convergence", unit="step", quiet=quiet) as bar:
        for label, start in cases.items():
            _study_start(scenario.replace(initial_state=start), label, estimators, seeds, rows,
                         curves, bar)
    return pd.DataFrame(rows), curves


def _study_start(case, label: str, estimators, seeds, rows: list, curves: dict, bar) -> None:
    """:func:`convergence_study`'s rows and curves of one start."""
    for seed in seeds:
        result = simulate(case, list(estimators), seed=int(seed), progress_bar=bar)
        for name in estimators:
            error = result.error_deg[name]
            rows.append({"start": label, "estimator": name, "seed": int(seed),
                         "converged_min": convergence_time_s(result.time_s, error) / 60.0,
                         "final_deg": float(error[-1]),
                         "diverged_step": result.diverged_step[name]})
            if seed == seeds[0]:
                curves[(label, name)] = error


def summary(table: pd.DataFrame) -> pd.DataFrame:
    """Per start and estimator: runs converged, and the median convergence time."""
    grouped = table.groupby(["start", "estimator"], sort=False)
    return pd.DataFrame({
        "converged": grouped["converged_min"].apply(lambda v: f"{v.notna().sum()}/{len(v)}"),
        "median_min": grouped["converged_min"].median(),
        "median_final_deg": grouped["final_deg"].median()}).reset_index()


def figure(time_s: np.ndarray, curves: dict, labels: dict):
    """The first seed's error from each start, one panel per start (log scale)."""
    import seaborn as sns
    from matplotlib.figure import Figure
    starts_ = list(dict.fromkeys(start for start, _ in curves))
    with sns.axes_style("whitegrid"):
        fig = Figure(figsize=(10.0, 3.0 * len(starts_)), layout="constrained")
        axes = fig.subplots(len(starts_), 1, sharex=True, squeeze=False)[:, 0]
    colours = dict(zip(dict.fromkeys(name for _, name in curves),
                       sns.color_palette("deep")))
    for ax, start in zip(axes, starts_):
        for (label, name), error in curves.items():
            if label == start:
                ax.semilogy(time_s / 3600.0, np.maximum(error, 1e-4), color=colours[name],
                            linewidth=1.2, label=labels[name])
        ax.axhline(CONVERGED_DEG, color="0.3", linestyle=":", linewidth=1.0,
                   label=f"converged: below {CONVERGED_DEG:g}° to the end")
        ax.set_ylabel("Attitude error (deg)")
        ax.set_title(f"Initial error {start}")
        ax.set_ylim(1e-3, 200.0)
    axes[-1].set_xlabel("Time (hours)")
    legend_outside(fig, axes, columns=3)
    return fig
