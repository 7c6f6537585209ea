"""A logger's file, declared rather than converted: a ``[recording]`` TOML
names the file and, for each sensor, its time column, its columns, its unit
(and for the reference its convention and frame); :func:`load_declared`
reads it into a checked :class:`~sensors.recording.Recording`.

.. code-block:: toml

    [recording]
    file = "phone.csv"          # beside this file, or an absolute path
    time_unit = "s"             # of every time column: s, ms, us or ns

    [recording.gyro]            # required: its samples are the recording's clock
    time = "t"
    columns = ["gx", "gy", "gz"]
    unit = "deg/s"              # rad/s or deg/s

    [recording.accelerometer]   # unit: m/s^2 or g
    [recording.magnetometer]    # unit: uT, nT, gauss or mT; calibrate = true fits
                                # its hard and soft iron, or declare hard_iron = [x,
                                # y, z] (its unit) and soft_iron = [[…], […], […]]
    [recording.reference]       # quaternion: 4 columns, order = "wxyz" or "xyzw";
                                # or Euler angles: 3 columns, sequence = "ZYX", unit
                                # = "deg" or "rad"; frame = "ENU" (default) or "NED"

The formats: CSV and Parquet (pandas), ``.npz`` (numpy), ``.mat`` (scipy)
and HDF5 (h5py); a column is a 1-D array, or ``columns`` names one (N, 3)
or (N, 4) array. Each sensor keeps its own timestamps: the gyro's samples
are the recording's steps (its rate fitted to their times, a dropped sample
put back with the rate before it: :func:`sensors.clocks.clock_steps`), and
every other reading is taken at the first gyro sample at or after its time,
as the star tracker's readings are (:mod:`sensors.star_tracker`); a sample
with no reading of a sensor holds none (a row of zeros: a dropout, which
the filters skip). A row of empty cells (NaN) is no reading, as a table that
merges sensors on their own clocks holds. The reference is interpolated on
the gyro's times (spherical, between readings not further apart than
:data:`sensors.declared_reference.REFERENCE_GAP_FACTOR` of its typical interval), NaN elsewhere.

What a logger gets wrong is one line each: an unknown column (the file's
columns are listed), times that go back or a gap in the gyro's clock, a row
that is partly empty, and a unit that cannot be right (rates beyond any
gyro's range; gravity far from 9.8 m/s², or a field far from the Earth's, in
the declared unit, with the unit that would fit); and a vector sensor's
axes or a reference's convention that turn unlike the gyro
(:mod:`sensors.turning`), with the declaration that would fit.
"""
from __future__ import annotations

import tomllib
import warnings
from pathlib import Path

import numpy as np

from dynamics.validation import InvalidParameterError
from sensors.clocks import (GAP_FACTOR, clock_fit, clock_period, dequantized, mean_interval,
                            mended, part_starts, repeated_rows, steady, unwrapped)
from sensors.declared_reference import (check_field_north, check_gravity_up, check_reference,
                                        declared_reference)
from sensors.declared_units import (UNITS, canonical_unit, check_gyro_axes, check_norm,
                                    check_rate, check_rates, check_reference_scale,
                                    check_turning, reading_scale, seconds_per_tick)
from sensors.magnetometer_calibration import calibrated
from sensors.recording import Recording, kind_in_words
from sensors.recording_keys import axes_matrix, axes_names, choice, known_keys, refuse
from sensors.tables import read_table
from sensors.turning import AXES_THRESHOLDS, axes_fit

SENSORS = ("gyro", "accelerometer", "magnetometer", "reference")
def load_declared(path) -> Recording:
    """The recording that the ``[recording]`` TOML at ``path`` declares,
    checked; :class:`InvalidParameterError` names the file and the key (and
    a gap in the gyro's clock: :func:`load_parts` splits the file there)."""
    parts = load_parts(path)
    if len(parts) > 1:
        path = Path(path)
        refuse(path, "recording.gyro.time", read_declaration(path)["gyro"]["time"],
               f"has {len(parts) - 1} gap(s) (the first after {parts[0].n_samples} readings); "
               "a recording is one unbroken gyro log: cut the file at its gaps, or run broad "
               f"--broad {path.name}, which scores each part as a trial of its own")
    return parts[0]


def load_parts(path) -> list[Recording]:
    """The recordings the TOML at ``path`` declares: one, or one per part
    of the gyro's clock between its gaps (``NAME_part1``, ``NAME_part2``,
    …), each with the readings of the other sensors in its span."""
    path = Path(path)
    declaration = read_declaration(path)
    own = all(isinstance(declaration.get(name), dict) and "file" in declaration[name]
              for name in SENSORS if name in declaration)
    table = {} if own and "file" not in declaration else \
        _read(path, "recording.file", declaration)
    return declared_recordings(declaration, sensor_tables(path, declaration, table), path)


def _read(path: Path, key: str, section: dict) -> dict:
    """The table of the file ``section`` names (``key``: where, for errors)."""
    try:
        return read_table(data_file(path, section, key))
    except InvalidParameterError as err:          # named by the declaration that gave it
        refuse(path, key, section.get("file"), err.rule)


def data_files(path: Path, declaration: dict) -> list[Path]:
    """Every file ``declaration`` reads: ``[recording]``'s, where it names
    one, and each sensor's own, once each, in that order."""
    files = [data_file(path, declaration)] if "file" in declaration else []
    for name in SENSORS:
        section = declaration.get(name)
        if isinstance(section, dict) and "file" in section:
            files.append(data_file(path, section, f"recording.{name}.file"))
    if not files:
        data_file(path, declaration)             # its refusal: no file named at all
    return list(dict.fromkeys(files))


def sensor_tables(path: Path, declaration: dict, table: dict) -> dict:
    """Sensor → the table its columns are in: ``table`` (the ``[recording]``
    file's), or the sensor's own ``file`` (a logger that writes one file per
    sensor), each file read once."""
    read, tables = {}, {}
    for name in SENSORS:
        section = declaration.get(name)
        given = section.get("file") if isinstance(section, dict) else None
        if given is None:
            tables[name] = table
            continue
        if given not in read:
            read[given] = _read(path, f"recording.{name}.file", section)
        tables[name] = read[given]
    return tables


def declared_recordings(declaration: dict, tables: dict, path: Path) -> list[Recording]:
    """The recordings ``declaration`` (a ``[recording]`` section) makes of
    ``tables`` (sensor → the table its columns are in: :func:`sensor_tables`),
    split at the gyro's gaps; errors name ``path``, the declaration."""
    tick = seconds_per_tick(path, declaration.get("time_unit", "s"))
    sections = {name: canonical_unit(declaration[name]) for name in SENSORS
                if name in declaration}
    if "gyro" not in sections:
        refuse(path, "recording.gyro", None, "is required: the gyro's samples are the "
                "recording's clock")
    origin = _time_origin(tables, sections)
    read = {name: _sensor(path, tables[name], name, section, tick, origin)
            for name, section in sections.items()}
    gyro_time, gyro = read["gyro"]
    starts = part_starts(gyro_time)
    bounds = [(a, b) for a, b in zip(starts, list(starts[1:]) + [len(gyro_time)]) if b - a > 1]
    if len(bounds) < len(starts):
        warnings.warn(f"{path.name}: {len(starts) - len(bounds)} gyro reading(s) alone between "
                      "gaps left out (a part needs two)", stacklevel=2)
    if not bounds:
        refuse(path, "recording.gyro.time", None, "has a gap after every reading: no two "
                "readings make a part")
    names = [path.stem] if len(bounds) == 1 else \
        [f"{path.stem}_part{i + 1}" for i in range(len(bounds))]
    return [_part(path, name, declaration, sections, read, slice(a, b))
            for name, (a, b) in zip(names, bounds)]


def _time_origin(tables: dict, sections: dict) -> int:
    """The earliest first value of the declared integer time columns (0 if
    any is not integer): every sensor's times are counted from it."""
    firsts = []
    for name, section in sections.items():
        table = tables[name]
        column = np.asarray(table.get(section.get("time"), [])) if isinstance(section, dict) \
            and isinstance(section.get("time"), str) else np.asarray([])
        if column.size == 0 or column.dtype.kind not in "iu":
            return 0
        firsts.append(int(column.reshape(-1)[0]))
    return min(firsts) if firsts else 0


def _part(path: Path, name: str, declaration: dict, sections: dict, read: dict,
          span: slice) -> Recording:
    """One unbroken stretch ``span`` of the gyro's clock as a recording."""
    logged = read["gyro"][0][span]
    gyro_time, gyro = _gyro_on_grid(path, logged, read["gyro"][1][span])
    rate = 1.0 / clock_period(gyro_time)
    check_rate(path, rate, declaration.get("time_unit", "s"))
    if not np.any(gyro != 0.0):
        refuse(path, "recording.gyro.columns", sections["gyro"]["columns"], "hold only zeros: "
                "the gyro recorded no rate (a channel not logged, or a dead sensor)")
    channels = {sensor: _with_gyro(gyro_time, logged, *read[sensor])
                for sensor in ("accelerometer", "magnetometer") if sensor in read}
    for sensor, values in channels.items():
        check_norm(path, sensor, values, sections[sensor]["unit"], sections[sensor]["columns"])
    if "accelerometer" in channels:
        check_turning(path, gyro, channels["accelerometer"], 1.0 / rate, sections["gyro"],
                      declaration.get("time_unit", "s"), channels.get("magnetometer"))
    for sensor, values in channels.items():
        _check_axes(path, sensor, gyro, values, 1.0 / rate, sections[sensor])
    if "accelerometer" in channels:
        check_gyro_axes(path, gyro, channels, 1.0 / rate, sections["gyro"])
    reference = np.full((len(gyro_time), 4), np.nan)
    if "reference" in read:
        reference = declared_reference(path, gyro_time, *read["reference"], sections["reference"])
        check_reference(path, gyro_time, gyro, read["reference"], sections["reference"],
                        reference, lambda: check_reference_scale(
                            path, gyro, reference, 1.0 / rate, sections["gyro"],
                            declaration.get("time_unit", "s")))
        if "accelerometer" in channels:
            check_gravity_up(path, reference, channels["accelerometer"], sections["reference"])
        if "magnetometer" in channels:
            check_field_north(path, reference, channels["magnetometer"])
    referenced = ~np.isnan(reference).any(axis=1)     # without a reference: all movement
    return Recording(name=name, gyro_radps=gyro, reference_quat=reference,
                     movement=referenced if referenced.any() else np.ones_like(referenced),
                     rate_hz=rate,
                     info=str(declaration.get("description", "")),
                     accelerometer_mps2=channels.get("accelerometer"),
                     magnetometer_uT=channels.get("magnetometer"))


def read_declaration(path: Path) -> dict:
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as err:
        raise InvalidParameterError("recording", str(path), f"cannot be read "
                                    f"({type(err).__name__}: {err})") from None
    try:
        declared = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        refuse(path, "", str(path), f"is not TOML ({err})")
    if not isinstance(declared.get("recording"), dict):
        refuse(path, "recording", None, "must be a [recording] section naming the file "
                "and its sensors' columns")
    known = known_keys("recording")
    unknown = sorted(set(declared["recording"]) - known)
    if unknown:
        refuse(path, f"recording.{unknown[0]}", declared["recording"][unknown[0]],
                f"is not a [recording] key; known: {', '.join(sorted(known))}")
    return declared["recording"]


def data_file(path: Path, declaration: dict, key: str = "recording.file") -> Path:
    """The file ``declaration`` (``[recording]`` or a sensor's section, at
    ``key``) names, beside ``path`` or absolute."""
    given = declaration.get("file")
    if not isinstance(given, str) or not given:
        refuse(path, key, given, "must name the logged file")
    data = Path(given) if Path(given).is_absolute() else path.parent / given
    if not data.is_file():
        refuse(path, key, given, f"is not a file (looked for {data})")
    return data


def _sensor(path: Path, table: dict, name: str, section, time_scale: float, origin: int = 0):
    """``(times s, values)`` of one declared sensor: its rows with a reading
    (a row of empty cells is none), converted to the toolkit's unit."""
    key = f"recording.{name}"
    if not isinstance(section, dict):
        refuse(path, key, section, "must be a section with time, columns and unit")
    known = known_keys(key)
    unknown = sorted(set(section) - known)
    if unknown:
        refuse(path, f"{key}.{unknown[0]}", section[unknown[0]],
                f"is not a key of the {name}'s section; known: {', '.join(sorted(known))}")
    printed = _column(path, table, f"{key}.time", section.get("time"), origin,
                      time=True) * time_scale
    width = 4 if name == "reference" and "sequence" not in section else 3
    values = _columns(path, table, f"{key}.columns", section.get("columns"), width)
    if len(values) != len(printed):
        refuse(path, f"{key}.columns", section.get("columns"), f"hold {len(values)} rows; "
                f"its time column {section.get('time')!r} holds {len(printed)}")
    kept = ~repeated_rows(printed, values)      # rows written twice: before the times' print
    printed, values = printed[kept], values[kept]
    times = dequantized(printed)
    if name == "gyro" and times is not printed:
        warnings.warn(f"{path.name}: {key}.time: {np.mean(np.diff(printed) == 0):.0%} of its "
                      "times repeat the one before (printed coarser than the clock ticks): "
                      "each run of equal times is spread evenly to the next", stacklevel=3)
    if not kept.all():
        warnings.warn(f"{path.name}: {key}: {np.count_nonzero(~kept)} row(s) repeating the one "
                      "before dropped", stacklevel=3)
    if width == 4:            # a quaternion of zeros: a frame the markers were not seen
        values[np.all(values == 0.0, axis=1)] = np.nan
    times, values = _readings(path, key, section, times, values)
    if not len(times):
        refuse(path, f"{key}.columns", section.get("columns"), "hold no reading")
    if name != "reference":
        unit = choice(path, f"{key}.unit", section.get("unit"), UNITS[name])
        values = values * (reading_scale(path, key, section) * UNITS[name][unit])
        if "axes" in section:
            values = values @ axes_matrix(section["axes"], f"{path.name}: {key}.axes").T
    if name == "gyro":
        _check_clock(path, section.get("time"), times)
        check_rates(path, values, section["unit"])
    else:
        _check_increasing(path, f"{key}.time", section.get("time"), times)
    if name == "magnetometer":
        values = calibrated(values, section, UNITS[name][section["unit"]],
                            f"{path.name}: {key}")
    return times, values


def _readings(path: Path, key: str, section: dict, times: np.ndarray, values: np.ndarray):
    """``(times, values)`` of a sensor's rows that hold a reading (a row of
    empty cells holds none), a logger's everyday slips mended and said: its
    last row cut short left out, rows repeated or out of order
    (:func:`sensors.clocks.mended`); an infinite or a partly empty row refused."""
    late = np.flatnonzero(np.isinf(times))
    if len(late):
        refuse(path, f"{key}.time", section.get("time"), f"row {late[0]} holds an infinite "
                f"time ({times[late[0]]}); a time is finite")
    infinite = np.flatnonzero(np.isinf(values).any(axis=1))
    if len(infinite):
        refuse(path, f"{key}.columns", section.get("columns"), f"row {infinite[0]} holds an "
                f"infinite value ({values[infinite[0]].tolist()}); a reading is finite")
    empty = np.isnan(values).all(axis=1) | np.isnan(times)
    partly = np.flatnonzero(np.isnan(values).any(axis=1) & ~empty)
    if list(partly) == [len(values) - 1]:   # the last line cut short (power lost): left out
        warnings.warn(f"{path.name}: {key}: its last row is cut short "
                      f"({values[-1].tolist()}): left out", stacklevel=4)
        empty[-1], partly = True, partly[:0]
    if len(partly):
        refuse(path, f"{key}.columns", section.get("columns"), f"row {partly[0]} is partly "
                f"empty ({values[partly[0]].tolist()}); a row is a reading or empty")
    times, values = times[~empty], values[~empty]
    times, values, dropped, moved = mended(times, values)
    if dropped or moved:
        said = [f"{dropped} row(s) repeating the one before dropped"] * bool(dropped) + \
            [f"{moved} row(s) out of their time's order put in it"] * bool(moved)
        warnings.warn(f"{path.name}: {key}: {'; '.join(said)}", stacklevel=5)
    return times, values


def _column(path: Path, table: dict, key: str, name, origin: int = 0,
            time: bool = False) -> np.ndarray:
    """Column ``name`` as floats, less ``origin`` (for times: integer epoch
    nanoseconds are counted from a common origin before they become floats,
    which would keep only a quarter of a microsecond; a counter's roll-over
    unwrapped, :func:`sensors.clocks.unwrapped`)."""
    if not isinstance(name, str) or name not in table:
        refuse(path, key, name, f"must name a column of the file; it has "
                f"{_listed(table)}")
    column = np.asarray(table[name])
    if column.size == 0:
        refuse(path, key, name, "holds no rows")
    if column.dtype.kind not in "iuf" or sum(size > 1 for size in column.shape) > 1:
        refuse(path, key, name, f"must be one column of numbers; it holds {_held(column)} "
                f"of shape {column.shape}")
    column = unwrapped(column.reshape(-1)) if time else column.reshape(-1)
    if column.dtype.kind in "iu":
        return (column.astype(np.int64) - origin).astype(float)
    return column.astype(float) - origin


def _held(array: np.ndarray) -> str:
    """What a column holds, in words: a table's object column is text or
    mixed cells (:func:`sensors.recording.kind_in_words` for the rest)."""
    return "text or mixed cells" if array.dtype.kind == "O" else kind_in_words(array)


def _columns(path: Path, table: dict, key: str, names, width: int) -> np.ndarray:
    """``names`` (a list of ``width`` columns, or one (N, width) array's name)."""
    if isinstance(names, str) and names in table:
        array = np.asarray(table[names])
        if array.dtype.kind not in "iuf":
            refuse(path, key, names, f"must hold numbers; it holds {_held(array)}")
        array = array.astype(float)
        if array.ndim == 2 and array.shape[0] == width and array.shape[1] != width:
            array = array.T               # stored one row per axis (MATLAB, HDF5)
        if array.ndim != 2 or array.shape[1] != width:
            refuse(path, key, names, f"must be an (N, {width}) array; it is {array.shape}")
        return array
    if not isinstance(names, list) or len(names) != width:
        refuse(path, key, names, f"must be a list of {width} columns, or the name of one "
                f"(N, {width}) array; the file has {_listed(table)}")
    columns = [_column(path, table, key, name) for name in names]
    lengths = {name: len(column) for name, column in zip(names, columns)}
    if len(set(lengths.values())) > 1:
        refuse(path, key, names, f"must be columns of one length; they hold "
                f"{', '.join(f'{name} {n}' for name, n in lengths.items())} rows")
    return np.column_stack(columns)


def _listed(table: dict) -> str:
    """The file's column names for a message (the first 20), or that it has none."""
    names = list(table)
    if not names:
        return "no column at all (an empty file)"
    return ", ".join(names[:20]) + (f" and {len(names) - 20} more" if len(names) > 20 else "")


def _check_increasing(path: Path, key: str, column, times: np.ndarray) -> None:
    """Times that increase; else the column and the first reading where not."""
    back = np.flatnonzero(np.diff(times) <= 0)
    if len(back):
        row = int(back[0]) + 1
        # A clock that restarted stays behind the readings before it; one
        # reading stamped out of turn (early, late or last) does not tell so.
        step = GAP_FACTOR * np.median(np.abs(np.diff(times)))
        later, before = times[row:row + 2], times[max(row - 2, 0):row]
        restart = len(later) == 2 and bool((later < before.min() - step).all())
        refuse(path, key, column, f"goes back or repeats at reading {row} ({times[row]:.9g} s "
               f"after {times[row - 1]:.9g} s); times must increase" + (
                   " (the logger's clock restarted there: split the file)" if restart else ""))


def _check_clock(path: Path, column, times: np.ndarray) -> None:
    """The gyro's times: increasing, two at least."""
    _check_increasing(path, "recording.gyro.time", column, times)
    if len(times) < 2:
        refuse(path, "recording.gyro.time", column, "holds one reading; a recording needs "
               "at least two")


def _gyro_on_grid(path: Path, times: np.ndarray, rates: np.ndarray) -> tuple:
    """The gyro's times and rates with each dropped sample
    (:func:`sensors.clocks.clock_fit`) put back, its rate held from the
    sample before and its time between its neighbours'; a warning says how
    many. Times that keep no steady clock (off the fitted one by more than
    :data:`~sensors.clocks.IRREGULAR_SHARE` of its period: an Arduino
    ``loop()``'s, a rate that changes) are resampled instead, said too."""
    steps, period, misfit = clock_fit(times) if len(times) > 1 else \
        (np.arange(len(times)), 0.0, 0.0)
    if not steady(period, misfit, len(times)):
        return _resampled(path, times, rates)
    missing = int(steps[-1]) + 1 - len(times)
    if missing == 0:
        return times, rates
    warnings.warn(f"{path.name}: {missing} gyro sample(s) missing between readings (intervals "
                  "of two or more periods); each is put back with the rate of the sample "
                  "before it", stacklevel=3)
    grid = np.arange(steps[-1] + 1)
    return np.interp(grid, steps, times), rates[np.searchsorted(steps, grid, side="right") - 1]


def _check_axes(path: Path, sensor: str, rates: np.ndarray, values: np.ndarray, dt: float,
                section: dict) -> None:
    """Refuse a vector sensor's axes that turn unlike the gyro where
    another order of them turns as it does (:func:`sensors.turning.axes_fit`,
    with the sensor's :data:`~sensors.turning.AXES_THRESHOLDS`)."""
    fit = axes_fit(rates, values, dt, AXES_THRESHOLDS[sensor])
    if fit is None:
        return
    declared, better, correlation = fit
    given = section.get("axes", ["x", "y", "z"])
    matrix = better @ axes_matrix(given, f"{path.name}: recording.{sensor}.axes")
    if np.count_nonzero(matrix < 0) >= 2:
        matrix = -matrix          # of the pair ±: the one with fewer axes negated
    vector = "gravity" if sensor == "accelerometer" else "the field"
    refuse(path, f"recording.{sensor}.axes", given, f"turn {vector} unlike the gyro (their "
           f"turning correlates {declared:.2f}); axes = {_listed_axes(axes_names(matrix))} "
           f"turns it as the gyro does ({correlation:.2f}; turning cannot tell {vector} "
           "from its opposite: check the signs)")


def _listed_axes(names: list) -> str:
    return "[" + ", ".join(f'"{name}"' for name in names) + "]"


def _resampled(path: Path, times: np.ndarray, rates: np.ndarray) -> tuple:
    """The gyro's rates on a uniform clock of its mean interval, linear
    between its readings (the filters integrate each step's rate over one
    step, which a rate read at uneven intervals would break: 2.1° for
    0.45° on intervals of 4 to 8 ms, 44° where the rate halved midway)."""
    period = mean_interval(times)
    grid = times[0] + period * np.arange(len(times))
    intervals = np.diff(times)
    warnings.warn(f"{path.name}: the gyro's times keep no steady clock (intervals "
                  f"{intervals.min() * 1e3:.3g} to {intervals.max() * 1e3:.3g} ms): its rates "
                  f"are resampled at {1 / period:.4g} Hz, linearly between readings",
                  stacklevel=4)
    return grid, _interpolated(grid, times, rates)


def _interpolated(clock: np.ndarray, times: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``(N, 3)`` ``values`` read at ``times``, linear between them, at ``clock``."""
    return np.column_stack([np.interp(clock, times, values[:, i]) for i in range(3)])


def _with_gyro(clock: np.ndarray, logged: np.ndarray, times: np.ndarray,
               values: np.ndarray) -> np.ndarray:
    """``values`` on the gyro's ``clock``: resampled with the gyro's rates
    where they were read on the gyro's ``logged`` times and the clock is not
    those (:func:`_resampled`), else as :func:`_on_clock` places them."""
    start = int(np.searchsorted(times, logged[0]))
    read = slice(start, start + len(logged))
    if len(clock) == len(logged) and not np.array_equal(clock, logged) and \
            np.array_equal(times[read], logged):
        return _interpolated(clock, logged, values[read])
    return _on_clock(clock, times, values)


def _on_clock(clock: np.ndarray, times: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``values`` read at ``times``, each at the first ``clock`` sample at or
    after it (the last of several there); zeros where none was read."""
    period = float(np.median(np.diff(clock)))
    index = np.searchsorted(clock, times, side="left")
    kept = (index < len(clock)) & (times >= clock[0] - period)
    index, values = index[kept], values[kept]
    last = len(index) - 1 - np.unique(index[::-1], return_index=True)[1]
    placed = np.zeros((len(clock), 3))
    placed[index[last]] = values[last]
    return placed
