"""``attitude-bench run``: one estimator on the scenario; NAME.csv and NAME.png."""
from __future__ import annotations

from benchmarks.commands.memory import per_run_memory
from benchmarks.commands.options import add_common, estimator_option
from benchmarks.commands.tables import summary_line
from benchmarks.divergence import report_of

OUTPUTS = ()
memory = per_run_memory(False)


def arguments(commands, defaults) -> None:
    """The ``run`` command's arguments."""
    run = commands.add_parser("run", help="run one estimator; write NAME.csv and NAME.png")
    estimator_option(run)
    add_common(run, defaults)


def run(args, scenario):
    from benchmarks import experiments
    stats = experiments.run_one(scenario, args.estimator, args.seed, args.out, quiet=args.quiet)
    print(summary_line(args.estimator, stats))
    return report_of(scenario.dt, {args.estimator: stats["diverged_step"]})
