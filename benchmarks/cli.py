"""The ``attitude-bench`` command line.

Every value is validated before anything is written; bad input gets one line
on stderr naming the parameter, the value and the rule, and exit status 2.
"""
from __future__ import annotations

import argparse
import re
import sys
import warnings
from pathlib import Path
from typing import Callable, NamedTuple

from benchmarks import experiments
from benchmarks.experiments import SWEEP_PARAMETERS
from benchmarks.metrics import STAT_COLUMNS
from benchmarks.output import (check_output_folder, figure_bytes, write_bytes,
                               write_text)
from benchmarks.scenario import SETTINGS, Scenario
from benchmarks.seeds import DEFAULT_TRAINING_SEEDS, format_seeds, parse_seeds
from benchmarks.divergence import EXIT_DIVERGED, DivergenceReport, report_of
from benchmarks.experiments.replay import DEFAULT_ESTIMATORS as REPLAY_ESTIMATORS
from benchmarks.simulation import WORKSHOP_ESTIMATORS
from dynamics.validation import MAX_SEED, InvalidParameterError
from estimators import ESTIMATORS

PROG = "attitude-bench"
EXIT_USAGE = 2

#: Scenario field → command-line flag, for the settings declared with one
#: (benchmarks.scenario.SETTINGS), in the order --help lists them.
SCENARIO_FLAGS = {setting.field: setting.flag for setting in SETTINGS if setting.flag}

class UsageError(Exception):
    """Bad command-line input; the message is the whole one-line explanation."""


class _Parser(argparse.ArgumentParser):
    """argparse, but its errors are one line and go through :class:`UsageError`,
    and ``-1e-5``, ``-inf`` or ``-8.7,-10.9`` is a value, not an option
    (Python 3.11's argparse only knows ``-1`` and ``-0.5``)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        number = r"((\d+\.?\d*|\.\d+)([eE][-+]?\d+)?|inf(inity)?|nan)"
        # Also a comma-separated list that starts negative: --values -8.7,-10.9
        self._negative_number_matcher = re.compile(
            rf"^-{number}(,\s*[-+]?{number})*$", re.IGNORECASE)

    def error(self, message):
        raise UsageError(message)


def _whole(name: str, minimum: int, maximum: int = MAX_SEED):
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or not minimum <= value <= maximum:
            raise argparse.ArgumentTypeError(
                f"{name} = {text!r}: must be a whole number from {minimum} to {maximum}")
        return value
    return parse


def _folder(text: str) -> Path:
    if not text.strip():
        raise argparse.ArgumentTypeError(f"out = {text!r}: must name a folder (. for this one)")
    return Path(text)


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None


def _number_list(text: str) -> list[float]:
    try:
        values = [float(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"values = {text!r}: must be numbers separated by commas, e.g. 1e-5,1e-4") from None
    if not values:
        raise argparse.ArgumentTypeError(f"values = {text!r}: must name at least one value")
    return values


def importable_from_here() -> None:
    """Let a user's ``myfilters:MyFilter`` in the current folder import, as
    under ``python -m``: the folder goes on the module path, last, so that it
    never hides an installed module. (Dask's local workers start with this
    process's path, so they find it too.)"""
    here = str(Path.cwd())
    if here not in sys.path and "" not in sys.path:
        sys.path.append(here)


def _module_name(text: str) -> str:
    """A Python module's dotted name, as ``import`` takes it."""
    if not all(part.isidentifier() for part in text.split(".")):
        raise argparse.ArgumentTypeError(f"allow_import = {text!r}: must be a module name "
                                         "such as myfilters or package.module")
    return text


def _estimator_list(text: str) -> tuple[str, ...]:
    given = [part.strip() for part in text.split(",") if part.strip()]
    names = tuple(dict.fromkeys(given))
    if len(names) != len(given):
        twice = next(name for name in names if given.count(name) > 1)
        raise argparse.ArgumentTypeError(
            f"estimators = {text!r}: names {twice} more than once; name each estimator once")
    if not names:
        raise argparse.ArgumentTypeError(f"estimators = {text!r}: must name at least one "
                                         "estimator")
    from benchmarks.simulation import resolve_estimator
    for name in names:
        try:
            resolve_estimator(name)
        except InvalidParameterError as err:
            raise argparse.ArgumentTypeError(f"estimators = {text!r}: {name}: {err.rule} "
                                             "(names separated by commas)") from None
    return names


def _seed_list(text: str) -> tuple[int, ...]:
    try:
        return parse_seeds(text)
    except InvalidParameterError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def _delay(text: str):
    return "auto" if text == "auto" else _number(text)


def _name_list(text: str) -> list[str]:
    names = [name.strip() for name in text.split(",") if name.strip()]
    if not names:
        raise argparse.ArgumentTypeError(f"{text!r}: must be names, comma-separated")
    return names


def _parameter_range(text: str) -> tuple[str, tuple[float, float]]:
    """``NAME=LO:HI`` as ``(name, (lo, hi))``."""
    name, _, bounds = text.partition("=")
    low, _, high = bounds.partition(":")
    try:
        return name.strip(), (float(low), float(high))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: must be NAME=LO:HI, e.g. "
                                         "gyro_noise=1e-8:1e-4") from None


def _add_scenario_options(parser: argparse.ArgumentParser, defaults: Scenario) -> None:
    group = parser.add_argument_group("scenario (defaults: the workshop's, or --scenario FILE)")
    group.add_argument("--scenario", metavar="FILE", type=Path, action="append",
                       help="TOML file of scenario settings (see scenarios/default.toml); "
                       "repeat to lay files over each other, later keys overriding earlier")
    _add_import_option(group)
    for setting in SETTINGS:
        if setting.flag:
            unit = f", {setting.unit}" if setting.unit else ""
            reader = f"; {setting.model} star tracker only" if setting.model else ""
            group.add_argument(setting.flag, type=_number, metavar="X", dest=setting.field,
                               help=f"{setting.doc}{unit} (default "
                               f"{getattr(defaults, setting.field):g}{reader})")


def help_defaults(argv) -> Scenario:
    """The scenario whose values ``--help`` shows as defaults: that of the
    ``--scenario`` files in ``argv`` where they load, else the workshop's."""
    if not argv or not any(item in ("-h", "--help") for item in argv):
        return Scenario()
    peek = argparse.ArgumentParser(add_help=False)
    peek.add_argument("--scenario", type=Path, action="append")
    peek.add_argument("--allow-import", action="append", default=[])
    peek.add_argument("--estimators", type=lambda text: text.split(","))
    peek.add_argument("--estimator")
    known = peek.parse_known_args(argv)[0]
    if not known.scenario:
        return Scenario()
    try:
        return Scenario.from_toml(known.scenario, allow_imports=allowed_imports(known))
    except InvalidParameterError:
        return Scenario()         # the run itself will say what is wrong


def _add_import_option(parser) -> None:
    parser.add_argument("--allow-import", action="append", default=[], metavar="MODULE",
                        type=_module_name,
                        help="let the scenario file's [estimators.\"MODULE:Class\"] sections "
                        "import MODULE (its code runs); naming MODULE:Class in --estimators "
                        "allows it too. Repeatable")


def _add_common(parser: argparse.ArgumentParser, seed: bool = True) -> None:
    if seed:
        parser.add_argument("--seed", type=_whole("seed", 0), default=0,
                            help="sensor noise seed (default 0)")
    parser.add_argument("--out", type=_folder, default=Path("results"), metavar="DIR",
                        help="output folder (default results/)")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    _add_divergence_option(parser)
    _add_scenario_options(parser, _HELP_DEFAULTS[0])


def _add_divergence_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--allow-divergence", action="store_true",
                        help="exit 0 even if an estimator diverged in some run (its statistics "
                        f"are NaN either way; without this flag the exit status is "
                        f"{EXIT_DIVERGED})")


def _estimator_name(text: str) -> str:
    """One estimator: a registry name or a user's ``package.module:ClassName``."""
    from benchmarks.simulation import resolve_estimator
    try:
        resolve_estimator(text)
    except InvalidParameterError as err:
        raise argparse.ArgumentTypeError(f"estimator = {text!r}: {err.rule}") from None
    return text


def _estimator_option(parser, required=True):
    parser.add_argument("--estimator", required=required, type=_estimator_name,
                        metavar="NAME", help=f"one of {', '.join(ESTIMATORS)}, or "
                        "package.module:ClassName for your own estimator")


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("attitude-bench")
    except PackageNotFoundError:       # run from a source tree that is not installed
        return "(not installed)"


def _parse_run(commands) -> None:
    """The ``run`` command's arguments."""
    run = commands.add_parser("run", help="run one estimator; write NAME.csv and NAME.png")
    _estimator_option(run)
    _add_common(run)


def _parse_compare(commands) -> None:
    """The ``compare`` command's arguments."""
    compare = commands.add_parser("compare", help="estimators on the same data; "
                                  "write compare.png and summary.csv")
    compare.add_argument("--estimators", type=_estimator_list, default=None,
                         metavar="A,B,...",
                         help=f"any of {', '.join(ESTIMATORS)} or package.module:ClassName "
                         "(default: the workshop's three; with vector sensors, "
                         f"{','.join(VECTOR_DEFAULTS)})")
    _tuned_options(compare, "--seed, the compared one")
    _add_common(compare)


def _tuned_options(parser, default_test: str) -> None:
    """``--tuned OBJ`` and its training and test seeds."""
    group = parser.add_argument_group("fair comparison (every estimator tuned first)")
    group.add_argument("--tuned", metavar="OBJ",
                       help="first tune every estimator with tunable settings on "
                       "--train-seeds for objective OBJ (see tune), then run them all "
                       "tuned; scores default and tuned on both sets, writes tuned.toml "
                       "and tuned.json")
    group.add_argument("--train-seeds", type=_seed_list, metavar="SPEC",
                       help="the training seeds of --tuned (default "
                       f"{format_seeds(DEFAULT_TRAINING_SEEDS)}); none may be a seed run")
    group.add_argument("--test-seeds", type=_seed_list, metavar="SPEC",
                       help=f"the test seeds of --tuned (default: {default_test}); "
                       "none may be a training seed")


def _parse_broad(commands) -> None:
    """The ``broad`` command's arguments."""
    broad = commands.add_parser(
        "broad", help="every estimator on the BROAD trials (gyro, accelerometer, magnetometer "
        "against an optical reference), scored as the dataset's authors score; write "
        "broad_trials.csv, broad_groups.csv, broad.png and broad_trial.png")
    broad.add_argument("--broad", "--test", type=Path, metavar="DIR",
                       help="a BROAD folder (trials.json with data_mat/, data_hdf5/ or .npz "
                       "trials; default: $ATTITUDE_BENCH_BROAD, else the two shipped trials)")
    broad.add_argument("--train", type=Path, metavar="DIR",
                       help="tune every estimator on all the trials of this other folder "
                       "(the same layout) and score the settings on --broad's: will they "
                       "work on another device? (writes broad_tuning.csv)")
    broad.add_argument("--trials", type=_name_list, metavar="A,B",
                       help="trials by number or name (default: every trial present)")
    broad.add_argument("--estimators", type=_estimator_list, metavar="A,B,...",
                       help="any of the registry's (default: dead reckoning, TRIAD, the MEKF, "
                       "USQUE, Madgwick (both), Mahony, and VQF (9D, 6D) and Fusion when "
                       "installed)")
    broad.add_argument("--gyro-delay", type=_number, default=0.0, metavar="SECONDS",
                       help="how late the gyro's samples are against the other channels "
                       "(default 0)")
    broad.add_argument("--accelerometer-sigma", type=_number, default=None, metavar="M/S2",
                       help="the smallest σ per axis the filters take for the accelerometer "
                       "(default 0.3: in motion it reads the linear acceleration too)")
    broad.add_argument("--magnetometer-sigma", type=_number, default=None, metavar="UT",
                       help="the same for the magnetometer, µT (default 4)")
    broad.add_argument("--case-study", action="store_true",
                       help="instead: the authors' Madgwick and Mahony at their chosen "
                       "settings beside their published numbers (writes broad_case_study.csv)")
    broad.add_argument("--grid", action="store_true",
                       help="with --case-study: also their grid search (Madgwick's 30 β, "
                       "Mahony's 4,100 Kp × Ki; about a minute per trial, use --workers): the "
                       "one setting for all trials and each trial's best beside theirs "
                       "(writes broad_case_study_grid.csv)")
    broad.add_argument("--tune", choices=("none", "all-trials", "per-trial"), default="none",
                       help="tune each estimator's settings (the authors' grid for Madgwick's "
                       "β, the tuner otherwise): all-trials, on the other half of the trials "
                       "than those scored (2-fold); per-trial, on each trial itself "
                       "(optimistic); none, the defaults (default); writes broad_tuning.csv")
    broad.add_argument("--workers", type=_whole("workers", 1), default=0, metavar="N",
                       help="run the trials on a local Dask cluster of N processes (default: "
                       "in this process)")
    broad.add_argument("--out", type=_folder, default=Path("results"), metavar="DIR",
                       help="output folder (default results/)")
    broad.add_argument("--quiet", action="store_true", help="no progress bars")
    _add_divergence_option(broad)


def _parse_show_config(commands) -> None:
    """The ``show-config`` command's arguments."""
    show = commands.add_parser("show-config", help="every estimator's effective settings on "
                               "the scenario, and where each came from (writes nothing)")
    show.add_argument("--estimators", type=_estimator_list, default=tuple(ESTIMATORS),
                      metavar="A,B,...", help="any of the registry's or "
                      "package.module:ClassName (default: every registry estimator)")
    show.add_argument("--out", type=_folder, default=None, metavar="DIR",
                      help="also write the table as DIR/config.csv (default: print only)")
    show.add_argument("--quiet", action="store_true", help="accepted, as by every command "
                      "(show-config shows no progress)")
    _add_divergence_option(show)
    _add_scenario_options(show, _HELP_DEFAULTS[0])


def command_show_config(args, scenario):
    from benchmarks.experiments.configuration import (effective_settings, format_settings,
                                                      given_fields)
    given = given_fields(args.scenario, [name for name in SCENARIO_FLAGS
                                         if getattr(args, name, None) is not None])
    rows = [row for name in args.estimators for row in effective_settings(scenario, name, given)]
    print(format_settings(rows))
    print("\n(file: the scenario's [estimators.NAME] section; scenario: a scenario setting "
          "given; derived: from the scenario's sensors; default: left at its default)")
    if args.out is not None:
        import pandas as pd
        write_text(args.out / "config.csv", pd.DataFrame(rows).to_csv(index=False))
        print(f"wrote {args.out / 'config.csv'}")
    return None


def _parse_sweep(commands) -> None:
    """The ``sweep`` command's arguments."""
    sweep = commands.add_parser("sweep", help="one estimator, one setting varied; "
                                "write sweep.png and sweep.csv")
    _estimator_option(sweep)
    sweep.add_argument("--param", required=True, choices=tuple(SWEEP_PARAMETERS),
                       metavar="P", help=f"one of {', '.join(SWEEP_PARAMETERS)}")
    sweep.add_argument("--values", required=True, type=_number_list, metavar="V1,V2,...",
                       help="values of P, comma-separated")
    _add_common(sweep)


def _parse_tune(commands) -> None:
    """The ``tune`` command's arguments."""
    tune = commands.add_parser("tune", help="fminbnd-style tuning of pc_exponent; "
                               "write tune.json and tune.png")
    tune.add_argument("--bounds", nargs=2, type=_number, metavar=("LO", "HI"),
                      help="pc_exponent's search interval (default -16 0; with --estimator, "
                      "--range NAME=LO:HI)")
    tune.add_argument("--xtol", type=_number, default=0.01, metavar="X",
                      help="x tolerance (default 0.01)")
    tune.add_argument("--seeds", type=_seed_list, default=None, metavar="SPEC",
                      help="training seeds: 0, 0-19 or 1,5,9 (default 0; not with --dataset)")
    group = tune.add_argument_group(
        "any estimator (without --estimator: the EKF's pc_exponent, as the workshop tunes it)")
    _estimator_option(group, required=False)
    group.add_argument("--parameters", type=_name_list, metavar="A,B",
                       help="its tunable settings to tune (default: those with a default; "
                       "see the README's tuning section)")
    group.add_argument("--objective", default="std", metavar="OBJ",
                       help="rms, mean, std, max (with the truth), anees (consistency), nis or "
                       "likelihood (no truth needed); default std")
    group.add_argument("--range", type=_parameter_range, action="append", default=[],
                       metavar="NAME=LO:HI", dest="ranges",
                       help="search range of one setting, in its units (repeatable)")
    group.add_argument("--dataset", action="append", metavar="NAME_OR_PATH", dest="datasets",
                       help="train on this recording (repeatable; broad-02, broad-07 or an "
                       ".npz) instead of simulated seeds")
    group.add_argument("--test-seeds", type=_seed_list, metavar="SPEC",
                       help="score the default and the tuned settings on these seeds too")
    group.add_argument("--test-dataset", action="append", metavar="NAME_OR_PATH",
                       dest="test_datasets", help="score them on this recording too (repeatable)")
    _add_common(tune, seed=False)


def _parse_landscape(commands) -> None:
    """The ``landscape`` command's arguments."""
    landscape = commands.add_parser("landscape", help="EKF statistics across pc_exponent; "
                                    "write landscape.csv, .png and .gif")
    landscape.add_argument("--pc-min", type=_number, default=-18.0, metavar="X",
                           help="first pc_exponent (default -18)")
    landscape.add_argument("--pc-max", type=_number, default=0.0, metavar="X",
                           help="last pc_exponent (default 0)")
    landscape.add_argument("--pc-step", type=_number, default=0.25, metavar="X",
                           help="grid step (default 0.25)")
    landscape.add_argument("--seeds", type=_seed_list, default=(0,), metavar="SPEC",
                           help="seeds: 0, 0-19 or 1,5,9 (default 0)")
    landscape.add_argument("--no-animation", action="store_true", help="skip landscape.gif")
    _add_common(landscape, seed=False)


def _parse_animate(commands) -> None:
    """The ``animate`` command's arguments."""
    animate = commands.add_parser("animate", help="3-D attitude animation; write "
                                  "attitude_NAME.gif and .png (truth alone without --estimator)")
    _estimator_option(animate, required=False)
    animate.add_argument("--every", type=_whole("every", 1), default=50, metavar="K",
                         help="one frame every K steps (default 50)")
    _add_common(animate)


def _parse_montecarlo(commands) -> None:
    """The ``montecarlo`` command's arguments."""
    montecarlo = commands.add_parser("montecarlo", help="many runs on the batched engine; "
                                     "write montecarlo.csv and montecarlo.png")
    montecarlo.add_argument("--estimators", type=_estimator_list, default=None,
                            metavar="A,B,...",
                            help=f"any of {', '.join(ESTIMATORS)} (default: the workshop's "
                            f"three; with vector sensors, {','.join(VECTOR_DEFAULTS)})")
    montecarlo.add_argument("--runs", type=_whole("runs", 1), default=100, metavar="N",
                            help="number of runs; run i uses seed S + i (default 100)")
    montecarlo.add_argument("--seed", type=_whole("seed", 0), default=0, metavar="S",
                            help="base seed (default 0)")
    montecarlo.add_argument("--chunk-size", type=_whole("chunk-size", 1), default=1024,
                            metavar="N", help="runs per chunk file (default 1024)")
    where = montecarlo.add_mutually_exclusive_group()
    where.add_argument("--workers", type=_whole("workers", 1), metavar="N",
                       help="run chunks on a local Dask cluster of N processes")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="run chunks on an existing Dask cluster")
    montecarlo.add_argument("--resume", action="store_true",
                            help="finish an interrupted campaign in --out")
    _tuned_options(montecarlo, f"the campaign's first {TUNED_TEST_RUNS} seeds")
    _add_common(montecarlo, seed=False)


def _parse_consistency(commands) -> None:
    """The ``consistency`` command's arguments."""
    consistency = commands.add_parser(
        "consistency", help="do the filters know their error? NEES against chi-square bands, "
        "efficiency against the best achievable; write consistency.csv and consistency.png")
    consistency.add_argument("--estimators", type=_estimator_list, default=None,
                             metavar="A,B,...",
                             help=f"any of {', '.join(ESTIMATORS)} (default: those the "
                             "scenario's sensors feed: the star tracker's "
                             f"{','.join(STAR_TRACKER_DEFAULTS)}, or with vector sensors "
                             f"{','.join(VECTOR_DEFAULTS)})")
    consistency.add_argument("--runs", type=_whole("runs", 1), default=100, metavar="N",
                             help="runs (seeds S … S+N-1) of each estimator (default 100)")
    consistency.add_argument("--seed", type=_whole("seed", 0), default=0, metavar="S",
                             help="base seed (default 0)")
    consistency.add_argument("--settle", type=_number, metavar="SECONDS",
                             help="time left out of the averages (default a tenth of tstop)")
    consistency.add_argument("--per-run-limit", type=_whole("per-run-limit", 1),
                             default=20, metavar="N",
                             help="at most N runs for estimators without an engine kernel "
                             "(default 20)")
    consistency.add_argument("--workers", type=_whole("workers", 1), metavar="N",
                             help="run those per-run simulations on a local Dask cluster")
    _tuned_options(consistency, f"the first {TUNED_TEST_RUNS} seeds run")
    _add_common(consistency, seed=False)


def _parse_replay(commands) -> None:
    """The ``replay`` command's arguments."""
    replay = commands.add_parser(
        "replay", help="a recorded gyro against an optical reference attitude (the BROAD "
        "dataset or your .npz); write replay.png and summary.csv")
    replay.add_argument("--dataset", default="broad-02", metavar="NAME_OR_PATH",
                        help="broad-02 (slow rotation, default), broad-07 (fast rotation), or "
                        "a .npz recording with the same keys")
    replay.add_argument("--estimators", type=_estimator_list, default=REPLAY_ESTIMATORS,
                        metavar="A,B,...", help=f"any of {', '.join(ESTIMATORS)} (default: "
                        f"{','.join(REPLAY_ESTIMATORS)})")
    replay.add_argument("--star-tracker-interval", type=_number, default=1.0, metavar="SECONDS",
                        help="seconds between pseudo star tracker readings, rounded to whole "
                        "samples (default 1)")
    replay.add_argument("--star-tracker-noise-deg", type=_number, default=0.1, metavar="DEG",
                        help="σ of the pseudo star tracker's error per axis, degrees "
                        "(default 0.1)")
    replay.add_argument("--seed", type=_whole("seed", 0), default=0,
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
    _add_import_option(replay)
    replay.add_argument("--out", type=_folder, default=Path("results"), metavar="DIR",
                        help="output folder (default results/)")
    replay.add_argument("--quiet", action="store_true", help="no progress bars")
    _add_divergence_option(replay)


def _parse_convergence(commands) -> None:
    """The ``convergence`` command's arguments."""
    convergence = commands.add_parser(
        "convergence", help="filters from large initial errors over seeds (Crassidis & "
        "Markley 2003, e.g. on scenarios/magnetometer_only.toml); write convergence.csv and "
        "convergence.png")
    convergence.add_argument("--estimators", type=_estimator_list, default=("mekf", "usque"),
                             metavar="A,B,...", help="default mekf,usque")
    convergence.add_argument("--seeds", type=_seed_list, default=tuple(range(5)),
                             metavar="SPEC", help="seeds: 0, 0-19 or 1,5,9 (default 0-4)")
    convergence.add_argument("--angles", type=_number_list, default=[90.0, 150.0],
                             metavar="A1,A2,...", help="initial errors to start from besides "
                             "the scenario's, degrees (default 90,150)")
    _add_common(convergence, seed=False)


def command_convergence(args, scenario):
    from benchmarks.experiments import convergence
    from benchmarks.simulation import build_estimator
    for angle in args.angles:
        if not 0.0 <= angle <= 180.0:
            raise UsageError(f"angles = {angle!r}: each must be within 0 and 180 degrees")
    table, curves = convergence.convergence_study(scenario, args.estimators, list(args.seeds),
                                                  args.angles, quiet=args.quiet)
    print(convergence.summary(table).to_string(index=False))
    labels = {name: build_estimator(name, scenario).label for name in args.estimators}
    drawn = figure_bytes(args.out / "convergence.png",
                         convergence.figure(scenario.time_s, curves, labels))
    write_text(args.out / "convergence.csv", table.to_csv(index=False))
    write_bytes(args.out / "convergence.png", drawn)
    print(f"wrote {args.out / 'convergence.csv'} and {args.out / 'convergence.png'}")
    return report_of(scenario.dt, {name: part["diverged_step"].to_numpy()
                                   for name, part in table.groupby("estimator", sort=False)})


def _parse_wahba(commands) -> None:
    """The ``wahba`` command's arguments."""
    wahba = commands.add_parser("wahba", help="the static solvers (TRIAD, q-method, QUEST, "
                                "ESOQ2, FOAM, SVD) on Markley & Mortari's test cases: "
                                "accuracy and time per solution; write wahba.csv")
    wahba.add_argument("--trials", type=_whole("trials", 1), default=1000, metavar="N",
                       help="random attitudes per case (default 1000)")
    wahba.add_argument("--seed", type=_whole("seed", 0), default=0, help="seed (default 0)")
    wahba.add_argument("--out", type=_folder, default=Path("results"), metavar="DIR",
                       help="output folder (default results/)")
    wahba.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_divergence_option(wahba)


def command_wahba(args, _scenario):
    from benchmarks.experiments.wahba_table import format_table, solver_table
    from benchmarks.output import write_text
    table = solver_table(trials=args.trials, seed=args.seed, quiet=args.quiet)
    print(format_table(table))
    write_text(args.out / "wahba.csv", table.to_csv(index=False))
    print(f"wrote {args.out / 'wahba.csv'}")
    return None


def _parse_workshop(commands) -> None:
    """The ``workshop`` command's arguments."""
    workshop = commands.add_parser("workshop", help="the whole exercise, steps 1-9, "
                                   "with report.md")
    workshop.add_argument("--part", choices=("exercise", "flight"), default="exercise",
                          help="the exercise (default), or the study after it: additive "
                          "against multiplicative filters and the best achievable")
    _add_common(workshop, seed=False)


#: The scenario whose values the flags' help shows (see :func:`help_defaults`).
_HELP_DEFAULTS = [Scenario()]


def build_parser(defaults: Scenario | None = None) -> argparse.ArgumentParser:
    """The command line; ``defaults`` is the scenario whose values the help
    lists as each flag's default (the workshop's if None)."""
    _HELP_DEFAULTS[0] = defaults or Scenario()
    parser = _Parser(prog=PROG, description="Compare spacecraft attitude estimators on the "
                     "Kalman-filter workshop's tumbling-spacecraft scenario.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND",
                                     parser_class=_Parser)
    for command in COMMAND_TABLE:
        command.arguments(commands)
    return parser


def allowed_imports(args: argparse.Namespace) -> list[str]:
    """The modules a scenario file may import: those of ``--allow-import``
    and the ``module:Class`` estimators named on the command line."""
    named = list(getattr(args, "estimators", None) or ()) + [getattr(args, "estimator", None)]
    return list(args.allow_import) + [name for name in named if name and ":" in name]


def scenario_from_args(args: argparse.Namespace) -> Scenario | None:
    """The scenario file (or defaults) with the command-line overrides applied
    (None for ``replay``, whose scenario comes from its recording)."""
    if args.command in ("replay", "wahba", "broad"):
        return None
    if args.command in ("tune", "landscape") and args.pc_exponent is not None:
        raise UsageError(f"pc_exponent = {args.pc_exponent!r}: {args.command} chooses "
                         "pc_exponent itself; leave --pc-exponent out (from --pc-exponent)")
    scenario = (Scenario.from_toml(args.scenario, allow_imports=allowed_imports(args))
                if args.scenario else Scenario())
    # All overrides at once: --tstop 0.001 --dt 1e-4 is checked against the new dt.
    given = {name: getattr(args, name) for name in SCENARIO_FLAGS
             if getattr(args, name) is not None}
    try:
        scenario = scenario.replace(**given)
    except InvalidParameterError as err:
        # Name the flag that set the value, or else the flags that changed its context.
        flags = [SCENARIO_FLAGS[err.name]] if err.name in given else \
            [SCENARIO_FLAGS[name] for name in given]
        raise UsageError(f"{err} (from {', '.join(flags)})") from None
    return scenario


#: Scenario field → its section (None: a top-level key).
SECTION_OF = {setting.field: setting.section for setting in SETTINGS}
#: The sections that configure one attitude sensor: only the estimators that
#: read that sensor see them, and only where the scenario has it.
SENSOR_SECTIONS = frozenset({"star_tracker", "magnetometer", "sun_sensor", "coarse_sun_sensors",
                             "accelerometer"})


#: The settings only one star tracker model reads: setting → that model.
READ_BY_MODEL = {setting.field: setting.model for setting in SETTINGS if setting.model}
#: Why a setting of the other model changes nothing, by the chosen model.
MODEL_IGNORES = {
    "rotation": "has no effect with the rotation star tracker, whose noise is "
                "[star_tracker] sigma_arcsec",
    "workshop": "has no effect with the workshop star tracker, whose noise is "
                "[star_tracker] noise_power; set [star_tracker] model = \"rotation\"",
}


def ineffective_reason(field_name: str, scenario: Scenario, names) -> str | None:
    """Why setting ``field_name`` cannot change the results of estimators
    ``names`` on ``scenario`` (None if it can): its sensor is not in the
    scenario, the chosen star tracker model ignores it, or none of the
    estimators reads its sensor (:attr:`estimators.AttitudeEstimator.reads`;
    a user's class may read anything)."""
    from benchmarks.sensor_use import scenario_sensors
    section = SECTION_OF.get(field_name)
    if section in SENSOR_SECTIONS and section not in scenario_sensors(scenario):
        why = ("its model is none, or an outage spans the run" if section == "star_tracker"
               else f"no [{section}] section with an interval_s")
        return f"has no effect: the scenario has no {section} ({why})"
    reader = READ_BY_MODEL.get(field_name)
    if reader is not None and reader != scenario.star_tracker_model:
        return MODEL_IGNORES[scenario.star_tracker_model]
    if not names and field_name not in ("tstop", "dt"):
        return "has no effect on the truth alone (no estimator is run)"
    if section in SENSOR_SECTIONS:
        if any(name not in ESTIMATORS or section in ESTIMATORS[name].reads for name in names):
            return None
        readers = [name for name, cls in ESTIMATORS.items() if section in cls.reads]
        return (f"has no effect on {', '.join(names)}, which read no {section}; it is read "
                f"by {', '.join(readers)}")
    if section == "estimators.ekf" and all(name in ESTIMATORS and name != "ekf"
                                            for name in names):
        return f"has no effect on {', '.join(names)}; it is read only by ekf"
    return None


def check_effects(args, scenario: Scenario | None) -> None:
    """Refuse a flag (or a swept setting) that cannot change what the chosen
    estimators compute: its rows or numbers would be identical, silently."""
    if scenario is None or args.command in ("tune", "landscape", "workshop"):
        return
    names = getattr(args, "estimators", None)
    if names is None:
        names = (args.estimator,) if getattr(args, "estimator", None) else ()
    flags = {name: flag for name, flag in SCENARIO_FLAGS.items()
             if getattr(args, name, None) is not None}
    if args.command == "sweep":
        swept = SWEEP_PARAMETERS[args.param].field
        if swept in flags:
            raise UsageError(f"{swept} = {getattr(args, swept)!r}: the sweep sets it "
                             f"(--param {args.param}); leave {flags[swept]} out")
        flags[swept] = "--param " + args.param
    for field_name, flag in flags.items():
        reason = ineffective_reason(field_name, scenario, names)
        if reason:
            value = args.param if flag.startswith("--param") else getattr(args, field_name)
            raise UsageError(f"{flag.split()[0].lstrip('-').replace('-', '_')} = {value!r}: "
                             f"{reason} (from {flag})")


def summary_line(name: str, stats: dict) -> str:
    return (f"{name}: mean {stats['mean_deg']:.4f} deg, std {stats['std_deg']:.4f} deg, "
            f"max {stats['max_deg']:.4f} deg, final {stats['final_deg']:.4f} deg")


def format_table(stats: dict, first_column: str = "estimator", columns=STAT_COLUMNS) -> str:
    """A fixed-width text table of ``{row name: statistics}``."""
    width = max(len(first_column), *(len(str(name)) for name in stats))
    lines = [f"{first_column:<{width}}  " + "  ".join(f"{c:>15}" for c in columns)]
    for name, row in stats.items():
        lines.append(f"{str(name):<{width}}  " + "  ".join(f"{row[c]:>15.6f}" for c in columns))
    lines += [f"note: {name}: {row['note']}" for name, row in stats.items() if row.get("note")]
    return "\n".join(lines)


# Each command validates everything it needs before its first write.

def command_run(args, scenario):
    stats = experiments.run_one(scenario, args.estimator, args.seed, args.out, quiet=args.quiet)
    print(summary_line(args.estimator, stats))
    return report_of(scenario.dt, {args.estimator: stats["diverged_step"]})


def command_compare(args, scenario):
    if args.tuned:
        scenario = _tuned_scenario(args, scenario, (args.seed,), (args.seed,))
    else:
        _no_tuning_options(args)
    _, stats = experiments.compare(scenario, args.seed, args.out, estimators=args.estimators,
                                   quiet=args.quiet)
    print(format_table(stats))
    print(f"wrote {args.out / 'compare.png'} and {args.out / 'summary.csv'}")
    return report_of(scenario.dt, {name: row["diverged_step"] for name, row in stats.items()})


#: The test seeds of ``montecarlo --tuned`` and ``consistency --tuned``,
#: unless given: the first of the seeds run.
TUNED_TEST_RUNS = 10


def _no_tuning_options(args) -> None:
    for flag, given in (("--train-seeds", getattr(args, "train_seeds", None)),
                        ("--test-seeds", getattr(args, "test_seeds", None)),
                        ("--train-dataset", getattr(args, "train_datasets", None))):
        if given:
            raise UsageError(f"{flag} needs --tuned OBJ")


def _tuned_scenario(args, scenario, run_seeds, default_test, before_writing=None):
    """``--tuned``: every estimator tuned on the training seeds, none of them
    among ``run_seeds`` (a range or a tuple: the seeds the command runs), and
    scored on the test seeds; the scenario with the tuned settings
    (``before_writing(tuned scenario)``: a last check before tuned.* are written)."""
    from benchmarks.experiments.objectives import seed_cases
    training_seeds = args.train_seeds or DEFAULT_TRAINING_SEEDS
    shared = [seed for seed in training_seeds if seed in run_seeds]
    if shared:
        raise InvalidParameterError("train-seeds", format_seeds(shared), "must not be seeds "
                                    "this command runs: it must run on seeds the tuning did "
                                    "not see")
    test_seeds = args.test_seeds or tuple(default_test)
    check = None if before_writing is None else \
        (lambda fair: before_writing(fair.scenario(scenario)))
    fair = _fair_comparison(args, seed_cases(scenario, training_seeds),
                            seed_cases(scenario, test_seeds),
                            f"seeds {format_seeds(training_seeds)}",
                            f"seeds {format_seeds(test_seeds)}", check)
    return fair.scenario(scenario)


def _tuned_campaign(args, scenario, before_writing=None):
    """``montecarlo`` and ``consistency``: the scenario tuned on training
    seeds outside the campaign's (``--tuned``), or as it is."""
    if not args.tuned:
        _no_tuning_options(args)
        return scenario
    runs = range(args.seed, args.seed + args.runs)
    return _tuned_scenario(args, scenario, runs, runs[:TUNED_TEST_RUNS], before_writing)


def _fair_comparison(args, training, test, trained_on: str, tested_on: str,
                     before_writing=None):
    """Tune every estimator of ``args`` on ``training``, score on ``test``,
    print the table and write tuned.toml and tuned.json (after
    ``before_writing(fair)``, a last check, if given)."""
    from benchmarks.experiments import tuning
    from benchmarks.experiments.objectives import checked_objective
    objective = checked_objective(args.tuned)
    fair = tuning.tune_all(args.estimators, objective, training, test, quiet=args.quiet)
    print(f"tuned for {objective} on {trained_on}, tested on {tested_on} (default -> tuned):")
    print(tuning.format_fair_comparison(fair))
    if before_writing is not None:
        before_writing(fair)
    write_text(args.out / "tuned.toml", fair.toml())
    experiments.write_json(args.out / "tuned.json", {
        "objective": objective, "training": [c.label for c in training],
        "test": [c.label for c in test], "rows": fair.rows})
    print(f"wrote {args.out / 'tuned.toml'} and {args.out / 'tuned.json'}\n")
    return fair


def command_sweep(args, scenario):
    try:
        experiments.sweep_scenarios(scenario, args.param, args.values)
    except InvalidParameterError as err:
        raise UsageError(f"{err} (from --values)") from None
    rows = experiments.sweep(scenario, args.estimator, args.param, args.values, args.seed,
                             args.out, quiet=args.quiet)
    print(format_table({f"{row['value']:g}": row for row in rows}, first_column=args.param))
    print(f"wrote {args.out / 'sweep.png'} and {args.out / 'sweep.csv'}")
    return report_of(scenario.dt, {args.estimator: [row["diverged_step"] for row in rows]})


def command_tune(args, scenario):
    if args.estimator is not None:
        if args.bounds is not None:
            raise UsageError("--bounds is pc_exponent's interval without --estimator; with it, "
                             "give each setting's range as --range NAME=LO:HI")
        return command_tune_estimator(args, scenario)
    args.bounds = args.bounds or [-16.0, 0.0]
    for flag, given in (("--parameters", args.parameters), ("--range", args.ranges),
                        ("--dataset", args.datasets), ("--test-seeds", args.test_seeds),
                        ("--test-dataset", args.test_datasets),
                        ("--objective", args.objective != "std")):
        if given:
            raise UsageError(f"{flag} needs --estimator NAME (without it, tune finds the "
                             "EKF's pc_exponent as the workshop does)")
    from benchmarks.experiments.tuning import format_iteration_table, tune_pc_exponent
    # tune_pc_exponent checks bounds and xtol before its first evaluation.
    result = tune_pc_exponent(scenario, args.seeds or (0,), args.bounds, args.xtol,
                              quiet=args.quiet)
    print(format_iteration_table(result.iterations))
    print()
    print(result.message)
    print(f"\npc_exponent = {result.pc_exponent:.4f}, loss = {result.loss_deg:.6f} deg "
          f"({result.evaluations} evaluations, seeds {format_seeds(result.seeds)})")
    if result.single_seed_optima:
        spread = result.single_seed_optima
        print(f"single-seed optima: 5% {spread['p5']:.3f}, 50% {spread['p50']:.3f}, "
              f"95% {spread['p95']:.3f}")
    if result.diverged_evaluations:
        print(f"{PROG}: warning: the ekf diverged at {result.diverged_evaluations} of "
              f"{result.evaluations} evaluations (pc_exponent values), each counted as an "
              "infinite loss; the optimum did not diverge", file=sys.stderr)
    experiments.write_json(args.out / "tune.json", result.as_json())
    _, stats = experiments.compare(scenario.replace(pc_exponent=result.pc_exponent),
                                   result.seeds[0], args.out, figure_name="tune.png",
                                   summary_name=None)
    print(f"wrote {args.out / 'tune.json'} and {args.out / 'tune.png'}")
    return report_of(scenario.dt, {name: row["diverged_step"] for name, row in stats.items()})


def command_tune_estimator(args, scenario):
    """``tune --estimator NAME``: its declared settings, on seeds or recordings."""
    from benchmarks.experiments import tuning
    from benchmarks.experiments.objectives import checked_objective
    objective = checked_objective(args.objective)
    settings = None
    if args.datasets or args.test_datasets:
        settings = _recording_settings(args)
    named = [name for name, _ in args.ranges]
    if len(set(named)) != len(named):
        twice = next(name for name in named if named.count(name) > 1)
        raise UsageError(f"range = {twice!r}: given more than once; give each setting's "
                         "--range once")
    imports = allowed_imports(args)
    training = tuning.cases_of(scenario, args.seeds or (None if args.datasets else (0,)),
                               args.datasets, settings=settings, allow_imports=imports)
    test = (tuning.cases_of(scenario, args.test_seeds, args.test_datasets, "test",
                            settings=settings, allow_imports=imports)
            if args.test_seeds or args.test_datasets else [])
    tuning.disjoint(training, test)
    result = tuning.tune_estimator(args.estimator, training, objective, args.parameters,
                                   dict(args.ranges), xatol=args.xtol, quiet=args.quiet)
    print(tuning.format_tuning_table(result))
    print(f"\n{result.message}")
    print(f"\n{args.estimator}, {objective} on {', '.join(result.cases)} ({result.method}, "
          f"{len(result.evaluations)} evaluations, {result.seconds:.1f} s):")
    for name in result.parameters:
        default = result.default[name]
        bound = " (at an end of its range: widen it with --range)" \
            if name in result.at_bound else ""
        print(f"  {name}: {'none' if default is None else f'{default:.6g}'} -> "
              f"{result.tuned[name]:.6g}{bound}")
    tuned = tuning.tuned_settings(result, training[0].scenario)
    rows = {"training": (training, {}, tuned)}
    if test:
        rows["test"] = (test, {}, tuned)
    report = {}
    for label, (cases, default_settings, tuned_settings) in rows.items():
        before = tuning.scores(args.estimator, objective, cases, default_settings)
        after = tuning.scores(args.estimator, objective, cases, tuned_settings)
        report[label] = {"default": before, "tuned": after, "cases": [c.label for c in cases]}
        print(f"  {label}: " + ", ".join(f"{key} {before[key]:.6g} -> {after[key]:.6g}"
                                         for key in before))
    data = {**result.as_json(), "scores": report, "tuned_settings": tuning.plain(tuned)}
    figure_case = (test or training)[0]
    curves = {}
    for label, chosen in (("default", {}), ("tuned", tuned)):
        curves[f"{args.estimator} ({label})"] = tuning.case_error(args.estimator, figure_case,
                                                                 chosen)
    drawn = figure_bytes(args.out / "tune.png",
                         tuning.tuning_figure(result, figure_case.time_s, curves))
    experiments.write_json(args.out / "tune.json", data)
    write_text(args.out / "tuned.toml", tuning.settings_toml(args.estimator, tuned))
    write_bytes(args.out / "tune.png", drawn)
    print(f"wrote {args.out / 'tune.json'}, {args.out / 'tuned.toml'} and {args.out / 'tune.png'}")
    return None


def _recording_settings(args):
    """With ``--dataset``: a recording's scenario comes from it, so a file may
    set ``[estimators.NAME]`` sections only (the one returned), and no
    scenario flag applies."""
    if args.scenario and len(args.scenario) > 1:
        raise UsageError("with --dataset, give at most one --scenario FILE (of "
                         "[estimators.NAME] sections)")
    for name, flag in SCENARIO_FLAGS.items():
        if getattr(args, name, None) is not None:
            raise UsageError(f"{name} = {getattr(args, name)!r}: a recording's scenario comes "
                             f"from it; leave {flag} out with --dataset (from {flag})")
    return args.scenario[0] if args.scenario else None


def command_landscape(args, scenario):
    from benchmarks.experiments.landscape import compute_landscape, pc_grid, write_landscape
    grid = pc_grid(args.pc_min, args.pc_max, args.pc_step)
    landscape = compute_landscape(scenario, grid, args.seeds, quiet=args.quiet)
    files = write_landscape(landscape, args.out, animate=not args.no_animation)
    best = landscape.table.iloc[landscape.best_index]
    print(f"lowest mean error std {best['std_deg']:.6f} deg at pc_exponent = "
          f"{landscape.best_pc_exponent:g} ({len(grid)} values x {len(args.seeds)} runs)")
    print("wrote " + ", ".join(str(path) for path in files.values()))
    return report_of(scenario.dt, {"ekf": landscape.diverged_step})


def command_animate(args, scenario):
    name = args.estimator or "truth"
    path, diverged = experiments.animate(scenario, args.estimator, args.seed, args.out,
                                         args.every, quiet=args.quiet)
    print(f"wrote {path} and {path.with_suffix('.png')} ({name})")
    return report_of(scenario.dt, {args.estimator: diverged}) if args.estimator else None


def _check_seed_range(args) -> None:
    if args.seed + args.runs - 1 > MAX_SEED:
        raise UsageError(f"seed = {args.seed}: with --runs {args.runs} the last seed would "
                         f"pass 2^63 - 1 = {MAX_SEED}; choose a smaller --seed or fewer runs")


def command_montecarlo(args, scenario):
    _check_seed_range(args)
    from benchmarks.engine.campaign import (CAMPAIGN_COLUMNS, Campaign, check_campaign_folder,
                                            check_campaign_out, run_campaign)
    from benchmarks.output import write_csv
    from benchmarks.figures.plots import distribution_figure
    from benchmarks.output import progress

    def campaign_of(chosen):
        return Campaign(scenario=chosen, estimators=args.estimators, runs=args.runs,
                        base_seed=args.seed, chunk_runs=args.chunk_size)
    # What the folder holds is checked before tuning, and the tuned campaign
    # against it before tuned.* are written: nothing half-written.
    check_campaign_folder(args.out, args.resume)
    scenario = _tuned_campaign(args, scenario, lambda tuned: check_campaign_out(
        campaign_of(tuned), args.out, args.resume))
    campaign = campaign_of(scenario)
    try:
        with progress(total=args.runs, desc="montecarlo", unit="run", quiet=args.quiet) as bar:
            frame = run_campaign(campaign, args.out, workers=args.workers or 0,
                                 scheduler=args.scheduler, resume=args.resume, progress_bar=bar)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted; finished chunks are kept in {args.out}; "
              "rerun with --resume to finish", file=sys.stderr)
        raise SystemExit(130) from None
    from benchmarks.sensor_use import Usage, tagged_label
    from benchmarks.simulation import resolve_estimator
    usage = frame.attrs.get("usage", {})
    labels = {name: tagged_label(resolve_estimator(name).label,
                                 usage.get(name, Usage()).note()) for name in args.estimators}
    drawn = figure_bytes(args.out / "montecarlo.png", distribution_figure(frame, labels))
    write_csv(args.out / "montecarlo.csv", CAMPAIGN_COLUMNS,
              (list(row) for row in frame[list(CAMPAIGN_COLUMNS)].itertuples(index=False)),
              digits=17)
    write_bytes(args.out / "montecarlo.png", drawn)
    # Diverged runs have NaN statistics: pandas' means and quantiles leave them out.
    summary = frame.groupby("estimator", sort=False)[list(STAT_COLUMNS)].mean()
    report = report_of(scenario.dt, {name: part["diverged_step"].to_numpy()
                                     for name, part in frame.groupby("estimator", sort=False)})
    left_out = f", leaving out {report.total} diverged" if report.total else ""
    print(f"mean over {args.runs} runs (seeds {args.seed}-{args.seed + args.runs - 1}"
          f"{left_out}):")
    print(format_table(summary.to_dict(orient="index")))
    spread = frame.groupby("estimator", sort=False)["std_deg"].quantile([0.05, 0.5, 0.95])
    for name in args.estimators:
        p5, p50, p95 = spread[name].tolist()
        print(f"{name}: error std over runs 5% {p5:.4f}, 50% {p50:.4f}, 95% {p95:.4f} deg")
    for name, usage in frame.attrs.get("usage", {}).items():
        if usage.note():
            print(f"note: {name}: {usage.note()}")
    print(f"wrote {args.out / 'montecarlo.csv'} and {args.out / 'montecarlo.png'}")
    return report


def command_workshop(args, scenario):
    if args.part == "flight":
        from benchmarks.experiments.flight_study import run_flight_study, study_scenario
        divergence = DivergenceReport(study_scenario().dt)
        report = run_flight_study(scenario, args.out, quiet=args.quiet, divergence=divergence)
    else:
        divergence = DivergenceReport(scenario.dt)
        from benchmarks.experiments.workshop import run_workshop
        report = run_workshop(scenario, args.out, quiet=args.quiet, divergence=divergence)
    print(f"wrote {report}")
    return divergence


def command_consistency(args, scenario):
    _check_seed_range(args)
    from benchmarks.experiments import consistency
    from benchmarks.engine.batch import ENGINE_ESTIMATORS, engine_limitation
    from benchmarks.output import progress
    if args.settle is not None and not 0 <= args.settle < scenario.tstop:
        raise UsageError(f"settle = {args.settle!r}: must be >= 0 and below tstop = "
                         f"{scenario.tstop:g}")
    scenario = _tuned_campaign(args, scenario)
    engine = [name for name in args.estimators if name in ENGINE_ESTIMATORS
              and engine_limitation(scenario, None, name) is None]
    total = args.runs * len(engine) + min(args.runs, args.per_run_limit) * (
        len(args.estimators) - len(engine))
    with progress(total=total, desc="consistency", unit="run", quiet=args.quiet) as bar:
        result = consistency.run_consistency(
            scenario, args.estimators, args.runs, base_seed=args.seed, settle_s=args.settle,
            per_run_limit=args.per_run_limit, workers=args.workers or 0, progress_bar=bar)
    print(consistency.format_summary(result.summary, result.settle_s))
    frame = consistency.consistency_frame(result)
    drawn = figure_bytes(args.out / "consistency.png", consistency.figure(result))
    write_text(args.out / "consistency.csv", frame.to_csv(index=False))
    write_bytes(args.out / "consistency.png", drawn)
    print(f"wrote {args.out / 'consistency.csv'} and {args.out / 'consistency.png'}")
    return report_of(scenario.dt, result.diverged_step)


def command_replay(args, _scenario):
    from benchmarks.experiments.replay import load_replay, run_replay, write_replay
    from benchmarks.resources import check_memory, per_run_bytes
    from benchmarks.experiments.gyro_delay import DELAY_SEARCH_SAMPLES, likeliest_gyro_delay
    from benchmarks.experiments.replay import REPLAY_SENSORS
    from benchmarks.sensor_use import refuse_unreadable
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
    if args.tuned:
        data = _tuned_replay(args, data, delay)
    else:
        _no_tuning_options(args)
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
    from benchmarks.experiments import tuning
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
    fair = _fair_comparison(args, training, test, ", ".join(args.train_datasets), args.dataset)
    return dataclasses.replace(data, scenario=fair.scenario(data.scenario))


#: What a BROAD trial gives the estimators besides the gyro.
BROAD_SENSORS = frozenset({"accelerometer", "magnetometer"})


def command_broad(args, _scenario):
    from benchmarks.broad import benchmark, case_study, tuning
    from benchmarks.broad.dataset import broad_folder, open_broad
    from benchmarks.sensor_use import refuse_unreadable
    if not args.case_study:
        refuse_unreadable(args.estimators, BROAD_SENSORS, "a BROAD trial")
    dataset = open_broad(broad_folder(args.broad))
    trials = dataset.selected(args.trials)
    if args.grid and not args.case_study:
        raise UsageError("--grid is the case study's grid search: give --case-study with it")
    if args.case_study:
        for flag, given in (("--gyro-delay", args.gyro_delay),
                            ("--accelerometer-sigma", args.accelerometer_sigma),
                            ("--magnetometer-sigma", args.magnetometer_sigma),
                            ("--tune", args.tune != "none"),
                            ("--train", args.train is not None)):
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
    from benchmarks.broad import inputs
    from benchmarks.broad.inputs import checked_sigmas
    sigmas = {sensor: value for sensor, value in (("accelerometer", args.accelerometer_sigma),
                                                  ("magnetometer", args.magnetometer_sigma))
              if value is not None}
    checked_sigmas(sigmas)
    mode, train = args.tune, None
    if args.train is not None:
        if args.tune != "none":
            raise UsageError(f"--train tunes on another dataset; --tune {args.tune} on this "
                             "one's trials: give one of them")
        if args.gyro_delay:
            raise UsageError("--gyro-delay is the scored device's; the training dataset's "
                             "delay is not known: leave it out with --train")
        mode, train = "other-dataset", open_broad(args.train, parameter="train")
        tuning.checked_apart(train, dataset, trials)
    options, tunings = tuning.tuned_options(dataset, trials, args.estimators, mode,
                                            args.gyro_delay, sigmas, args.workers, args.quiet,
                                            train=train)
    result = benchmark.run_broad(dataset, trials, args.estimators, args.gyro_delay, sigmas,
                                 quiet=args.quiet, workers=args.workers, options=options,
                                 tuning=mode)
    print(f"{PROG}: note: {inputs.assumed()}", file=sys.stderr)
    print(benchmark.format_trials(result))
    if len(tunings):
        print("\ntuned (training loss: mean total RMSE over the training trials, °):")
        print(tunings.to_string(index=False, float_format=lambda v: f"{v:.6g}"))
    print(f"\ntotal RMSE (°) per group, mean over its trials (trials run), "
          f"{tuning.MODE_LABELS[mode]}:")
    print(benchmark.format_groups(result))
    drawn = {name: figure_bytes(args.out / name, figure(result)) for name, figure in
             (("broad.png", benchmark.groups_figure), ("broad_trial.png", benchmark.trial_figure))}
    write_text(args.out / "broad_trials.csv", result.trials.to_csv(index=False))
    write_text(args.out / "broad_groups.csv", result.groups.to_csv(index=False))
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
    return report_of(result.dt, {name: part["diverged_step"].to_numpy() for name, part
                                 in result.trials.groupby("estimator", sort=False)})


def _engine_memory(args, scenario) -> None:
    """A command on the streaming engine alone: its memory is flat."""
    from benchmarks.resources import check_memory, engine_bytes
    check_memory(scenario, engine_bytes(scenario.n_steps))


def _montecarlo_memory(args, scenario) -> None:
    """The engine's buffers grow with montecarlo's chunks."""
    from benchmarks.resources import check_memory, engine_bytes
    check_memory(scenario, engine_bytes(scenario.n_steps, args.chunk_size),
                 chunk_runs=args.chunk_size)


def _landscape_memory(args, scenario) -> None:
    """It keeps the first seed's error curve at every grid value, and two more."""
    from benchmarks.experiments.landscape import pc_grid
    from benchmarks.resources import check_memory, per_run_bytes
    curves = len(pc_grid(args.pc_min, args.pc_max, args.pc_step)) + 2
    check_memory(scenario, per_run_bytes(scenario.n_steps, curves, traced=False))


def _per_run_memory(traced: bool):
    """The per-run path's records of each estimator (three if none are named)."""
    def check(args, scenario) -> None:
        from benchmarks.resources import check_memory, engine_bytes, per_run_bytes
        estimators = len(getattr(args, "estimators", ()) or ()) or 3
        check_memory(scenario, per_run_bytes(scenario.n_steps, estimators, traced),
                     streaming_bytes=engine_bytes(scenario.n_steps))
    return check


class Command(NamedTuple):
    """One command: its arguments (added to the sub-parsers), its run
    (``run(args, scenario)``, returning a divergence report or None), the
    files it writes into ``--out`` (checked before any work) and its memory
    check (``memory(args, scenario)``, before any work; None: checked by the
    run itself, as replay does once its recording is read)."""

    name: str
    arguments: Callable
    run: Callable
    outputs: tuple
    memory: Callable | None


#: Every command, in the order ``--help`` lists them; main() only dispatches.
COMMAND_TABLE = (
    Command("run", _parse_run, command_run, (), _per_run_memory(False)),
    Command("compare", _parse_compare, command_compare, ("compare.png", "summary.csv"),
            _per_run_memory(True)),
    Command("sweep", _parse_sweep, command_sweep, ("sweep.png", "sweep.csv"),
            _per_run_memory(False)),
    Command("tune", _parse_tune, command_tune, ("tune.json", "tune.png", "tuned.toml"),
            _engine_memory),
    Command("landscape", _parse_landscape, command_landscape,
            ("landscape.csv", "landscape.png", "landscape.gif"), _landscape_memory),
    Command("animate", _parse_animate, command_animate, (), _per_run_memory(False)),
    Command("montecarlo", _parse_montecarlo, command_montecarlo,
            ("montecarlo.csv", "montecarlo.png", "campaign.json"), _montecarlo_memory),
    Command("consistency", _parse_consistency, command_consistency,
            ("consistency.csv", "consistency.png"), _per_run_memory(True)),
    Command("replay", _parse_replay, command_replay,
            ("replay.png", "summary.csv", "ATTRIBUTION.txt"), None),
    Command("broad", _parse_broad, command_broad,
            ("broad_trials.csv", "broad_groups.csv", "broad.png", "broad_trial.png",
             "broad_case_study.csv", "broad_case_study_grid.csv", "broad_tuning.csv",
             "ATTRIBUTION.txt"), None),
    Command("workshop", _parse_workshop, command_workshop, ("report.md",),
            _per_run_memory(True)),
    Command("show-config", _parse_show_config, command_show_config, ("config.csv",), None),
    Command("convergence", _parse_convergence, command_convergence,
            ("convergence.csv", "convergence.png"), _per_run_memory(False)),
    Command("wahba", _parse_wahba, command_wahba, ("wahba.csv",), None),
)
COMMANDS = {command.name: command for command in COMMAND_TABLE}
EXIT_IO = 1


def main(argv=None) -> int:
    """The command line: one command's run; a warning the library gives
    (an estimator taking the per-run path, a reading applied at its step) is
    one line on stderr, ``attitude-bench: note: …``."""
    with warnings.catch_warnings():
        warnings.showwarning = _note
        return _main(argv)


#: The estimators a command runs when --estimators is not given, by the
#: scenario's sensors: a star tracker alone, or vector sensors.
STAR_TRACKER_DEFAULTS = ("dead-reckoning", "dead-reckoning-resets", "ekf", "mekf", "usque")
VECTOR_DEFAULTS = ("dead-reckoning", "triad", "quest", "ekf", "mekf", "usque")


def default_estimators(command: str, scenario) -> tuple:
    """``--estimators`` when not given: with vector sensors, the filters and
    two static solvers (:data:`VECTOR_DEFAULTS`) for every command; else the
    workshop's three for ``compare`` and ``montecarlo``, and every star
    tracker estimator for ``consistency``; ``broad``'s own
    (:func:`benchmarks.broad.benchmark.default_estimators`)."""
    if command == "broad":
        from benchmarks.broad.benchmark import default_estimators as broad_defaults
        return broad_defaults()
    if scenario is not None and scenario.has_vector_sensors:
        from benchmarks.sensor_use import scenario_sensors, usable_estimators
        return usable_estimators(VECTOR_DEFAULTS, scenario_sensors(scenario))
    return STAR_TRACKER_DEFAULTS if command == "consistency" else tuple(WORKSHOP_ESTIMATORS)


def check_sensors(args, scenario) -> None:
    """Refuse an estimator that can use none of the scenario's sensors
    (:func:`benchmarks.simulation.refuse_unreadable`), before any work."""
    if scenario is None or args.command in ("show-config", "workshop", "landscape"):
        return
    names = getattr(args, "estimators", None) or (
        (args.estimator,) if getattr(args, "estimator", None) else ())
    from benchmarks.sensor_use import refuse_unreadable, scenario_sensors
    refuse_unreadable(names, scenario_sensors(scenario), "the scenario")


def _note(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"{PROG}: note: {message}", file=sys.stderr)


def _main(argv) -> int:
    importable_from_here()
    try:
        args = build_parser(help_defaults(sys.argv[1:] if argv is None else argv)
                            ).parse_args(argv)
        scenario = scenario_from_args(args)
        if getattr(args, "estimators", "") is None:
            args.estimators = default_estimators(args.command, scenario)
        check_sensors(args, scenario)
        check_effects(args, scenario)
        command = COMMANDS[args.command]
        if getattr(args, "out", None) is not None:
            check_output_folder(args.out, command.outputs)
        if command.memory is not None and scenario is not None:
            command.memory(args, scenario)     # refuse what cannot fit, before any work
        report = command.run(args, scenario)
    except (UsageError, InvalidParameterError) as err:
        print(f"{PROG}: error: {err}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as err:
        # A file system failure after the checks (full disk, a mount gone
        # read-only): one line; atomic writes leave no half-written file.
        where = f" ({err.filename})" if err.filename else ""
        print(f"{PROG}: error: cannot write the results{where}: {err.strerror or err}",
              file=sys.stderr)
        return EXIT_IO
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    return _divergence_status(report, getattr(args, "allow_divergence", False))


def _divergence_status(report: DivergenceReport | None, allowed: bool) -> int:
    """0, or :data:`EXIT_DIVERGED` after saying which estimators diverged."""
    if report is None or not report.total:
        return 0
    for line in report.lines():
        print(f"{PROG}: warning: {line}", file=sys.stderr)
    if allowed:
        return 0
    print(f"{PROG}: exit status {EXIT_DIVERGED} because runs diverged (the results are "
          "written; pass --allow-divergence to exit 0)", file=sys.stderr)
    return EXIT_DIVERGED


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
