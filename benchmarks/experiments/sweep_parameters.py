"""The settings ``sweep`` can vary, by their command-line name.

Apart from :mod:`benchmarks.experiments.runs` (which draws the sweep) so that
the command line lists them without importing matplotlib.
"""
from __future__ import annotations

from dataclasses import dataclass

from benchmarks.scenario import SECTIONS, SETTINGS


@dataclass(frozen=True)
class SweepParameter:
    """A scenario setting that ``sweep`` can vary, how its legend reads, and
    the conversion of a swept value to the field's unit (None: as given)."""

    field: str
    legend: str     # format string; {value} and {label} (the estimator's label)
    convert: object = None
    unit: str = ""  # of the swept value, as given


def _section_parameters() -> dict:
    """Every key a scenario section declares sweepable, as ``SECTION.KEY``."""
    units = {(setting.section, setting.key): setting.unit for setting in SETTINGS}
    return {f"{section}.{key}": SweepParameter(spec.field, f"{section}.{key} = {{value:g}}",
                                               spec.convert, units.get((section, key), ""))
            for section, keys in SECTIONS.items() for key, spec in keys.items()
            if spec.sweepable}


#: Sweepable settings by their command-line name: the workshop's four (the
#: settings declared with a ``sweep`` name), then every sweepable key of the
#: scenario's sections as ``SECTION.KEY`` (benchmarks.scenario.SETTINGS).
SWEEP_PARAMETERS = {
    **{setting.sweep: SweepParameter(setting.field, setting.legend, unit=setting.unit)
       for setting in SETTINGS if setting.sweep},
    **_section_parameters(),
}
