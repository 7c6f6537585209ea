"""``attitude-bench montecarlo``: many runs on the batched engine, in chunks
on disk (resumable, on Dask workers if asked); montecarlo.csv and .png."""
from __future__ import annotations

import sys

from benchmarks.commands.options import (PROG, TUNED_TEST_RUNS, VECTOR_DEFAULTS, UsageError,
                                         add_common, estimators_option, tuned_options, whole)
from benchmarks.commands.tables import format_table
from benchmarks.commands.tuned import tuned_campaign
from benchmarks.divergence import report_of
from benchmarks.metrics import STAT_COLUMNS
from benchmarks.output import figure_bytes, write_bytes
from dynamics.validation import MAX_SEED

OUTPUTS = ("montecarlo.csv", "montecarlo.png", "campaign.json")


def arguments(commands, defaults) -> None:
    """The ``montecarlo`` command's arguments."""
    montecarlo = commands.add_parser("montecarlo", help="many runs on the batched engine; "
                                     "write montecarlo.csv and montecarlo.png")
    estimators_option(montecarlo, "the workshop's three; with vector sensors, "
                      f"{','.join(VECTOR_DEFAULTS)}")
    montecarlo.add_argument("--runs", type=whole("runs", 1), default=100, metavar="N",
                            help="number of runs; run i uses seed S + i (default 100)")
    montecarlo.add_argument("--seed", type=whole("seed", 0), default=0, metavar="S",
                            help="base seed (default 0)")
    montecarlo.add_argument("--chunk-size", type=whole("chunk-size", 1), default=1024,
                            metavar="N", help="runs per chunk file (default 1024)")
    where = montecarlo.add_mutually_exclusive_group()
    where.add_argument("--workers", type=whole("workers", 1), metavar="N",
                       help="run chunks on a local Dask cluster of N processes")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="run chunks on an existing Dask cluster")
    montecarlo.add_argument("--resume", action="store_true",
                            help="finish an interrupted campaign in --out")
    tuned_options(montecarlo, f"the campaign's first {TUNED_TEST_RUNS} seeds")
    add_common(montecarlo, defaults, seed=False)


def check_seed_range(args) -> None:
    if args.seed + args.runs - 1 > MAX_SEED:
        raise UsageError(f"seed = {args.seed}: with --runs {args.runs} the last seed would "
                         f"pass 2^63 - 1 = {MAX_SEED}; choose a smaller --seed or fewer runs")


def run(args, scenario):
    check_seed_range(args)
    from benchmarks.engine.campaign import (CAMPAIGN_COLUMNS, Campaign, check_campaign_folder,
                                            check_campaign_out, run_campaign)
    from benchmarks.output import write_csv
    from benchmarks.figures.plots import distribution_figure
    from benchmarks.output import progress

    def campaign_of(chosen):
        return Campaign(scenario=chosen, estimators=args.estimators, runs=args.runs,
                        base_seed=args.seed, chunk_runs=args.chunk_size)
    # What the folder holds is checked before tuning, and the tuned campaign
    # against it before tuned.* are written: nothing half-written.
    check_campaign_folder(args.out, args.resume)
    scenario = tuned_campaign(args, scenario, lambda tuned: check_campaign_out(
        campaign_of(tuned), args.out, args.resume))
    campaign = campaign_of(scenario)
    try:
        with progress(total=args.runs, desc="montecarlo", unit="run", quiet=args.quiet) as bar:
            frame = run_campaign(campaign, args.out, workers=args.workers or 0,
                                 scheduler=args.scheduler, resume=args.resume, progress_bar=bar)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted; finished chunks are kept in {args.out}; "
              "rerun with --resume to finish", file=sys.stderr)
        raise SystemExit(130) from None
    from benchmarks.sensor_use import Usage, tagged_label
    from benchmarks.simulation import resolve_estimator
    usage = frame.attrs.get("usage", {})
    labels = {name: tagged_label(resolve_estimator(name).label,
                                 usage.get(name, Usage()).note()) for name in args.estimators}
    drawn = figure_bytes(args.out / "montecarlo.png", distribution_figure(frame, labels))
    write_csv(args.out / "montecarlo.csv", CAMPAIGN_COLUMNS,
              (list(row) for row in frame[list(CAMPAIGN_COLUMNS)].itertuples(index=False)),
              digits=17)
    write_bytes(args.out / "montecarlo.png", drawn)
    # Diverged runs have NaN statistics: pandas' means and quantiles leave them out.
    summary = frame.groupby("estimator", sort=False)[list(STAT_COLUMNS)].mean()
    report = report_of(scenario.dt, {name: part["diverged_step"].to_numpy()
                                     for name, part in frame.groupby("estimator", sort=False)})
    left_out = f", leaving out {report.total} diverged" if report.total else ""
    print(f"mean over {args.runs} runs (seeds {args.seed}-{args.seed + args.runs - 1}"
          f"{left_out}):")
    print(format_table(summary.to_dict(orient="index")))
    spread = frame.groupby("estimator", sort=False)["std_deg"].quantile([0.05, 0.5, 0.95])
    for name in args.estimators:
        p5, p50, p95 = spread[name].tolist()
        print(f"{name}: error std over runs 5% {p5:.4f}, 50% {p50:.4f}, 95% {p95:.4f} deg")
    for name, usage in frame.attrs.get("usage", {}).items():
        if usage.note():
            print(f"note: {name}: {usage.note()}")
    print(f"wrote {args.out / 'montecarlo.csv'} and {args.out / 'montecarlo.png'}")
    return report


def memory(args, scenario) -> None:
    """The engine's buffers grow with montecarlo's chunks."""
    from benchmarks.resources import check_memory, engine_bytes
    check_memory(scenario, engine_bytes(scenario.n_steps, args.chunk_size),
                 chunk_runs=args.chunk_size)
