"""Which sensors the data has, which estimators can use them, and what each
made of them: so that no number is printed under an estimator's name that
is not that estimator's use of the data.

* :func:`present_sensors` and :func:`scenario_sensors` — the attitude
  sensors a record holds, or a scenario declares (the names of
  :mod:`estimators.sensing`);
* :func:`refuse_unreadable` — one line for an estimator that can use none
  of them (it would dead-reckon from its start under its own name);
  :func:`usable_estimators` for default lists, which leave it out;
* :class:`Usage` — what one run of an estimator made of its readings
  (offered, rejected, used; whether it had a heading reference), summed over
  the runs of a campaign (:meth:`Usage.combined`), and said as a note in the
  tables and as a tag in the figures' legends (:meth:`Usage.note`,
  :func:`tagged_label`);
* :func:`warn_unmodelled` — what the simulated truth has that no estimator
  models (a magnetometer's hard and soft iron).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from dynamics.validation import InvalidParameterError
from estimators import resolve_estimator, sensing


def present_sensors(sensors) -> frozenset:
    """The attitude sensors that took at least one reading in ``sensors`` (a
    :class:`~benchmarks.simulation.SensorData`; the gyro aside)."""
    names = {readings.sensor for readings in sensors.vectors if np.any(readings.available)}
    if np.any(sensors.available):
        names.add(sensing.STAR_TRACKER)
    return frozenset(names)


def scenario_sensors(scenario) -> frozenset:
    """The attitude sensors ``scenario`` declares: its vector sensors, and its
    star tracker unless its model is ``"none"`` or an outage spans the run."""
    names = {sensor.name for sensor in scenario.build_vector_sensors()}
    out_throughout = any(start <= 0.0 and stop >= scenario.tstop
                         for start, stop in scenario.star_tracker_outages_s)
    if scenario.star_tracker_model != "none" and not out_throughout:
        names.add(sensing.STAR_TRACKER)
    return frozenset(names)


def _class_of(item):
    return resolve_estimator(item) if isinstance(item, str) else type(item)


def refuse_unreadable(estimators, present, where: str = "the data") -> None:
    """Refuse (one line) an estimator that can use none of the sensors
    ``present`` (:func:`estimators.sensing.unusable_reason`)."""
    for item in estimators:
        cls = _class_of(item)
        reason = sensing.unusable_reason(cls, present)
        if reason:
            key = item if isinstance(item, str) else cls.name
            raise InvalidParameterError("estimator", key, reason.replace("the data", where))


def usable_estimators(estimators, present) -> tuple:
    """The estimators of ``estimators`` that can use the sensors ``present``
    (for default lists: those that cannot are left out, not refused)."""
    return tuple(name for name in estimators
                 if sensing.unusable_reason(resolve_estimator(name), present) is None)


#: The short form of each kind of note, for figure legends.
NOTE_TAGS = {"inclination only": "inclination only", "used none": "no reading used"}


@dataclass
class Usage:
    """What runs of one estimator made of their readings: readings offered
    and rejected by sensor (None where not counted: the engine counts only
    its vector readings' rejections), runs that used none of theirs, and
    whether it had a heading reference."""

    runs: int = 1
    offered: dict | None = field(default_factory=dict)
    rejected: dict = field(default_factory=dict)
    unused_runs: int = 0
    heading: bool = True

    @classmethod
    def of(cls, estimator, present) -> "Usage":
        """A per-run estimator's, after its run on data with sensors ``present``."""
        offered = dict(getattr(estimator, "offered", {}))
        unused = bool(getattr(estimator, "needs", ()) and sum(offered.values())
                      and estimator.readings_used() == 0)
        return cls(offered=offered, rejected=dict(getattr(estimator, "rejected", {})),
                   unused_runs=int(unused),
                   heading=sensing.heading_observed(type(estimator), present))

    @classmethod
    def combined(cls, usages) -> "Usage":
        """The usages of several runs as one (counts summed)."""
        usages = list(usages)
        total = cls(runs=0, offered={}, heading=all(u.heading for u in usages))
        for usage in usages:
            total.runs += usage.runs
            total.unused_runs += usage.unused_runs
            if usage.offered is None or total.offered is None:
                total.offered = None
            else:
                for sensor, count in usage.offered.items():
                    total.offered[sensor] = total.offered.get(sensor, 0) + count
            for sensor, count in usage.rejected.items():
                total.rejected[sensor] = total.rejected.get(sensor, 0) + count
        return total

    def note(self) -> str:
        """What the numbers are where they are not plain ("" when they are)."""
        notes = [] if self.heading else ["inclination only: no heading reference"]
        if self.unused_runs:
            runs = "" if self.runs == 1 else f" in {self.unused_runs} of {self.runs} runs"
            notes.append(f"used none of its readings{runs}: the gyro's estimate from its start")
        for sensor, count in self.rejected.items():
            if not count:
                continue
            offered = (self.offered or {}).get(sensor)
            notes.append(f"rejected {100.0 * count / offered:.3g}% of {offered:,} {sensor} "
                         "readings" if offered else
                         f"rejected {count / self.runs:.4g} {sensor} readings a run")
        return "; ".join(notes)


def tagged_label(label: str, note: str) -> str:
    """``label`` with the short form of ``note`` (:data:`NOTE_TAGS`), so that
    a figure's legend says what the curve is."""
    tags = [tag for start, tag in NOTE_TAGS.items() if start in note]
    return f"{label} [{', '.join(tags)}]" if tags else label


def _estimates_hard_iron(item, scenario) -> bool:
    """Whether estimator ``item`` (a name or a per-run object), as
    ``scenario`` configures it, estimates the magnetometer's hard iron (the
    MEKF's ``magnetometer_bias_states``, or the IMU models' online fit,
    ``hard_iron_fit``)."""
    from estimators.mekf import estimates_hard_iron
    if isinstance(item, str):
        cls = _class_of(item)
        if not {"magnetometer_bias_states", "hard_iron_fit"} & set(
                getattr(cls, "option_names", tuple)()):
            return False
        settings = cls.configured_settings(scenario)
    else:
        settings = getattr(item, "__dict__", {})
    return estimates_hard_iron(settings) or bool(settings.get("hard_iron_fit", False))


def warn_unmodelled(scenario, estimators, references=None) -> None:
    """Say (a warning, once) what the scenario's truth has that no estimator
    among ``estimators`` models: a magnetometer's hard or soft iron (a hard
    iron alone is modelled by a filter that estimates it). Its
    error is then in every magnetometer reading, and in the estimates by
    about the hard iron over the field (a ``|b| / |B|`` rad tilt of the
    field's direction)."""
    if scenario.magnetometer_interval_s is None:
        return
    readers = [item for item in estimators
               if sensing.MAGNETOMETER in (getattr(_class_of(item), "reads", None) or ())]
    hard = np.asarray(scenario.magnetometer_bias_nT, dtype=float)
    soft = np.asarray(scenario.magnetometer_soft_iron, dtype=float)
    if np.any(hard) and np.array_equal(soft, np.eye(3)):
        readers = [item for item in readers if not _estimates_hard_iron(item, scenario)]
    if not readers or (not np.any(hard) and np.array_equal(soft, np.eye(3))):
        return
    what = " and ".join(part for part, present in (
        (f"hard iron (bias_nT = {hard.tolist()})", np.any(hard)),
        (f"soft iron (soft_iron = {soft.tolist()})", not np.array_equal(soft, np.eye(3))))
        if present)
    size = ""
    if np.any(hard) and references is not None and references.magnetic_field_nT is not None:
        strength = float(np.median(np.linalg.norm(references.magnetic_field_nT, axis=1)))
        size = (f"; the hard iron against the field ({strength:,.0f} nT) is about "
                f"{np.degrees(np.linalg.norm(hard) / strength):.2g}°")
    warnings.warn(f"the magnetometer's {what} is in the simulated readings but in no "
                  f"estimator's model ({', '.join(map(str, readers))}): its error is in their "
                  f"estimates{size} (sensors.magnetometer_calibration.twostep estimates a "
                  "hard iron from the readings and the field's norm)", stacklevel=3)
