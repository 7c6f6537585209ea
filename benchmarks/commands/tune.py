"""``attitude-bench tune``: the EKF's pc_exponent as the workshop tunes it
(fminbnd), or any estimator's declared settings on seeds or recordings;
tune.json, tune.png and tuned.toml."""
from __future__ import annotations

import argparse
import sys

from benchmarks.commands.memory import engine_memory
from benchmarks.commands.options import (PROG, SCENARIO_FLAGS, UsageError, add_common,
                                         estimator_option, name_list, number, seed_list)
from benchmarks.commands.scenario_args import allowed_imports
from benchmarks.divergence import report_of
from benchmarks.output import figure_bytes, write_bytes, write_json, write_text
from benchmarks.seeds import format_seeds

OUTPUTS = ("tune.json", "tune.png", "tuned.toml")
memory = engine_memory


def _parameter_range(text: str) -> tuple[str, tuple[float, float]]:
    """``NAME=LO:HI`` as ``(name, (lo, hi))``."""
    name, _, bounds = text.partition("=")
    low, _, high = bounds.partition(":")
    try:
        return name.strip(), (float(low), float(high))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: must be NAME=LO:HI, e.g. "
                                         "gyro_noise=1e-8:1e-4") from None


def arguments(commands, defaults) -> None:
    """The ``tune`` command's arguments."""
    tune = commands.add_parser("tune", help="fminbnd-style tuning of pc_exponent; "
                               "write tune.json and tune.png")
    tune.add_argument("--bounds", nargs=2, type=number, metavar=("LO", "HI"),
                      help="pc_exponent's search interval (default -16 0; with --estimator, "
                      "--range NAME=LO:HI)")
    tune.add_argument("--xtol", type=number, default=0.01, metavar="X",
                      help="x tolerance (default 0.01)")
    tune.add_argument("--seeds", type=seed_list, default=None, metavar="SPEC",
                      help="training seeds: 0, 0-19 or 1,5,9 (default 0; not with --dataset)")
    group = tune.add_argument_group(
        "any estimator (without --estimator: the EKF's pc_exponent, as the workshop tunes it)")
    estimator_option(group, required=False)
    group.add_argument("--parameters", type=name_list, metavar="A,B",
                       help="its tunable settings to tune (default: those with a default; "
                       "see the README's tuning section)")
    group.add_argument("--objective", default="std", metavar="OBJ",
                       help="rms, mean, std, max (with the truth), anees (consistency), nis or "
                       "likelihood (no truth needed); default std")
    group.add_argument("--range", type=_parameter_range, action="append", default=[],
                       metavar="NAME=LO:HI", dest="ranges",
                       help="search range of one setting, in its units (repeatable)")
    group.add_argument("--dataset", action="append", metavar="NAME_OR_PATH", dest="datasets",
                       help="train on this recording (repeatable; broad-02, broad-07 or an "
                       ".npz) instead of simulated seeds")
    group.add_argument("--test-seeds", type=seed_list, metavar="SPEC",
                       help="score the default and the tuned settings on these seeds too")
    group.add_argument("--test-dataset", action="append", metavar="NAME_OR_PATH",
                       dest="test_datasets", help="score them on this recording too (repeatable)")
    add_common(tune, defaults, seed=False)


def run(args, scenario):
    from benchmarks import experiments
    if args.estimator is not None:
        if args.bounds is not None:
            raise UsageError("--bounds is pc_exponent's interval without --estimator; with it, "
                             "give each setting's range as --range NAME=LO:HI")
        return run_estimator(args, scenario)
    args.bounds = args.bounds or [-16.0, 0.0]
    for flag, given in (("--parameters", args.parameters), ("--range", args.ranges),
                        ("--dataset", args.datasets), ("--test-seeds", args.test_seeds),
                        ("--test-dataset", args.test_datasets),
                        ("--objective", args.objective != "std")):
        if given:
            raise UsageError(f"{flag} needs --estimator NAME (without it, tune finds the "
                             "EKF's pc_exponent as the workshop does)")
    from benchmarks.experiments.tuning import format_iteration_table, tune_pc_exponent
    # tune_pc_exponent checks bounds and xtol before its first evaluation.
    result = tune_pc_exponent(scenario, args.seeds or (0,), args.bounds, args.xtol,
                              quiet=args.quiet)
    print(format_iteration_table(result.iterations))
    print()
    print(result.message)
    print(f"\npc_exponent = {result.pc_exponent:.4f}, loss = {result.loss_deg:.6f} deg "
          f"({result.evaluations} evaluations, seeds {format_seeds(result.seeds)})")
    if result.single_seed_optima:
        spread = result.single_seed_optima
        print(f"single-seed optima: 5% {spread['p5']:.3f}, 50% {spread['p50']:.3f}, "
              f"95% {spread['p95']:.3f}")
    if result.diverged_evaluations:
        print(f"{PROG}: warning: the ekf diverged at {result.diverged_evaluations} of "
              f"{result.evaluations} evaluations (pc_exponent values), each counted as an "
              "infinite loss; the optimum did not diverge", file=sys.stderr)
    write_json(args.out / "tune.json", result.as_json())
    _, stats = experiments.compare(scenario.replace(pc_exponent=result.pc_exponent),
                                   result.seeds[0], args.out, figure_name="tune.png",
                                   summary_name=None)
    print(f"wrote {args.out / 'tune.json'} and {args.out / 'tune.png'}")
    return report_of(scenario.dt, {name: row["diverged_step"] for name, row in stats.items()})


def run_estimator(args, scenario):
    """``tune --estimator NAME``: its declared settings, on seeds or recordings."""
    from benchmarks.experiments import estimator_tuning as tuning
    from benchmarks.experiments.objectives import checked_objective
    objective = checked_objective(args.objective)
    settings = None
    if args.datasets or args.test_datasets:
        settings = _recording_settings(args)
    named = [name for name, _ in args.ranges]
    if len(set(named)) != len(named):
        twice = next(name for name in named if named.count(name) > 1)
        raise UsageError(f"range = {twice!r}: given more than once; give each setting's "
                         "--range once")
    imports = allowed_imports(args)
    training = tuning.cases_of(scenario, args.seeds or (None if args.datasets else (0,)),
                               args.datasets, settings=settings, allow_imports=imports)
    test = (tuning.cases_of(scenario, args.test_seeds, args.test_datasets, "test",
                            settings=settings, allow_imports=imports)
            if args.test_seeds or args.test_datasets else [])
    tuning.disjoint(training, test)
    result = tuning.tune_estimator(args.estimator, training, objective, args.parameters,
                                   dict(args.ranges), xatol=args.xtol, quiet=args.quiet)
    print(tuning.format_tuning_table(result))
    print(f"\n{result.message}")
    print(f"\n{args.estimator}, {objective} on {', '.join(result.cases)} ({result.method}, "
          f"{len(result.evaluations)} evaluations, {result.seconds:.1f} s):")
    for name in result.parameters:
        default = result.default[name]
        bound = " (at an end of its range: widen it with --range)" \
            if name in result.at_bound else ""
        print(f"  {name}: {'none' if default is None else f'{default:.6g}'} -> "
              f"{result.tuned[name]:.6g}{bound}")
    tuned = tuning.tuned_settings(result, training[0].scenario)
    rows = {"training": (training, {}, tuned)}
    if test:
        rows["test"] = (test, {}, tuned)
    report = {}
    for label, (cases, default_settings, tuned_settings) in rows.items():
        before = tuning.scores(args.estimator, objective, cases, default_settings)
        after = tuning.scores(args.estimator, objective, cases, tuned_settings)
        report[label] = {"default": before, "tuned": after, "cases": [c.label for c in cases]}
        print(f"  {label}: " + ", ".join(f"{key} {before[key]:.6g} -> {after[key]:.6g}"
                                         for key in before))
    data = {**result.as_json(), "scores": report, "tuned_settings": tuning.plain(tuned)}
    figure_case = (test or training)[0]
    curves = {}
    for label, chosen in (("default", {}), ("tuned", tuned)):
        curves[f"{args.estimator} ({label})"] = tuning.case_error(args.estimator, figure_case,
                                                                 chosen)
    drawn = figure_bytes(args.out / "tune.png",
                         tuning.tuning_figure(result, figure_case.time_s, curves))
    write_json(args.out / "tune.json", data)
    write_text(args.out / "tuned.toml", tuning.settings_toml(args.estimator, tuned))
    write_bytes(args.out / "tune.png", drawn)
    print(f"wrote {args.out / 'tune.json'}, {args.out / 'tuned.toml'} and {args.out / 'tune.png'}")
    return None


def _recording_settings(args):
    """With ``--dataset``: a recording's scenario comes from it, so a file may
    set ``[estimators.NAME]`` sections only (the one returned), and no
    scenario flag applies."""
    if args.scenario and len(args.scenario) > 1:
        raise UsageError("with --dataset, give at most one --scenario FILE (of "
                         "[estimators.NAME] sections)")
    for name, flag in SCENARIO_FLAGS.items():
        if getattr(args, name, None) is not None:
            raise UsageError(f"{name} = {getattr(args, name)!r}: a recording's scenario comes "
                             f"from it; leave {flag} out with --dataset (from {flag})")
    return args.scenario[0] if args.scenario else None
