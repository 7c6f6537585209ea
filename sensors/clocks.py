"""A sensor's clock: the uniform clock its times were sampled on, and where
it stops.

A logger's times are rarely the clock's: rounded to whole milliseconds, a
sample dropped now and then, a gap where it paused. :func:`clock_steps`
fits the uniform clock through them, :func:`part_starts` finds where it
stops (:mod:`sensors.declared` splits a recording there). A counter that
rolls over (an Arduino's ``micros()`` every 2³² µs, 71.6 minutes; a 16-bit
tick counter) is unwrapped first (:func:`unwrapped`).
"""
from __future__ import annotations

import numpy as np

#: A gap in the gyro's clock: an interval of more than this many typical ones.
GAP_FACTOR = 3.0
#: The sizes of the counters a logger's times roll over at: 16 and 32 bits.
COUNTER_MODULI = (2 ** 16, 2 ** 32)


def unwrapped(times: np.ndarray) -> np.ndarray:
    """Integer ``times`` with each roll-over of their counter undone: where
    they go back by nearly a modulus of :data:`COUNTER_MODULI` (all of them
    below it, and the step across the roll-over, the modulus added, no more
    than :data:`GAP_FACTOR` times the typical one), the modulus is added to
    every time from there. Other times, and any that go back otherwise, are
    left as they are (the check that times increase names them)."""
    if times.dtype.kind not in "iu" or len(times) < 3 or times.min() < 0:
        return times
    steps = np.diff(times.astype(np.int64))
    typical = np.median(steps[steps > 0]) if np.any(steps > 0) else 0
    for modulus in COUNTER_MODULI:
        rolled = (steps < 0) & (steps + modulus > 0) & (steps + modulus <= GAP_FACTOR * typical)
        if times.max() < modulus and rolled.any():
            return times.astype(np.int64) + modulus * np.concatenate(
                [[0], np.cumsum(rolled)]).astype(np.int64)
    return times


def mean_interval(times: np.ndarray) -> float:
    """The mean interval of ``times`` (at least two): their span over
    their count less one."""
    return (times[-1] - times[0]) / (len(times) - 1)


def clock_fit(times: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Each sample's step on a uniform clock, the clock's period, and the
    RMS distance of the times to it: the least-squares line through the
    samples' times against their steps, an interval of about k periods
    counting k steps (k - 1 samples dropped). The steps are counted in the
    median interval and in the mean one, and the count whose line fits the
    times better is taken: the median is the period where samples were
    dropped, the mean where the times are rounded (integer milliseconds at
    256 Hz: intervals of 3 and 4 ms, median 4)."""
    intervals, best = np.diff(times), None
    for guess in (np.median(intervals), mean_interval(times)):
        steps = np.concatenate([[0], np.cumsum(np.maximum(1.0, np.rint(intervals / guess)))])
        period, origin = np.polyfit(steps, times, 1)
        misfit = float(np.mean((times - origin - period * steps) ** 2))
        if best is None or misfit < best[0]:
            best = (misfit, steps.astype(np.int64), float(period))
    return best[1], best[2], float(np.sqrt(best[0]))


def clock_steps(times: np.ndarray) -> tuple[np.ndarray, float]:
    """Each sample's step on a uniform clock, and its period (:func:`clock_fit`)."""
    return clock_fit(times)[:2]


#: Times that repeat at this share of their steps or more (never going
#: back) were printed coarser than the clock ticks (an Arduino's
#: ``Serial.print(t, 2)`` at 200 Hz: each time twice): :func:`dequantized`.
QUANTISED_SHARE = 0.05


def dequantized(times: np.ndarray) -> np.ndarray:
    """``times`` printed coarser than their clock (:data:`QUANTISED_SHARE`
    of the steps repeat, none goes back) spread evenly: each run of ``k``
    equal times over the interval to the next time, ``k`` parts of it (the
    last run over its own typical interval); other times as they are. The
    same times give the same spread, so sensors logged on one time column
    stay on one row each. An empty time (NaN) stays empty, the times around
    it spread as if it were not there."""
    finite = ~np.isnan(times)
    if not finite.all():
        given = times[finite]
        kept = dequantized(given)
        if kept is given:                   # nothing to spread: the times as they are
            return times
        spread = np.array(times, dtype=float)
        spread[finite] = kept
        return spread
    steps = np.diff(times)
    if len(times) < 3 or np.any(steps < 0) or np.mean(steps == 0) < QUANTISED_SHARE:
        return times
    times = times.astype(float)
    starts = np.concatenate([[0], np.flatnonzero(steps > 0) + 1])
    ends = np.concatenate([starts[1:], [len(times)]])
    nexts = np.concatenate([times[starts[1:]], [np.nan]])
    quantum = np.median(np.diff(times[starts])) if len(starts) > 1 else 0.0
    nexts[-1] = times[starts[-1]] + quantum
    spread = times.copy()
    for start, end, after in zip(starts, ends, nexts):
        spread[start:end] = times[start] + (after - times[start]) * np.arange(end - start) \
            / (end - start)
    return spread


#: Rows a logger repeated or wrote out of turn are mended (:func:`mended`)
#: where they are at most this share of the steps, and each goes back by
#: at most :data:`GAP_FACTOR` typical steps (else the clock restarted: named).
MENDED_SHARE = 0.01


def repeated_rows(times: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``(N,)`` bool: the rows that repeat the one before them, their time
    and every value (a row of empty cells repeats none)."""
    return np.concatenate([[False], (np.diff(times) == 0)
                           & np.all(values[1:] == values[:-1], axis=1)])


def mended(times: np.ndarray, values: np.ndarray) -> tuple:
    """``(times, values, rows dropped, rows moved)``: a row that repeats the
    one before it (time and values) dropped, however many (a logger that
    writes rows twice: nothing is lost), and rows written out of turn put in
    their time's order, where they are few (:data:`MENDED_SHARE`) and near;
    otherwise as they are (the check that times increase names them)."""
    if len(times) < 3:
        return times, values, 0, 0
    repeated = repeated_rows(times, values)
    kept_times, kept = times[~repeated], values[~repeated]
    steps = np.diff(kept_times)
    back = steps <= 0
    if not back.any():
        return kept_times, kept, int(np.count_nonzero(repeated)), 0
    if back.mean() > MENDED_SHARE or np.any(steps < -GAP_FACTOR * np.median(steps[~back])):
        return times, values, 0, 0
    order = np.argsort(kept_times, kind="stable")
    if np.any(np.diff(kept_times[order]) <= 0):      # a time read twice apart: not mended
        return times, values, 0, 0
    moved = int(np.count_nonzero(order != np.arange(len(order))))
    return kept_times[order], kept[order], int(np.count_nonzero(repeated)), moved


#: Times off the uniform clock fitted through them (:func:`clock_fit`) by
#: more than this share of its period (RMS) keep no steady clock, dropped
#: samples aside: rounding to whole milliseconds at 256 Hz is 0.07 of it,
#: intervals of 4 to 8 ms drift by many periods.
IRREGULAR_SHARE = 0.25


def steady(period: float, misfit: float, count: int) -> bool:
    """Whether ``count`` times off the uniform clock of ``period`` fitted
    through them by ``misfit`` (RMS, :func:`clock_fit`) keep a steady clock:
    within :data:`IRREGULAR_SHARE` of its period (two times always do)."""
    return count <= 2 or not misfit > IRREGULAR_SHARE * period


def clock_period(times: np.ndarray) -> float:
    """A sensor's period, as the loader takes it (:mod:`sensors.declared`):
    in each part between the gaps (:func:`part_starts`, where the loader
    splits a recording), the median interval where the fitted one
    (:func:`clock_fit`) agrees with it to 1 ppm (a clock without drops or
    rounding, read as before), else the fitted one; where the part's times
    keep no steady clock (:func:`steady`), its mean interval, which the
    loader resamples such a gyro at: the fitted line's period counts uneven
    intervals as dropped samples (291 Hz for a 285 Hz loop whose intervals
    vary by ±80 %, printed to 10 ms). Over several parts, their periods'
    mean weighted by their readings."""
    bounds = np.append(part_starts(times), len(times))
    parts = [times[start:end] for start, end in zip(bounds[:-1], bounds[1:]) if end - start > 1]
    if len(parts) == 1:
        return _part_period(parts[0])
    return float(np.average([_part_period(part) for part in parts],
                            weights=[len(part) for part in parts]))


def _part_period(times: np.ndarray) -> float:
    """:func:`clock_period` of one part between gaps."""
    _, fitted, misfit = clock_fit(times)
    if not steady(fitted, misfit, len(times)):
        return float(mean_interval(times))
    median = float(np.median(np.diff(times)))
    return median if abs(fitted - median) <= 1e-6 * median else fitted


def part_starts(times: np.ndarray) -> np.ndarray:
    """Where the gyro's clock starts anew: the first sample after each gap
    (an interval of more than :data:`GAP_FACTOR` typical ones, counted to
    the nearest: two samples lost are three intervals, put back, however a
    jittered clock or a float's rounding leaves it: 3.0000000000000378
    typical intervals had split a log), and 0."""
    steps = np.diff(times)
    return np.concatenate([[0], np.flatnonzero(np.rint(steps / np.median(steps)) > GAP_FACTOR)
                           + 1])
