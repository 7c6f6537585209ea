"""Every key of a ``[recording]`` declaration, declared once: its section,
name, unit or values, meaning and default. :mod:`sensors.declared` refuses
any other key by these, and ``attitude-bench show-config --keys`` prints
them beside the scenario's (:data:`benchmarks.scenario.SETTINGS`)."""
from __future__ import annotations

from typing import NamedTuple


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
                 "(.csv, .parquet, .npz, .mat, .h5, .hdf5)"),
    RecordingKey("recording", "description", "text", "what the recording is", '""'),
    RecordingKey("recording", "time_unit", "s, ms, us, ns", "the unit of every time column",
                 "s"),
    *(key for sensor in _SENSORS for key in (
        RecordingKey(f"recording.{sensor}", "time", "column", "its time column (its own clock)"),
        RecordingKey(f"recording.{sensor}", "columns", "columns",
                     "its 3 columns (the reference's 4, or 3 Euler angles), or one array's "
                     "name"),
        RecordingKey(f"recording.{sensor}", "unit", _UNITS.get(sensor, "deg, rad"),
                     "the unit of its readings" if sensor != "reference" else
                     "the unit of Euler angles", "required" if sensor != "reference" else "deg"),
    )),
    RecordingKey("recording.magnetometer", "calibrate", "true, false",
                 "fit its hard and soft iron to the recording (an ellipsoid fit)", "false"),
    RecordingKey("recording.magnetometer", "hard_iron", "its unit",
                 "a known hard iron, taken off every reading", "none"),
    RecordingKey("recording.magnetometer", "soft_iron", "3 × 3",
                 "a known soft iron: field = inv(soft_iron) (reading − hard_iron)", "identity"),
    RecordingKey("recording.reference", "order", "wxyz, xyzw", "a quaternion's order",
                 "wxyz"),
    RecordingKey("recording.reference", "sequence", "e.g. ZYX",
                 "Euler angles instead of a quaternion, in scipy's sequence", "none"),
    RecordingKey("recording.reference", "frame", "ENU, NED",
                 "the world frame the reference turns into", "ENU"),
)


def known_keys(section: str) -> set:
    """The keys ``section`` (``"recording"``, ``"recording.gyro"``, …) may
    hold; a sensor's section in ``[recording]``."""
    keys = {key.key for key in KEYS if key.section == section}
    return keys | set(_SENSORS) if section == "recording" else keys
