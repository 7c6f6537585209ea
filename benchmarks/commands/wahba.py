"""``attitude-bench wahba``: the static solvers on Markley & Mortari's test
cases, accuracy and time per solution; wahba.csv."""
from __future__ import annotations

from benchmarks.commands.options import add_divergence_option, add_out_options, whole

OUTPUTS = ("wahba.csv",)
memory = None


def arguments(commands, defaults) -> None:
    """The ``wahba`` command's arguments."""
    wahba = commands.add_parser("wahba", help="the static solvers (TRIAD, q-method, QUEST, "
                                "ESOQ2, FOAM, SVD) on Markley & Mortari's test cases: "
                                "accuracy and time per solution; write wahba.csv")
    wahba.add_argument("--trials", type=whole("trials", 1), default=1000, metavar="N",
                       help="random attitudes per case (default 1000)")
    wahba.add_argument("--seed", type=whole("seed", 0), default=0, help="seed (default 0)")
    add_out_options(wahba, "no progress bar")
    add_divergence_option(wahba)


def run(args, _scenario):
    from benchmarks.experiments.wahba_table import format_table, solver_table
    from benchmarks.output import write_text
    table = solver_table(trials=args.trials, seed=args.seed, quiet=args.quiet)
    print(format_table(table))
    write_text(args.out / "wahba.csv", table.to_csv(index=False))
    print(f"wrote {args.out / 'wahba.csv'}")
    return None
