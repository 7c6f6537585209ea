"""The BROAD trials without their rest: does an estimator need one?

Each trial is run twice with the same settings: whole, and with everything
before its first movement sample cut off and the magnetometer kept at a
quarter of the gyro's rate (a phone's magnetometer beside its gyro). Both
are scored on the same samples, the movement after the cut (the authors'
total RMSE, :mod:`benchmarks.broad.metric`). Nothing in the inputs comes from
a rest (:mod:`benchmarks.broad.inputs`), so what changes is what the
estimators themselves learn in the rest: the gyro's bias, the field, the
start.

Run ``python -m benchmarks.broad.without_rest --broad DIR`` (the full
dataset; the two shipped trials without ``--broad``); it prints each
estimator's mean over the trials, whole and cut, and their ratio, and
writes ``without_rest.csv`` (one row per trial and estimator) to ``--out``.
``--simulated N`` runs it on N simulated hand-held recordings instead
(:mod:`sensors.handheld`): a uniform field and a true reference, where
what an estimator loses without its rest is its own, not the room's;
``--motion FIELD=VALUE`` and ``--imu FIELD=VALUE`` (each as often as
needed) set any field of their :class:`~dynamics.handheld.HandheldMotion`
and :class:`~sensors.handheld.HandheldImu`, e.g. a brisker hand
(``--motion rate_rms_dps=250``) or a gyro without scale errors
(``--imu gyro_scale_percent=0``).
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import fields, replace
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.broad.dataset import open_broad, refuse_field_flag, trial_label
from benchmarks.broad.trial_notes import applied_delay
from benchmarks.broad.inputs import imu_inputs
from benchmarks.broad.metric import rmse_deg
from benchmarks.engine.recorded import run_recorded
from benchmarks.output import progress, write_text
from benchmarks.shipped import shipped_file
from dynamics.validation import InvalidParameterError
from estimators import resolve_estimator
from sensors.delay import delay_argument

#: The estimators compared by default: ours, online and offline, and VQF's.
DEFAULT_ESTIMATORS = ("mekf", "mekf-smoother", "vqf", "vqf-offline")
#: The magnetometer keeps every MAGNETOMETER_EVERY-th reading in the cut trials.
MAGNETOMETER_EVERY = 4
#: What the table of simulated recordings says of its data.
SIMULATED_ATTRIBUTION = ("Simulated hand-held recordings (dynamics/handheld.py, "
                         "sensors/handheld.py): no recorded data.")


def cut(recording):
    """``recording`` from its first movement sample on, with the magnetometer
    at a quarter rate: its inputs (:func:`benchmarks.broad.inputs.imu_inputs`)."""
    start = int(np.argmax(recording.movement))
    inputs = imu_inputs(recording.from_sample(start))
    vectors = tuple(replace(v, available=v.available & (np.arange(len(v.available))
                                                        % MAGNETOMETER_EVERY == 0))
                    if v.sensor == "magnetometer" else v for v in inputs.sensors.vectors)
    return start, inputs, vectors


def scores(dataset, trial: str, names) -> list[dict]:
    """One trial's rows: each estimator's total RMSE whole and cut."""
    return recording_scores(dataset.load(trial), trial, names)


def recording_scores(recording, trial: str, names) -> list[dict]:
    """``recording``'s rows, named ``trial``: each estimator's total RMSE
    whole and cut."""
    whole = imu_inputs(recording)
    start, part, vectors = cut(recording)
    rows = []
    for name in names:
        cls = resolve_estimator(name)
        full = run_recorded(cls.from_scenario(whole.scenario), whole.sensors.omega_meas_radps,
                            whole.sensors.vectors).estimates[start:]
        # An estimator that takes its magnetometer's interval as a setting (VQF's
        # magTs) is told it; the MEKF reads it off each reading's interval.
        told = ({"magnetometer_interval_s": MAGNETOMETER_EVERY * recording.dt}
                if "magnetometer_interval_s" in cls.option_names() else {})
        cut_run = run_recorded(cls.from_scenario(part.scenario, **told),
                               part.sensors.omega_meas_radps, vectors).estimates
        reference, movement = recording.reference_quat[start:], recording.movement[start:]
        rows.append({"trial": trial, "estimator": name, "cut_at_sample": start,
                     "whole_deg": rmse_deg(full, reference, movement)["total_rmse_deg"],
                     "without_rest_deg": rmse_deg(cut_run, reference,
                                                  movement)["total_rmse_deg"]})
    return rows


def script_parser(prog: str, doc: str) -> argparse.ArgumentParser:
    """The arguments the BROAD benchmark scripts share: ``--broad``,
    ``--out`` and ``--quiet``."""
    parser = argparse.ArgumentParser(prog=prog, description=doc.split("\n\n")[0])
    parser.add_argument("--broad", type=Path, help="the BROAD folder (default: the two "
                        "shipped trials)")
    parser.add_argument("--out", type=Path, default=Path("results"))
    parser.add_argument("--quiet", action="store_true")
    parser.add_argument("--magnetometer-delay", type=delay_argument, default=0.0,
                        metavar="SECONDS|auto", help="as broad's (default 0)")
    return parser


def trial_rows(args, name: str, scores, check=lambda: None):
    """The dataset of ``args.broad`` and the rows of ``scores(dataset, trial)``
    over its trials, ``check()`` first; None where the input is refused (one
    line on stderr, ``NAME: error: …``)."""
    folder = args.broad or shipped_file("datasets/broad/trials.json").parent
    try:
        dataset = replace(open_broad(folder), magnetometer_delay=args.magnetometer_delay)
        if args.magnetometer_delay != 0.0:
            refuse_field_flag("--magnetometer-delay", args.magnetometer_delay,
                              dataset.sensors(dataset.available))
        check()
        rows = [row for trial in progress(dataset.available, desc="trials", quiet=args.quiet)
                for row in scores(dataset, trial)]
    except InvalidParameterError as err:
        print(f"{name}: error: {err}", file=sys.stderr)
        return None
    if args.magnetometer_delay == "auto":
        print(f"{name}: note: {delays_fitted(dataset)}", file=sys.stderr)
    return dataset, rows


def delays_fitted(dataset) -> str:
    """What ``--magnetometer-delay auto`` fitted over ``dataset``'s trials,
    in one line (:func:`benchmarks.broad.trial_notes.applied_delay`)."""
    fits = {trial: applied_delay(dataset.files[trial], trial) for trial in dataset.available}
    clear = {trial: fit.delay_s * 1e3 for trial, fit in fits.items() if fit is not None}
    kept = [trial_label(trial) for trial in fits if trial not in clear]
    said = (f"the magnetometer's delay against the gyro, fitted on {len(clear)} of {len(fits)} "
            f"trials: {min(clear.values()):.1f} to {max(clear.values()):.1f} ms (positive: "
            "late; each trial's readings taken at their times)" if clear else
            "no trial's magnetometer is clearly late or early against its gyro")
    return said + (f"; kept as recorded: {', '.join(kept)}" if kept and clear else "")


def write_table(out: Path, name: str, table: pd.DataFrame, attribution: str) -> None:
    """``table`` as ``out/name`` and the data's ``attribution`` beside it."""
    out.mkdir(parents=True, exist_ok=True)
    write_text(out / name, table.to_csv(index=False))
    write_text(out / "ATTRIBUTION.txt", attribution + "\n")
    print(f"wrote {out / name}, {out / 'ATTRIBUTION.txt'}\n{attribution}")


def simulated_rows(args, names):
    """The rows of ``args.simulated`` simulated hand-held recordings (seeds
    0, 1, …: :func:`sensors.handheld.simulated_recording`, with the fields
    ``args.motion`` and ``args.imu`` set), a uniform field and a true
    reference: what an estimator loses there is its own."""
    from dynamics.handheld import HandheldMotion
    from sensors.handheld import HandheldImu, simulated_recording
    if args.simulated is None:
        for flag, given in (("--motion", args.motion), ("--imu", args.imu)):
            if given:
                raise InvalidParameterError(flag, given[0], "applies to --simulated only")
        return None
    if args.broad is not None:
        raise InvalidParameterError("--simulated", args.simulated, "cannot be given with --broad")
    if args.simulated < 1:
        raise InvalidParameterError("--simulated", args.simulated, "must be a whole number >= 1")
    if args.magnetometer_delay != 0.0:
        raise InvalidParameterError("--magnetometer-delay", args.magnetometer_delay,
                                    "applies to recorded trials; the simulated magnetometer "
                                    "reads on time")
    motion = HandheldMotion(**field_values("--motion", args.motion, HandheldMotion))
    imu = HandheldImu(**field_values("--imu", args.imu, HandheldImu))
    for name in names:
        resolve_estimator(name)
    return [row for seed in progress(range(args.simulated), desc="recordings", quiet=args.quiet)
            for row in recording_scores(simulated_recording(seed, motion, imu),
                                        f"handheld-{seed}", names)]


def field_values(flag: str, pairs, cls) -> dict:
    """``FIELD=VALUE`` strings (``pairs``, from ``flag``) as the keywords of
    dataclass ``cls``: each field one of its own, each value a number (the
    class then checks its range)."""
    known = [field.name for field in fields(cls)]
    values = {}
    for pair in pairs or ():
        name, _, text = pair.partition("=")
        name = name.strip()
        try:
            value = float(text)
        except ValueError:
            value = None
        if name not in known or value is None:
            raise InvalidParameterError(flag, pair, "must be FIELD=NUMBER with FIELD one of "
                                        + ", ".join(known))
        values[name] = value
    return values


def main(argv=None) -> int:
    parser = script_parser("python -m benchmarks.broad.without_rest", __doc__)
    parser.add_argument("--estimators", default=",".join(DEFAULT_ESTIMATORS))
    parser.add_argument("--simulated", type=int, metavar="N",
                        help="N simulated hand-held recordings in a uniform field instead "
                             "of BROAD's trials")
    parser.add_argument("--motion", action="append", metavar="FIELD=VALUE",
                        help="with --simulated: a field of the hand's motion "
                             "(dynamics.handheld.HandheldMotion), e.g. rate_rms_dps=250")
    parser.add_argument("--imu", action="append", metavar="FIELD=VALUE",
                        help="with --simulated: a field of the IMU's errors "
                             "(sensors.handheld.HandheldImu), e.g. gyro_scale_percent=0")
    args = parser.parse_args(argv)
    names = [name.strip() for name in args.estimators.split(",") if name.strip()]
    try:
        rows = simulated_rows(args, names)
    except InvalidParameterError as err:
        print(f"without_rest: error: {err}", file=sys.stderr)
        return 2
    if rows is not None:
        changed = (args.motion or []) + (args.imu or [])
        what = f"{args.simulated} simulated hand-held recordings" + (
            f" ({', '.join(changed)})" if changed else "")
        attribution = SIMULATED_ATTRIBUTION
    else:
        found = trial_rows(args, "without_rest",
                           lambda dataset, trial: scores(dataset, trial, names),
                           check=lambda: [resolve_estimator(name) for name in names])
        if found is None:
            return 2
        dataset, rows = found
        what, attribution = f"{len(dataset.available)} trials", dataset.attribution
    table = pd.DataFrame(rows)
    summary = table.groupby("estimator", sort=False)[["whole_deg", "without_rest_deg"]].mean()
    summary["ratio"] = summary["without_rest_deg"] / summary["whole_deg"]
    print(f"{what}, total RMSE over the movement after the cut "
          f"(degrees), magnetometer at 1/{MAGNETOMETER_EVERY} rate in the cut trials:")
    print(summary.to_string(float_format=lambda x: f"{x:.3f}"))
    write_table(args.out, "without_rest.csv", table, attribution)
    return 0


if __name__ == "__main__":
    sys.exit(main())
