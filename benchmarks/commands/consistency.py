"""``attitude-bench consistency``: do the filters know their error? NEES
against chi-square bands and efficiency against the best achievable;
consistency.csv and consistency.png."""
from __future__ import annotations

from benchmarks.commands.memory import per_run_memory
from benchmarks.commands.montecarlo import check_seed_range
from benchmarks.commands.options import (STAR_TRACKER_DEFAULTS, TUNED_TEST_RUNS, VECTOR_DEFAULTS,
                                         UsageError, add_common, estimators_option, number,
                                         tuned_options, whole)
from benchmarks.commands.tuned import tuned_campaign
from benchmarks.divergence import report_of
from benchmarks.output import figure_bytes, write_bytes, write_text

OUTPUTS = ("consistency.csv", "consistency.png")
memory = per_run_memory(True)


def arguments(commands, defaults) -> None:
    """The ``consistency`` command's arguments."""
    consistency = commands.add_parser(
        "consistency", help="do the filters know their error? NEES against chi-square bands, "
        "efficiency against the best achievable; write consistency.csv and consistency.png")
    estimators_option(consistency, "those the scenario's sensors feed: the star tracker's "
                      f"{','.join(STAR_TRACKER_DEFAULTS)}, or with vector sensors "
                      f"{','.join(VECTOR_DEFAULTS)}")
    consistency.add_argument("--runs", type=whole("runs", 1), default=100, metavar="N",
                             help="runs (seeds S … S+N-1) of each estimator (default 100)")
    consistency.add_argument("--seed", type=whole("seed", 0), default=0, metavar="S",
                             help="base seed (default 0)")
    consistency.add_argument("--settle", type=number, metavar="SECONDS",
                             help="time left out of the averages (default a tenth of tstop)")
    consistency.add_argument("--per-run-limit", type=whole("per-run-limit", 1),
                             default=20, metavar="N",
                             help="at most N runs for estimators without an engine kernel "
                             "(default 20)")
    consistency.add_argument("--workers", type=whole("workers", 1), metavar="N",
                             help="run those per-run simulations on a local Dask cluster")
    tuned_options(consistency, f"the first {TUNED_TEST_RUNS} seeds run")
    add_common(consistency, defaults, seed=False)


def run(args, scenario):
    check_seed_range(args)
    from benchmarks.experiments import consistency
    from benchmarks.engine.batch import ENGINE_ESTIMATORS, engine_limitation
    from benchmarks.output import progress
    if args.settle is not None and not 0 <= args.settle < scenario.tstop:
        raise UsageError(f"settle = {args.settle!r}: must be >= 0 and below tstop = "
                         f"{scenario.tstop:g}")
    scenario = tuned_campaign(args, scenario)
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
