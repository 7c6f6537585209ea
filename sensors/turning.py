"""Does every channel of a recording turn as its gyro says?

A logger's declaration can be wrong in ways no range check sees: a
magnetometer's axes in another order, a reference quaternion read scalar
first when it was written scalar last. Each leaves the numbers plausible and
the scores meaningless (150° and no message). The gyro is the one channel
that says how the body turns, and every other channel must agree with it:

- a vector fixed in the world (gravity, the Earth's field), seen from the
  body, turns as :math:`\\dot v = -\\omega \\times v` (Markley & Crassidis
  2014, §3.1, eq. 3.18's kinematics for a constant vector);
- a reference attitude :math:`R_k` (body → world) turns by
  :math:`R_k^\\top R_{k+n} = \\exp([\\bar\\omega \\times] n\\,\\Delta t)` over
  ``n`` samples, :math:`\\bar\\omega` the gyro's mean rate in the body frame.

Both are compared over blocks of :data:`TURNING_WINDOW_S` (the readings'
noise, differentiated, would drown the turning), or, for a sensor that
reads slower, between its readings. The vectors' agreement is a
correlation, which a sensor's scale and sign do not move, with a hard
iron's constant offset fitted (the change is linear in it); the
reference's is the share of its turning that one fixed rotation of the
gyro's rates, less a constant bias, leaves unexplained (Wahba's problem,
solved by scipy's ``Rotation.align_vectors``, and the bias, in turn), the
rotation being the reference's axes against the IMU's.
"""
from __future__ import annotations

import itertools
import math
import warnings

import numpy as np

from sensors.vector import readings_taken

#: Both channels are averaged over blocks this long, s.
TURNING_WINDOW_S = 0.1
#: The unit check: where the accelerometer's turning and the gyro's agree
#: in shape (correlation above this; a turn about the vertical turns no
#: gravity, and is no evidence), the scale that fits them must be within
#: this factor of 1 (a unit's mistake is 57).
TURNING_CORRELATION, TURNING_FACTOR = 0.3, 10.0
#: Below this, gravity turns the other way from the gyro's prediction: a
#: mirrored (left-handed) frame, which no clean log comes near (BROAD: 0.84-0.99).
MIRRORED_CORRELATION = -2 * TURNING_CORRELATION
#: The axes check: declared axes whose turning correlates below the first
#: with the gyro's, where another order of the axes correlates above the
#: second, are wrong. A correct magnetometer on BROAD's 30 trials correlates
#: 0.84–0.99 (0.42 with a magnet attached 1 cm from it: then no order
#: fits, and none is proposed); an accelerometer in translation, 0.3 or
#: less, and no other order above 0.6 (linear acceleration turns with no
#: rate), so it is seldom judged. A wrong order that keeps one axis in place
#: correlates as far as the body turns about that axis: 0.3-0.5 where it
#: turns about all three alike, 0.62 for a quarter turn about the axis that
#: carries most of the rate (``tests/test_turning.py``; it had been judged
#: below 0.6, and passed). So the declared order is judged below 0.8, under
#: every correct one on BROAD, and refused only where another reaches 0.9.
AXES_DECLARED_BELOW, AXES_OTHER_ABOVE = 0.8, 0.9
#: Each sensor's axes thresholds. An accelerometer's turning, its offset
#: fitted, correlates 0.48–0.87 with the gyro's on BROAD's 30 trials (a
#: translation's linear acceleration, not gravity, drives its low end;
#: another order then reaches 0.9): judged only below 0.3, where one of its
#: axes is swapped (trial 02 with x and z swapped: -0.04, the right order
#: 0.85), it is refused where another order passes 0.75.
AXES_THRESHOLDS = {"magnetometer": (AXES_DECLARED_BELOW, AXES_OTHER_ABOVE),
                   "accelerometer": (0.3, 0.75)}
#: The reference check: a reference whose turning is left unexplained by
#: more than this share (by any fixed rotation of the gyro's rates) is not
#: the attitude of that gyro's body as declared (0.03 % to 0.56 % on BROAD's
#: 30 trials; 15 % to 120 % for the same trials read in the wrong order).
REFERENCE_UNEXPLAINED = 0.1
#: … and one whose axes are turned more than this from the gyro's, deg
#: (0.1–1.5° on BROAD), is said to be: every score would include it.
REFERENCE_TURNED_DEG = 5.0
#: The reference's fit takes the gyro's bias as unknown, fitted with the
#: rotation in turn this many times (a MEMS gyro's bias of degrees a second
#: would otherwise be read as turning the reference does not do).
BIAS_ITERATIONS = 5
#: What a reference that is the gyro's own body leaves unexplained (BROAD).
OWN_BODY_UNEXPLAINED = 0.01
#: Evidence enough: this many blocks, turning this fast on average (rad/s).
MIN_BLOCKS, MIN_RATE_RADPS = 20, 0.1


def _block_means(values: np.ndarray, steps: int) -> np.ndarray:
    blocks = len(values) // steps    # none where the values are shorter than a block
    return values[:blocks * steps].reshape(blocks, steps, values.shape[1]).mean(axis=1)


def held_readings(vectors: np.ndarray) -> np.ndarray:
    """A vector channel read at some of the gyro's samples (zeros between
    readings) held from each reading to the next (zeros before the first)."""
    read = readings_taken(vectors)
    last = np.maximum.accumulate(np.where(read, np.arange(len(vectors)), 0))
    return vectors[last]


def _turning(rates: np.ndarray, vectors: np.ndarray, dt: float, offset: bool = False,
             window_s: float = TURNING_WINDOW_S):
    """The vectors' change per block of :data:`TURNING_WINDOW_S` (for a
    sensor that reads slower, between its readings), and the change the
    gyro predicts, -ω × v at the block's mean; with ``offset``, -ω × (v - h)
    for the constant ``h`` that fits best (a hard iron: linear in ``h``).
    None where there are too few blocks."""
    read = np.flatnonzero(readings_taken(vectors))
    if len(read) > 1 and np.median(np.diff(read)) * dt > window_s:
        summed = np.concatenate([np.zeros((1, 3)), np.cumsum(rates, axis=0)])
        steps = np.diff(read)[:, None]
        # from reading i to reading j the gyro's readings i + 1 … j (each the
        # rate over the interval before its sample)
        rate = (summed[read[1:] + 1] - summed[read[:-1] + 1]) / steps
        vector = vectors[read]
        change = np.diff(vector, axis=0) / (steps * dt)
        vector = (vector[1:] + vector[:-1]) / 2
    else:
        steps = max(1, int(round(window_s / dt)))
        vector, rate = _block_means(held_readings(vectors), steps), _block_means(rates, steps)
        change = np.diff(vector, axis=0) / (steps * dt)
        rate, vector = (rate[1:] + rate[:-1]) / 2, (vector[1:] + vector[:-1]) / 2
    if len(change) < 2:
        return None
    predicted = -np.cross(rate, vector)
    if offset:              # change = -ω × v + ω × h = predicted + [ω×] h
        cross = np.cross(rate[:, None, :], np.eye(3)).transpose(0, 2, 1)   # [ω×]: ω × e_j
        h = np.linalg.lstsq(cross.reshape(-1, 3), (change - predicted).reshape(-1), rcond=None)[0]
        predicted = predicted + cross @ h
    return change, predicted


def _correlation(a: np.ndarray, b: np.ndarray) -> float | None:
    scale = math.sqrt(float(np.sum(a * a)) * float(np.sum(b * b)))
    return float(np.sum(a * b)) / scale if scale > 0.0 else None


def gravity_turning(rates: np.ndarray, specific_force: np.ndarray, dt: float,
                    window_s: float = TURNING_WINDOW_S) -> tuple | None:
    """``(correlation, scale)`` of gravity's turning as the accelerometer
    sees it with the turning ``rates`` predict, and the factor by which the
    rates must be multiplied to match it (1 for a gyro in the toolkit's
    rad/s); None where there is too little of it. A correlation near −1 is
    a frame mirrored between the two: columns in a left-handed order
    (``ω × v`` changes its sign under a reflection of both)."""
    read = np.flatnonzero(readings_taken(specific_force))
    if len(read) < 0.9 * len(specific_force) and (
            len(read) < 2 or np.median(np.diff(read)) * dt <= window_s):
        # an accelerometer on its own clock (a phone logger's own timestamps
        # cover three gyro samples in four): its readings held from each to
        # the next, whose turning the windows then see; one slower than the
        # windows is compared reading to reading (_turning)
        specific_force = held_readings(specific_force)
    turning = _turning(rates, specific_force, dt, window_s=window_s)
    if turning is None:
        return None
    change, predicted = turning
    correlation = _correlation(change, predicted)
    if correlation is None:
        return None
    return correlation, float(np.sum(change * predicted)) / float(np.sum(predicted * predicted))


def field_correlation(rates: np.ndarray, field: np.ndarray, dt: float) -> float | None:
    """How the field's turning (a hard iron's offset fitted) correlates with
    the gyro's prediction: near 1 in the gyro's frame, near -1 in its mirror
    (0.84–0.99 on BROAD's 30 trials, where the accelerometer's, in fast
    translation, falls to -0.54); None where too little is seen."""
    turning = _turning(rates, field, dt, offset=True)
    return None if turning is None or not np.any(turning[1]) else _correlation(*turning)


def turning_scale(rates: np.ndarray, specific_force: np.ndarray, dt: float,
                  window_s: float = TURNING_WINDOW_S) -> float | None:
    """The factor by which ``rates`` must be multiplied to turn gravity as
    the accelerometer sees it turn (1 for a gyro in the toolkit's rad/s);
    None where the turning is not seen clearly enough to say."""
    found = gravity_turning(rates, specific_force, dt, window_s)
    return None if found is None or found[0] < TURNING_CORRELATION else found[1]


def _orders() -> list[np.ndarray]:
    """The reorderings of three axes up to a common sign (signed
    permutations, one of each pair ``M``, ``-M``: a vector's turning cannot
    tell ``v`` from ``-v``, which turn alike)."""
    orders = []
    for columns in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=2):
            matrix = np.zeros((3, 3))
            matrix[range(3), columns] = (1.0, *signs)
            orders.append(matrix)
    return orders


ORDERS = _orders()


def axes_fit(rates: np.ndarray, vectors: np.ndarray, dt: float,
             thresholds: tuple = (AXES_DECLARED_BELOW, AXES_OTHER_ABOVE)):
    """``(declared, better, its correlation)``: how the turning of
    ``vectors`` (in the device's axes as declared; rows of zeros where the
    sensor did not read) correlates with the gyro's, and the reordering
    ``better`` (a matrix: device axes = ``better`` @ declared, up to its
    sign, which turning cannot tell) that fits far better; or None where
    the declared axes fit, or where the turning is not seen clearly enough
    to say; ``thresholds``: (declared below, another order above), a
    magnetometer's by default (:data:`AXES_THRESHOLDS`). A constant offset
    (a hard iron) is fitted with each order."""
    return _better_order(rates, vectors, dt, thresholds, ORDERS,
                         lambda order: (rates, vectors @ order.T))


def rates_fit(rates: np.ndarray, vectors: np.ndarray, dt: float,
              thresholds: tuple = (AXES_DECLARED_BELOW, AXES_OTHER_ABOVE)):
    """:func:`axes_fit` the other way: ``(declared, better, its
    correlation)``, ``better`` the reordering of the gyro's axes (rates
    ``better @ ω``) under which ``vectors`` turn as the rates predict, far
    better than as declared; None where the declared axes fit, or too little
    is seen. Its sign is the rates': a mirror turns the other way."""
    signed = [sign * order for order in ORDERS for sign in (1, -1)]
    return _better_order(rates, vectors, dt, thresholds, signed,
                         lambda order: (rates @ order.T, vectors))


def _better_order(rates: np.ndarray, vectors: np.ndarray, dt: float, thresholds: tuple,
                  orders: list, reordered):
    """What :func:`axes_fit` and :func:`rates_fit` share: the declared
    turning's correlation and, below ``thresholds[0]``, the one of
    ``orders`` whose ``reordered(order)`` (rates, vectors) correlates best,
    where it reaches ``thresholds[1]``."""
    turning = _turning(rates, vectors, dt, offset=True)
    if turning is None or not np.any(turning[1]) or len(turning[0]) < MIN_BLOCKS:
        return None                   # too few blocks: a correlation by chance
    declared = _correlation(*turning)
    if declared is None or declared >= thresholds[0]:
        return None
    fits = [(_correlation(*_turning(*reordered(order), dt, offset=True)) or -1.0, index)
            for index, order in enumerate(orders)]
    best, index = max(fits)
    return (declared, orders[index], best) if best >= thresholds[1] else None


def _turned_rates(rates: np.ndarray, steps: int, starts: int) -> np.ndarray:
    """The gyro's mean rate from each block's first sample to the next
    block's, ``(starts - 1, 3)``: reading ``k`` is the rate over the interval
    before sample ``k`` (an IMU's, as the filters take it), so the turn from
    sample ``s`` to ``s + steps`` is read at ``s + 1`` to ``s + steps``."""
    return _block_means(rates[1:], steps)[:starts - 1]


def reference_fit(rates: np.ndarray, reference_quat: np.ndarray, dt: float):
    """``(unexplained, rotation)``: the share of the reference's turning
    (scalar-first quaternions, body → world, NaN where none) that the
    fixed rotation of the gyro's rates best fitting it leaves unexplained,
    and that rotation (None where the rates turn about one axis only, which
    leaves it undetermined); None where there is too little turning."""
    from scipy.spatial.transform import Rotation
    steps = max(1, int(round(TURNING_WINDOW_S / dt)))
    starts = np.arange(len(rates) // steps) * steps
    if len(starts) < 2:
        return None
    quat = reference_quat[starts]
    paired = ~np.isnan(quat[:-1]).any(axis=1) & ~np.isnan(quat[1:]).any(axis=1)
    if np.count_nonzero(paired) < MIN_BLOCKS:
        return None
    attitude = Rotation.from_quat(quat[:-1][paired], scalar_first=True)
    after = Rotation.from_quat(quat[1:][paired], scalar_first=True)
    turned = (attitude.inv() * after).as_rotvec() / (steps * dt)
    rate = _turned_rates(rates, steps, len(starts))[paired]
    if np.sqrt(np.mean(np.sum(rate * rate, axis=1))) < MIN_RATE_RADPS:
        return None
    if not np.any(turned):
        return 1.0, None                    # a reference that never turns while the gyro does
    bias = np.zeros(3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)    # a poorly defined fit: see below
        for _ in range(BIAS_ITERATIONS):    # turned ≈ C (rate - b): C, then b, in turn
            rotation, _ = Rotation.align_vectors(turned, rate - bias)
            bias = np.mean(rate - rotation.inv().apply(turned), axis=0)
    unexplained = float(np.sum((turned - rotation.apply(rate - bias)) ** 2)
                        / np.sum(turned * turned))
    spread = np.linalg.svd(rate - bias, compute_uv=False)
    return unexplained, (rotation if spread[1] >= 0.2 * spread[0] else None)


def reference_scale(rates: np.ndarray, reference_quat: np.ndarray, dt: float) -> float | None:
    """The factor by which ``rates`` must be multiplied to turn as fast as
    the reference turns (1 for a gyro in rad/s on the reference's clock):
    the ratio of their RMS rates over blocks of :data:`TURNING_WINDOW_S`;
    None where neither turns at :data:`MIN_RATE_RADPS` on average, or the
    reference hardly at all (a still reference beside a gyro's bias, or a
    gyro in a wrong unit: no scale to tell it by), or too few blocks hold
    a reference."""
    from scipy.spatial.transform import Rotation
    steps = max(1, int(round(TURNING_WINDOW_S / dt)))
    starts = np.arange(len(rates) // steps) * steps
    quat = reference_quat[starts]
    paired = ~np.isnan(quat[:-1]).any(axis=1) & ~np.isnan(quat[1:]).any(axis=1)
    if np.count_nonzero(paired) < MIN_BLOCKS:
        return None
    turned = (Rotation.from_quat(quat[:-1][paired], scalar_first=True).inv() * Rotation.from_quat(
        quat[1:][paired], scalar_first=True)).as_rotvec() / (steps * dt)
    rate = _turned_rates(rates, steps, len(starts))[paired]
    turned_rms, rate_rms = (float(np.sqrt(np.mean(np.sum(x * x, axis=1)))) for x in (turned, rate))
    if max(turned_rms, rate_rms) < MIN_RATE_RADPS or rate_rms == 0.0 or \
            turned_rms < MIN_RATE_RADPS / TURNING_FACTOR:
        return None
    return turned_rms / rate_rms


def reference_fits(fit) -> bool:
    """Whether a :func:`reference_fit` says the reference is the gyro's
    body, in the gyro's axes (no fit, for too little turning, is no
    evidence against it)."""
    return fit is None or (fit[0] <= REFERENCE_UNEXPLAINED and (
        fit[1] is None or math.degrees(fit[1].magnitude()) <= REFERENCE_TURNED_DEG))


#: What a warned-of reference's scores mean, and what to check.
REFERENCE_ADVICE = ("every score includes it (check the reference's convention, its axes "
                    "against the IMU's and its clock against the gyro's)")
#: The offsets of its clock against the gyro's a warned-of reference is
#: tried at, s: within half a second either way, every 5 ms.
MAX_CLOCK_OFFSET_S, CLOCK_OFFSET_STEP_S = 0.5, 0.005


def clock_offset(rates: np.ndarray, reference_quat: np.ndarray, dt: float):
    """``(offset_s, unexplained)``: the shift of the reference's clock
    against the gyro's (positive: its attitudes come that late) whose
    :func:`reference_fit` leaves the least unexplained; None where none fits."""
    step = max(1, int(round(CLOCK_OFFSET_STEP_S / dt)))
    most = int(round(MAX_CLOCK_OFFSET_S / dt))
    best = None
    for shift in range(-most, most + 1, step):
        fit = (reference_fit(rates[:len(rates) - shift], reference_quat[shift:], dt)
               if shift >= 0 else reference_fit(rates[-shift:], reference_quat[:shift], dt))
        if fit is not None and (best is None or fit[0] < best[1]):
            best = (shift * dt, fit[0])
    return best


def reference_advice(fit, rates: np.ndarray, reference_quat: np.ndarray, dt: float) -> str:
    """What to check of a reference whose ``fit`` (:func:`reference_fit`)
    does not fit: where its turning is left unexplained, its clock's offset
    if one explains it (:func:`clock_offset`), else :data:`REFERENCE_ADVICE`
    (which alone a reference that fits with its axes turned is told)."""
    if fit[0] <= REFERENCE_UNEXPLAINED:
        return REFERENCE_ADVICE
    found = clock_offset(rates, reference_quat, dt)
    if found is None or found[1] > REFERENCE_UNEXPLAINED or abs(found[0]) < dt / 2:
        return REFERENCE_ADVICE
    return offset_advice(found)


def offset_advice(found: tuple) -> str:
    """What an offset :func:`clock_offset` ``found`` says of a reference's
    clock, in words."""
    offset_s, unexplained = found
    return (f"its clock {abs(offset_s) * 1e3:.0f} ms {'behind' if offset_s > 0 else 'ahead of'} "
            f"the gyro's would explain it ({unexplained * 100:.1f} % unexplained then): every "
            "score includes that offset")


def reference_problem(fit) -> str:
    """What a :func:`reference_fit` that does not fit says, in words."""
    unexplained, rotation = fit
    if unexplained > REFERENCE_UNEXPLAINED or rotation is None:
        return (f"turns unlike the gyro ({unexplained * 100:.0f} % of its turning unexplained "
                "by any fixed rotation of the gyro's rates, less a constant bias; about "
                f"{OWN_BODY_UNEXPLAINED * 100:.0f} % for the gyro's own body)")
    return (f"turns as the gyro only with its axes turned "
            f"{math.degrees(rotation.magnitude()):.1f}° from the gyro's")


def first_fitting(rates: np.ndarray, candidates, dt: float) -> str | None:
    """The first of the ``(what, quaternions)`` candidates whose turning
    shows, clearly, the gyro's body in the gyro's axes."""
    for text, quat in candidates:
        fit = reference_fit(rates, quat, dt)
        if fit is not None and reference_fits(fit):
            return text
    return None
