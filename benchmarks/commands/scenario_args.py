"""The scenario a command runs: from its ``--scenario`` files, ``--set`` and flags,
its default estimators, and the checks that refuse, before any work, an
estimator that can read none of its sensors or a flag that changes nothing.
"""
from __future__ import annotations

import argparse
import sys
import tomllib
from pathlib import Path

from benchmarks.commands.options import (SCENARIO_FLAGS, STAR_TRACKER_DEFAULTS, VECTOR_DEFAULTS,
                                         UsageError)
from benchmarks.experiments.sweep_parameters import SWEEP_PARAMETERS
from benchmarks.scenario import SETTINGS, Scenario
from dynamics.validation import InvalidParameterError
from estimators.registry import ESTIMATORS


def importable_from_here() -> None:
    """Let a user's ``myfilters:MyFilter`` in the current folder import, as
    under ``python -m``: the folder goes on the module path, last, so that it
    never hides an installed module. (Dask's local workers start with this
    process's path, so they find it too.)"""
    here = str(Path.cwd())
    if here not in sys.path and "" not in sys.path:
        sys.path.append(here)


def help_defaults(argv) -> Scenario:
    """The scenario whose values ``--help`` shows as defaults: that of the
    ``--scenario`` files in ``argv`` where they load, else the workshop's."""
    if not argv or not any(item in ("-h", "--help") for item in argv):
        return Scenario()
    peek = argparse.ArgumentParser(add_help=False)
    peek.add_argument("--scenario", type=Path, action="append")
    peek.add_argument("--allow-import", action="append", default=[])
    peek.add_argument("--estimators", type=lambda text: text.split(","))
    peek.add_argument("--estimator")
    known = peek.parse_known_args(argv)[0]
    if not known.scenario:
        return Scenario()
    try:
        return Scenario.from_toml(known.scenario, allow_imports=allowed_imports(known))
    except InvalidParameterError:
        return Scenario()         # the run itself will say what is wrong


def allowed_imports(args: argparse.Namespace) -> list[str]:
    """The modules a scenario file may import: those of ``--allow-import``
    and the ``module:Class`` estimators named on the command line."""
    named = list(getattr(args, "estimators", None) or ()) + [getattr(args, "estimator", None)]
    return list(args.allow_import) + [name for name in named if name and ":" in name]


def scenario_from_args(args: argparse.Namespace) -> Scenario | None:
    """The scenario file (or defaults) with the command-line overrides applied
    (None for ``replay``, whose scenario comes from its recording)."""
    if args.command in ("replay", "wahba", "broad", "inspect"):
        return None
    if args.command in ("tune", "landscape") and args.pc_exponent is not None:
        raise UsageError(f"pc_exponent = {args.pc_exponent!r}: {args.command} chooses "
                         "pc_exponent itself; leave --pc-exponent out (from --pc-exponent)")
    layers = [*(args.scenario or ()), *([set_layer(args.set)] if args.set else ())]
    try:
        scenario = (Scenario.from_toml(layers, allow_imports=allowed_imports(args))
                    if layers else Scenario())
    except InvalidParameterError as err:
        raise UsageError(file_named(err)) from None
    # All overrides at once: --tstop 0.001 --dt 1e-4 is checked against the new dt.
    given = {name: getattr(args, name) for name in SCENARIO_FLAGS
             if getattr(args, name) is not None}
    try:
        scenario = scenario.replace(**given)
    except InvalidParameterError as err:
        # Name the flag that set the value, or else the flags that changed its context.
        flags = [SCENARIO_FLAGS[err.name]] if err.name in given else \
            [SCENARIO_FLAGS[name] for name in given]
        raise UsageError(f"{err} (from {', '.join(flags)})") from None
    return scenario


def file_named(err: InvalidParameterError) -> str:
    """``err`` naming its setting as the files and ``--set`` do, the field
    after it (``gyro.noise_power (gyro_noise) = -1: ...``), where it names a
    scenario field that lives in a section."""
    setting = next((s for s in SETTINGS if s.field == err.name and s.section), None)
    if setting is None:
        return str(err)
    return str(InvalidParameterError(f"{setting.section}.{setting.key} ({err.name})",
                                     err.value, err.rule))


#: Scenario field → its section (None: a top-level key).
SECTION_OF = {setting.field: setting.section for setting in SETTINGS}
#: The sections that configure one attitude sensor: only the estimators that
#: read that sensor see them, and only where the scenario has it.
SENSOR_SECTIONS = frozenset({"star_tracker", "magnetometer", "sun_sensor", "coarse_sun_sensors",
                             "accelerometer"})


#: The settings only one star tracker model reads: setting → that model.
READ_BY_MODEL = {setting.field: setting.model for setting in SETTINGS if setting.model}
#: Why a setting of the other model changes nothing, by the chosen model.
MODEL_IGNORES = {
    "rotation": "has no effect with the rotation star tracker, whose noise is "
                "[star_tracker] sigma_arcsec",
    "workshop": "has no effect with the workshop star tracker, whose noise is "
                "[star_tracker] noise_power; set [star_tracker] model = \"rotation\"",
}


def ineffective_reason(field_name: str, scenario: Scenario, names) -> str | None:
    """Why setting ``field_name`` cannot change the results of estimators
    ``names`` on ``scenario`` (None if it can): its sensor is not in the
    scenario, the chosen star tracker model ignores it, or none of the
    estimators reads its sensor (:attr:`estimators.AttitudeEstimator.reads`;
    a user's class may read anything)."""
    from benchmarks.sensor_use import scenario_sensors
    section = SECTION_OF.get(field_name)
    if section in SENSOR_SECTIONS and section not in scenario_sensors(scenario):
        why = ("its model is none, or an outage spans the run" if section == "star_tracker"
               else f"no [{section}] section with an interval_s")
        return f"has no effect: the scenario has no {section} ({why})"
    reader = READ_BY_MODEL.get(field_name)
    if reader is not None and reader != scenario.star_tracker_model:
        return MODEL_IGNORES[scenario.star_tracker_model]
    if not names and field_name not in ("tstop", "dt"):
        return "has no effect on the truth alone (no estimator is run)"
    if section in SENSOR_SECTIONS:
        if any(name not in ESTIMATORS or section in ESTIMATORS[name].reads for name in names):
            return None
        readers = [name for name, cls in ESTIMATORS.items() if section in cls.reads]
        return (f"has no effect on {', '.join(names)}, which read no {section}; it is read "
                f"by {', '.join(readers)}")
    if section == "estimators.ekf" and all(name in ESTIMATORS and name != "ekf"
                                            for name in names):
        return f"has no effect on {', '.join(names)}; it is read only by ekf"
    return None


def check_effects(args, scenario: Scenario | None) -> None:
    """Refuse a flag (or a swept setting) that cannot change what the chosen
    estimators compute: its rows or numbers would be identical, silently."""
    if scenario is None or args.command in ("tune", "landscape", "workshop"):
        return
    names = getattr(args, "estimators", None)
    if names is None:
        names = (args.estimator,) if getattr(args, "estimator", None) else ()
    flags = {name: flag for name, flag in SCENARIO_FLAGS.items()
             if getattr(args, name, None) is not None}
    if args.command == "sweep":
        swept = SWEEP_PARAMETERS[args.param].field
        if swept in flags:
            raise UsageError(f"{swept} = {getattr(args, swept)!r}: the sweep sets it "
                             f"(--param {args.param}); leave {flags[swept]} out")
        flags[swept] = "--param " + args.param
    for field_name, flag in flags.items():
        reason = ineffective_reason(field_name, scenario, names)
        if reason:
            value = args.param if flag.startswith("--param") else getattr(args, field_name)
            raise UsageError(f"{flag.split()[0].lstrip('-').replace('-', '_')} = {value!r}: "
                             f"{reason} (from {flag})")


def default_estimators(command: str, scenario) -> tuple:
    """``--estimators`` when not given: with vector sensors, the filters and
    two static solvers (:data:`VECTOR_DEFAULTS`) for every command; else the
    workshop's three for ``compare`` and ``montecarlo``, and every star
    tracker estimator for ``consistency``; ``broad``'s and ``replay``'s own
    (:func:`benchmarks.broad.benchmark.default_estimators`,
    :data:`benchmarks.experiments.replay.DEFAULT_ESTIMATORS`)."""
    if command == "broad":
        from benchmarks.broad.benchmark import default_estimators as broad_defaults
        return broad_defaults()
    if command == "replay":
        from benchmarks.experiments.replay import DEFAULT_ESTIMATORS
        return DEFAULT_ESTIMATORS
    if scenario is not None and scenario.has_vector_sensors:
        from benchmarks.sensor_use import scenario_sensors, usable_estimators
        return usable_estimators(VECTOR_DEFAULTS, scenario_sensors(scenario))
    from benchmarks.simulation import WORKSHOP_ESTIMATORS
    return STAR_TRACKER_DEFAULTS if command == "consistency" else tuple(WORKSHOP_ESTIMATORS)


def check_sensors(args, scenario) -> None:
    """Refuse an estimator that can use none of the scenario's sensors
    (:func:`benchmarks.simulation.refuse_unreadable`), before any work."""
    if scenario is None or args.command in ("show-config", "workshop", "landscape"):
        return
    names = getattr(args, "estimators", None) or (
        (args.estimator,) if getattr(args, "estimator", None) else ())
    from benchmarks.sensor_use import refuse_unreadable, scenario_sensors
    refuse_unreadable(names, scenario_sensors(scenario), "the scenario")


def set_layer(assignments) -> dict:
    """The document of ``SECTION.KEY=VALUE`` assignments (``--set``), as the
    file saying ``[SECTION] KEY = VALUE`` reads: ``gyro.arw_deg_per_rthr=0.15``,
    ``star_tracker.model=rotation``, ``estimators.mekf.gyro_noise=1e-9``,
    ``tstop=10`` (a top-level key). The value is read as TOML (a number, a
    list, true), else as the string it is."""
    document = {}
    for assignment in assignments:
        name, equals, text = assignment.partition("=")
        keys = name.strip().split(".")
        if not equals or not all(key.strip() for key in keys) or not text.strip():
            raise InvalidParameterError("set", assignment, "must be SECTION.KEY=VALUE, e.g. "
                                        "gyro.arw_deg_per_rthr=0.15 (or KEY=VALUE for a "
                                        "top-level key)")
        try:
            value = tomllib.loads(f"value = {text.strip()}")["value"]
        except tomllib.TOMLDecodeError:
            value = text.strip()
        place = document
        for key in keys[:-1]:
            place = place.setdefault(key.strip(), {})
            if not isinstance(place, dict):
                raise InvalidParameterError("set", assignment, f"sets a key inside {key}, "
                                            "which is given a value")
        place[keys[-1].strip()] = value
    return document
