"""``attitude-bench show-config``: every estimator's effective settings on the
scenario and where each came from (writes nothing, or config.csv)."""
from __future__ import annotations

from benchmarks.commands.options import (SCENARIO_FLAGS, add_divergence_option,
                                         add_scenario_options, estimator_list, folder)
from benchmarks.output import write_text
from estimators.registry import CATALOG

OUTPUTS = ("config.csv",)
memory = None


def arguments(commands, defaults) -> None:
    """The ``show-config`` command's arguments."""
    show = commands.add_parser("show-config", help="every estimator's effective settings on "
                               "the scenario, and where each came from (writes nothing)")
    show.add_argument("--estimators", type=estimator_list, default=tuple(CATALOG),
                      metavar="A,B,...", help="any of the registry's or "
                      "package.module:ClassName (default: every registry estimator)")
    show.add_argument("--out", type=folder, default=None, metavar="DIR",
                      help="also write the table as DIR/config.csv (default: print only)")
    show.add_argument("--keys", action="store_true",
                      help="instead: every key a scenario file and a [recording] file take "
                      "(section, key, unit, meaning, default), as Markdown tables")
    show.add_argument("--quiet", action="store_true", help="accepted, as by every command "
                      "(show-config shows no progress)")
    add_divergence_option(show)
    add_scenario_options(show, defaults)


def run(args, scenario):
    from benchmarks.experiments.configuration import (effective_settings, format_settings,
                                                      given_fields, key_reference)
    if args.keys:
        print(key_reference(), end="")
        return None
    given = given_fields(args.scenario, [name for name in SCENARIO_FLAGS
                                         if getattr(args, name, None) is not None])
    rows = [row for name in args.estimators for row in effective_settings(scenario, name, given)]
    print(format_settings(rows))
    print("\n(file: the scenario's [estimators.NAME] section; scenario: a scenario setting "
          "given; derived: from the scenario's sensors; default: left at its default)")
    if args.out is not None:
        import pandas as pd
        write_text(args.out / "config.csv", pd.DataFrame(rows).to_csv(index=False))
        print(f"wrote {args.out / 'config.csv'}")
    return None
