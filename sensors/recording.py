"""Real sensors: a recorded gyro and an independent reference attitude.

A :class:`Recording` is what a motion-capture trial gives: a gyro sampled at
a fixed rate (body frame, rad/s) and, on the same samples, a reference
attitude from an optical system (unit quaternions, body → reference frame,
scalar first, as everywhere in this project), with rows of NaN where the
markers were not seen, and a flag marking the movement phase — before it the
sensor rests, which gives the gyro's bias at switch-on.

:func:`load_recording` reads one from a numpy ``.npz`` archive with the keys
of the BROAD dataset (Laidig et al., *Data* 6(7), 2021) and checks it, so a
malformed file is one clear error, not a traceback deep in a filter.
"""
from __future__ import annotations

import warnings
import zipfile
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from dynamics.validation import MAX_MEASURED_RATE_RADPS, InvalidParameterError
from sensors.turning import (first_fitting, reference_advice, reference_fit, reference_fits,
                             reference_problem)
from sensors.vector import readings_taken

#: The archive's keys: the gyro (N, 3) rad/s, the reference (N, 4), the
#: movement flags (N,) and the sampling rate; ``info`` is optional.
#: The sampling rates a recording may have, Hz.
MIN_RATE_HZ, MAX_RATE_HZ = 0.01, 1e6
REQUIRED_KEYS = ("imu_gyr_radps", "opt_quat", "movement", "sampling_rate_hz")
#: The optional vector channels: the accelerometer (N, 3) m/s², the
#: magnetometer (N, 3) µT.
VECTOR_KEYS = ("imu_acc_mps2", "imu_mag_uT")
#: The largest reading each vector channel may hold, per axis, in its unit:
#: ten times the widest range of such sensors (a high-g MEMS accelerometer's
#: ±200 g, about 2,000 m/s²; a MEMS magnetometer's ±4.9 mT, 4,900 µT). A
#: larger finite reading (1e300) is a corrupt file, and its square, which
#: every filter and every variance takes, overflows.
VECTOR_LIMITS = {"imu_acc_mps2": (2e4, "m/s²"), "imu_mag_uT": (5e4, "µT")}
#: Plausible medians of each vector sensor's norm in its toolkit unit: in
#: motion an accelerometer's median stays near g; the Earth's field is 22 to
#: 67 µT (:data:`estimators.imu.heading.EARTH_FIELD_NORM_UT`), a room's or a
#: vehicle's disturbances allowed for. Outside them the unit is wrong (a
#: field in nT or gauss, an acceleration in g), not the sensor.
PLAUSIBLE_NORMS = {"accelerometer": (4.0, 20.0), "magnetometer": (5.0, 500.0)}
#: The sensor of each vector channel.
VECTOR_SENSORS = {"imu_acc_mps2": "accelerometer", "imu_mag_uT": "magnetometer"}
#: A reference quaternion may be off unit length by this much (rounding of
#: the recording, not a different convention or scale).
UNIT_TOLERANCE = 1e-6


@dataclass(frozen=True)
class Recording:
    """A recorded trial.

    Attributes
    ----------
    name : str
    gyro_radps : (N, 3) gyro readings, rad/s, body frame
    reference_quat : (N, 4) reference attitude, scalar-first, body → reference;
        NaN rows where there is none
    movement : (N,) bool, the movement phase
    rate_hz : float, sampling rate
    info : str, the recording's own description
    accelerometer_mps2 : (N, 3) or None, the accelerometer's specific force,
        m/s², body frame (gravity reads +up at rest)
    magnetometer_uT : (N, 3) or None, the magnetometer, µT, body frame
    magnetometer_timed : bool, its readings already taken at their samples'
        times (a delay taken out: :mod:`sensors.delay`), so none is taken
        out again
    """

    name: str
    gyro_radps: np.ndarray
    reference_quat: np.ndarray
    movement: np.ndarray
    rate_hz: float
    info: str = ""
    accelerometer_mps2: np.ndarray | None = None
    magnetometer_uT: np.ndarray | None = None
    magnetometer_timed: bool = False

    @property
    def has_vectors(self) -> bool:
        """Whether the accelerometer and the magnetometer were recorded."""
        return self.accelerometer_mps2 is not None and self.magnetometer_uT is not None

    @property
    def dt(self) -> float:
        return 1.0 / self.rate_hz

    @property
    def n_samples(self) -> int:
        return len(self.gyro_radps)

    @property
    def time_s(self) -> np.ndarray:
        return np.arange(self.n_samples) * self.dt

    @property
    def has_reference(self) -> np.ndarray:
        """(N,) bool: samples with a reference attitude."""
        return ~np.isnan(self.reference_quat).any(axis=1)

    @property
    def rest_samples(self) -> slice:
        """The initial rest: every sample before the movement phase starts."""
        return slice(0, int(np.argmax(self.movement)) if self.movement.any() else self.n_samples)

    def rest_gyro_radps(self) -> np.ndarray:
        """``(R, 3)``: the gyro's readings over the initial rest (none where
        the recording moves from its first sample), rad/s."""
        return self.gyro_radps[self.rest_samples]

    def rest_gyro_mean_radps(self) -> np.ndarray:
        """The gyro's mean over the initial rest: its bias at switch-on (rad/s);
        NaN where the recording has none (it moves from its first sample)."""
        rest = self.rest_gyro_radps()
        return rest.mean(axis=0) if len(rest) else np.full(3, np.nan)

    def reference_gaps(self) -> list[tuple[int, int]]:
        """Runs of samples without a reference, as ``[start, stop)`` index pairs."""
        return true_runs(~self.has_reference)

    def from_sample(self, start: int) -> "Recording":
        """The recording from sample ``start`` on."""
        return replace(self, gyro_radps=self.gyro_radps[start:],
                       reference_quat=self.reference_quat[start:],
                       movement=self.movement[start:],
                       accelerometer_mps2=_rows_from(self.accelerometer_mps2, start),
                       magnetometer_uT=_rows_from(self.magnetometer_uT, start))


    def until_sample(self, stop: int) -> "Recording":
        """The recording before sample ``stop``."""
        return replace(self, gyro_radps=self.gyro_radps[:stop],
                       reference_quat=self.reference_quat[:stop], movement=self.movement[:stop],
                       accelerometer_mps2=_rows_to(self.accelerometer_mps2, stop),
                       magnetometer_uT=_rows_to(self.magnetometer_uT, stop))


def true_runs(flags) -> list[tuple[int, int]]:
    """The runs of true ``flags`` ``(N,)`` (anything numpy reads as bool), as
    ``[start, stop)`` index pairs."""
    truth = np.asarray(flags, dtype=bool).astype(np.int8)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], truth, [0]])))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])]


def reading_interval_s(read: np.ndarray, dt: float) -> float:
    """The time between a channel's readings put on the gyro's grid (``read``:
    ``(N,)`` bool, where it read; a logger's sensor on its own, slower clock):
    the median spacing of its readings, in whole gyro steps of ``dt``; ``dt``
    where it reads fewer than twice."""
    spacing = np.diff(np.flatnonzero(read))
    return float(np.median(spacing)) * dt if len(spacing) else dt


def _rows_from(channel, start: int):
    return None if channel is None else channel[start:]


def _rows_to(channel, stop: int):
    return None if channel is None else channel[:stop]


def load_recording(path, name: str | None = None) -> Recording:
    """Read and check a recording from an ``.npz`` archive with :data:`REQUIRED_KEYS`.

    Raises :class:`~dynamics.validation.InvalidParameterError` (parameter
    ``dataset``) naming what is wrong: a missing file or key, a wrong shape,
    channels that are not real numbers (true/false, complex, text, objects),
    non-finite gyro readings, a reference that is not unit quaternions, a
    movement mask that is not true/false, a rate that is not positive. A
    recording may move from its first sample: no estimator needs a rest
    (where one is, ``replay`` takes the gyro's noise and its switch-on bias
    from it).
    """
    path = Path(path)

    def refuse(rule: str):
        raise InvalidParameterError("dataset", str(path), rule)

    if not path.is_file():
        refuse("file does not exist")
    if not zipfile.is_zipfile(path):
        refuse("must be a numpy .npz archive (a zip file); this file is not one")
    return checked_recording(_read_archive(path, refuse), name or path.stem, refuse)


def checked_recording(data: dict, name: str, refuse) -> Recording:
    """A :class:`Recording` of arrays under :data:`REQUIRED_KEYS` (and,
    optionally, :data:`VECTOR_KEYS`), each checked; ``refuse(rule)`` raises
    the error that names the source."""
    missing = [key for key in REQUIRED_KEYS if key not in data]
    if missing:
        refuse(f"has no key {missing[0]!r}; a recording needs {', '.join(REQUIRED_KEYS)}")
    for key in ("imu_gyr_radps", "opt_quat", "sampling_rate_hz"):
        _check_numbers(key, data[key], refuse)
    gyro, reference = data["imu_gyr_radps"], data["opt_quat"]
    movement, rate = data["movement"], data["sampling_rate_hz"]
    if gyro.ndim != 2 or gyro.shape[1] != 3 or len(gyro) < 2:
        refuse(f"imu_gyr_radps has shape {gyro.shape}; must be (N, 3) with N >= 2")
    n = len(gyro)
    if reference.shape != (n, 4):
        refuse(f"opt_quat has shape {reference.shape}; must be ({n}, 4), one row per gyro sample")
    if movement.shape != (n,):
        refuse(f"movement has shape {movement.shape}; must be ({n},)")
    if movement.dtype != bool and (movement.dtype.kind not in "iu"
                                   or not np.isin(movement, (0, 1)).all()):
        refuse(f"movement must be true/false (or the integers 0/1) per sample; it holds "
               f"{kind_in_words(movement)}")
    if rate.shape != () or not np.isfinite(rate) or rate <= 0:
        shown = rate.tolist() if rate.size < 5 else f"an array of shape {rate.shape}"
        refuse(f"sampling_rate_hz = {shown!r} must be one positive number (Hz)")
    if not MIN_RATE_HZ <= rate <= MAX_RATE_HZ:
        refuse(f"sampling_rate_hz = {float(rate):g} must be within {MIN_RATE_HZ:g} to "
               f"{MAX_RATE_HZ:g} Hz (an IMU's rate)")
    gyro = gyro.astype(float)
    bad = np.flatnonzero(~np.isfinite(gyro).all(axis=1))
    if len(bad):
        refuse(f"imu_gyr_radps must be finite; row {bad[0]} is {gyro[bad[0]].tolist()}")
    fast = np.flatnonzero(np.abs(gyro).max(axis=1) > MAX_MEASURED_RATE_RADPS)
    if len(fast):
        refuse(f"imu_gyr_radps must be within ±{MAX_MEASURED_RATE_RADPS:g} rad/s (as an estimator "
               f"accepts); row {fast[0]} is {gyro[fast[0]].tolist()}")
    reference = reference.astype(float)
    present = ~np.isnan(reference).any(axis=1)
    if not present.any():
        refuse("opt_quat has no reference attitude (every row is NaN)")
    partly = np.flatnonzero(np.isnan(reference).any(axis=1) & ~np.isnan(reference).all(axis=1))
    if len(partly):
        refuse(f"opt_quat row {partly[0]} is partly NaN; a row is a quaternion or all NaN")
    norms = np.linalg.norm(reference[present], axis=1)
    off = np.flatnonzero(~(np.abs(norms - 1.0) <= UNIT_TOLERANCE))
    if len(off):
        row = int(np.flatnonzero(present)[off[0]])
        refuse(f"opt_quat must hold unit quaternions [w, x, y, z]; row {row} has norm "
               f"{norms[off[0]]:.6g}")
    _check_reference_turning(gyro, reference, float(rate), refuse, name)
    info = str(data["info"]) if "info" in data and data["info"].shape == () else ""
    vectors = {key: _checked_channel(key, data[key], n, refuse)
               for key in VECTOR_KEYS if key in data}
    return Recording(name=name, gyro_radps=gyro, reference_quat=reference,
                     movement=movement.astype(bool), rate_hz=float(rate), info=info,
                     accelerometer_mps2=vectors.get("imu_acc_mps2"),
                     magnetometer_uT=vectors.get("imu_mag_uT"))


def _check_reference_turning(gyro: np.ndarray, reference: np.ndarray, rate: float,
                             refuse, name: str) -> None:
    """Refuse a reference that turns unlike the gyro (:func:`sensors.turning.
    reference_fit`) where it would fit scalar last or inverted; warn where
    neither fits."""
    fit = reference_fit(gyro, reference, 1.0 / rate)
    if reference_fits(fit):
        return
    candidates = {"read as [x, y, z, w]": np.roll(reference, 1, axis=1),
                  "inverted (an attitude world → body)": reference * [1.0, -1.0, -1.0, -1.0]}
    fitting = first_fitting(gyro, candidates.items(), 1.0 / rate)
    if fitting:
        refuse(f"opt_quat {reference_problem(fit)}; {fitting} it would fit")
    warnings.warn(f"{name}: opt_quat {reference_problem(fit)}: "
                  f"{reference_advice(fit, gyro, reference, 1.0 / rate)}", stacklevel=3)


def _checked_channel(key: str, array: np.ndarray, n: int, refuse) -> np.ndarray:
    """A vector channel: (n, 3) finite real numbers, one row per gyro sample."""
    _check_numbers(key, array, refuse)
    if array.shape != (n, 3):
        refuse(f"{key} has shape {array.shape}; must be ({n}, 3), one row per gyro sample")
    array = array.astype(float)
    bad = np.flatnonzero(~np.isfinite(array).all(axis=1))
    if len(bad):
        refuse(f"{key} must be finite; row {bad[0]} is {array[bad[0]].tolist()}")
    limit, unit = VECTOR_LIMITS[key]
    huge = np.flatnonzero(np.abs(array).max(axis=1) > limit)
    if len(huge):
        refuse(f"{key} must be within ±{limit:g} {unit} (ten times any such sensor's range); "
               f"row {huge[0]} is {array[huge[0]].tolist()}")
    sensor = VECTOR_SENSORS[key]
    norms = np.linalg.norm(array[readings_taken(array)], axis=1)
    if not len(norms):
        refuse(f"{key} holds only zeros: no {sensor} reading at all (an IMU without one: "
               "leave the key out)")
    median, (low, high) = float(np.median(norms)), PLAUSIBLE_NORMS[sensor]
    if not low <= median <= high:
        refuse(f"{key}'s median norm is {median:.4g} {unit}, where an IMU's {sensor} "
               f"reads {low:g} to {high:g} {unit}: are its readings in another unit?")
    return array


def _read_archive(path: Path, refuse) -> dict:
    """The archive's arrays; an unreadable one names its key (object arrays,
    which only pickle could read, are refused: loading a pickle runs code)."""
    try:
        archive = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
        refuse(f"must be a numpy .npz archive ({type(err).__name__}: {err})")
    data = {}
    with archive:
        for key in archive.files:
            try:
                data[key] = archive[key]
            except ValueError as err:
                refuse(f"{key} cannot be read ({err}); it must hold numbers")
            except (OSError, EOFError, zipfile.BadZipFile) as err:
                refuse(f"must be a numpy .npz archive ({type(err).__name__}: {err})")
    return data


def kind_in_words(array: np.ndarray) -> str:
    """What an array holds, in words."""
    kinds = {"b": "true/false", "c": "complex numbers", "U": "text", "S": "bytes",
             "O": "Python objects", "V": "raw records", "M": "dates", "m": "time spans"}
    return kinds.get(array.dtype.kind, f"{array.dtype} numbers")


def _check_numbers(key: str, array: np.ndarray, refuse) -> None:
    """``key`` holds real numbers: not true/false, complex numbers, text, objects."""
    if array.dtype.kind not in "iuf":
        refuse(f"{key} must hold real numbers; it holds {kind_in_words(array)}")
