"""``attitude-bench sweep``: one estimator, one setting varied; sweep.png and
sweep.csv."""
from __future__ import annotations

from benchmarks.commands.memory import per_run_memory
from benchmarks.commands.options import UsageError, add_common, estimator_option, number_list
from benchmarks.commands.tables import format_table
from benchmarks.divergence import report_of
from benchmarks.experiments.sweep_parameters import SWEEP_PARAMETERS
from dynamics.validation import InvalidParameterError

OUTPUTS = ("sweep.png", "sweep.csv")
memory = per_run_memory(False)


def arguments(commands, defaults) -> None:
    """The ``sweep`` command's arguments."""
    sweep = commands.add_parser("sweep", help="one estimator, one setting varied; "
                                "write sweep.png and sweep.csv")
    estimator_option(sweep)
    sweep.add_argument("--param", required=True, choices=tuple(SWEEP_PARAMETERS),
                       metavar="P", help=f"one of {', '.join(SWEEP_PARAMETERS)}")
    sweep.add_argument("--values", required=True, type=number_list, metavar="V1,V2,...",
                       help="values of P, comma-separated")
    add_common(sweep, defaults)


def run(args, scenario):
    from benchmarks import experiments
    try:
        experiments.sweep_scenarios(scenario, args.param, args.values)
    except InvalidParameterError as err:
        raise UsageError(f"{err} (from --values)") from None
    rows = experiments.sweep(scenario, args.estimator, args.param, args.values, args.seed,
                             args.out, quiet=args.quiet)
    print(format_table({f"{row['value']:g}": row for row in rows}, first_column=args.param))
    print(f"wrote {args.out / 'sweep.png'} and {args.out / 'sweep.csv'}")
    return report_of(scenario.dt, {args.estimator: [row["diverged_step"] for row in rows]})
