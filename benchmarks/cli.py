"""The ``attitude-bench`` command line.

Every value is validated before anything is written; bad input gets one line
on stderr naming the parameter, the value and the rule, and exit status 2.
"""
from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from benchmarks.metrics import STAT_COLUMNS, error_statistics
from benchmarks.output import write_csv, write_figure
from benchmarks.plots import comparison_figure
from benchmarks.scenario import Scenario
from benchmarks.simulation import WORKSHOP_ESTIMATORS, simulate
from dynamics.validation import InvalidParameterError

PROG = "attitude-bench"
EXIT_USAGE = 2

#: Command-line flag → scenario field, for the overridable settings.
SCENARIO_FLAGS = {
    "gyro_noise": "--gyro-noise",
    "star_tracker_noise": "--star-tracker-noise",
    "time_between_measurements": "--time-between-measurements",
    "pc_exponent": "--pc-exponent",
    "tstop": "--tstop",
    "dt": "--dt",
}

TRACE_COLUMNS = ("time_s", "q_true_w", "q_true_x", "q_true_y", "q_true_z",
                 "q_est_w", "q_est_x", "q_est_y", "q_est_z", "error_deg")


class UsageError(Exception):
    """Bad command-line input; the message is the whole one-line explanation."""


class _Parser(argparse.ArgumentParser):
    """argparse, but its errors are one line and go through :class:`UsageError`,
    and ``-1e-5`` or ``-inf`` is a value, not an option (Python 3.11's argparse
    only knows ``-1`` and ``-0.5``)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(
            r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-inf(inity)?$", re.IGNORECASE)

    def error(self, message):
        raise UsageError(message)


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"seed = {text!r}: must be a whole number >= 0") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"seed = {text!r}: must be a whole number >= 0")
    return value


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None


def _add_scenario_options(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("scenario (defaults: the workshop's, or --scenario FILE)")
    group.add_argument("--scenario", metavar="FILE", type=Path,
                       help="TOML file of scenario settings (see scenarios/default.toml)")
    group.add_argument("--gyro-noise", type=_number, metavar="POWER",
                       help="gyro noise power, rad^2/s (default 1e-5)")
    group.add_argument("--star-tracker-noise", type=_number, metavar="POWER",
                       help="star tracker noise power (default 1e-6)")
    group.add_argument("--time-between-measurements", type=_number, metavar="SECONDS",
                       help="star tracker interval, a whole multiple of dt (default 0.2)")
    group.add_argument("--pc-exponent", type=_number, metavar="X",
                       help="EKF process covariance Q = exp(X) I4 (default -8.7)")
    group.add_argument("--tstop", type=_number, metavar="SECONDS",
                       help="simulated time (default 50)")
    group.add_argument("--dt", type=_number, metavar="SECONDS",
                       help="gyro and estimator step (default 0.01)")


def _add_run_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--seed", type=_seed, default=0, help="sensor noise seed (default 0)")
    parser.add_argument("--out", type=Path, default=Path("results"), metavar="DIR",
                        help="output folder (default results/)")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog=PROG, description="Compare spacecraft attitude estimators on the "
                     "Kalman-filter workshop's tumbling-spacecraft scenario.")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND",
                                     parser_class=_Parser)
    run = commands.add_parser("run", help="run one estimator; write NAME.csv and NAME.png")
    run.add_argument("--estimator", required=True, choices=WORKSHOP_ESTIMATORS, metavar="NAME",
                     help=f"one of {', '.join(WORKSHOP_ESTIMATORS)}")
    _add_run_options(run)
    _add_scenario_options(run)
    compare = commands.add_parser("compare", help="run the three workshop estimators on the "
                                  "same data; write compare.png and summary.csv")
    _add_run_options(compare)
    _add_scenario_options(compare)
    return parser


def scenario_from_args(args: argparse.Namespace) -> Scenario:
    """The scenario file (or defaults) with the command-line overrides applied."""
    scenario = Scenario.from_toml(args.scenario) if args.scenario else Scenario()
    for field_name, flag in SCENARIO_FLAGS.items():
        value = getattr(args, field_name)
        if value is None:
            continue
        try:
            scenario = scenario.replace(**{field_name: value})
        except InvalidParameterError as err:
            raise UsageError(f"{err} (from {flag})") from None
    return scenario


def _summary_line(name: str, stats: dict) -> str:
    return (f"{name}: mean {stats['mean_deg']:.4f} deg, std {stats['std_deg']:.4f} deg, "
            f"max {stats['max_deg']:.4f} deg, final {stats['final_deg']:.4f} deg")


def command_run(args, scenario: Scenario) -> None:
    result = simulate(scenario, [args.estimator], seed=args.seed)
    name = args.estimator
    error = result.error_deg[name]
    q_true, q_est = result.truth.q_true, result.estimates[name]
    rows = ((float(t), *map(float, qt), *map(float, qe), float(e))
            for t, qt, qe, e in zip(result.time_s, q_true, q_est, error))
    write_csv(args.out / f"{name}.csv", TRACE_COLUMNS, rows)
    write_figure(args.out / f"{name}.png",
                 comparison_figure(result.time_s, {result.labels[name]: error}))
    print(_summary_line(name, error_statistics(error)))


def command_compare(args, scenario: Scenario) -> None:
    result = simulate(scenario, WORKSHOP_ESTIMATORS, seed=args.seed)
    stats = {name: error_statistics(error) for name, error in result.error_deg.items()}
    write_csv(args.out / "summary.csv", ("estimator",) + STAT_COLUMNS,
              ([name, *(stats[name][c] for c in STAT_COLUMNS)] for name in stats))
    curves = {result.labels[name]: error for name, error in result.error_deg.items()}
    write_figure(args.out / "compare.png", comparison_figure(result.time_s, curves))
    print(format_table(stats))
    print(f"wrote {args.out / 'compare.png'} and {args.out / 'summary.csv'}")


def format_table(stats: dict, first_column: str = "estimator") -> str:
    """A fixed-width text table of ``{row name: statistics}``."""
    width = max(len(first_column), *(len(str(name)) for name in stats))
    lines = [f"{first_column:<{width}}  " + "  ".join(f"{c:>15}" for c in STAT_COLUMNS)]
    for name, row in stats.items():
        lines.append(f"{str(name):<{width}}  " + "  ".join(f"{row[c]:>15.6f}"
                                                          for c in STAT_COLUMNS))
    return "\n".join(lines)


COMMANDS = {"run": command_run, "compare": command_compare}


def main(argv=None) -> int:
    try:
        args = build_parser().parse_args(argv)
        scenario = scenario_from_args(args)
        COMMANDS[args.command](args, scenario)
    except (UsageError, InvalidParameterError) as err:
        print(f"{PROG}: error: {err}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
