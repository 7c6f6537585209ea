"""A scenario read by the sections of its file (issue 31).

Each section of :data:`~benchmarks.scenario.settings.SECTIONS` is a read-only
attribute of a :class:`~benchmarks.scenario.Scenario` whose attributes are
that section's keys, with the names and units the file gives them::

    scenario.gyro.arw_deg_per_rthr      # deg/√h, from the field gyro_noise (rad²/s)
    scenario.magnetometer.sigma_nT      # the field magnetometer_sigma_nT
    scenario.truth.initial_rate_radps   # the field initial_rate_radps

A key in datasheet units is converted back from the field it sets (its
``read_back``, declared beside its conversion in
:data:`~benchmarks.scenario.settings.DATASHEET_KEYS`); any other key is the
field's value itself. Top-level keys (``tstop``, ``dt``, ``initial_state``)
are attributes of the scenario already. A view only reads: a scenario is
changed with :meth:`~benchmarks.scenario.Scenario.replace`, which takes a
section's keys by the same names (``scenario.replace(gyro={"arw_deg_per_rthr":
0.15})``).
"""
from __future__ import annotations

from benchmarks.scenario.settings import SECTIONS, flatten_sections, plain_value
from dynamics.validation import InvalidParameterError


class SectionView:
    """One ``[section]`` of a scenario, its keys as attributes (read-only)."""

    __slots__ = ("_scenario", "_section")

    def __init__(self, scenario, section: str):
        object.__setattr__(self, "_scenario", scenario)
        object.__setattr__(self, "_section", section)

    def __getattr__(self, key: str):
        if key.startswith("_"):          # not a key (and no recursion on a bare instance)
            raise AttributeError(key)
        keys = SECTIONS[self._section]
        spec = keys.get(key)
        if spec is None:
            raise AttributeError(f"[{self._section}] has no key {key!r}; its keys: "
                                 f"{', '.join(keys)}")
        value = getattr(self._scenario, spec.field)
        return spec.read_back(value) if spec.read_back is not None else value

    def __setattr__(self, key: str, value) -> None:
        raise AttributeError(f"[{self._section}] of a scenario is read-only; change it with "
                             f"scenario.replace({self._section}={{{key!r}: ...}})")

    def __reduce__(self):            # copy and pickle: the same section of the scenario
        return SectionView, (self._scenario, self._section)

    def __dir__(self) -> list[str]:
        return list(SECTIONS[self._section])

    def __repr__(self) -> str:
        return f"<[{self._section}] of a Scenario: {', '.join(SECTIONS[self._section])}>"


def section_view(section: str) -> property:
    """The read-only property that gives ``section`` of a scenario."""
    return property(lambda scenario: SectionView(scenario, section),
                    doc=f"The [{section}] section, its keys as the file writes them: "
                        f"{', '.join(SECTIONS[section])} (:class:`SectionView`).")


def add_section_views(cls, *, leave_out=()) -> None:
    """Give ``cls`` a :func:`section_view` for each section but ``leave_out``;
    a section whose name ``cls`` already uses is refused, not hidden."""
    for section in SECTIONS:
        if section in leave_out:
            continue
        if hasattr(cls, section):
            raise TypeError(f"[{section}] would hide {cls.__name__}.{section}; leave it out "
                            "of the section views or rename one of them")
        setattr(cls, section, section_view(section))


def field_changes(changes: dict, fields) -> dict:
    """:meth:`~benchmarks.scenario.Scenario.replace`'s ``changes`` as values of
    ``fields``: a section's keys, given as ``SECTION={KEY: value}`` or as
    ``SECTION.KEY`` (``--set``'s name), read as the file's ``[SECTION]`` reads
    them (datasheet units included, :func:`flatten_sections`); a field's
    name as it is. An unknown name is refused, naming the known ones."""
    document = {}
    for name, value in changes.items():
        section, dot, key = name.partition(".")
        if name in SECTIONS:
            if not isinstance(value, dict):
                example = next(iter(SECTIONS[name]))
                raise InvalidParameterError(name, plain_value(value), "must be a dict of the "
                                            f"section's keys, e.g. {name}={{{example!r}: ...}}")
            section, items = name, value.items()
        elif dot and section in SECTIONS:
            items = ((key, value),)
        else:
            document[name] = value
            continue
        keys = document.setdefault(section, {})
        for item, item_value in items:
            if item in keys:
                raise InvalidParameterError(f"{section}.{item}", plain_value(item_value),
                                            "is given twice")
            keys[item] = item_value
    flat = flatten_sections(document)
    unknown = sorted(set(flat) - set(fields))
    if unknown:
        raise InvalidParameterError(unknown[0], flat[unknown[0]], "is not a scenario setting; "
                                    f"known: {', '.join(fields)}; or a section's keys, e.g. "
                                    "gyro={'arw_deg_per_rthr': ...}")
    return flat
