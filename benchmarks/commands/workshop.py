"""``attitude-bench workshop``: the whole exercise, steps 1-9, with
report.md (or ``--part flight``, the study after it)."""
from __future__ import annotations

from benchmarks.commands.memory import per_run_memory
from benchmarks.commands.options import add_common
from benchmarks.divergence import DivergenceReport

OUTPUTS = ("report.md",)
memory = per_run_memory(True)


def arguments(commands, defaults) -> None:
    """The ``workshop`` command's arguments."""
    workshop = commands.add_parser("workshop", help="the whole exercise, steps 1-9, "
                                   "with report.md")
    workshop.add_argument("--part", choices=("exercise", "flight"), default="exercise",
                          help="the exercise (default), or the study after it: additive "
                          "against multiplicative filters and the best achievable")
    add_common(workshop, defaults, seed=False)


def run(args, scenario):
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
