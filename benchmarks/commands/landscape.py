"""``attitude-bench landscape``: the EKF's error statistics across
pc_exponent; landscape.csv, .png and .gif."""
from __future__ import annotations

from benchmarks.commands.options import add_common, number, seed_list
from benchmarks.divergence import report_of

OUTPUTS = ("landscape.csv", "landscape.png", "landscape.gif")


def arguments(commands, defaults) -> None:
    """The ``landscape`` command's arguments."""
    landscape = commands.add_parser("landscape", help="EKF statistics across pc_exponent; "
                                    "write landscape.csv, .png and .gif")
    landscape.add_argument("--pc-min", type=number, default=-18.0, metavar="X",
                           help="first pc_exponent (default -18)")
    landscape.add_argument("--pc-max", type=number, default=0.0, metavar="X",
                           help="last pc_exponent (default 0)")
    landscape.add_argument("--pc-step", type=number, default=0.25, metavar="X",
                           help="grid step (default 0.25)")
    landscape.add_argument("--seeds", type=seed_list, default=(0,), metavar="SPEC",
                           help="seeds: 0, 0-19 or 1,5,9 (default 0)")
    landscape.add_argument("--no-animation", action="store_true", help="skip landscape.gif")
    add_common(landscape, defaults, seed=False)


def run(args, scenario):
    from benchmarks.experiments.landscape import compute_landscape, pc_grid, write_landscape
    grid = pc_grid(args.pc_min, args.pc_max, args.pc_step)
    landscape = compute_landscape(scenario, grid, args.seeds, quiet=args.quiet)
    files = write_landscape(landscape, args.out, animate=not args.no_animation)
    best = landscape.table.iloc[landscape.best_index]
    print(f"lowest mean error std {best['std_deg']:.6f} deg at pc_exponent = "
          f"{landscape.best_pc_exponent:g} ({len(grid)} values x {len(args.seeds)} runs)")
    print("wrote " + ", ".join(str(path) for path in files.values()))
    return report_of(scenario.dt, {"ekf": landscape.diverged_step})


def memory(args, scenario) -> None:
    """It keeps the first seed's error curve at every grid value, and two more."""
    from benchmarks.experiments.landscape import pc_grid
    from benchmarks.resources import check_memory, per_run_bytes
    curves = len(pc_grid(args.pc_min, args.pc_max, args.pc_step)) + 2
    check_memory(scenario, per_run_bytes(scenario.n_steps, curves, traced=False))
