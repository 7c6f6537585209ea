"""``attitude-bench convergence``: filters from large initial errors over
seeds (Crassidis & Markley 2003); convergence.csv and convergence.png."""
from __future__ import annotations

from benchmarks.commands.memory import per_run_memory
from benchmarks.commands.options import (UsageError, add_common, estimator_list, number_list,
                                         seed_list)
from benchmarks.divergence import report_of
from benchmarks.output import figure_bytes, write_bytes, write_text

OUTPUTS = ("convergence.csv", "convergence.png")
memory = per_run_memory(False)


def arguments(commands, defaults) -> None:
    """The ``convergence`` command's arguments."""
    convergence = commands.add_parser(
        "convergence", help="filters from large initial errors over seeds (Crassidis & "
        "Markley 2003, e.g. on scenarios/magnetometer_only.toml); write convergence.csv and "
        "convergence.png")
    convergence.add_argument("--estimators", type=estimator_list, default=("mekf", "usque"),
                             metavar="A,B,...", help="default mekf,usque")
    convergence.add_argument("--seeds", type=seed_list, default=tuple(range(5)),
                             metavar="SPEC", help="seeds: 0, 0-19 or 1,5,9 (default 0-4)")
    convergence.add_argument("--angles", type=number_list, default=[90.0, 150.0],
                             metavar="A1,A2,...", help="initial errors to start from besides "
                             "the scenario's, degrees (default 90,150)")
    add_common(convergence, defaults, seed=False)


def run(args, scenario):
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
