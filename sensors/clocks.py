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

#: A gap in the gyro's clock: an interval this many times its median.
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


def clock_steps(times: np.ndarray) -> tuple[np.ndarray, float]:
    """Each sample's step on a uniform clock, and the clock's period:
    the least-squares line through the samples' times against their steps,
    an interval of about k periods counting k steps (k - 1 samples dropped).
    The steps are counted in the median interval and in the mean one, and
    the count whose line fits the times better is taken: the median is the
    period where samples were dropped, the mean where the times are rounded
    (integer milliseconds at 256 Hz: intervals of 3 and 4 ms, median 4)."""
    intervals, best = np.diff(times), None
    for guess in (np.median(intervals), (times[-1] - times[0]) / (len(times) - 1)):
        steps = np.concatenate([[0], np.cumsum(np.maximum(1.0, np.rint(intervals / guess)))])
        period, origin = np.polyfit(steps, times, 1)
        misfit = float(np.mean((times - origin - period * steps) ** 2))
        if best is None or misfit < best[0]:
            best = (misfit, steps.astype(np.int64), float(period))
    return best[1], best[2]


def clock_period(times: np.ndarray) -> float:
    """A sensor's period: the median interval where the fitted one
    (:func:`clock_steps`) agrees with it to 1 ppm (a clock without drops or
    rounding, read as before), else the fitted one."""
    median = float(np.median(np.diff(times)))
    fitted = clock_steps(times)[1]
    return median if abs(fitted - median) <= 1e-6 * median else fitted


def part_starts(times: np.ndarray) -> np.ndarray:
    """Where the gyro's clock starts anew: the first sample after each gap
    (an interval over :data:`GAP_FACTOR` times the typical one), and 0."""
    steps = np.diff(times)
    return np.concatenate([[0], np.flatnonzero(steps > GAP_FACTOR * np.median(steps)) + 1])
