r"""When a magnetometer's reading was taken: its delay against the gyro,
fitted from how the field turns.

Each channel of a MEMS IMU is filtered inside the sensor, by its own filter,
so a reading stamped :math:`t_k` may describe the body at :math:`t_k - \tau`.
Seen from the body, a vector fixed in the world turns as
:math:`\dot v = -\omega \times v` (Markley & Crassidis 2014, §3.1, eq. 3.18's
kinematics for a constant vector; :mod:`sensors.turning` checks the axes
with it), so two readings :math:`i < j` differ by

.. math::

    v_j - v_i = -\theta_{ij} \times (\bar v - h), \qquad
    \theta_{ij} = \int_{t_i - \tau}^{t_j - \tau} \omega\, dt,

the gyro's rotation over the interval the readings describe, :math:`\bar v`
their mean and :math:`h` a hard iron's constant offset (the change is linear
in it). The delay is the :math:`\tau` whose rotations explain the readings'
changes best, in least squares over the whole recording, :math:`h` fitted
with it at each :math:`\tau` (:func:`delay_fit`): no reference is read, and
a recording that turns is enough. The gyro's integral takes each reading as
the rate over the interval before it, as the filters do on a recording
(``rate_interpolation = "end"``), so the delay is the one the filters see: a
gyro that reads the rate over the interval after each sample makes an
on-time magnetometer one sample late. Likewise the delay is against the
gyro samples the readings are placed at: a reading on its own clock is
placed at the next gyro sample (:mod:`sensors.declared`), up to a step
after its time, and the fit includes that. Pairs across a gap in the
readings are left out (they would turn beyond the first order). The
delay's standard error is a jackknife's over stretches of the recording
(:func:`_jackknife_error`): neighbouring pairs share a reading and the
room's field, which least squares' own error would take as independent.

A reading is then taken at its sample's time (:func:`at_sample_times`):
turned by the gyro's rotation over the delay,
:math:`v(t_k) = \exp(-[\theta \times])\,(v_k - h) + h` with
:math:`\theta = \int_{t_k - \tau}^{t_k} \omega\, dt`, one rotation
vector: exact for a fixed axis, and to the first order of the axis's turn
otherwise, which delays within :data:`MAX_DELAY_S` keep small.

On BROAD's 30 trials the magnetometer reads 11.8 to 14.1 ms late (3.4 to
4.0 of their 3.5 ms samples; standard errors 0.1 to 0.9 ms), each trial
fitted alone. Where it is not taken out, a filter's field turns late against
its gyro: in a turn of 400 °/s the field seems 5° off, and the field's
disturbance tests reject what is the sensor's timing (BROAD's fast trials: a
tenth to a quarter of the MEKF's field readings).

The accelerometer is not fitted: a hand's linear acceleration turns with
its rate (centripetal and tangential), and would move the fit.
"""
from __future__ import annotations

import argparse
import hashlib
import math
import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from dynamics.validation import InvalidParameterError
from sensors.vector import readings_taken

#: Delays are searched within ±MAX_DELAY_S s of none.
MAX_DELAY_S = 0.1
#: The readings are compared in pairs this far apart, s (or consecutive
#: readings, where they are further apart): long enough for the field to
#: turn beyond its noise, short for the rotation's first order.
PAIR_SPACING_S = 0.02
#: The search: a grid of COARSE_STEP_S, then FINE_STEPS points between the
#: best's neighbours, then the parabola through the best three.
COARSE_STEP_S, FINE_STEPS = 0.004, 17
#: Evidence enough: this many pairs turning at least this fast (rad/s).
MIN_PAIRS, MIN_RATE_RADPS = 100, 0.1
#: A pair further apart than this many times the usual spans a gap in the
#: readings: left out.
GAP_FACTOR = 1.5
#: The stretches the delay's standard error is found over (:func:`_jackknife_error`).
JACKKNIFE_BLOCKS = 20
#: A delay is clear this many standard errors from none (:meth:`DelayFit.clear`).
CLEAR_ERRORS = 5.0
def checked_delay(value):
    """``value`` as a delay setting: ``"auto"``, or seconds within
    ±:data:`MAX_DELAY_S`; else :class:`InvalidParameterError` naming
    ``magnetometer_delay``."""
    if isinstance(value, str) and value.strip().lower() == "auto":
        return "auto"
    try:
        seconds = float(value)
    except (TypeError, ValueError):
        seconds = math.nan
    if not (math.isfinite(seconds) and abs(seconds) <= MAX_DELAY_S):
        raise InvalidParameterError("magnetometer_delay", value, DELAY_RULE)
    return seconds


#: What a delay setting must be.
DELAY_RULE = (f"must be auto or seconds within ±{MAX_DELAY_S:g} (a sensor's filter delays its "
              "readings by milliseconds: a longer delay is its timestamps to check)")


def delay_argument(text: str):
    """A command line's delay (``--magnetometer-delay``): ``auto`` (fit it),
    or seconds within ±:data:`MAX_DELAY_S` (a sensor's filter delays it by
    milliseconds; beyond, its timestamps are to be checked, and the
    readings' turn by the gyro would leave its first order)."""
    try:
        return checked_delay(text)
    except InvalidParameterError:
        raise argparse.ArgumentTypeError(f"{text!r}: {DELAY_RULE}") from None


@dataclass(frozen=True)
class DelayFit:
    """A fitted delay: ``delay_s`` (positive: the readings come late), its
    standard error (a block jackknife's, :func:`_jackknife_error`), the
    hard iron ``offset`` fitted with it, and the share of the readings'
    change it leaves unexplained."""

    delay_s: float
    standard_error_s: float
    offset: np.ndarray
    unexplained: float
    #: the best delay lies at the search's edge: the readings' timing is
    #: beyond it, or their field does not turn as the gyro says
    beyond: bool = False

    def clear(self, dt: float) -> bool:
        """Whether the readings are clearly late (or early) by a tenth of a
        sample of step ``dt`` or more: :data:`CLEAR_ERRORS` standard errors
        from none, within the search, and explaining some of the field's turning."""
        return (not self.beyond and self.unexplained < 1.0
                and abs(self.delay_s) >= max(dt / 10, CLEAR_ERRORS * self.standard_error_s))


def _integral(rates: np.ndarray, dt: float) -> np.ndarray:
    """The gyro's rotation from sample 0 to each sample, each reading the
    rate over the interval before it."""
    total = np.zeros((len(rates), 3))
    total[1:] = np.cumsum(rates[1:], axis=0) * dt
    return total


def _integral_at(total: np.ndarray, rates: np.ndarray, dt: float, t: np.ndarray) -> np.ndarray:
    """:func:`_integral` at times ``t`` (s), linear within a sample."""
    k = np.clip(np.floor(t / dt).astype(int), 0, len(total) - 2)
    return total[k] + (t / dt - k)[:, None] * rates[k + 1] * dt


class _Pairs:
    """The readings' pairs (module docstring) and what each delay leaves
    unexplained of their change."""

    def __init__(self, rates: np.ndarray, vectors: np.ndarray, available: np.ndarray, dt: float):
        read = np.flatnonzero(available)
        spacing = max(1, int(round(PAIR_SPACING_S / dt)))       # in gyro samples
        between = np.median(np.diff(read)) if len(read) > 1 else spacing
        read = read[::max(1, int(round(spacing / between)))]
        i, j = read[:-1], read[1:]
        span = j - i
        usual = np.median(span) if len(span) else 0
        margin = int(np.ceil(MAX_DELAY_S / dt)) + 1
        # a pair across a gap in the readings would turn too far for the first order
        kept = (i >= margin) & (j < len(rates) - margin) & (span <= GAP_FACTOR * usual)
        self.i, self.j = i[kept], j[kept]
        self.rates, self.dt = rates, dt
        self.total = _integral(rates, dt)
        self.change = vectors[self.j] - vectors[self.i]
        self.mean = (vectors[self.i] + vectors[self.j]) / 2
        #: the change's squared sum, which every share is of
        self.size = float(np.sum(self.change * self.change))

    def enough(self) -> bool:
        """Whether enough pairs turn to time the readings (a rest, however
        long, neither helps nor hinders)."""
        turned = self.total[self.j] - self.total[self.i]
        rates = np.linalg.norm(turned, axis=1) / ((self.j - self.i) * self.dt)
        return (int(np.count_nonzero(rates >= MIN_RATE_RADPS)) >= MIN_PAIRS
                and self.size > 0.0)                                   # a stuck sensor: no

    def unexplained(self, delay_s: float) -> tuple[float, np.ndarray]:
        """The share of the pairs' change that the gyro's rotation, ``delay_s``
        late, leaves unexplained, and the hard iron fitted with it."""
        left, offset = self.left(delay_s)
        return float(np.sum(left)) / self.size, offset

    def left(self, delay_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Each pair's change left unexplained (squared) with ``delay_s``,
        and the hard iron fitted over all pairs."""
        theta = (_integral_at(self.total, self.rates, self.dt, self.j * self.dt - delay_s)
                 - _integral_at(self.total, self.rates, self.dt, self.i * self.dt - delay_s))
        residual = self.change + np.cross(theta, self.mean)      # = θ × h, h the hard iron
        # least squares in h by its normal equations, summed pair by pair:
        # Σ [θ×]ᵀ[θ×] = Σ (|θ|² I − θθᵀ), Σ [θ×]ᵀ r = −Σ θ × r
        normal = np.sum(theta * theta) * np.eye(3) - theta.T @ theta
        right = -np.sum(np.cross(theta, residual), axis=0)
        offset = np.linalg.lstsq(normal, right, rcond=None)[0]
        left = residual - np.cross(theta, offset)
        return np.sum(left * left, axis=1), offset


def _best(pairs: _Pairs, delays: np.ndarray) -> tuple[int, np.ndarray]:
    shares = np.array([pairs.unexplained(d)[0] for d in delays])
    return int(np.argmin(shares)), shares


def delay_fit(rates: np.ndarray, vectors: np.ndarray, available: np.ndarray,
              dt: float) -> DelayFit | None:
    """The delay of a vector sensor's readings ``vectors`` ``(N, 3)`` (read
    where ``available``) against the gyro's ``rates`` ``(N, 3)``, rad/s, on
    the gyro's grid of step ``dt`` (module docstring); None where too few
    pairs of readings turn to say. A best delay at the search's edge is
    :attr:`DelayFit.beyond` (none within :data:`MAX_DELAY_S` explains it)."""
    pairs = _pairs(rates, vectors, available, dt)
    if pairs is None:
        return None
    coarse = np.arange(-MAX_DELAY_S, MAX_DELAY_S + COARSE_STEP_S / 2, COARSE_STEP_S)
    best, shares = _best(pairs, coarse)
    if best in (0, len(coarse) - 1):
        unexplained, offset = pairs.unexplained(coarse[best])
        return DelayFit(float(coarse[best]), math.inf, offset, unexplained, True)
    fine = np.linspace(coarse[best - 1], coarse[best + 1], FINE_STEPS)
    best, shares = _best(pairs, fine)
    delay, step = fine[best], fine[1] - fine[0]
    middle = min(max(best, 1), len(fine) - 2)          # the parabola through the best three
    low, mid, high = shares[middle - 1:middle + 2]
    curvature = (low - 2.0 * mid + high) / step ** 2    # the share's second derivative
    if middle == best and curvature > 0.0:
        delay += 0.5 * (low - high) / (curvature * step)
    left, offset = pairs.left(delay)
    return DelayFit(float(delay), _jackknife_error(pairs, delay, step, left), offset,
                    float(np.sum(left)) / pairs.size)


def recording_fit(recording) -> DelayFit | None:
    """:func:`delay_fit` of a recording's magnetometer against its gyro
    (:class:`sensors.recording.Recording`; its readings the rows that are
    not exactly zero, which on a gyro's grid is no reading), kept as
    :func:`timed_readings` keeps it."""
    field = recording.magnetometer_uT
    return _kept(recording.gyro_radps, field, readings_taken(field), recording.dt, False)[0]


def timed_readings(rates, vectors, available, dt: float) -> tuple:
    """``(fit, timed)``: :func:`delay_fit` of the readings and, where it is
    clear (:meth:`DelayFit.clear`), the readings at their samples' times
    (:func:`at_sample_times`, read-only: every caller of the same readings
    shares them); ``timed`` None where it is not clear — the one rule of
    ``--magnetometer-delay auto`` and of an offline estimator timing its
    field. The answer for the same readings is kept, by a digest of their
    contents (never their identity): a tuning runs each recording many
    times, and a trial's note reads the fit its estimators took."""
    return _kept(rates, vectors, available, dt, True)


#: The fits kept (:func:`timed_readings`), the last used last, and how many
#: bytes of timed readings they may hold (24 a sample: 1.3 MB for a BROAD
#: trial, 17 MB for an hour at 200 Hz; the last always) and how many fits;
#: the bookkeeping under a lock (a worker may run tasks in threads: two that
#: fit the same readings at once each fit them, and keep one answer).
_KEPT = OrderedDict()
_KEPT_LOCK = threading.Lock()
KEPT_BYTES = 64 << 20
KEPT_FITS = 256


def _digest(*arrays) -> str:
    """A digest of the arrays' contents, shapes and types."""
    digest = hashlib.blake2b()
    for array in arrays:
        array = np.ascontiguousarray(array)
        digest.update(f"{array.shape}{array.dtype.str}".encode())
        digest.update(memoryview(array).cast("B"))
    return digest.hexdigest()


def _kept(rates, vectors, available, dt: float, timed: bool) -> tuple:
    key = (_digest(rates, vectors, available), dt)
    with _KEPT_LOCK:
        kept = _KEPT.get(key)
    fit, readings = kept or (delay_fit(rates, vectors, available, dt), None)
    if timed and readings is None and fit is not None and fit.clear(dt):
        readings = at_sample_times(rates, vectors, available, dt, fit.delay_s, fit.offset)
        readings.flags.writeable = False
    with _KEPT_LOCK:
        _KEPT.pop(key, None)
        _KEPT[key] = (fit, readings)
        while len(_KEPT) > 1 and (len(_KEPT) > KEPT_FITS or sum(
                0 if kept is None else kept.nbytes for _, kept in _KEPT.values()) > KEPT_BYTES):
            _KEPT.popitem(last=False)
    return fit, readings


#: What a clear delay's note advises (``broad``, ``inspect``).
AUTO_ADVICE = ("--magnetometer-delay auto takes each reading at its sample's time "
               "for every estimator (the offline ones do so by default)")


def _pairs(rates, vectors, available, dt: float) -> _Pairs | None:
    """The readings' pairs, or None where the readings or the rates are not
    finite, or too few pairs turn (:meth:`_Pairs.enough`)."""
    rates, vectors = np.asarray(rates, dtype=float), np.asarray(vectors, dtype=float)
    available = np.asarray(available, dtype=bool)
    if not (np.isfinite(rates).all() and np.isfinite(vectors[available]).all()):
        return None
    pairs = _Pairs(rates, vectors, available, dt)
    return pairs if pairs.enough() else None


def hard_iron_at(rates, vectors, available, dt: float, delay_s: float) -> np.ndarray:
    """The hard iron that fits the readings best at a given delay (zero
    where too few turn to fit it): the offset :func:`at_sample_times`
    turns them about."""
    pairs = _pairs(rates, vectors, available, dt)
    return np.zeros(3) if pairs is None else pairs.unexplained(delay_s)[1]


def _jackknife_error(pairs: _Pairs, delay: float, step: float, mid: np.ndarray) -> float:
    """The delay's standard error by the delete-a-block jackknife over
    :data:`JACKKNIFE_BLOCKS` stretches of the recording (Efron & Tibshirani,
    *An Introduction to the Bootstrap*, 1993, §11.2), each block's deletion
    taken to first order (one Newton step from the fit): neighbouring pairs
    share a reading and the room's field, so their errors are not
    independent, and least squares' own error, which takes them so, would
    be several times off. ``mid``: each pair's share left at ``delay``."""
    low, high = pairs.left(delay - step)[0], pairs.left(delay + step)[0]
    curvature = float(np.sum(low) - 2.0 * np.sum(mid) + np.sum(high)) / step ** 2
    if curvature <= 0.0:
        return math.inf
    blocks = np.array_split(high - low, JACKKNIFE_BLOCKS)
    k = len(blocks)
    # deleting block b moves the fit by its gradient over the others' curvature
    shifts = np.array([np.sum(b) / (2.0 * step) for b in blocks]) / (curvature * (k - 1) / k)
    return float(np.sqrt((k - 1) / k * np.sum((shifts - shifts.mean()) ** 2)))


def described(fit: DelayFit | None, dt: float) -> str:
    """What ``fit`` (:func:`delay_fit`, on a gyro of step ``dt``) says of a
    magnetometer's timing, as what follows "the magnetometer"."""
    if fit is None:
        return "turns too little to be timed against the gyro"
    if fit.beyond:
        return (f"is off the gyro by more than {MAX_DELAY_S * 1e3:.0f} ms, or its field does "
                "not turn as the gyro says: check its timestamps and its axes")
    if not math.isfinite(fit.standard_error_s):        # no best delay: no error to give
        return "turns with no clear best delay against the gyro (its timing cannot be told)"
    said = (f"{abs(fit.delay_s) * 1e3:.1f} ± {fit.standard_error_s * 1e3:.1f} ms "
            f"{'late' if fit.delay_s > 0 else 'early'} against the gyro")
    if fit.unexplained >= 1.0:
        return (f"does not turn as the gyro says at any delay ({said}): check its axes and "
                "timestamps")
    if not fit.clear(dt):
        return f"is on time as far as its turning tells ({said})"
    return f"reads {said} (fitted from how the field turns as the gyro says)"


def at_sample_times(rates: np.ndarray, vectors: np.ndarray, available: np.ndarray, dt: float,
                    delay_s: float, offset=np.zeros(3)) -> np.ndarray:
    """``vectors`` each turned by the gyro's rotation over ``delay_s``
    (module docstring): the readings at their samples' times; ``offset`` the
    hard iron, which turns with the body. Rows not ``available`` are kept."""
    from scipy.spatial.transform import Rotation   # here: the fit itself needs no scipy
    rates = np.asarray(rates, dtype=float)
    out = np.array(vectors, dtype=float)
    read = np.flatnonzero(available)
    total = _integral(rates, dt)
    last = (len(rates) - 1) * dt
    theta = total[read] - _integral_at(total, rates, dt,
                                       np.clip(read * dt - delay_s, 0.0, last))
    out[read] = Rotation.from_rotvec(-theta).apply(out[read] - offset) + offset
    return out
