"""Which readings an estimator reads, and which it needs to be more than
dead reckoning.

Every estimator integrates the gyro. Beyond it, each declares two things
on its class:

* :attr:`~estimators.AttitudeEstimator.reads`, the sensors whose readings
  it can apply (a frozenset of the names below);
* :attr:`~estimators.AttitudeEstimator.needs`, the sets of sensors any one
  of which gives it an attitude reference: with none of them present it
  would only dead-reckon from its start (or hold it) and be printed under
  its own name. It is refused then (:func:`unusable_reason`).

The names are those of the scenario's sections and of the vector readings
(:class:`sensors.vector.VectorReadings.sensor`): ``star_tracker``,
``magnetometer``, ``sun_sensor``, ``coarse_sun_sensors``, ``accelerometer``.

A ground IMU's accelerometer fixes the inclination only: the rotation
about gravity (the heading) needs a second direction. An estimator that
reads nothing else of what is present is scored on its inclination
(:func:`heading_observed`).

A user's class that declares nothing (``reads = None``) is taken at its
word: it is never refused; the toolkit warns where it ignores vector
readings (:func:`benchmarks.simulation.vectors_for`).
"""
from __future__ import annotations

from itertools import combinations

STAR_TRACKER = "star_tracker"
MAGNETOMETER = "magnetometer"
SUN_SENSOR = "sun_sensor"
COARSE_SUN_SENSORS = "coarse_sun_sensors"
ACCELEROMETER = "accelerometer"

#: The vector sensors, in the order a scenario builds them.
VECTOR_SENSORS = (MAGNETOMETER, SUN_SENSOR, COARSE_SUN_SENSORS, ACCELEROMETER)
#: Every attitude sensor the toolkit simulates or reads from a recording.
ATTITUDE_SENSORS = (STAR_TRACKER, *VECTOR_SENSORS)
#: The direction each vector sensor measures: two sensors of one direction
#: (the fine and the coarse sun sensors) do not fix an attitude together.
DIRECTION = {MAGNETOMETER: "field", SUN_SENSOR: "sun", COARSE_SUN_SENSORS: "sun",
             ACCELEROMETER: "gravity"}

#: ``needs`` of a filter: any one attitude sensor (a vector sensor's
#: direction turns along an orbit, so one suffices over time).
ANY_ATTITUDE_SENSOR = tuple(frozenset({name}) for name in ATTITUDE_SENSORS)
#: ``needs`` of a static solver: two sensors of different directions at one time.
TWO_DIRECTIONS = tuple(frozenset(pair) for pair in combinations(VECTOR_SENSORS, 2)
                       if DIRECTION[pair[0]] != DIRECTION[pair[1]])


def _names(sensors) -> str:
    names = sorted(sensors)
    if not names:
        return "the gyro only"
    return ", ".join(names[:-1]) + (" and " if len(names) > 1 else "") + names[-1]


def _alternatives(needs) -> str:
    if tuple(needs) == ANY_ATTITUDE_SENSOR:
        return "an attitude sensor (a star tracker or a vector sensor)"
    if tuple(needs) == TWO_DIRECTIONS:
        return ("two vector sensors of different directions (two of a magnetometer, a sun "
                "sensor and an accelerometer)")
    groups = [_names(group) for group in needs]
    return " or ".join(f"({text})" if len(needs) > 1 and " and " in text else text
                       for text in groups)


def unusable_reason(cls, present) -> str | None:
    """Why estimator class ``cls`` cannot estimate an attitude from the
    sensors ``present`` (sensor names, the gyro aside), or None if it can
    (or does not declare what it reads)."""
    needs = getattr(cls, "needs", ())
    if getattr(cls, "reads", None) is None or not needs:
        return None
    present = frozenset(present)
    if any(group <= present for group in needs):
        return None
    return (f"needs {_alternatives(needs)}, and the data has {_names(present)}: it would "
            "only dead-reckon from its start and be scored under its own name")


def heading_observed(cls, present) -> bool:
    """Whether ``cls``'s estimate has a heading reference among ``present``:
    False when the only attitude sensor it reads there is the accelerometer
    (gravity fixes the inclination, not the rotation about it), or when the
    class says its output has none (:attr:`~estimators.AttitudeEstimator.has_heading`)."""
    if not getattr(cls, "has_heading", True):
        return False
    reads = getattr(cls, "reads", None)
    if reads is None:
        return True
    used = frozenset(reads) & frozenset(present)
    return used != {ACCELEROMETER}


def used_sensors(cls, present) -> frozenset:
    """The sensors among ``present`` that ``cls`` reads (all of them for a
    class that does not declare what it reads)."""
    reads = getattr(cls, "reads", None)
    return frozenset(present) if reads is None else frozenset(reads) & frozenset(present)
