"""``show-config``: every estimator's effective settings, and where each came from.

An estimator built from a scenario (:meth:`estimators.AttitudeEstimator.from_scenario`)
takes each constructor keyword from one of four places, in this order of
precedence:

``file``     the scenario's ``[estimators.NAME]`` section;
``scenario`` a scenario setting the file (or a flag) gives;
``derived``  derived from the scenario's sensors (the EKF's ``Q``, ``R`` and
             ``P₀``, the six-state filters' noise densities and ``R``, dead
             reckoning's rate timing, the EKF's output);
``default``  the estimator's own default, or a scenario setting left at its default.
"""
from __future__ import annotations

import dataclasses
import inspect

import numpy as np

from benchmarks.scenario import Scenario, field_names
from estimators import resolve_estimator

SOURCES = ("file", "scenario", "derived", "default")
#: Scenario fields whose default is to be derived (None until then).
_DERIVED_UNLESS_GIVEN = frozenset(f.name for f in dataclasses.fields(Scenario) if f.default is None)


def given_fields(paths=(), flags=()) -> frozenset:
    """The scenario fields a user gave: in the files ``paths`` (in any of a
    key's units or places) or as the flags ``flags`` (field names). A value
    given is ``scenario``, even where it equals the default."""
    from benchmarks.scenario import flatten_sections, read_toml
    given = set(flags)
    for path in paths or ():
        given.update(key for key in flatten_sections(read_toml(path)) if key != "estimator_options")
    return frozenset(given)


def effective_settings(scenario: Scenario, name: str, given=frozenset()) -> list[dict]:
    """Rows ``{estimator, setting, value, source, from}`` for each constructor
    keyword of estimator ``name`` as ``scenario`` builds it (``given``: the
    fields the user gave, :func:`given_fields`)."""
    cls = resolve_estimator(name)
    section = cls.scenario_section(scenario)
    scenario_values = cls.settings_from_scenario(scenario)
    defaults = Scenario()
    rows = []
    for keyword, parameter in inspect.signature(cls.__init__).parameters.items():
        if parameter.kind is not inspect.Parameter.KEYWORD_ONLY:
            continue
        field = "dt" if keyword == "dt" else cls.scenario_defaults.get(keyword)
        if keyword in section:
            value, source, origin = section[keyword], "file", f"[estimators.{name}]"
        elif keyword in scenario_values:
            value = scenario_values[keyword]
            source, origin = _scenario_source(scenario, defaults, field, given)
        else:
            value, source, origin = parameter.default, "default", cls.__name__
        if keyword in ("initial_state",) and value is None:
            continue                        # a former name, not a setting of its own
        rows.append({"estimator": name, "setting": keyword, "value": _shown(value),
                     "source": source, "from": origin})
    return rows


def _scenario_source(scenario: Scenario, defaults: Scenario, field: str | None, given):
    """Where a keyword taken from the scenario came from."""
    if field in given:
        return "scenario", f"scenario {field}"
    if field is None:
        return "derived", "the scenario's sensors"
    if field not in field_names():
        return "derived", f"the sensors ({field})"
    if field in scenario.derived_fields:
        return "derived", f"the sensors ({field})"
    if field in _DERIVED_UNLESS_GIVEN:        # not derived: the file or a flag gave it
        return "scenario", f"scenario {field}"
    if field != "dt" and _same(getattr(scenario, field), getattr(defaults, field)):
        return "default", f"scenario {field}"
    return "scenario", f"scenario {field}"


def _same(a, b) -> bool:
    try:
        return bool(np.array_equal(np.asarray(a), np.asarray(b)))
    except (TypeError, ValueError):
        return a == b


def _shown(value) -> str:
    """A value as one short line."""
    if isinstance(value, np.ndarray):
        if value.ndim == 2 and value.shape[0] == value.shape[1] and \
                np.allclose(value, np.diag(np.diag(value))):
            diagonal = np.diag(value)
            if np.all(diagonal == diagonal[0]):
                return f"{diagonal[0]:.6g} I{len(diagonal)}"
            return "diag(" + ", ".join(f"{v:.6g}" for v in diagonal) + ")"
        return np.array2string(value, precision=6, separator=", ").replace("\n", "")
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_shown(v) for v in value) + "]"
    return str(value)


def format_settings(rows: list[dict]) -> str:
    """The printed table, one estimator after another."""
    if not rows:
        return "(no settings)"
    width = max(len(row["setting"]) for row in rows)
    value_width = min(44, max(len(row["value"]) for row in rows))
    lines, current = [], None
    for row in rows:
        if row["estimator"] != current:
            current = row["estimator"]
            lines.append(("" if not lines else "\n") + f"[{current}]")
        lines.append(f"  {row['setting']:<{width}}  {row['value']:<{value_width}}  "
                     f"{row['source']:<8} {row['from']}")
    return "\n".join(lines)


def key_reference() -> str:
    """Every key of a scenario file (:data:`benchmarks.scenario.SETTINGS`,
    its default from :class:`Scenario`) and of a ``[recording]`` file
    (:data:`sensors.recording_keys.KEYS`), as two Markdown tables: the
    README's key reference, generated from the one declaration of each."""
    from benchmarks.scenario import SETTINGS
    from sensors.recording_keys import KEYS
    defaults = Scenario()
    lines = ["| section | key | unit | meaning | default |", "|---|---|---|---|---|"]
    for setting in SETTINGS:
        default = getattr(defaults, setting.field)
        lines.append(_row(f"[{setting.section}]" if setting.section else "(top level)",
                          setting.key, setting.unit, setting.doc,
                          "none" if default is None else _shown(default)))
    lines += ["", "| section | key | unit or values | meaning | default |",
              "|---|---|---|---|---|"]
    lines += [_row(f"[{key.section}]", key.key, key.unit, key.meaning, key.default)
              for key in KEYS]
    return "\n".join(lines) + "\n"


def _row(*cells) -> str:
    return "| " + " | ".join(f"`{cells[1]}`" if i == 1 else str(cell).replace("|", "\\|")
                             for i, cell in enumerate(cells)) + " |"


__all__ = ["SOURCES", "effective_settings", "format_settings", "key_reference"]
