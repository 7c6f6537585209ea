"""``attitude-bench animate``: the 3-D attitude animation, attitude_NAME.gif
and its last frame (the truth alone without ``--estimator``)."""
from __future__ import annotations

from benchmarks.commands.memory import per_run_memory
from benchmarks.commands.options import add_common, estimator_option, whole
from benchmarks.divergence import report_of

OUTPUTS = ()
memory = per_run_memory(False)


def arguments(commands, defaults) -> None:
    """The ``animate`` command's arguments."""
    animate = commands.add_parser("animate", help="3-D attitude animation; write "
                                  "attitude_NAME.gif and .png (truth alone without --estimator)")
    estimator_option(animate, required=False)
    animate.add_argument("--every", type=whole("every", 1), default=50, metavar="K",
                         help="one frame every K steps (default 50)")
    add_common(animate, defaults)


def run(args, scenario):
    from benchmarks import experiments
    name = args.estimator or "truth"
    path, diverged = experiments.animate(scenario, args.estimator, args.seed, args.out,
                                         args.every, quiet=args.quiet)
    print(f"wrote {path} and {path.with_suffix('.png')} ({name})")
    return report_of(scenario.dt, {args.estimator: diverged}) if args.estimator else None
