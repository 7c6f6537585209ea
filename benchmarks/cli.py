"""The ``attitude-bench`` command line: it builds the parser from the
commands' modules (:mod:`benchmarks.commands`) and dispatches.

Every value is validated before anything is written; bad input gets one line
on stderr naming the parameter, the value and the rule, and exit status 2.
"""
from __future__ import annotations

import sys
import warnings

from benchmarks.commands import COMMAND_MODULES, command
from benchmarks.commands.options import PROG, Parser, UsageError
from benchmarks.commands.scenario_args import (check_effects, check_sensors, default_estimators,
                                               help_defaults, importable_from_here,
                                               scenario_from_args)
from benchmarks.divergence import EXIT_DIVERGED, DivergenceReport
from benchmarks.output import check_output_folder
from dynamics.validation import InvalidParameterError

EXIT_USAGE = 2
EXIT_IO = 1


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("attitude-bench")
    except PackageNotFoundError:       # run from a source tree that is not installed
        return "(not installed)"


def build_parser(defaults=None) -> Parser:
    """The command line; ``defaults`` is the scenario whose values the help
    lists as each flag's default (the workshop's if None)."""
    if defaults is None:
        from benchmarks.scenario import Scenario
        defaults = Scenario()
    parser = Parser(prog=PROG, description="Compare spacecraft attitude estimators on the "
                    "Kalman-filter workshop's tumbling-spacecraft scenario.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND",
                                     parser_class=Parser)
    for name in COMMAND_MODULES:
        command(name).arguments(commands, defaults)
    return parser


def main(argv=None) -> int:
    """The command line: one command's run; a warning the library gives
    (an estimator taking the per-run path, a reading applied at its step) is
    one line on stderr, ``attitude-bench: note: …``, once per run of the
    command (campaigns warn from each of their parts)."""
    shown = set()

    def note(message, category, filename, lineno, file=None, line=None) -> None:
        if str(message) not in shown:
            shown.add(str(message))
            print(f"{PROG}: note: {message}", file=sys.stderr)
    with warnings.catch_warnings():
        warnings.showwarning = note
        return _main(argv)


def _main(argv) -> int:
    importable_from_here()
    try:
        args = build_parser(help_defaults(sys.argv[1:] if argv is None else argv)
                            ).parse_args(argv)
        report = _run(args)
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


def _run(args):
    """Check everything the command needs, before any work; then run it."""
    scenario = scenario_from_args(args)
    if getattr(args, "estimators", "") is None:
        args.estimators = default_estimators(args.command, scenario)
        args.estimators_by_default = True
    check_sensors(args, scenario)
    check_effects(args, scenario)
    chosen = command(args.command)
    if getattr(args, "out", None) is not None:
        check_output_folder(args.out, chosen.OUTPUTS)
    if chosen.memory is not None and scenario is not None:
        chosen.memory(args, scenario)     # refuse what cannot fit, before any work
    return chosen.run(args, scenario)


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
