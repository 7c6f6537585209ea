"""``attitude-bench replay``: a recorded gyro against an optical reference
attitude (a BROAD trial or the user's .npz), with a pseudo star tracker;
replay.png and summary.csv."""
from __future__ import annotations

import sys
from pathlib import Path

from benchmarks.commands.options import (PROG, UsageError, add_divergence_option,
                                         add_import_option, add_out_options, estimators_option,
                                         number, whole)
from benchmarks.commands.scenario_args import allowed_imports
from benchmarks.commands.tuned import fair_comparison, no_tuning_options
from benchmarks.divergence import report_of

OUTPUTS = ("replay.png", "summary.csv", "ATTRIBUTION.txt")
memory = None      # checked by the run, once the recording is read


def _delay(text: str):
    return "auto" if text == "auto" else number(text)


def arguments(commands, defaults) -> None:
    """The ``replay`` command's arguments."""
    replay = commands.add_parser(
        "replay", help="a recorded gyro against an optical reference attitude (the BROAD "
        "dataset or your .npz); write replay.png and summary.csv")
    replay.add_argument("--dataset", default="broad-02", metavar="NAME_OR_PATH",
                        help="broad-02 (slow rotation, default), broad-07 (fast rotation), or "
                        "a .npz recording with the same keys, or a [recording] .toml declaring "
                        "your log")
    estimators_option(replay, "dead reckoning, the EKF and the MEKF")
    replay.add_argument("--star-tracker-interval", type=number, default=1.0, metavar="SECONDS",
                        help="seconds between pseudo star tracker readings, rounded to whole "
                        "samples (default 1)")
    replay.add_argument("--star-tracker-noise-deg", type=number, default=0.1, metavar="DEG",
                        help="σ of the pseudo star tracker's error per axis, degrees "
                        "(default 0.1)")
    replay.add_argument("--seed", type=whole("seed", 0), default=0,
                        help="seed of the pseudo star tracker's noise (default 0)")
    replay.add_argument("--gyro-delay", type=_delay, default=0.0, metavar="SECONDS|auto",
                        help="how late the gyro's samples are against the reference "
                        "(default 0); auto: the delay under which the MEKF's innovations are "
                        "likeliest (no reference used)")
    replay.add_argument("--scenario", metavar="FILE", type=Path,
                        help="a TOML file of [estimators.NAME] sections overriding the "
                        "settings derived from the recording")
    replay.add_argument("--tuned", metavar="OBJ",
                        help="first tune every estimator with tunable settings on the "
                        "--train-dataset recordings for objective OBJ (see tune), then replay "
                        "--dataset with them all tuned; writes tuned.toml and tuned.json")
    replay.add_argument("--train-dataset", action="append", metavar="NAME_OR_PATH",
                        dest="train_datasets", help="a training recording of --tuned, never "
                        "--dataset itself (repeatable; the same pseudo star tracker and gyro "
                        "delay)")
    add_import_option(replay)
    add_out_options(replay)
    add_divergence_option(replay)


def run(args, _scenario):
    from benchmarks.experiments.replay import load_replay, run_replay, write_replay
    from benchmarks.resources import check_memory, per_run_bytes
    from benchmarks.experiments.gyro_delay import DELAY_SEARCH_SAMPLES, likeliest_gyro_delay
    from benchmarks.experiments.replay import REPLAY_SENSORS
    from benchmarks.sensor_use import refuse_unreadable
    from benchmarks.broad.trial_notes import note_clipping
    # The estimators, the recording, the settings and the memory are checked before any write.
    refuse_unreadable(args.estimators, REPLAY_SENSORS, "the replay")
    delay = args.gyro_delay
    if delay == "auto":
        delay, log, at_bound = likeliest_gyro_delay(
            args.dataset, "mekf", args.star_tracker_interval, args.star_tracker_noise_deg,
            args.seed, args.scenario, allowed_imports(args), args.quiet)
        print(f"gyro delay {delay * 1000:.3f} ms: the MEKF's innovations likeliest "
              f"({log.evaluations} evaluations, no reference used)")
        if at_bound:
            low, high = DELAY_SEARCH_SAMPLES
            print(f"{PROG}: warning: the delay found is at an end of the search ({low:g} to "
                  f"{high:g} samples): the likeliest may lie beyond; give --gyro-delay "
                  "SECONDS", file=sys.stderr)
    data = load_replay(args.dataset, args.star_tracker_interval, args.star_tracker_noise_deg,
                       args.seed, settings=args.scenario, allow_imports=allowed_imports(args),
                       gyro_delay_s=delay)
    # replay reads the gyro alone: its clipping is said, as broad says it
    note_clipping(data.recording, Path(str(args.dataset)), channels=("gyro",))
    if args.tuned:
        data = _tuned_replay(args, data, delay)
    else:
        no_tuning_options(args)
    check_memory(data.scenario, per_run_bytes(data.recording.n_samples, len(args.estimators),
                                              traced=True))
    result = run_replay(data, args.estimators, args.seed, quiet=args.quiet)
    summary = write_replay(result, args.out)
    interval = result.run.scenario.time_between_measurements
    print(f"{result.recording.name}: {result.recording.n_samples:,} samples at "
          f"{result.recording.rate_hz:g} Hz from its first reference attitude; pseudo star "
          f"tracker every {interval:.4g} s, σ {args.star_tracker_noise_deg:g}° per axis")
    print(summary.to_string(index=False, float_format=lambda v: f"{v:.4f}"))
    written = ["replay.png", "summary.csv"] + (["ATTRIBUTION.txt"] if result.attribution else [])
    print(f"wrote {', '.join(str(args.out / name) for name in written)}")
    if result.attribution:
        print(result.attribution)
    return report_of(result.run.scenario.dt, result.run.diverged_step)


def _tuned_replay(args, data, delay: float):
    """``replay --tuned``: every estimator tuned on the training recordings
    (their pseudo star trackers and gyro delay as the replay's) and scored on
    the replayed one; ``data`` with the tuned settings."""
    import dataclasses
    from benchmarks.experiments import estimator_tuning as tuning
    from benchmarks.experiments.objectives import recording_case
    from benchmarks.experiments.replay import dataset_source
    if not args.train_datasets:
        raise UsageError("--tuned needs at least one --train-dataset NAME_OR_PATH (a "
                         "recording other than --dataset to tune on)")
    replay = {"interval_s": args.star_tracker_interval,
              "noise_deg": args.star_tracker_noise_deg, "seed": args.seed,
              "gyro_delay_s": delay}
    training = tuning.cases_of(None, datasets=args.train_datasets, settings=args.scenario,
                               allow_imports=allowed_imports(args), replay=replay)
    test = [recording_case(data, args.dataset, dataset_source(args.dataset))]
    tuning.disjoint(training, test)
    fair = fair_comparison(args, training, test, ", ".join(args.train_datasets), args.dataset)
    return dataclasses.replace(data, scenario=fair.scenario(data.scenario))
