"""The units of a declared log (:mod:`sensors.declared`) and the checks
that catch a wrong one: each refusal names the key, the value, the rule
and, where one fits, the unit that would.

A unit's mistake leaves every reading plausible on its own: a gyro in rad/s
declared deg/s reads 57 times too slow, a clock in ticks of 100 µs
declared in µs runs 100 times too fast. The turning the other channels see
(gravity in the accelerometer, the reference's attitude) against the
gyro's rates tells both apart: a gyro unit's mistake is a factor of 57.3, a
clock's a power of ten (:func:`scale_hint`).
"""
from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np

from dynamics.environment import STANDARD_GRAVITY_MPS2
from dynamics.validation import MAX_MEASURED_RATE_RADPS
from sensors.recording import PLAUSIBLE_NORMS, VECTOR_LIMITS
from sensors.recording_keys import axes_matrix, axes_names, refuse
from sensors.turning import (AXES_THRESHOLDS, MIRRORED_CORRELATION, TURNING_CORRELATION,
                             TURNING_FACTOR, TURNING_WINDOW_S, field_correlation,
                             gravity_turning, rates_fit, reference_fit, reference_fits,
                             reference_scale, turning_scale)
from sensors.vector import readings_taken

#: Each time unit in seconds; ``time_unit`` may also be a number, the
#: seconds of one tick of the times (an Xsens ``SampleTimeFine``: 1e-4).
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
#: The gyro's plausible rates, Hz: from a logger's slowest (a phone saving
#: power, 1 Hz) to the fastest MEMS output (tens of kHz). Beyond them the
#: times' unit is wrong, not the IMU.
PLAUSIBLE_RATE_HZ = (1.0, 1e5)
#: Each sensor's units: name → factor to the toolkit's unit (rad/s, m/s², µT).
UNITS = {
    "gyro": {"rad/s": 1.0, "deg/s": math.pi / 180.0},
    "accelerometer": {"m/s^2": 1.0, "g": STANDARD_GRAVITY_MPS2},
    "magnetometer": {"uT": 1.0, "nT": 1e-3, "gauss": 100.0, "mT": 1e3},
}
#: How else a unit is written: the same unit (µ as the micro sign or the
#: Greek letter, a superscript, a logger's abbreviation).
UNIT_ALIASES = {"µT": "uT", "μT": "uT", "m/s²": "m/s^2", "m/s2": "m/s^2", "°/s": "deg/s",
                "dps": "deg/s", "rad/sec": "rad/s"}
#: How else ``time_unit`` is written: a named unit, or a tick of seconds.
TIME_ALIASES = {"µs": "us", "μs": "us", "sec": "s", "msec": "ms", "usec": "us", "nsec": "ns",
                "min": 60.0}
#: Each vector sensor's typical norm in its toolkit unit: g, and a middle
#: Earth's field (22 to 67 µT). Raw counts' scale is hinted to it, and
#: ``inspect`` tells a headerless file's accelerometer from its
#: magnetometer by it.
TYPICAL_NORMS = {"accelerometer": STANDARD_GRAVITY_MPS2, "magnetometer": 45.0}
#: A specific force's norm is near g at rest and stays within a few g of it
#: in a hand's motion: its 5th percentile below this share of its 95th is
#: an accelerometer without gravity (or falls and jumps).
GRAVITY_FREE_RATIO = 0.2
#: A scale between the turnings is read as a unit's mistake (57.3) or a
#: clock's (a power of ten) within this factor of it: the scale is found
#: within 0.9 to 1.14 of the truth on BROAD's trials, and raw counts of an
#: MPU-6050 (131 per °/s) are 1.31 from 100.
HINT_FACTOR = 1.2
#: A turning scale this far from 1 (or none) is looked at again on the
#: windows a wrong clock would need (BROAD's 30 trials: 0.45 to 1.14 where
#: their turning is clear).
CLOCK_SEARCH_FACTOR = 2.0
#: The fewest windows a wrong clock's search reads (a clock 10ⁿ times off
#: holds as many of its windows as the right clock holds of the usual one:
#: 600 a minute; a still body's 10 s windows of a minute, six, agreed with
#: its translation by chance and named a clock 100 times off).
CLOCK_BLOCKS = 20


def canonical_unit(section):
    """A sensor's section with its ``unit`` as the toolkit names it
    (:data:`UNIT_ALIASES`); anything else as it is."""
    if isinstance(section, dict) and isinstance(section.get("unit"), str) and \
            section["unit"] in UNIT_ALIASES:
        return {**section, "unit": UNIT_ALIASES[section["unit"]]}
    return section


def seconds_per_tick(path: Path, declared) -> float:
    """``time_unit`` in seconds: one of :data:`TIME_UNITS` (or
    :data:`TIME_ALIASES`), or a positive number of seconds (a logger's
    tick); refused otherwise, naming ``path``."""
    tick = _aliased(declared)
    if (isinstance(tick, str) and tick in TIME_UNITS) or \
            (_is_number(tick) and math.isfinite(tick) and tick > 0):
        return tick_seconds(declared)
    refuse(path, "recording.time_unit", declared, "must be one of s, ms, us, ns, or the "
           "seconds of one tick (a positive number: 1e-4, 60 for minutes)")


def tick_seconds(declared) -> float:
    """A checked ``time_unit`` (:func:`seconds_per_tick`) in seconds."""
    tick = _aliased(declared)
    return float(tick) if _is_number(tick) else TIME_UNITS[tick]


def _aliased(declared):
    """``time_unit`` as :data:`TIME_UNITS` names it, or its number."""
    return TIME_ALIASES.get(declared, declared) if isinstance(declared, str) else declared


def tick_name(seconds: float):
    """A tick of ``seconds`` as ``time_unit``: its name where it has one,
    else the number."""
    named = [name for name, tick in TIME_UNITS.items() if math.isclose(tick, seconds)]
    return named[0] if named else float(f"{seconds:.6g}")


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def reading_scale(path: Path, key: str, section: dict) -> float:
    """A sensor's ``scale`` (1 if none): a finite number, not zero."""
    scale = section.get("scale", 1.0)
    if not _is_number(scale) or not math.isfinite(scale) or scale == 0:
        refuse(path, f"{key}.scale", scale, "must be a finite number, not zero (raw counts: "
               "the unit's share of one count, 1/131 for an MPU-6050's gyro in deg/s)")
    return float(scale)


def check_rates(path: Path, rates: np.ndarray, unit: str) -> None:
    """Refuse rates beyond any gyro's range, naming deg/s where it would fit."""
    fastest = float(np.abs(rates).max())
    if fastest > MAX_MEASURED_RATE_RADPS:
        hint = (" (were they deg/s? unit = \"deg/s\")" if unit == "rad/s" and
                fastest * math.pi / 180 <= MAX_MEASURED_RATE_RADPS else "")
        refuse(path, "recording.gyro.unit", unit, f"gives rates up to {fastest:.4g} rad/s, "
                f"beyond any gyro's range ({MAX_MEASURED_RATE_RADPS:g} rad/s){hint}")


def check_rate(path: Path, rate: float, declared) -> None:
    """Refuse a gyro rate outside :data:`PLAUSIBLE_RATE_HZ`, naming the
    times' unit (with the one that would fit): a nanosecond clock declared
    in seconds reads as a gyro a billion times too fast."""
    low, high = PLAUSIBLE_RATE_HZ
    if low <= rate <= high:
        return
    tick = seconds_per_tick(path, declared)
    fitting = [other for other, seconds in TIME_UNITS.items()
               if low <= rate * tick / seconds <= high]
    hint = f"; time_unit = \"{fitting[0]}\" would fit" if fitting else ""
    refuse(path, "recording.time_unit", declared, f"makes the gyro read at {rate:.3g} Hz, "
            f"where an IMU reads at {low:g} Hz to {high / 1e3:g} kHz{hint}")


def scale_hint(path: Path, scale: float, unit: str, time_unit) -> tuple:
    """``(key, value, hint)`` for rates that must be multiplied by ``scale``
    to turn as another channel sees the body turn: the gyro's unit where
    another one makes the scale about 1, else the clock's tick where a
    power of ten does (times in a tick of 100 µs declared in µs turn
    everything 100 times too fast), else the gyro's unit, with the unit
    that brings the scale within :data:`~sensors.turning.TURNING_FACTOR`."""
    for other, factor in UNITS["gyro"].items():
        if other != unit and abs(math.log(scale * UNITS["gyro"][unit] / factor)) \
                <= math.log(HINT_FACTOR):
            return "recording.gyro.unit", unit, f" (were they {other}? unit = \"{other}\")"
    power = round(math.log10(scale))
    if power != 0 and abs(math.log10(scale) - power) <= math.log10(HINT_FACTOR):
        tick = seconds_per_tick(path, time_unit) * 10.0 ** power
        named = tick_name(tick)
        shown = f"\"{named}\"" if isinstance(named, str) else f"{named:g}"
        return ("recording.time_unit", time_unit, f" (is a tick of the times {tick:g} s? "
                f"time_unit = {shown})")
    fitting = [other for other, factor in UNITS["gyro"].items()
               if 1 / TURNING_FACTOR <= scale * UNITS["gyro"][unit] / factor <= TURNING_FACTOR]
    return "recording.gyro.unit", unit, (f" (were they {fitting[0]}? unit = \"{fitting[0]}\")"
                                         if fitting else f" (raw counts? scale = {scale:.3g} "
                                         "fits, times any scale declared)")


def check_turning(path: Path, rates: np.ndarray, specific_force: np.ndarray, dt: float,
                  section: dict, time_unit, field: np.ndarray | None = None) -> None:
    """Refuse a gyro whose rates, in the declared unit, turn gravity 57
    times faster or slower than the accelerometer sees it turn (or a clock
    in the wrong tick, 10ⁿ times), or the other way (every sensor's columns
    in a left-handed order: where a magnetometer's ``field`` is read, its
    turning must say so too, as a fast translation's linear acceleration
    turns the accelerometer's readings against the gyro's prediction, down
    to -0.54 on BROAD, and no magnetic field's)."""
    found = gravity_turning(rates, specific_force, dt)
    field_turns = field is not None and (field_correlation(rates, field, dt) or 0.0) \
        >= TURNING_CORRELATION        # with the gyro: a right-handed frame
    if found is not None and found[0] <= MIRRORED_CORRELATION and not field_turns:
        refuse(path, "recording.gyro.columns", section["columns"],
               f"turn gravity the other way from the accelerometer's readings (correlation "
               f"{found[0]:.2f}): the sensors' columns as declared make a left-handed frame "
               "(a logger's z, y, x order?); declare each sensor's columns as x, y, z")
    scale, power = clock_turning_scale(rates, specific_force, dt)
    if scale is None or (not power and 1 / TURNING_FACTOR <= scale <= TURNING_FACTOR):
        return
    key, value, hint = scale_hint(path, scale, section["unit"], time_unit)
    refuse(path, key, value, f"makes the gyro turn gravity {_as_fast(1 / scale)} the "
            f"accelerometer sees it turn{hint}")


def check_gyro_axes(path: Path, rates: np.ndarray, channels: dict, dt: float,
                    section: dict) -> None:
    """Refuse a gyro whose axes turn gravity unlike the accelerometer sees
    it turn, where another order of the gyro's turns it as it does, and the
    field too where a magnetometer reads it (the other sensors' axes having
    passed their own checks: the gyro is the one out of their frame, a
    logger's x and y swapped in its file; it had scored 120° with no word)."""
    fit = rates_fit(rates, channels["accelerometer"], dt)
    field = channels.get("magnetometer")
    if fit is None or (field is not None and (field_correlation(rates @ fit[1].T, field, dt)
                                              or 0.0) < AXES_THRESHOLDS["magnetometer"][1]):
        return
    declared, better, correlation = fit
    given = section.get("axes", ["x", "y", "z"])
    names = axes_names(better @ axes_matrix(given, f"{path.name}: recording.gyro.axes"))
    others = "the accelerometer's and the magnetometer's" if field is not None else \
        "the accelerometer's (or its axes are the gyro's in another order)"
    refuse(path, "recording.gyro.axes", given, f"turn gravity unlike the accelerometer sees it "
           f"turn (their turning correlates {declared:.2f}); axes = "
           f"[{', '.join(repr(n).replace(chr(39), chr(34)) for n in names)}] turns it, and "
           f"{others} readings, as they turn ({correlation:.2f})")


def clock_turning_scale(rates: np.ndarray, specific_force: np.ndarray, dt: float) -> tuple:
    """``(scale, power)``: :func:`~sensors.turning.turning_scale`, power 0;
    or where it sees too little,
    or a scale :data:`CLOCK_SEARCH_FACTOR` or more from 1, the scale over a
    window of the usual one's length in a clock 10, 100 or 1000 times
    faster or slower, where that shows it at about that power of ten (the
    power then; a clock's mistake, however near 1 the usual window's): a
    clock in the wrong unit makes the usual window hold a tenth or ten
    times the real turning, which it then blurs or drowns in noise."""
    scale = turning_scale(rates, specific_force, dt)
    if scale is not None and (1 / CLOCK_SEARCH_FACTOR <= scale <= CLOCK_SEARCH_FACTOR
                              or _unit_mistake(scale)):
        return scale, 0
    for power in (1, -1, 2, -2, 3, -3):       # the scale 10**power: its window
        window = TURNING_WINDOW_S / 10.0 ** power
        if len(rates) * dt < CLOCK_BLOCKS * window:
            continue        # too few windows to tell (a still body's few happen to agree)
        found = turning_scale(rates, specific_force, dt, window)
        if found is not None and abs(math.log10(found) - power) <= math.log10(HINT_FACTOR):
            return found, power
    return scale, 0


def _unit_mistake(scale: float) -> bool:
    """Whether ``scale`` is a gyro unit's mistake (57.3 or its inverse,
    within :data:`HINT_FACTOR`): seen so over the usual window, it is that,
    not a clock's, whose longer windows can alias near a power of ten (a
    gyro logged in deg/s, declared rad/s, was blamed on a clock 100 times
    too slow, and followed, scored 54° with no word)."""
    factors = UNITS["gyro"].values()
    return any(abs(math.log(scale * a / b)) <= math.log(HINT_FACTOR)
               for a in factors for b in factors if a != b)


def check_reference_scale(path: Path, rates: np.ndarray, reference: np.ndarray, dt: float,
                          section: dict, time_unit) -> None:
    """Refuse a gyro whose rates turn the body :data:`~sensors.turning.
    TURNING_FACTOR` times faster or slower than the reference turns (its
    unit's or the clock's mistake: :func:`scale_hint`), where the rates so
    scaled turn as the reference does (else the reference's own
    declaration is wrong, which :func:`sensors.declared_reference.
    check_reference` names)."""
    scale = reference_scale(rates, reference, dt)
    if scale is None or 1 / TURNING_FACTOR <= scale <= TURNING_FACTOR or \
            not reference_fits(reference_fit(rates * scale, reference, dt)):
        return
    key, value, hint = scale_hint(path, scale, section["unit"], time_unit)
    refuse(path, key, value, f"makes the gyro turn {_as_fast(1 / scale)} the reference "
            f"turns{hint}")


def _as_fast(ratio: float) -> str:
    return f"{ratio:.3g} times as fast as" if ratio >= 1 else f"{1 / ratio:.3g} times slower than"


def check_norm(path: Path, name: str, values: np.ndarray, unit: str,
               section_columns=None) -> None:
    """A vector sensor's median norm, where it read, plausible in its unit;
    an accelerometer without gravity (:data:`GRAVITY_FREE_RATIO`) refused, or
    noted where its median is in place."""
    norms = np.linalg.norm(values[readings_taken(values)], axis=1)
    if not len(norms):
        refuse(path, f"recording.{name}.columns", section_columns, "hold only zeros, or no "
               "reading in the gyro's span: no reading at all")
    median = float(np.median(norms))
    low, high = PLAUSIBLE_NORMS[name]
    limit, shown = VECTOR_LIMITS["imu_acc_mps2" if name == "accelerometer" else "imu_mag_uT"]
    low_norm, high_norm = np.percentile(norms, [5.0, 95.0])
    gravity_free = name == "accelerometer" and low_norm < GRAVITY_FREE_RATIO * high_norm
    no_gravity = (f"hold no gravity: their norm's 5th percentile is {low_norm / high_norm:.0%} "
                  "of its 95th (a phone's user acceleration?); declare the accelerometer's "
                  "readings that include gravity")
    if low <= median <= high and np.abs(values).max() <= limit:
        if gravity_free:          # or a recording of jumps and falls: said, not refused
            warnings.warn(f"{path.name}: recording.{name}.columns may {no_gravity}", stacklevel=3)
        return
    if gravity_free:              # no unit would make it gravity
        refuse(path, f"recording.{name}.columns", section_columns, no_gravity)
    fitting = [other for other, factor in UNITS[name].items() if other != unit and
               low <= median / UNITS[name][unit] * factor <= high]
    typical = TYPICAL_NORMS[name]
    hint = f"; unit = \"{fitting[0]}\" would fit" if fitting else (
        f"; raw counts? scale = {typical / median:.3g} would put it at {typical:.3g} {shown}, "
        "times any scale declared")
    refuse(path, f"recording.{name}.unit", unit, f"makes the median reading {median:.4g} "
            f"{shown}, not within {low:g} to {high:g} {shown} as "
            f"{'gravity' if name == 'accelerometer' else 'the Earth field'} would be{hint}")
