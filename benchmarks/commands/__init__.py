"""The commands of ``attitude-bench``, one module each.

Each command's module declares its arguments (``arguments(commands,
defaults)``, added to the sub-parsers), its run (``run(args, scenario)``,
returning a divergence report or None), the files it writes into ``--out``
(``OUTPUTS``, checked before any work) and its memory check (``memory(args,
scenario)`` before any work; None where the run checks it itself). What the
commands share: :mod:`~benchmarks.commands.options` (argument types and
groups), :mod:`~benchmarks.commands.scenario_args` (the scenario from files
and flags, and the checks on it), :mod:`~benchmarks.commands.tuned`
(``--tuned``), :mod:`~benchmarks.commands.memory` and
:mod:`~benchmarks.commands.tables`.

A command's module imports only what its arguments need at its top; what
its run needs (numba, matplotlib, pandas, the estimators) is imported in the
run, so that ``--help`` and a refused argument answer at once.
"""
import importlib

#: Every command, in the order ``--help`` lists them: its name → its module.
COMMAND_MODULES = {
    "run": "run",
    "compare": "compare",
    "sweep": "sweep",
    "tune": "tune",
    "landscape": "landscape",
    "animate": "animate",
    "montecarlo": "montecarlo",
    "consistency": "consistency",
    "replay": "replay",
    "broad": "broad",
    "workshop": "workshop",
    "show-config": "show_config",
    "convergence": "convergence",
    "wahba": "wahba",
    "inspect": "inspect",
}


def command(name: str):
    """The module of command ``name``."""
    return importlib.import_module(f"benchmarks.commands.{COMMAND_MODULES[name]}")
