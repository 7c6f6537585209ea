"""Every key of a ``[recording]`` declaration, declared once: its section,
name, unit or values, meaning and default. :mod:`sensors.declared` refuses
any other key by these, and ``attitude-bench show-config --keys`` prints
them beside the scenario's (:data:`benchmarks.scenario.SETTINGS`)."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from dynamics.validation import InvalidParameterError


class RecordingKey(NamedTuple):
    section: str            # "recording", or a sensor's: "recording.gyro", …
    key: str
    unit: str               # its unit, or the values it takes
    meaning: str
    default: str = "required"


_SENSORS = ("gyro", "accelerometer", "magnetometer", "reference")
_UNITS = {"gyro": "rad/s, deg/s", "accelerometer": "m/s^2, g",
          "magnetometer": "uT, nT, gauss, mT"}

KEYS = (
    RecordingKey("recording", "file", "path", "the logged file, beside this one or absolute "
                 "(.csv, .parquet with `pip install '.[parquet]'`, .npz, .mat, .h5 or .hdf5 "
                 "with `'.[hdf5]'`; a CSV's opening lines that begin with `#` or `//` are "
                 "skipped, its separator and decimal comma found, and without a header its "
                 "columns are named 1, 2, …)",
                 "required unless each sensor names its own"),
    RecordingKey("recording", "description", "text", "what the recording is", '""'),
    RecordingKey("recording", "time_unit", "s, ms, us, ns or a number",
                 "the unit of every time column, or the seconds of one tick (`1e-4` for "
                 "an Xsens `SampleTimeFine`); a 16- or 32-bit counter's roll-over is "
                 "unwrapped", "s"),
    *(key for sensor in _SENSORS for key in (
        RecordingKey(f"recording.{sensor}", "file", "path",
                     "its own logged file, where a logger writes one file per sensor (its "
                     "time and columns are read there)", "[recording]'s"),
        RecordingKey(f"recording.{sensor}", "time", "column", "its time column (its own clock)"),
        RecordingKey(f"recording.{sensor}", "columns", "columns",
                     ("its 4 columns, or 3 of Euler angles" if sensor == "reference" else
                      "its 3 columns") + ", or one array's name"),
        RecordingKey(f"recording.{sensor}", "unit", _UNITS.get(sensor, "deg, rad"),
                     "the unit of its readings" if sensor != "reference" else
                     "the unit of Euler angles", "required" if sensor != "reference" else "deg"),
    )),
    *(RecordingKey(f"recording.{sensor}", "axes", "3 of x, y, z, -x, -y, -z",
                   "the device's x, y, z as this sensor's columns (a magnetometer mounted "
                   "apart from the gyro: [\"y\", \"x\", \"-z\"])", '["x", "y", "z"]')
      for sensor in ("gyro", "accelerometer", "magnetometer")),
    *(RecordingKey(f"recording.{sensor}", "scale", "a number",
                   "each reading is multiplied by it before its unit applies (raw counts: "
                   f"{example}); a unit that fits no unit's refusal names the scale that fits",
                   "1")
      for sensor, example in (("gyro", "1/131 for an MPU-6050 at ±250 °/s, unit deg/s"),
                              ("accelerometer", "1/16384 for an MPU-6050 at ±2 g, unit g"),
                              ("magnetometer", "0.15 for an AK8963 in 16-bit mode, unit uT"))),
    RecordingKey("recording.magnetometer", "calibrate", "true, false",
                 "fit its hard and soft iron to the recording (an ellipsoid fit)", "false"),
    RecordingKey("recording.magnetometer", "hard_iron", "its unit",
                 "a known hard iron, taken off every reading (in the device's axes, after "
                 "axes)", "none"),
    RecordingKey("recording.magnetometer", "soft_iron", "3 × 3",
                 "a known soft iron: field = inv(soft_iron) (reading − hard_iron), in the "
                 "device's axes", "identity"),
    RecordingKey("recording.reference", "order", "wxyz, xyzw", "a quaternion's order",
                 "wxyz"),
    RecordingKey("recording.reference", "sequence", "e.g. ZYX",
                 "Euler angles instead of a quaternion, in scipy's sequence", "none"),
    RecordingKey("recording.reference", "frame", "ENU, NED, Y-up",
                 "the world frame the reference turns into", "ENU"),
)


def refuse(path, key: str, value, rule: str):
    """Raise the one-line error naming the declaration ``path``, its key
    (``recording.gyro.unit``), the value and the rule."""
    where = f"{path.name}: {key}" if key else path.name
    raise InvalidParameterError(where, value, rule)


def choice(path, key: str, value, choices) -> str:
    """``value`` if it is one of ``choices``, else refused."""
    if not isinstance(value, str) or value not in choices:
        refuse(path, key, value, f"must be one of {', '.join(choices)}")
    return value


def known_keys(section: str) -> set:
    """The keys ``section`` (``"recording"``, ``"recording.gyro"``, …) may
    hold; a sensor's section in ``[recording]``."""
    keys = {key.key for key in KEYS if key.section == section}
    return keys | set(_SENSORS) if section == "recording" else keys


_AXES = {"x": 0, "y": 1, "z": 2}


def axes_matrix(value, where: str) -> np.ndarray:
    """The matrix that turns a sensor's readings into the device's axes,
    from an ``axes`` key (``["y", "x", "-z"]``: the device's x is the
    sensor's y, …): a signed permutation, refused in one line otherwise."""
    rule = 'must be three of "x", "y", "z", each once, each maybe with "-"'
    if not isinstance(value, list) or len(value) != 3 or \
            not all(isinstance(a, str) and a.lstrip("-") in _AXES for a in value):
        raise InvalidParameterError(where, value, rule)
    if sorted(a.lstrip("-") for a in value) != ["x", "y", "z"]:
        raise InvalidParameterError(where, value, rule)
    matrix = np.zeros((3, 3))
    for row, axis in enumerate(value):
        matrix[row, _AXES[axis.lstrip("-")]] = -1.0 if axis.startswith("-") else 1.0
    return matrix


def axes_names(matrix: np.ndarray) -> list:
    """The ``axes`` key of a signed permutation (:func:`axes_matrix`'s inverse)."""
    names = []
    for row in matrix:
        column = int(np.flatnonzero(row)[0])
        names.append(("-" if row[column] < 0 else "") + "xyz"[column])
    return names
