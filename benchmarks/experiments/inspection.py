"""What a logged file holds, before anything runs on it (``attitude-bench
inspect``): each sensor's rate, the jitter and the gaps of its clock, readings
at the sensor's rail (clipped), the rest periods, gravity, the field's norm
and dip; and, for a file with no declaration yet, the ``[recording]``
declaration (:mod:`sensors.declared`) its columns suggest, to edit.

The guess reads the columns' names (a prefix naming the sensor, ``gyr``,
``acc``, ``mag``, ``quat`` …, and the axes ``x, y, z`` or ``w, x, y, z``;
an (N, 3) or (N, 4) array's own name) and their sizes (the unit that puts
the gyro's turning, gravity and the Earth's field where they belong: the
same checks :mod:`sensors.declared` makes). Where it cannot tell, it says so
and leaves the section out for the user to write.
"""
from __future__ import annotations

import math

import numpy as np

from benchmarks.experiments.columns import (column_values, columns_by_values, headerless,
                                            sensor_columns, time_columns, time_for)
from dynamics.validation import InvalidParameterError
from estimators.imu.heading import EARTH_FIELD_NORM_UT
from estimators.imu.rest import ACC_THRESHOLD_MPS2, GYRO_THRESHOLD_RADPS, MIN_DURATION_S
from sensors.clocks import clock_period, dequantized, part_starts, repeated_rows, unwrapped
from sensors.declared import SENSORS, declared_recordings
from sensors.declared_units import (HINT_FACTOR, PLAUSIBLE_NORMS, TIME_UNITS, UNITS,
                                    clock_turning_scale, tick_name, tick_seconds)
from sensors.recording import reading_interval_s
from sensors.turning import reference_fit, reference_fits
from sensors.vector import readings_taken


def time_unit(intervals: np.ndarray) -> str:
    """The unit that makes an IMU's sample interval most like one: the
    unit whose reading of the median interval is nearest (on a log scale)
    to 5 ms, an IMU's 200 Hz; the units are a thousand apart, so a clock of
    0.16 to 160 ms, 6 kHz to 6 Hz, reads right."""
    typical = float(np.median(intervals))
    return min(TIME_UNITS, key=lambda unit: abs(math.log(max(typical * TIME_UNITS[unit],
                                                             1e-300) / 5e-3)))


def clock(times: np.ndarray) -> dict:
    """A sensor's clock: its readings, rate, jitter (the intervals' spread
    between its gaps, over the period) and gaps."""
    times = times[~np.isnan(times)]
    intervals = np.diff(times)
    if not len(intervals):
        return {"readings": len(times)}
    typical = clock_period(times)
    gaps = np.zeros(len(intervals), dtype=bool)   # the jitter is the spread between them
    gaps[part_starts(times)[1:] - 1] = True       # where the loader splits the recording
    return {"readings": len(times), "interval": typical,
            "jitter": float(np.std(intervals[~gaps]) / typical) if (~gaps).any() else 0.0,
            "longest": float(intervals.max()), "gaps": int(np.count_nonzero(gaps))}


def fitting_unit(sensor: str, values: np.ndarray) -> str | None:
    """The unit of ``sensor`` that puts its median norm where it belongs."""
    norms = np.linalg.norm(values[~np.isnan(values).any(axis=1)], axis=1)
    median = float(np.median(norms[norms > 0])) if np.any(norms > 0) else 0.0
    low, high = PLAUSIBLE_NORMS[sensor]
    best = sorted(UNITS[sensor].items(), key=lambda item: abs(math.log(
        max(median * item[1], 1e-300) / math.sqrt(low * high))))
    unit, factor = best[0]
    return unit if low <= median * factor <= high else None


def gyro_unit(rates: np.ndarray, specific_force: np.ndarray | None, dt: float) -> tuple:
    """``(rad/s or deg/s, power, turned)``: the gyro's unit, and the power of ten
    by which the times' tick is longer than assumed, that together turn
    gravity as the accelerometer sees it turn (:func:`sensors.
    declared_units.clock_turning_scale`; a tick other than assumed only
    where it fits within :data:`~sensors.declared_units.HINT_FACTOR`);
    without an accelerometer, by the rates' size (a hand-held or vehicle
    IMU's rates rarely pass 20 rad/s) and the tick assumed; ``turned``:
    whether gravity's turning told them (else the rates' size did)."""
    if specific_force is not None:
        scale, _ = clock_turning_scale(rates, specific_force, dt)
        if scale is not None:
            def misfit(pair):
                return abs(math.log(scale / (UNITS["gyro"][pair[0]] * 10.0 ** pair[1])))
            unit, power = min(((unit, power) for unit in UNITS["gyro"] for power in
                               range(-3, 4)), key=lambda pair: misfit(pair)
                              + (math.log(HINT_FACTOR) if pair[1] else 0.0))
            if power == 0 or misfit((unit, power)) <= math.log(HINT_FACTOR):
                return unit, power, True   # a tick only where it fits (raw counts fit none)
            return min(UNITS["gyro"], key=lambda unit: misfit((unit, 0))), 0, True
    return ("deg/s" if np.nanmax(np.abs(rates)) > 20.0 else "rad/s"), 0, False


def rest_periods(rates: np.ndarray, specific_force: np.ndarray, dt: float) -> list:
    """(start, stop) s of the stretches at rest: for at least VQF's
    :data:`~estimators.imu.rest.MIN_DURATION_S`, every reading within its
    thresholds of the stretch's mean (Laidig & Seel 2023, §3.4)."""
    steps = max(1, int(round(MIN_DURATION_S / dt / 4)))        # quarter windows
    blocks = len(rates) // steps
    still = np.zeros(blocks, dtype=bool)
    for i in range(blocks):
        part = slice(i * steps, (i + 1) * steps)
        rate, force = rates[part], specific_force[part]
        still[i] = (np.linalg.norm(rate - rate.mean(axis=0), axis=1).max() < GYRO_THRESHOLD_RADPS
                    and np.abs(rate.mean(axis=0)).max() < GYRO_THRESHOLD_RADPS
                    and np.linalg.norm(force - force.mean(axis=0), axis=1).max()
                    < ACC_THRESHOLD_MPS2)
    periods, start = [], None
    for i, flag in enumerate(np.append(still, False)):
        if flag and start is None:
            start = i
        elif not flag and start is not None:
            if (i - start) * steps * dt >= MIN_DURATION_S:
                periods.append((start * steps * dt, i * steps * dt))
            start = None
    return periods


def clipped(values: np.ndarray) -> tuple[int, float]:
    """(readings at the channel's extreme on some axis, that extreme) when
    three in a row sit exactly there: the sensor's rail, where it clips (a
    quantised sensor reaches its extreme now and then, not three times on end)."""
    present = values[~np.isnan(values).any(axis=1)]
    if not len(present):
        return 0, 0.0
    extreme = float(np.abs(present).max())
    at = np.any(np.abs(present) == extreme, axis=1)
    run = np.convolve(at, np.ones(3), mode="valid") == 3      # three in a row: a rail
    count = int(np.count_nonzero(at))
    return (count, extreme) if run.any() and extreme > 0 else (0, extreme)


def guess_declaration(table: dict, file_name: str) -> tuple[dict, list]:
    """``(declaration, notes)``: the ``[recording]`` section the columns
    suggest (units by size, :func:`fitting_unit`, :func:`gyro_unit`) and
    what could not be told, one line each."""
    columns, times = sensor_columns(table), time_columns(table)
    notes, declaration = [], {"file": file_name}
    if headerless(table):
        columns, times = columns_by_values(table)
        notes.append("no header: the columns are told by their values (" + ", ".join(
            f"{sensor} {', '.join(chosen)}" for sensor, chosen in
            [("time", times), *columns.items()] if chosen) + "): check them")
    missing = [sensor for sensor in ("gyro", "accelerometer", "magnetometer", "reference")
               if sensor not in columns]
    if missing:
        notes.append(f"no columns recognised as {', '.join(missing)}: declare them by hand "
                     "if the file has them")
    if not times:
        notes.append("no time column recognised (a column named t, time or timestamp whose "
                     "values increase): declare each sensor's time by hand")
        return declaration, notes
    if "gyro" in columns:
        gyro_time = np.asarray(table[time_for("gyro", columns["gyro"], times, table)],
                               dtype=float)
        gyro_time = dequantized(gyro_time[~np.isnan(gyro_time)])     # as the loader reads it
        declaration["time_unit"] = time_unit(np.diff(gyro_time))
    seconds = TIME_UNITS[declaration.get("time_unit", "s")]
    for sensor, chosen in columns.items():
        section = {"time": time_for(sensor, chosen, times, table), "columns": chosen}
        values = column_values(table, chosen)
        if sensor in ("accelerometer", "magnetometer"):
            unit = fitting_unit(sensor, values)
            if unit is None:
                notes.append(f"{sensor}: no unit puts its readings where "
                             f"{'gravity' if sensor == 'accelerometer' else 'the field'} "
                             "belongs: check the columns and give its unit")
            section["unit"] = unit or next(iter(UNITS[sensor]))
        if sensor == "reference":
            section["order"] = "wxyz"        # the columns are listed w, x, y, z
            if isinstance(chosen, str):
                notes.append(f"{ONE_ARRAY}cannot be told from its name: wxyz assumed, "
                             "check it")
        declaration[sensor] = section
    if "gyro" in declaration:
        _guess_gyro(declaration, table, gyro_time, seconds, notes)
    return declaration, notes


def _guess_gyro(declaration: dict, table, gyro_time: np.ndarray, seconds: float,
                notes: list) -> None:
    """The gyro's unit (and the clock's tick, where another fits) in
    ``declaration``, by how its rates turn gravity (:func:`gyro_unit`),
    with a note where they are a guess; an infinite reading read as none.
    ``gyro_time``: its times as the loader reads them (no empty one)."""
    gyro = declaration["gyro"]
    force = None
    accelerometer = declaration.get("accelerometer")
    if accelerometer and accelerometer["time"] == gyro["time"]:
        force = column_values(table, accelerometer["columns"]) * \
            UNITS["accelerometer"][accelerometer["unit"]]
        force = np.nan_to_num(force, posinf=0.0, neginf=0.0)
    rates = np.nan_to_num(column_values(table, gyro["columns"]), posinf=0.0, neginf=0.0)
    step = float(np.median(np.diff(gyro_time))) * seconds
    gyro["unit"], power, turned = gyro_unit(rates, force, step)
    if not turned:
        notes.append(f"gyro: {gyro['unit']} by the rates' size: "
                     + ("the log turns too little for gravity's turning to tell its unit"
                        if force is not None else "no accelerometer on its clock to tell "
                        "its unit by") + " (check it)")
    if power:
        declaration["time_unit"] = tick_name(seconds * 10.0 ** power)
        notes.append(f"time: its tick is taken as {seconds * 10.0 ** power:g} s, which "
                     "turns gravity as the gyro does (check it)")


#: The note of a reference given as one array, whose order its name cannot tell.
ONE_ARRAY = "reference: one array; its order (w, x, y, z or x, y, z, w) "


def loaded_guess(declaration: dict, table: dict, path, notes: list):
    """The recordings the guessed ``declaration`` makes of ``table``, or
    None (with a note) where it does not load. A reference given as one
    array is tried in either order: the one that turns as the gyro does
    (:mod:`sensors.turning`) is kept, and the note says so."""
    reference = declaration.get("reference", {})
    orders = ("wxyz", "xyzw") if isinstance(reference.get("columns"), str) else (None,)
    refused = None
    for order in orders:
        if order:
            reference["order"] = order
        try:
            parts = declared_recordings(declaration, dict.fromkeys(SENSORS, table), path)
        except InvalidParameterError as err:
            refused = refused or err
            if err.name.endswith("recording.reference.order"):
                continue
            break
        if order and _told_by_turning(parts):
            notes[:] = [note for note in notes if not note.startswith(ONE_ARRAY)]
            notes.append(f"{ONE_ARRAY}is told by its turning against the gyro's: {order}")
        return parts
    if orders[0]:
        reference["order"] = orders[0]
    notes.append(f"as suggested, it does not load: {refused}")
    return None


def _told_by_turning(parts) -> bool:
    """Whether every part's reference turns as its gyro does, and one at
    least turns enough to tell (:func:`sensors.turning.reference_fit`)."""
    fits = [reference_fit(part.gyro_radps, part.reference_quat, 1.0 / part.rate_hz)
            for part in parts]
    return any(fit is not None for fit in fits) and all(map(reference_fits, fits))


def next_step(declaration: dict, target: str) -> str:
    """What to do with a suggested declaration (at ``target``): run it with
    ``broad`` where it has an accelerometer, with ``replay`` where it has a
    gyro and a reference only; a gyro alone runs with neither."""
    if "accelerometer" in declaration:
        return f"then run: attitude-bench broad --broad {target}"
    if "reference" in declaration:
        return f"then run: attitude-bench replay --dataset {target}"
    return ("a gyro alone runs with nothing here: declare its accelerometer (then: "
            f"attitude-bench broad --broad {target}) or its reference attitude (then: "
            f"attitude-bench replay --dataset {target})")


def declaration_toml(declaration: dict, source: str, loads: bool = True) -> str:
    """``declaration`` as the ``[recording]`` file a user edits (where it
    does not ``loads`` yet, a skeleton to complete, and it says so)."""
    step = next_step(declaration, "THIS_FILE")
    lines = [f"# The [recording] that attitude-bench inspect suggests for {source}:",
             f"# check each column and unit, {step}"
             if loads else "# it does not load as it is: complete what inspect could not "
             f"tell (its notes), {step}",
             "[recording]"]
    lines += [f"{key} = {_toml(value)}" for key, value in declaration.items()
              if not isinstance(value, dict)]
    for sensor in ("gyro", "accelerometer", "magnetometer", "reference"):
        if sensor in declaration:
            lines += ["", f"[recording.{sensor}]"]
            lines += [f"{key} = {_toml(value)}" for key, value in declaration[sensor].items()]
    return "\n".join(lines) + "\n"


def _toml(value) -> str:
    import json
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, list):
        return "[" + ", ".join(json.dumps(str(item)) for item in value) + "]"
    return json.dumps(str(value))


def findings(parts, tables: dict, declaration: dict) -> list[str]:
    """What the file holds, one line each: every sensor's clock, clipping,
    and for each part of the loaded recording (``parts``: split at the
    gyro's gaps) the rest periods, gravity and the field. ``tables``: each
    sensor's table (:func:`sensors.declared.sensor_tables`)."""
    seconds = tick_seconds(declaration.get("time_unit", "s"))
    lines = []
    for sensor in ("gyro", "accelerometer", "magnetometer", "reference"):
        if sensor not in declaration:
            continue
        section, table = declaration[sensor], tables[sensor]
        values = column_values(table, section["columns"])
        times = unwrapped(np.asarray(table[section["time"]]).reshape(-1)).astype(float)
        taken = ~np.isnan(values).all(axis=1)
        # Zeros are no reading of a vector or a quaternion (declared.py reads
        # them so); a gyro's are a rate, Euler angles' an attitude.
        if sensor in ("accelerometer", "magnetometer") or values.shape[1] == 4:
            taken &= readings_taken(values)
        # As the loader reads them: rows written twice dropped, the column
        # spread where printed coarser than its clock, then the readings taken.
        kept = ~repeated_rows(times, values)
        clock_of = clock(dequantized(times[kept])[taken[kept]] * seconds)
        if "interval" not in clock_of:
            lines.append(f"{sensor:<14} {clock_of['readings']:>9,} reading(s): no rate to tell")
            continue
        lines.append(f"{sensor:<14} {clock_of['readings']:>9,} readings, "
                     f"{1 / clock_of['interval']:8.2f} Hz, jitter {clock_of['jitter']:6.1%}, "
                     f"longest interval {clock_of['longest'] * 1e3:8.2f} ms, "
                     f"{clock_of['gaps']} gap{'s' if clock_of['gaps'] != 1 else ''}")
        count, extreme = clipped(values) if sensor != "reference" else (0, 0.0)
        if count:
            lines.append(f"{'':<14} {count:,} readings at ±{extreme:.6g} (its rail: clipped?)")
    from sensors.magnetometer_calibration import declares_calibration
    calibrated = declares_calibration(declaration.get("magnetometer", {}))
    if len(parts) == 1:
        return lines + _physics(parts[0], calibrated)
    lines.append(f"the gyro's clock has {len(parts) - 1} gap{'s' if len(parts) > 2 else ''}: "
                 f"{len(parts)} parts, each a trial of its own")
    for part in parts:
        lines += [f"{part.name} ({part.n_samples:,} samples): {line}"
                  for line in _physics(part, calibrated)]
    return lines


def _physics(recording, calibrated: bool = False) -> list[str]:
    """Rest, gravity, the field and the magnetometer's calibration
    (``calibrated``: the declaration applies one already)."""
    lines = _motion(recording)
    if recording.magnetometer_uT is not None:
        lines.append("calibration: the declaration applies one (calibrate, hard_iron or "
                     "soft_iron)" if calibrated else _calibration(recording.magnetometer_uT))
        lines.append(_magnetometer_timing(recording))
    if recording.has_reference.any():
        lines.append(_reference_turning(recording))
    return lines


def _reference_turning(recording) -> str:
    """How the reference turns against the gyro (:mod:`sensors.turning`)."""
    fit = reference_fit(recording.gyro_radps, recording.reference_quat, 1.0 / recording.rate_hz)
    if fit is None:
        return "reference: too little turning to check it against the gyro"
    unexplained, rotation = fit
    axes = ("its axes' turn from the gyro's undetermined (a turn about one axis)"
            if rotation is None else
            f"its axes {np.degrees(rotation.magnitude()):.1f}° from the gyro's")
    verdict = "turns as the gyro does" if reference_fits(fit) else \
        "does not turn as the gyro does"
    return f"reference: {verdict}, {100 * unexplained:.1f} % of its turning unexplained; {axes}"


def _magnetometer_timing(recording) -> str:
    """How late the magnetometer reads against the gyro (:mod:`sensors.delay`)."""
    from sensors.delay import AUTO_ADVICE, described, recording_fit
    fit = recording_fit(recording)
    advice = f"; broad {AUTO_ADVICE}" if fit is not None and fit.clear(recording.dt) else ""
    return f"magnetometer timing: it {described(fit, recording.dt)}{advice}"


def _calibration(field: np.ndarray) -> str:
    """The magnetometer's hard and soft iron as an ellipsoid fit finds them
    (:mod:`sensors.magnetometer_calibration`), or why it cannot."""
    from dynamics.validation import InvalidParameterError
    from sensors.magnetometer_calibration import fit_ellipsoid
    try:
        found = fit_ellipsoid(field, name="the magnetometer's readings")
    except InvalidParameterError as err:
        return f"calibration: no ellipsoid fit: {err.value}: {err.rule}"
    return (f"calibration: {found.describe('µT')}; to apply it: calibrate = true in "
            "[recording.magnetometer]")


def _motion(recording) -> list[str]:
    """Rest, gravity and the field, on the gyro's clock."""
    if recording.accelerometer_mps2 is None:
        return ["rest, gravity: no accelerometer"]
    force = recording.accelerometer_mps2
    read = readings_taken(force)
    # The accelerometer may read at fewer samples than the gyro: its own step.
    step = reading_interval_s(read, recording.dt)
    periods = rest_periods(recording.gyro_radps[read], force[read], step)
    rest = (f"{len(periods)} period{'s' if len(periods) != 1 else ''} at rest, "
            f"{sum(b - a for a, b in periods):.1f} s in all (first {periods[0][0]:.1f} to "
            f"{periods[0][1]:.1f} s)" if periods else
            "no rest found: nothing needs one (the filters start without it)")
    lines = [f"rest: {rest}",
             f"gravity: {np.median(np.linalg.norm(force[read], axis=1)):.3f} m/s² "
             "(median norm)"]
    if recording.magnetometer_uT is not None:
        field = recording.magnetometer_uT
        both = read & readings_taken(field)
        if not both.any():
            return lines + ["field: the accelerometer and the magnetometer never read at the "
                            "same sample: no dip to tell"]
        up = force[both] / np.linalg.norm(force[both], axis=1)[:, None]
        norms = np.linalg.norm(field[both], axis=1)
        dip = np.degrees(-np.arcsin(np.clip(np.sum(field[both] * up, axis=1) / norms, -1, 1)))
        low, high = EARTH_FIELD_NORM_UT
        lines.append(f"field: {np.median(norms):.1f} µT, dip {np.median(dip):.1f}° (medians "
                     f"where both read; the Earth's: {low:g} to {high:g} µT)")
    return lines
