"""``attitude-bench broad``: every estimator on the BROAD trials (or any
folder in their layout), scored as the dataset's authors score; or their
case study reproduced (``--case-study``)."""
from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

from benchmarks.commands.options import (PROG, UsageError, add_divergence_option,
                                         add_out_options, estimator_list, name_list, number,
                                         whole)
from benchmarks.divergence import report_of
from benchmarks.output import figure_bytes, write_bytes, write_text
from sensors.delay import delay_argument

OUTPUTS = ("broad_trials.csv", "broad_groups.csv", "broad.png", "broad_trial.png",
           "broad_case_study.csv", "broad_case_study_grid.csv", "broad_tuning.csv",
           "ATTRIBUTION.txt")
memory = None      # the trials' sizes are known once they are read

#: What a BROAD trial gives the estimators besides the gyro.
BROAD_SENSORS = frozenset({"accelerometer", "magnetometer"})
#: Without a magnetometer, the same filter as another in the default list:
#: left out of it there, so that no result is repeated under two labels.
SIX_AXIS_TWINS = {"madgwick-broad": "madgwick", "vqf-6d": "vqf"}


def arguments(commands, defaults) -> None:
    """The ``broad`` command's arguments."""
    broad = commands.add_parser(
        "broad", help="every estimator on the BROAD trials (gyro, accelerometer, magnetometer "
        "against an optical reference), scored as the dataset's authors score; write "
        "broad_trials.csv, broad_groups.csv, broad.png and broad_trial.png")
    broad.add_argument("--broad", "--test", type=Path, metavar="DIR",
                       help="a BROAD folder (trials.json with data_mat/, data_hdf5/ or .npz "
                       "trials), a [recording] .toml file declaring your own log, or a folder "
                       "of them (default: $ATTITUDE_BENCH_BROAD, else the two shipped trials)")
    broad.add_argument("--train", type=Path, metavar="DIR",
                       help="tune every estimator on all the trials of this other folder "
                       "(the same layout) and score the settings on --broad's: will they "
                       "work on another device? (writes broad_tuning.csv)")
    broad.add_argument("--trials", type=name_list, metavar="A,B",
                       help="trials by number or name (default: every trial present)")
    broad.add_argument("--estimators", type=estimator_list, metavar="A,B,...",
                       help="any of the registry's (default: dead reckoning, TRIAD, the MEKF, "
                       "USQUE, Madgwick (both), Mahony, and VQF (9D, 6D) and Fusion when "
                       "installed)")
    broad.add_argument("--gyro-delay", type=number, default=0.0, metavar="SECONDS",
                       help="how late the gyro's samples are against the other channels "
                       "(default 0)")
    broad.add_argument("--magnetometer-delay", type=delay_argument, default=0.0,
                       metavar="SECONDS|auto",
                       help="how late the magnetometer reads against the gyro: each reading is "
                       "taken at its sample's time, turned by the gyro; auto fits it from how "
                       "the field turns (default 0: the recording as it is, with a note where "
                       "it is clearly late)")
    broad.add_argument("--accelerometer-sigma", type=number, default=None, metavar="M/S2",
                       help="the smallest σ per axis the filters take for the accelerometer "
                       "(default 0.3: in motion it reads the linear acceleration too)")
    broad.add_argument("--magnetometer-sigma", type=number, default=None, metavar="UT",
                       help="the same for the magnetometer, µT (default 4)")
    broad.add_argument("--case-study", action="store_true",
                       help="instead: the authors' Madgwick and Mahony at their chosen "
                       "settings beside their published numbers (writes broad_case_study.csv)")
    broad.add_argument("--grid", action="store_true",
                       help="with --case-study: also their grid search (Madgwick's 30 β, "
                       "Mahony's 4,100 Kp × Ki; about a minute per trial, use --workers): the "
                       "one setting for all trials and each trial's best beside theirs "
                       "(writes broad_case_study_grid.csv)")
    broad.add_argument("--tune", choices=("none", "all-trials", "per-trial", "halves"),
                       default="none",
                       help="tune each estimator's settings (the authors' grid for Madgwick's "
                       "β, the tuner otherwise): all-trials, on the other half of the trials "
                       "than those scored (2-fold); per-trial, on each trial itself "
                       "(optimistic); halves, without a reference: the Kalman filters on each "
                       "trial's first half by their innovations' likelihood, every estimator "
                       "scored on the second half; none, the defaults (default); writes "
                       "broad_tuning.csv")
    broad.add_argument("--agreement", action="store_true",
                       help="also score every trial with a reference by the estimators' "
                       "agreement (the agreement_* columns; a trial without one always is)")
    broad.add_argument("--workers", type=whole("workers", 1), default=0, metavar="N",
                       help="run the trials on a local Dask cluster of N processes (default: "
                       "in this process)")
    add_out_options(broad)
    add_divergence_option(broad)


def run(args, _scenario):
    from benchmarks.broad.dataset import broad_folder, open_broad
    from benchmarks.sensor_use import refuse_unreadable
    if not args.case_study:
        refuse_unreadable(args.estimators, BROAD_SENSORS, "a BROAD trial")
    dataset = replace(open_broad(broad_folder(args.broad)),
                      magnetometer_delay=args.magnetometer_delay)
    trials = dataset.selected(args.trials)
    if args.grid and not args.case_study:
        raise UsageError("--grid is the case study's grid search: give --case-study with it")
    present = dataset.sensors(trials)
    if args.case_study:
        if present != BROAD_SENSORS:
            raise UsageError("--case-study runs the authors' Madgwick and Mahony with the "
                             "magnetometer, and these trials have none")
        return _case_study(args, dataset, trials)
    _check_magnetometer_flags(args, present)
    args.estimators = _runnable(args, present)
    from benchmarks.broad import benchmark, inputs, tuning
    from benchmarks.broad.inputs import checked_sigmas
    sigmas = {sensor: value for sensor, value in (("accelerometer", args.accelerometer_sigma),
                                                  ("magnetometer", args.magnetometer_sigma))
              if value is not None}
    checked_sigmas(sigmas)
    mode, train = _training(args, dataset, trials)
    if mode in ("all-trials", "per-trial") and \
            not any(dataset.load(trial).has_reference.any() for trial in trials):
        raise UsageError(f"--tune {mode} scores settings against a reference, and no trial "
                         "here has one: leave it out (the filters are then ranked by their "
                         "agreement), or tune them on a dataset that has one (--train DIR)")
    options, tunings = tuning.tuned_options(dataset, trials, args.estimators, mode,
                                            args.gyro_delay, sigmas, args.workers, args.quiet,
                                            train=train)
    result = benchmark.run_broad(dataset, trials, args.estimators, args.gyro_delay, sigmas,
                                 quiet=args.quiet, workers=args.workers, options=options,
                                 tuning=mode, agreement=args.agreement)
    print(f"{PROG}: note: {inputs.assumed(heading=not result.headless, sigmas=sigmas)}",
          file=sys.stderr)
    against = " against the others' median" if result.by_agreement else ""
    if against:
        print(f"No trial has a reference: every score below is the RMS angle to "
              f"{result.against}, sample by sample. That is agreement, not accuracy: filters "
              "that share a model share its errors.")
    print(benchmark.format_trials(result))
    if len(tunings):
        print("\ntuned (training loss: " + ("the innovations' ln det S + NIS per update over "
              "the trial's first half, no reference read" if mode == "halves" else
              f"mean {result.metric.split('_')[0]} RMSE over the training trials, °") + "):")
        print(tunings.to_string(index=False, float_format=lambda v: f"{v:.6g}"))
    print(f"\n{result.metric.split('_')[0]} RMSE (°){against} per group, mean over its trials "
          f"(trials run), {tuning.MODE_LABELS[mode]}:")
    print(benchmark.format_groups(result, result.metric))
    _write(args, result, tunings, dataset, train)
    return report_of(result.dt, {name: part["diverged_step"].to_numpy() for name, part
                                 in result.trials.groupby("estimator", sort=False)})


def _check_magnetometer_flags(args, present) -> None:
    """The magnetometer's flags refused where the trials (their vector
    sensors ``present``) have none, and its delay with a moved gyro."""
    from benchmarks.broad.dataset import refuse_field_flag
    for flag, value, given in (
            ("--magnetometer-sigma", args.magnetometer_sigma, args.magnetometer_sigma is not None),
            ("--magnetometer-delay", args.magnetometer_delay, args.magnetometer_delay != 0.0)):
        if given:
            refuse_field_flag(flag, value, present)
    if args.gyro_delay and args.magnetometer_delay != 0.0:
        raise UsageError("--magnetometer-delay is the magnetometer's against the gyro as "
                         "recorded, and --gyro-delay moves the gyro: give one of them")


def _runnable(args, present) -> tuple:
    """``--estimators`` on trials whose vector sensors are ``present``:
    where a trial has no magnetometer (a 6-axis IMU), an estimator that
    needs one is refused if named, and left out of the default list with
    a note."""
    from benchmarks.sensor_use import refuse_unreadable, usable_estimators
    if present == BROAD_SENSORS:
        return args.estimators
    where = "each log here (no magnetometer)"
    if not getattr(args, "estimators_by_default", False):
        refuse_unreadable(args.estimators, present, where)
        return args.estimators
    usable = usable_estimators(args.estimators, present)
    twins = [name for name in usable if SIX_AXIS_TWINS.get(name) in usable]
    left_out = [name for name in args.estimators if name not in usable]
    if left_out or twins:
        said = [f"{', '.join(left_out)} (each needs one)"] * bool(left_out) + [
            f"{name} (without one, the same filter as {SIX_AXIS_TWINS[name]})" for name in twins]
        print(f"{PROG}: note: no magnetometer in these trials: left out {'; '.join(said)}; "
              "every other filter is scored on its inclination, its heading being the "
              "gyro's", file=sys.stderr)
    return tuple(name for name in usable if name not in twins)


def _training(args, dataset, trials):
    """``(mode, training dataset)``: ``--tune``'s mode, or ``--train``'s
    other dataset (None but there), checked apart from the scored trials."""
    from benchmarks.broad import tuning
    from benchmarks.broad.dataset import open_broad
    if args.train is None:
        return args.tune, None
    if args.tune != "none":
        raise UsageError(f"--train tunes on another dataset; --tune {args.tune} on this "
                         "one's trials: give one of them")
    if args.gyro_delay:
        raise UsageError("--gyro-delay is the scored device's; the training dataset's "
                         "delay is not known: leave it out with --train")
    if args.magnetometer_delay not in (0.0, "auto"):
        raise UsageError(f"--magnetometer-delay {args.magnetometer_delay:g} is the scored "
                         "device's; the training dataset's is not known: give auto (each "
                         "trial's fitted) or leave it out with --train")
    train = replace(open_broad(args.train, parameter="train"),
                    magnetometer_delay=args.magnetometer_delay)
    tuning.checked_apart(train, dataset, trials)
    if train.sensors(train.available) != dataset.sensors(trials):
        raise UsageError("--train: its trials and the scored ones differ in having a "
                         "magnetometer; settings tuned on the one kind are scored on another "
                         "error than they would be on the other: train on data of the same kind")
    return "other-dataset", train


def _write(args, result, tunings, dataset, train) -> None:
    """The tables, the figures (drawn before the first write) and the
    attribution of the data and of the settings' training data."""
    from benchmarks.broad import figures
    from benchmarks.broad.benchmark import with_scored_against
    drawn = {name: figure_bytes(args.out / name, figure(result)) for name, figure in
             (("broad.png", figures.groups_figure), ("broad_trial.png", figures.trial_figure))}
    write_text(args.out / "broad_trials.csv",
               with_scored_against(result.trials, result).to_csv(index=False))
    write_text(args.out / "broad_groups.csv",
               with_scored_against(result.groups, result).to_csv(index=False))
    for name, data in drawn.items():
        write_bytes(args.out / name, data)
    attribution = dataset.attribution
    if train is not None and train.attribution != attribution:    # the settings derive from it
        attribution += "\nThe settings were tuned on: " + train.attribution
    write_text(args.out / "ATTRIBUTION.txt", attribution + "\n")
    names = ("broad_trials.csv", "broad_groups.csv", "broad.png", "broad_trial.png",
             "ATTRIBUTION.txt")
    if len(tunings):
        write_text(args.out / "broad_tuning.csv", tunings.to_csv(index=False))
        names += ("broad_tuning.csv",)
    print(f"wrote {', '.join(str(args.out / name) for name in names)}\n{attribution}")


def _case_study(args, dataset, trials):
    """``--case-study``: the authors' filters at their settings beside their
    published numbers (and with ``--grid``, their grid search)."""
    from benchmarks.broad import case_study
    for flag, given in (("--gyro-delay", args.gyro_delay),
                        ("--magnetometer-delay", args.magnetometer_delay != 0.0),
                        ("--accelerometer-sigma", args.accelerometer_sigma),
                        ("--magnetometer-sigma", args.magnetometer_sigma),
                        ("--tune", args.tune != "none"),
                        ("--train", args.train is not None),
                        ("--agreement", args.agreement),
                        ("--estimators", not getattr(args, "estimators_by_default", False))):
        if given:
            raise UsageError(f"{flag} does not apply to --case-study: it runs the "
                             "authors' filters on the data as they ran them")
    published = case_study.published_results(dataset.folder)
    frame = case_study.reproduce(dataset, trials, published, quiet=args.quiet)
    print(frame.to_string(index=False, float_format=lambda v: f"{v:.5f}"))
    if args.grid:
        chosen, grid = case_study.grid_study(dataset, trials, published, args.workers,
                                             args.quiet)
        print("\neach trial's best on the authors' grid, theirs and ours:")
        print(grid.to_string(index=False, float_format=lambda v: f"{v:.5f}"))
        for name, setting in chosen.items():
            print(f"{name}: the one setting for these {len(trials)} trials {setting}; "
                  f"the authors' (over their 39) {case_study.CHOSEN[name]}")
    write_text(args.out / "broad_case_study.csv", frame.to_csv(index=False))
    if args.grid:
        write_text(args.out / "broad_case_study_grid.csv", grid.to_csv(index=False))
    write_text(args.out / "ATTRIBUTION.txt", dataset.attribution + "\n")
    print(f"wrote {args.out / 'broad_case_study.csv'}\n{dataset.attribution}")
    return None
