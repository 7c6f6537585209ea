"""``--tuned OBJ``: every estimator tuned on training seeds or recordings the
command does not run, scored on test ones, then run tuned (``compare``,
``montecarlo``, ``consistency``, ``replay``); tuned.toml and tuned.json."""
from __future__ import annotations

from benchmarks.commands.options import TUNED_TEST_RUNS, UsageError
from benchmarks.output import write_json, write_text
from benchmarks.seeds import DEFAULT_TRAINING_SEEDS, format_seeds
from dynamics.validation import InvalidParameterError


def no_tuning_options(args) -> None:
    for flag, given in (("--train-seeds", getattr(args, "train_seeds", None)),
                        ("--test-seeds", getattr(args, "test_seeds", None)),
                        ("--train-dataset", getattr(args, "train_datasets", None))):
        if given:
            raise UsageError(f"{flag} needs --tuned OBJ")


def tuned_scenario(args, scenario, run_seeds, default_test, before_writing=None):
    """``--tuned``: every estimator tuned on the training seeds, none of them
    among ``run_seeds`` (a range or a tuple: the seeds the command runs), and
    scored on the test seeds; the scenario with the tuned settings
    (``before_writing(tuned scenario)``: a last check before tuned.* are written)."""
    from benchmarks.experiments.objectives import seed_cases
    training_seeds = args.train_seeds or DEFAULT_TRAINING_SEEDS
    shared = [seed for seed in training_seeds if seed in run_seeds]
    if shared:
        raise InvalidParameterError("train-seeds", format_seeds(shared), "must not be seeds "
                                    "this command runs: it must run on seeds the tuning did "
                                    "not see")
    test_seeds = args.test_seeds or tuple(default_test)
    check = None if before_writing is None else \
        (lambda fair: before_writing(fair.scenario(scenario)))
    fair = fair_comparison(args, seed_cases(scenario, training_seeds),
                            seed_cases(scenario, test_seeds),
                            f"seeds {format_seeds(training_seeds)}",
                            f"seeds {format_seeds(test_seeds)}", check)
    return fair.scenario(scenario)


def tuned_campaign(args, scenario, before_writing=None):
    """``montecarlo`` and ``consistency``: the scenario tuned on training
    seeds outside the campaign's (``--tuned``), or as it is."""
    if not args.tuned:
        no_tuning_options(args)
        return scenario
    runs = range(args.seed, args.seed + args.runs)
    return tuned_scenario(args, scenario, runs, runs[:TUNED_TEST_RUNS], before_writing)


def fair_comparison(args, training, test, trained_on: str, tested_on: str,
                     before_writing=None):
    """Tune every estimator of ``args`` on ``training``, score on ``test``,
    print the table and write tuned.toml and tuned.json (after
    ``before_writing(fair)``, a last check, if given)."""
    from benchmarks.experiments import fair_comparison as tuning
    from benchmarks.experiments.objectives import checked_objective
    objective = checked_objective(args.tuned)
    fair = tuning.tune_all(args.estimators, objective, training, test, quiet=args.quiet)
    print(f"tuned for {objective} on {trained_on}, tested on {tested_on} (default -> tuned):")
    print(tuning.format_fair_comparison(fair))
    if before_writing is not None:
        before_writing(fair)
    write_text(args.out / "tuned.toml", fair.toml())
    write_json(args.out / "tuned.json", {
        "objective": objective, "training": [c.label for c in training],
        "test": [c.label for c in test], "rows": fair.rows})
    print(f"wrote {args.out / 'tuned.toml'} and {args.out / 'tuned.json'}\n")
    return fair
