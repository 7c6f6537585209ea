r"""The magnetometer as a heading reference only, and when to trust it.

**Heading only.** A magnetometer reading :math:`m` (body frame) turned into
the reference frame by the estimate, :math:`m_E = A(\hat q)\, m`, points
north (the reference's azimuth) when the estimate's heading is right; its
azimuth :math:`\psi = \operatorname{atan2}(m_{E,x}, m_{E,y}) - \psi_r` is the
heading error, a rotation by :math:`\psi` about the vertical
(Laidig & Seel 2023, §3.3; the heading correction of VQF's
:math:`\delta`). With the body-frame error state :math:`q = \hat q \otimes
\delta q(\delta\theta)`, that rotation is :math:`e_z^\mathsf{T} A(\hat q)\,
\delta\theta`, so the update is

.. math::

    y = \psi, \qquad H = \bigl[\, v^\mathsf{T}\ \ 0 \,\bigr], \quad
    v = A(\hat q)^\mathsf{T} e_z, \qquad R = \frac{S_h}{T},

with the gain's attitude rows projected on :math:`v`, :math:`K_\theta \leftarrow
v\, v^\mathsf{T} K_\theta` (the optimal gain under the constraint that the
correction turns about the vertical only; the covariance follows the gain
used, in Joseph form). So a disturbed field can turn the heading, never
tilt the inclination. :math:`S_h` (rad²·s) is a density for the same
reason as gravity's (:mod:`estimators.imu.gravity`): the heading's error is
the room's field, which changes slowly as the body moves.

**When to trust it** (VQF §3.3, their defaults, taken as published). A
field is undisturbed when its norm is within :data:`NORM_TOLERANCE` of a
reference norm and its dip within :data:`DIP_TOLERANCE_RAD` of a reference
dip, for :data:`MIN_UNDISTURBED_S`; the reference follows the undisturbed
field (time constant :data:`REFERENCE_TIME_CONSTANT_S`). A field that stays
constant for :data:`NEW_FIELD_S` of motion (:data:`NEW_FIELD_MIN_RATE_RADPS`)
becomes the new reference (VQF's first one after :data:`FIRST_FIELD_S`;
here the first reference races, below): the
reference is learnt from the readings the filter trusts, never from a rest
the recording may not have. A disturbed field is not used for
:data:`MAX_REJECTION_S`; after that it is used with
:data:`REJECTION_FACTOR` times its σ, so that a lasting change of the field
cannot lose the heading for good. Where the field's reference is known (a
site's IGRF), its norm and dip are the reference from the start.

**A field that turns with the body** (beyond VQF). A magnet fixed to the
device (hard iron) keeps its norm, and, while the body turns about the
vertical, its dip: the tests above take it for a new constant field, and
the heading then follows the body. The Earth's field is fixed in the frame
that the gyro's strapdown holds still (:mod:`estimators.imu.gravity`);
a field fixed to the body turns there with every turn of the body. So a
reading is also tested there: turned into the strapdown frame, it must lie
within :data:`STEADY_TOLERANCE` of its own low-passed value (time constant
:data:`STEADY_TIME_CONSTANT_S`, :func:`steady_step`), or it is disturbed —
however constant its norm and dip — and never used, however long it has
been rejected: a field that turns with the body holds no heading.

**The first reference.** Where no reference is known, the first reading's
norm and dip are taken as the reference (:func:`first_state`), with no
rejection time used up, but unconfirmed: it is confirmed by
:data:`FIRST_FIELD_S` of readings that agree with it, in all. Until then it
races any other constant field (beyond VQF, whose first field needs
:data:`FIRST_FIELD_S` in motion): a candidate wins once it has been seen,
at any rate of turn, :data:`MIN_UNDISTURBED_S` longer than the reference
has (at most :data:`FIRST_FIELD_S`), and the heading learnt from the
replaced field is forgotten (:func:`forget_heading`: the filter's heading
variance is raised to :data:`FORGOTTEN_HEADING_SIGMA_RAD` squared,
:func:`widen_heading`), because the
start's heading came from that field: a recording that begins beside a
magnet costs seconds, not the minute a Kalman gain grown small would take
to turn the heading back. While the first reference is unconfirmed, a
candidate also outlives a disagreement shorter than
:data:`MIN_UNDISTURBED_S` (one reading's spike, a brief excursion of the
dip), where VQF starts its candidate anew. BROAD's 30 trials cut at their
first movement, magnetometer at a quarter rate: the MEKF 4.88° → 4.27° (the
candidate's grace) → 3.83° (the race and the forgetting; trials 28 and 29,
which start beside a magnet, 15.7° → 8.0° and 11.3° → 7.0°); the whole
trials, whose first reference is confirmed at rest, unchanged. Once a
reference is confirmed, a new field needs VQF's unbroken agreement for
:data:`NEW_FIELD_S` in motion, and the heading is kept.

**A first field no place on Earth has.** The Earth's field is 22 to 67 µT
at its surface (:data:`EARTH_FIELD_NORM_UT`); an unconfirmed reference
outside that is likelier a magnet's or a steel's, and loses its lead in the
race: an earthly candidate replaces it once seen :data:`MIN_UNDISTURBED_S`
(after the hold time by which the old field's own candidate outlives it),
however long the readings had agreed with it. It is otherwise a first
reference like any other: confirmed by :data:`FIRST_FIELD_S` of agreement,
and raced by unearthly candidates as before, because a field read in
another unit, or the Earth's own lifted above 67 µT by a scale error, is as
likely as a magnet; then the rule costs at most a brief earthly disturbance
in the first seconds taken for the field (and given back). BROAD's trials 28
and 29, cut at their first movement beside a magnet (70 and 72 µT): 8.04°
→ 6.96° and 7.03° → 6.65°; the 30 cut trials' mean 2.942° → 2.893°,
nothing else changed.

A trust state is :func:`new_state`; every function works on plain arrays.
"""
from __future__ import annotations

import math

import numpy as np

from estimators.imu import lowpass
from estimators.imu.gravity import rotate

#: VQF's disturbance detection (``magNormTh``, ``magDipTh``,
#: ``magMinUndisturbedTime``, ``magRefTau``, ``magNewTime``,
#: ``magNewFirstTime``, ``magNewMinGyr``, ``magMaxRejectionTime``,
#: ``magRejectionFactor``).
NORM_TOLERANCE = 0.1
DIP_TOLERANCE_RAD = math.radians(10.0)
MIN_UNDISTURBED_S = 0.5
REFERENCE_TIME_CONSTANT_S = 20.0
NEW_FIELD_S = 20.0
FIRST_FIELD_S = 5.0
NEW_FIELD_MIN_RATE_RADPS = math.radians(20.0)
MAX_REJECTION_S = 60.0
REJECTION_FACTOR = 2.0
#: The field in the strapdown frame: its low-pass time constant, s, and how
#: far (a fraction of its norm) a reading may lie from it: wide enough for the
#: strapdown's drift in a fast turn (a 1 % scale error at 1000 °/s is 5° in
#: the time constant), narrow enough for a magnet on a body that turns.
STEADY_TIME_CONSTANT_S = 0.5
STEADY_TOLERANCE = 0.2

#: The norms the Earth's field has at its surface, µT (as a recording holds
#: its field, :attr:`sensors.recording.Recording.magnetometer_uT`): from about
#: 22 over South America to about 67 near the south magnetic pole (the IGRF:
#: Alken et al., *Earth, Planets and Space* 73:49, 2021; ppigrf's model at
#: 2025.0 on a 2° grid at sea level gives 22.1 to 66.9 µT,
#: ``tests/test_imu_models.py``).
EARTH_FIELD_NORM_UT = (22.0, 67.0)

#: The heading's σ once the first field, which the start's heading came
#: from, is replaced (rad): a field not yet confirmed may be a magnet's, off
#: by any angle; 45° lets the new field set the heading in a few readings
#: while the linear update stays near its linear range.
FORGOTTEN_HEADING_SIGMA_RAD = math.pi / 4

#: Entries of a trust state (FORGET: the first reference was replaced since
#: the filter last read it, :func:`forget_heading`; SUPPORT_S: how long
#: readings have agreed with the reference, in all).
(REF_NORM, REF_DIP, UNDISTURBED_S, REJECTED_S, CANDIDATE_NORM, CANDIDATE_DIP,
 CANDIDATE_S, DISTURBED, CONFIRMED, CANDIDATE_MISSED_S, FORGET, SUPPORT_S) = range(12)
#: The length of a trust state.
STATE_SIZE = 12


def new_state(reference_norm: float = 0.0, reference_dip: float = 0.0) -> np.ndarray:
    """A trust state: no reference yet (norm 0), or a known one, trusted."""
    state = np.zeros(STATE_SIZE)
    state[REF_NORM], state[REF_DIP] = reference_norm, reference_dip
    state[REJECTED_S] = MAX_REJECTION_S
    state[CANDIDATE_NORM] = -1.0
    state[DISTURBED] = 0.0 if reference_norm > 0.0 else 1.0
    state[CONFIRMED] = 1.0 if reference_norm > 0.0 else 0.0
    return state


def first_state(norm: float, dip: float) -> np.ndarray:
    """A trust state whose reference is the first reading's (module
    docstring): trusted, with its whole rejection time ahead."""
    state = new_state(norm, dip)
    state[REJECTED_S] = 0.0
    state[CONFIRMED] = 0.0
    return state


def field_in_reference(q, field, out) -> tuple:
    """The field ``field`` (body) in the reference frame by estimate ``q``,
    into ``out``; its norm and dip (rad, positive downward)."""
    rotate(q, field, out)
    norm = math.sqrt(out[0] * out[0] + out[1] * out[1] + out[2] * out[2])
    return norm, -math.asin(max(-1.0, min(1.0, out[2] / norm)))


def steady_step(q_strapdown, field, coeffs, dt: float, state, scratch) -> bool:
    """Whether the field ``field`` (body), turned into the strapdown frame,
    lies within :data:`STEADY_TOLERANCE` of its low-passed value there
    (module docstring); ``state`` the low-pass filter's (4, 3), ``scratch`` (2, 3)."""
    rotate(q_strapdown, field, scratch[0])
    lowpass.step(scratch[0], coeffs, STEADY_TIME_CONSTANT_S, dt, state, scratch[1])
    d0 = scratch[0, 0] - scratch[1, 0]
    d1 = scratch[0, 1] - scratch[1, 1]
    d2 = scratch[0, 2] - scratch[1, 2]
    mean = scratch[1, 0] ** 2 + scratch[1, 1] ** 2 + scratch[1, 2] ** 2
    return d0 * d0 + d1 * d1 + d2 * d2 < STEADY_TOLERANCE ** 2 * mean


def _earthly(norm: float) -> bool:
    """Whether the Earth's field has the norm ``norm`` (µT) somewhere at its
    surface (:data:`EARTH_FIELD_NORM_UT`)."""
    return EARTH_FIELD_NORM_UT[0] <= norm <= EARTH_FIELD_NORM_UT[1]


def _close(norm: float, dip: float, reference_norm: float, reference_dip: float) -> bool:
    """Whether a field of ``norm`` and ``dip`` is the field of the reference
    ones: within :data:`NORM_TOLERANCE` of its norm and :data:`DIP_TOLERANCE_RAD`
    of its dip."""
    return (abs(norm - reference_norm) < NORM_TOLERANCE * reference_norm
            and abs(dip - reference_dip) < DIP_TOLERANCE_RAD)


def trust_step(norm: float, dip: float, rate_lp_norm: float, dt: float, state,
               steady: bool = True) -> float:
    """One reading's trust, ``dt`` s after the last (module docstring): 1.0
    to use it, :data:`REJECTION_FACTOR` to use it with that many times its σ,
    0.0 not to use it; ``steady``: whether it is steady in the strapdown
    frame (:func:`steady_step`)."""
    close = steady and _close(norm, dip, state[REF_NORM], state[REF_DIP])
    gain = 1.0 - math.exp(-dt / REFERENCE_TIME_CONSTANT_S)
    if close:
        state[UNDISTURBED_S] += dt
        state[SUPPORT_S] += dt
        if state[SUPPORT_S] >= FIRST_FIELD_S and state[CONFIRMED] == 0.0:
            state[CONFIRMED] = 1.0
            state[CANDIDATE_S] = 0.0     # time at rest counts toward a new field no more
        if state[UNDISTURBED_S] >= MIN_UNDISTURBED_S:
            state[DISTURBED] = 0.0
            state[REF_NORM] += gain * (norm - state[REF_NORM])
            state[REF_DIP] += gain * (dip - state[REF_DIP])
    else:
        state[UNDISTURBED_S] = 0.0
        state[DISTURBED] = 1.0
    _candidate_step(norm, dip, rate_lp_norm, dt, gain, state, steady)
    if state[DISTURBED] == 0.0:
        state[REJECTED_S] = max(state[REJECTED_S] - REJECTION_FACTOR * dt, 0.0)
        return 1.0
    if state[REJECTED_S] <= MAX_REJECTION_S:
        state[REJECTED_S] += dt
        return 0.0
    return REJECTION_FACTOR if steady else 0.0


def _candidate_step(norm: float, dip: float, rate_lp_norm: float, dt: float, gain: float,
                    state, steady: bool) -> None:
    """A constant field, steady in the strapdown frame, seen for
    :data:`NEW_FIELD_S` in motion becomes the reference; while the first
    reference is unconfirmed, one seen (at any rate of turn)
    :data:`MIN_UNDISTURBED_S` longer than it was, at most
    :data:`FIRST_FIELD_S` (an earthly one against a reference that is not:
    :data:`MIN_UNDISTURBED_S`), replaces it and asks the filter to forget
    the heading it gave (FORGET), and a candidate outlives a disagreement shorter
    than :data:`MIN_UNDISTURBED_S` (module docstring)."""
    agrees = steady and _close(norm, dip, state[CANDIDATE_NORM], state[CANDIDATE_DIP])
    if agrees:
        state[CANDIDATE_MISSED_S] = 0.0
        if rate_lp_norm >= NEW_FIELD_MIN_RATE_RADPS or state[CONFIRMED] == 0.0:
            state[CANDIDATE_S] += dt
        state[CANDIDATE_NORM] += gain * (norm - state[CANDIDATE_NORM])
        state[CANDIDATE_DIP] += gain * (dip - state[CANDIDATE_DIP])
        lead = (state[SUPPORT_S] if _earthly(state[REF_NORM])
                or not _earthly(state[CANDIDATE_NORM]) else 0.0)
        first = state[CONFIRMED] == 0.0 and state[CANDIDATE_S] >= min(
            FIRST_FIELD_S, lead + MIN_UNDISTURBED_S)
        if state[DISTURBED] > 0.0 and (state[CANDIDATE_S] >= NEW_FIELD_S or first):
            same = _close(state[CANDIDATE_NORM], state[CANDIDATE_DIP], state[REF_NORM],
                          state[REF_DIP])
            if not (same or state[CONFIRMED] > 0.0):
                state[FORGET] = 1.0
            state[REF_NORM], state[REF_DIP] = state[CANDIDATE_NORM], state[CANDIDATE_DIP]
            state[DISTURBED] = 0.0
            state[UNDISTURBED_S] = MIN_UNDISTURBED_S
            state[SUPPORT_S] = state[CANDIDATE_S]
            if state[CANDIDATE_S] >= FIRST_FIELD_S:
                state[CONFIRMED] = 1.0
    elif (state[CONFIRMED] == 0.0 and state[CANDIDATE_NORM] > 0.0
          and state[CANDIDATE_MISSED_S] + dt < MIN_UNDISTURBED_S):
        state[CANDIDATE_MISSED_S] += dt
    else:
        state[CANDIDATE_S] = state[CANDIDATE_MISSED_S] = 0.0
        state[CANDIDATE_NORM], state[CANDIDATE_DIP] = norm, dip


def forget_heading(state) -> bool:
    """Whether the first reference was replaced since the last call (the
    heading learnt from it is to be forgotten, :func:`widen_heading`); clears
    the flag."""
    replaced = state[FORGET] != 0.0
    state[FORGET] = 0.0
    return replaced


def widen_heading(v, P) -> None:
    """The heading's variance ``vᵀ P_θθ v`` raised to at least
    :data:`FORGOTTEN_HEADING_SIGMA_RAD` squared, along ``v`` (the vertical
    in the body frame, the heading's axis): ``P_θθ += max(0, σ² − vᵀ P_θθ v)
    v vᵀ``; raised, not added to, so that forgetting twice is forgetting once."""
    current = 0.0
    for i in range(3):
        for j in range(3):
            current += v[i] * P[i, j] * v[j]
    extra = max(FORGOTTEN_HEADING_SIGMA_RAD ** 2 - current, 0.0)
    for i in range(3):
        for j in range(3):
            P[i, j] += extra * v[i] * v[j]


def validated(state) -> bool:
    """Whether the field has a reference and is undisturbed now: only then
    may the heading's updates move the bias (a field not yet learnt, or
    disturbed, would bend the bias toward its own error)."""
    return state[REF_NORM] > 0.0 and state[DISTURBED] == 0.0
