"""``attitude-bench compare``: estimators on the same data, optionally each
tuned first (``--tuned``); compare.png and summary.csv."""
from __future__ import annotations

from benchmarks.commands.memory import per_run_memory
from benchmarks.commands.options import (VECTOR_DEFAULTS, add_common, estimators_option,
                                         tuned_options)
from benchmarks.commands.tables import format_table
from benchmarks.commands.tuned import no_tuning_options, tuned_scenario
from benchmarks.divergence import report_of

OUTPUTS = ("compare.png", "summary.csv")
memory = per_run_memory(True)


def arguments(commands, defaults) -> None:
    """The ``compare`` command's arguments."""
    compare = commands.add_parser("compare", help="estimators on the same data; "
                                  "write compare.png and summary.csv")
    estimators_option(compare, "the workshop's three; with vector sensors, "
                      f"{','.join(VECTOR_DEFAULTS)}")
    tuned_options(compare, "--seed, the compared one")
    add_common(compare, defaults)


def run(args, scenario):
    from benchmarks import experiments
    if args.tuned:
        scenario = tuned_scenario(args, scenario, (args.seed,), (args.seed,))
    else:
        no_tuning_options(args)
    _, stats = experiments.compare(scenario, args.seed, args.out, estimators=args.estimators,
                                   quiet=args.quiet)
    print(format_table(stats))
    print(f"wrote {args.out / 'compare.png'} and {args.out / 'summary.csv'}")
    return report_of(scenario.dt, {name: row["diverged_step"] for name, row in stats.items()})
