"""What a logged file's columns are, before anything is read from them
(``attitude-bench inspect``): each sensor's columns and each one's time
column, by their names (a prefix naming the sensor, ``gyr``, ``acc``,
``mag``, ``quat`` …, and the axes ``x, y, z`` or ``w, x, y, z``; an (N, 3)
or (N, 4) array's own name; ROS's ``field.angular_velocity.x``; camelCase
``SampleTimeFine``) or, in a file without a header (columns ``"1"``,
``"2"`` …), by their values (:func:`columns_by_values`).
"""
from __future__ import annotations

import re

import numpy as np

from sensors.clocks import dequantized, unwrapped

#: Name tokens of each sensor's columns (the prefix before the axis letter).
SENSOR_TOKENS = {
    "gyro": ("gyr", "gyro", "omega", "angvel", "rate", "g", "w", "angular", "gyroscope"),
    "accelerometer": ("acc", "accel", "a", "f", "linear"),
    "magnetometer": ("mag", "magn", "m", "b", "field", "compass"),
    "reference": ("q", "quat", "opt", "ref", "orient", "att", "mocap", "orientation",
                  "attitude"),
}
#: Name tokens of a column that holds no sensor's readings (a ROS message's
#: covariances beside its orientation).
NOT_READINGS = ("covariance", "cov", "std", "var", "sigma")
#: The first word of a ROS message's fields as ``rostopic echo -p`` writes
#: them (``field.angular_velocity.x``), which names no sensor.
MESSAGE_PREFIX = "field"
#: Name tokens of a time column (``micros``: an Arduino's; ``stamp``: ROS's).
TIME_TOKENS = ("t", "time", "times", "timestamp", "ts", "sec", "seconds", "ms", "stamp",
               "micros", "millis", "nanos", "epoch")
_AXIS = re.compile(r"^(?P<prefix>.*?)[\s._-]*(?P<axis>[wxyz])$", re.IGNORECASE)
#: A quaternion's numbered columns, q0 the scalar (Madgwick's q0…q3).
_NUMBERED = re.compile(r"^(?P<prefix>.*?)[\s._-]*(?P<index>[0-3])$")


def _words(name: str) -> list:
    """A name's words: split at what is not a letter and where camelCase
    turns (``SampleTimeFine``: sample, time, fine)."""
    return [token for token in re.split(r"[^a-z]+", re.sub(
        r"([a-z])([A-Z])", r"\1 \2", name).lower()) if token]


def _bare(name: str) -> str:
    """A column's name without the unit in brackets after it (phyphox's
    ``Gyroscope x (rad/s)``, ``Magnetic field x (µT)``)."""
    return re.sub(r"\s*[(\[][^)\]]*[)\]]\s*$", "", name).strip() or name


def _tokens(name: str) -> set:
    return set(_words(name))


def _sensor_of(prefix: str) -> str | None:
    """The sensor a column prefix names, if exactly one: by its first word
    where that names one (``acc_m_s2``: the unit's ``m`` is no
    magnetometer), else by all its words."""
    words = _words(prefix)
    if len(words) > 1 and words[0] == MESSAGE_PREFIX:
        words = words[1:]
    if set(words) & set(NOT_READINGS):
        return None
    for tokens in ({words[0]} if words else set(), set(words) | {prefix.lower()}):
        named = [sensor for sensor, names in SENSOR_TOKENS.items()
                 if tokens & set(names) or any(token.startswith(names[0]) for token in tokens)]
        if len(named) == 1:
            return named[0]
    return None


def sensor_columns(table: dict) -> dict:
    """Sensor → its columns (a list of 3, or 4 for the reference, in the
    file's order; or one array's name) as the names suggest."""
    groups = {}
    for name, values in table.items():
        array = np.asarray(values)
        if array.dtype.kind not in "iuf":
            continue                       # text or mixed cells: no sensor's column
        if sum(size > 1 for size in array.shape) == 1:
            array = array.reshape(-1)      # MATLAB keeps a vector as (1, N)
        if array.ndim == 2 and (3 in array.shape or 4 in array.shape):
            width = 4 if 4 in array.shape else 3
            sensor = _sensor_of(name)
            if sensor and (sensor == "reference") == (width == 4):
                groups.setdefault(sensor, name)
            continue
        match = _AXIS.match(_bare(name))
        if match and array.ndim == 1:
            groups.setdefault(match["prefix"], {})[match["axis"].lower()] = name
        numbered = _NUMBERED.match(_bare(name))
        if not match and numbered and array.ndim == 1 and numbered["prefix"] \
                and _sensor_of(numbered["prefix"]) == "reference":
            groups.setdefault(numbered["prefix"], {})["wxyz"[int(numbered["index"])]] = name
    found = {}
    for prefix, axes in groups.items():
        if isinstance(axes, str):
            found.setdefault(prefix, axes)
            continue
        sensor = _sensor_of(prefix)
        wanted = "wxyz" if sensor == "reference" else "xyz"
        lengths = {np.asarray(table[axes[axis]]).size for axis in wanted if axis in axes}
        if sensor and set(axes) >= set(wanted) and sensor not in found and len(lengths) == 1:
            found[sensor] = [axes[axis] for axis in wanted]
    return found


#: A time column may go back or repeat at this share of its steps at most
#: (a duplicated row, two rows swapped), which the declaration's loading
#: then mends or names: it is still the time column.
TIME_BACK_SHARE = 0.01


def time_columns(table: dict) -> list[str]:
    """The columns named as times whose readings increase: those that always
    do first, then those that go back or repeat at :data:`TIME_BACK_SHARE`
    of their steps at most, then those printed coarser than their clock,
    which increase once spread as the loader spreads them
    (:func:`sensors.clocks.dequantized`)."""
    names, nearly, coarse = [], [], []
    for name, values in table.items():
        steps = _time_steps(values)
        if steps is None or not _tokens(name) & set(TIME_TOKENS):
            continue
        if np.all(steps > 0):
            names.append(name)
        elif np.mean(steps <= 0) <= TIME_BACK_SHARE:
            nearly.append(name)
        elif np.all(_time_steps(values, spread=True) > 0):
            coarse.append(name)
    return names + nearly + coarse


def _time_steps(values, spread: bool = False) -> np.ndarray | None:
    """A column's steps as times (a counter's roll-over unwrapped, empty
    cells left out; with ``spread``, times printed coarser than their clock
    spread as the loader spreads them); None where it is not one column of
    numbers, or holds fewer than two."""
    raw = np.asarray(values)
    if raw.dtype.kind not in "iuf" or sum(size > 1 for size in raw.shape) != 1:
        return None
    times = unwrapped(raw.reshape(-1)).astype(float)
    times = times[~np.isnan(times)]
    if spread:
        times = dequantized(times)
    return np.diff(times) if len(times) > 1 else None


def column_values(table: dict, columns) -> np.ndarray:
    if isinstance(columns, str):
        array = np.asarray(table[columns], dtype=float)
        return array.T if array.shape[0] in (3, 4) and array.shape[1] not in (3, 4) else array
    return np.column_stack([np.asarray(table[name], dtype=float).reshape(-1)
                            for name in columns])


def time_for(sensor: str, columns, times: list, table: dict) -> str:
    """The sensor's time column: one whose name names it (its columns'
    prefix, ``t_acc`` beside ``acc_x``, or a word of the sensor's,
    ``t_mag_ms`` beside ``mx``), else one that holds a time exactly where
    its columns hold a reading (a merged table's own clock), else the first."""
    names = [columns] if isinstance(columns, str) else columns
    words = set().union(*(_tokens(name) for name in names)) - set("wxyz")
    unread = np.isnan(column_values(table, columns)).any(axis=1)

    def names_it(time: str) -> bool:
        rest = _tokens(time) - set(TIME_TOKENS)
        return bool(rest & words) or any(_sensor_of(token) == sensor for token in rest)

    def reads_with_it(time: str) -> bool:
        stamps = np.asarray(table[time], dtype=float)
        return stamps.shape == unread.shape and np.array_equal(np.isnan(stamps), unread)

    return ([time for time in times if names_it(time)]
            or [time for time in times if reads_with_it(time)] or times)[0]


#: A vector sensor's norm is steady (gravity, the field: its 10th percentile
#: at least this share of its median); a gyro's is not (near 0 at rest).
STEADY_SHARE = 0.5


def headerless(table: dict) -> bool:
    """Whether ``table``'s columns are a file's without a header (named
    ``"1"``, ``"2"`` …: :mod:`sensors.tables`)."""
    return bool(table) and list(table) == [str(i) for i in range(1, len(table) + 1)]


def columns_by_values(table: dict) -> tuple[dict, list]:
    """``(sensor → its columns, [the time column])`` of a file without a
    header, told by the values: the first column whose times increase is
    the time; the others, in the file's order, make triples (or a
    quadruple of unit norm, a quaternion, scalar first assumed): a steady
    norm is the accelerometer's or the magnetometer's, whichever unit puts
    it nearer its :data:`~sensors.declared_units.TYPICAL_NORMS` (an
    accelerometer in g and a field in gauss both read about 1: 1 g is
    exactly g), and an unsteady one the gyro's. What is not told is left out (the caller says so)."""
    from sensors.declared_units import TYPICAL_NORMS, UNITS
    names = [name for name in table if np.asarray(table[name]).dtype.kind in "iuf"]
    times = [name for name in names
             if (steps := _time_steps(table[name])) is not None and np.all(steps > 0)][:1]
    rest, found, i = [name for name in names if name not in times], {}, 0
    while i + 3 <= len(rest):
        four = rest[i:i + 4]
        values = column_values(table, four) if len(four) == 4 else None
        if values is not None and "reference" not in found and np.allclose(
                np.linalg.norm(values[~np.isnan(values).any(axis=1)], axis=1), 1.0, atol=0.01):
            found["reference"], i = four, i + 4
            continue
        values = column_values(table, rest[i:i + 3])
        norms = np.linalg.norm(values[~np.isnan(values).any(axis=1)], axis=1)
        median = float(np.median(norms)) if len(norms) else 0.0
        if median > 0 and np.percentile(norms, 10) >= STEADY_SHARE * median:
            sensor = min(TYPICAL_NORMS, key=lambda name: min(
                abs(np.log(median * factor / TYPICAL_NORMS[name]))
                for factor in UNITS[name].values()))
        else:
            sensor = "gyro"
        found.setdefault(sensor, rest[i:i + 3])
        i += 3
    return found, times

