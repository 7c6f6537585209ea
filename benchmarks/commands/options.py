"""What the commands' arguments share: their types (each refusal one line
naming the parameter, the value and the rule), the scenario's flags, and the
option groups several commands take.

Imported to build the parser, so it imports nothing heavy: ``--help`` and a
refused argument answer at once.
"""
from __future__ import annotations

import argparse
import re
from pathlib import Path

from benchmarks.divergence import EXIT_DIVERGED
from benchmarks.scenario import SETTINGS, Scenario
from benchmarks.seeds import DEFAULT_TRAINING_SEEDS, format_seeds, parse_seeds
from dynamics.validation import MAX_SEED, InvalidParameterError
from estimators.registry import ESTIMATORS, check_estimator_name

PROG = "attitude-bench"

#: Scenario field → command-line flag, for the settings declared with one
#: (benchmarks.scenario.SETTINGS), in the order --help lists them.
SCENARIO_FLAGS = {setting.field: setting.flag for setting in SETTINGS if setting.flag}

#: The estimators a command runs when --estimators is not given, by the
#: scenario's sensors: a star tracker alone, or vector sensors.
STAR_TRACKER_DEFAULTS = ("dead-reckoning", "dead-reckoning-resets", "ekf", "mekf", "usque")
VECTOR_DEFAULTS = ("dead-reckoning", "triad", "quest", "ekf", "mekf", "usque")

#: The test seeds of ``montecarlo --tuned`` and ``consistency --tuned``,
#: unless given: the first of the seeds run.
TUNED_TEST_RUNS = 10

#: Every registry estimator, as the help lists them.
REGISTRY_NAMES = ", ".join(ESTIMATORS)


class UsageError(Exception):
    """Bad command-line input; the message is the whole one-line explanation."""


class Parser(argparse.ArgumentParser):
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


def whole(name: str, minimum: int, maximum: int = MAX_SEED):
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


def folder(text: str) -> Path:
    if not text.strip():
        raise argparse.ArgumentTypeError(f"out = {text!r}: must name a folder (. for this one)")
    return Path(text)


def number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None


def number_list(text: str) -> list[float]:
    try:
        values = [float(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"values = {text!r}: must be numbers separated by commas, e.g. 1e-5,1e-4") from None
    if not values:
        raise argparse.ArgumentTypeError(f"values = {text!r}: must name at least one value")
    return values


def module_name(text: str) -> str:
    """A Python module's dotted name, as ``import`` takes it."""
    if not all(part.isidentifier() for part in text.split(".")):
        raise argparse.ArgumentTypeError(f"allow_import = {text!r}: must be a module name "
                                         "such as myfilters or package.module")
    return text


def estimator_list(text: str) -> tuple[str, ...]:
    given = [part.strip() for part in text.split(",") if part.strip()]
    names = tuple(dict.fromkeys(given))
    if len(names) != len(given):
        twice = next(name for name in names if given.count(name) > 1)
        raise argparse.ArgumentTypeError(
            f"estimators = {text!r}: names {twice} more than once; name each estimator once")
    if not names:
        raise argparse.ArgumentTypeError(f"estimators = {text!r}: must name at least one "
                                         "estimator")
    for name in names:
        try:
            check_estimator_name(name)
        except InvalidParameterError as err:
            raise argparse.ArgumentTypeError(f"estimators = {text!r}: {name}: {err.rule} "
                                             "(names separated by commas)") from None
    return names


def seed_list(text: str) -> tuple[int, ...]:
    try:
        return parse_seeds(text)
    except InvalidParameterError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def name_list(text: str) -> list[str]:
    names = [name.strip() for name in text.split(",") if name.strip()]
    if not names:
        raise argparse.ArgumentTypeError(f"{text!r}: must be names, comma-separated")
    return names


def add_scenario_options(parser: argparse.ArgumentParser, defaults: Scenario) -> None:
    group = parser.add_argument_group("scenario (defaults: the workshop's, or --scenario FILE)")
    group.add_argument("--scenario", metavar="FILE", type=Path, action="append",
                       help="TOML file of scenario settings (see scenarios/default.toml); "
                       "repeat to lay files over each other, later keys overriding earlier")
    group.add_argument("--set", metavar="SECTION.KEY=VALUE", action="append",
                       help="one setting over the --scenario files, named as in them "
                       "(e.g. gyro.arw_deg_per_rthr=0.15, star_tracker.model=rotation, "
                       "tstop=10); repeatable")
    add_import_option(group)
    for setting in SETTINGS:
        if setting.flag:
            unit = f", {setting.unit}" if setting.unit else ""
            reader = f"; {setting.model} star tracker only" if setting.model else ""
            group.add_argument(setting.flag, type=number, metavar="X", dest=setting.field,
                               help=f"{setting.doc}{unit} (default "
                               f"{getattr(defaults, setting.field):g}{reader})")


def add_import_option(parser) -> None:
    parser.add_argument("--allow-import", action="append", default=[], metavar="MODULE",
                        type=module_name,
                        help="let the scenario file's [estimators.\"MODULE:Class\"] sections "
                        "import MODULE (its code runs); naming MODULE:Class in --estimators "
                        "allows it too. Repeatable")


def add_common(parser: argparse.ArgumentParser, defaults: Scenario, seed: bool = True) -> None:
    """The options of every command on a scenario; ``defaults``: the scenario
    whose values the help shows (:func:`help_defaults`)."""
    if seed:
        parser.add_argument("--seed", type=whole("seed", 0), default=0,
                            help="sensor noise seed (default 0)")
    add_out_options(parser)
    add_divergence_option(parser)
    add_scenario_options(parser, defaults)


def add_divergence_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--allow-divergence", action="store_true",
                        help="exit 0 even if an estimator diverged in some run (its statistics "
                        f"are NaN either way; without this flag the exit status is "
                        f"{EXIT_DIVERGED})")


def estimator_name(text: str) -> str:
    """One estimator: a registry name or a user's ``package.module:ClassName``."""
    try:
        check_estimator_name(text)
    except InvalidParameterError as err:
        raise argparse.ArgumentTypeError(f"estimator = {text!r}: {err.rule}") from None
    return text


def estimators_option(parser, default: str) -> None:
    """``--estimators A,B,...`` (None when not given: the command's
    :func:`~benchmarks.commands.scenario_args.default_estimators`, which
    ``default`` describes)."""
    parser.add_argument("--estimators", type=estimator_list, default=None, metavar="A,B,...",
                        help=f"any of {REGISTRY_NAMES}, or package.module:ClassName for your "
                        f"own (default: {default})")


def estimator_option(parser, required=True):
    parser.add_argument("--estimator", required=required, type=estimator_name,
                        metavar="NAME", help=f"one of {REGISTRY_NAMES}, or "
                        "package.module:ClassName for your own estimator")


def tuned_options(parser, default_test: str) -> None:
    """``--tuned OBJ`` and its training and test seeds."""
    group = parser.add_argument_group("fair comparison (every estimator tuned first)")
    group.add_argument("--tuned", metavar="OBJ",
                       help="first tune every estimator with tunable settings on "
                       "--train-seeds for objective OBJ (see tune), then run them all "
                       "tuned; scores default and tuned on both sets, writes tuned.toml "
                       "and tuned.json")
    group.add_argument("--train-seeds", type=seed_list, metavar="SPEC",
                       help="the training seeds of --tuned (default "
                       f"{format_seeds(DEFAULT_TRAINING_SEEDS)}); none may be a seed run")
    group.add_argument("--test-seeds", type=seed_list, metavar="SPEC",
                       help=f"the test seeds of --tuned (default: {default_test}); "
                       "none may be a training seed")


def add_out_options(parser, what: str = "no progress bars") -> None:
    """``--out DIR`` and ``--quiet``, for the commands without a scenario."""
    parser.add_argument("--out", type=folder, default=Path("results"), metavar="DIR",
                        help="output folder (default results/)")
    parser.add_argument("--quiet", action="store_true", help=what)
