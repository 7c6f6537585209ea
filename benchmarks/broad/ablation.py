"""What each IMU model of the MEKF buys on BROAD: each switched off in turn.

The MEKF on an IMU recording runs the models of :mod:`estimators.imu`
(:data:`benchmarks.broad.inputs.IMU_MODELS`). Here it runs on every trial
with all of them, then with one at a time replaced by the textbook's
reading of that sensor (or, for the hard iron's online fit and the gyro's
error along the rate, left out),
then with none (the textbook MEKF: the
accelerometer and the magnetometer as vector readings behind a 99.99 % χ²
gate and a 10 % test of the field's norm), each scored as ``broad`` scores
(the mean total RMSE over the trials, :mod:`benchmarks.broad.metric`), and
on each trial without its rest (:mod:`benchmarks.broad.without_rest`).

Run ``python -m benchmarks.broad.ablation --broad DIR``; it prints one row
per variant and writes ``ablation.csv`` (one row per trial and variant).
"""
from __future__ import annotations

import sys

import pandas as pd

from benchmarks.broad.inputs import GATE_PROBABILITY, MAGNETIC_NORM_TOLERANCE, imu_inputs
from benchmarks.broad.metric import rmse_deg
from benchmarks.broad.without_rest import cut, script_parser, trial_rows, write_table
from benchmarks.engine.recorded import run_recorded
from estimators import MultiplicativeEKF

#: The textbook's reading of each sensor, and its tests.
GATES = {"gate_probability": GATE_PROBABILITY, "magnetic_norm_tolerance": MAGNETIC_NORM_TOLERANCE}
#: Variant → the MEKF's settings over the recording's.
VARIANTS = {
    "all IMU models": {},
    "gravity as a vector reading": {"gravity_model": "reading", **GATES},
    "the field as a vector reading": {"magnetometer_model": "vector", "hard_iron_fit": False,
                                      **GATES},
    "no hard iron fitted online": {"hard_iron_fit": False},
    "no zero-rate update at rest": {"rest_updates": False},
    "no error of the rate's own": {"gyro_scale_density": 0.0},
    "the textbook MEKF (none)": {"gravity_model": "reading", "magnetometer_model": "vector",
                                 "rest_updates": False, "hard_iron_fit": False,
                                 "gyro_scale_density": 0.0, **GATES},
}


def scores(dataset, trial: str) -> list[dict]:
    """One trial's rows: each variant's total, heading and inclination RMSE
    over the movement, and its total without the trial's rest
    (:func:`benchmarks.broad.without_rest.cut`; the cut is the movement's
    first sample, so both score the same samples)."""
    recording = dataset.load(trial)
    inputs = imu_inputs(recording)
    start, part, vectors = cut(recording)
    after = recording.reference_quat[start:], recording.movement[start:]
    rows = []
    for variant, settings in VARIANTS.items():
        mekf = MultiplicativeEKF.from_scenario(inputs.scenario, **settings)
        run = run_recorded(mekf, inputs.sensors.omega_meas_radps, inputs.sensors.vectors)
        mekf = MultiplicativeEKF.from_scenario(part.scenario, **settings)
        cut_run = run_recorded(mekf, part.sensors.omega_meas_radps, vectors)
        rows.append({"trial": trial, "variant": variant,
                     **rmse_deg(run.estimates, recording.reference_quat, recording.movement),
                     "without_rest_deg": rmse_deg(cut_run.estimates, *after)["total_rmse_deg"]})
    return rows


def main(argv=None) -> int:
    args = script_parser("python -m benchmarks.broad.ablation", __doc__).parse_args(argv)
    found = trial_rows(args, "ablation", scores)
    if found is None:
        return 2
    dataset, rows = found
    table = pd.DataFrame(rows)
    means = table.groupby("variant", sort=False)[["total_rmse_deg", "heading_rmse_deg",
                                                  "inclination_rmse_deg",
                                                  "without_rest_deg"]].mean()
    print(f"MEKF on {len(dataset.available)} trials, mean RMSE over the movement (degrees):")
    print(means.to_string(float_format=lambda x: f"{x:.3f}"))
    write_table(args.out, "ablation.csv", table, dataset.attribution)
    return 0


if __name__ == "__main__":
    sys.exit(main())
