"""A declared reference attitude (``[recording.reference]``, :mod:`sensors.
declared`): quaternions in either order or Euler angles, into ENU or NED,
interpolated on the gyro's clock, and checked to turn as the gyro turns
(:mod:`sensors.turning`), naming the declaration that would fit where
another does."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from dynamics.validation import InvalidParameterError
from sensors.recording_keys import choice, refuse
from sensors.turning import (clock_offset, first_fitting, offset_advice, reference_advice,
                             reference_fit, reference_fits, reference_problem)
from sensors.vector import readings_taken

#: The reference is interpolated between readings at most this many of its
#: typical intervals apart (a longer one is a gap: the markers were not seen).
REFERENCE_GAP_FACTOR = 1.5
#: The rotation to East-North-Up from each world frame a reference may be
#: declared in: ENU, North-East-Down, and a motion-capture room's Y-up
#: (OptiTrack Motive's default: x, y up, z; its heading is the room's, as
#: every motion-capture frame's: :func:`check_field_north` says how far).
FRAME_ROTATIONS = {"ENU": np.eye(3),
                   "NED": np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]),
                   "Y-up": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])}
FRAMES = tuple(FRAME_ROTATIONS)
NED_TO_ENU = FRAME_ROTATIONS["NED"]
#: The field's azimuth in the reference's world beyond which its north is
#: said not to be the field's, deg: the magnetic declination is within it
#: almost everywhere people record.
NORTH_TOLERANCE_DEG = 20.0
#: The reference's keys that have a default, and it.
DEFAULTS = {"order": "wxyz", "unit": "deg", "frame": "ENU"}


def declared_reference(path: Path, clock: np.ndarray, times: np.ndarray, values: np.ndarray,
               section: dict) -> np.ndarray:
    """The reference attitude (body → ENU, scalar first) at the gyro's
    times: interpolated on the shortest arc between consecutive readings
    not further apart than :data:`REFERENCE_GAP_FACTOR` of its typical
    interval; NaN elsewhere (across a gap, and before or after it)."""
    return _on_gyro_times(path, clock, times, _in_enu(path, _reference_rotations(
        path, values, section), section))


def _in_enu(path: Path, rotations, section: dict):
    """``rotations`` (body → the declared frame) as body → ENU."""
    from scipy.spatial.transform import Rotation
    frame = choice(path, "recording.reference.frame", section.get("frame", "ENU"), FRAMES)
    return rotations if frame == "ENU" else Rotation.from_matrix(FRAME_ROTATIONS[frame]) \
        * rotations


def _on_gyro_times(path: Path, clock: np.ndarray, times: np.ndarray, rotations) -> np.ndarray:
    from scipy.spatial.transform import Slerp
    if len(times) < 2:
        refuse(path, "recording.reference.columns", None, "hold one reading; the reference "
                "needs two to be interpolated")
    within = (clock >= times[0]) & (clock <= times[-1])
    after = np.clip(np.searchsorted(times, clock, side="left"), 1, len(times) - 1)
    exact = np.isin(clock, times)
    typical = float(np.median(np.diff(times)))
    close = (times[after] - times[after - 1]) <= REFERENCE_GAP_FACTOR * typical
    valid = within & (close | exact)
    quat = np.full((len(clock), 4), np.nan)
    between = valid & ~exact
    if between.any():
        at = Slerp(times, rotations)(clock[between])
        quat[between] = at.as_quat(canonical=True, scalar_first=True)
    quat[exact] = rotations[np.searchsorted(times, clock[exact])].as_quat(canonical=True,
                                                                          scalar_first=True)
    return quat


def check_reference(path: Path, clock: np.ndarray, rates: np.ndarray, read: tuple,
                    section: dict, reference: np.ndarray, check_scale=None) -> None:
    """Refuse a reference that turns unlike the gyro (:func:`sensors.turning.
    reference_fit`) where another declaration of it fits, naming it; else
    call ``check_scale`` (which refuses a gyro or a clock in the wrong unit:
    :func:`sensors.declared_units.check_reference_scale`; a gyro 57 times
    too slow shows too little turning to fit); warn where still nothing
    fits (the gyro's clock or the reference's axes may be the cause, which
    no key declares)."""
    dt = float(np.median(np.diff(clock)))
    fit = reference_fit(rates, reference, dt)
    if fit is not None and reference_fits(fit):
        _note_clock_offset(path, fit, rates, reference, dt)
        return
    key = "sequence" if "sequence" in section else "order"
    fitting = fit and first_fitting(rates, (
        (text, _on_gyro_times(path, clock, read[0], rotations))
        for text, rotations in _reference_candidates(path, section, read[1])), dt)
    if fitting:
        key = fitting.split(" = ")[0] if " = " in fitting else key    # the key it changes
        refuse(path, f"recording.reference.{key}", section.get(key, DEFAULTS.get(key)),
               f"makes a reference that {reference_problem(fit)}; {fitting} would fit")
    if check_scale is not None:
        check_scale()
    if fit is not None:
        warnings.warn(f"{path.name}: recording.reference: it {reference_problem(fit)}: "
                      f"{reference_advice(fit, rates, reference, dt)}", stacklevel=2)


#: A reference that fits but leaves more of its turning than this share
#: unexplained (four times the most of BROAD's 30 trials, 0.56 %; twice it
#: while the check read each gyro reading as the interval after its sample)
#: is tried at offsets of its clock: a 50 ms offset left 3.0 % and passed,
#: every score some degrees worse (1.65° to 4.68°).
CLOCK_NOTE_UNEXPLAINED = 0.022


def _note_clock_offset(path: Path, fit, rates: np.ndarray, reference: np.ndarray,
                       dt: float) -> None:
    """Say where an offset of the reference's clock against the gyro's
    explains its turning far better (half of what it leaves unexplained)."""
    if fit[0] <= CLOCK_NOTE_UNEXPLAINED:
        return
    found = clock_offset(rates, reference, dt)
    if found is None or abs(found[0]) < dt / 2 or found[1] > fit[0] / 2:
        return
    warnings.warn(f"{path.name}: recording.reference: it fits, {fit[0] * 100:.1f} % of its "
                  f"turning unexplained; {offset_advice(found)}", stacklevel=3)


def check_gravity_up(path: Path, reference: np.ndarray, specific_force: np.ndarray,
                     section: dict) -> None:
    """Refuse a reference and an accelerometer that put gravity down: the
    accelerometer's readings turned into the world by the reference (ENU,
    the declared frame converted) must point up on the whole (+9.8 m/s² at
    rest, and so on average in motion). A median below zero is a flipped
    accelerometer (a log of acceleration, as Apple's Core Motion gives it,
    not of specific force) or a reference in the other frame, which no
    turning of either with the gyro tells apart."""
    seen = np.isfinite(reference).all(axis=1) & readings_taken(specific_force)
    if not seen.any():
        return
    from dynamics.quaternion import to_rotation
    world = np.median(to_rotation(reference[seen]).apply(specific_force[seen]), axis=0)
    up = float(world[2])
    if abs(up) < 0.5 * np.linalg.norm(world):        # gravity along another axis
        axis = int(np.argmax(np.abs(world)))
        named = ("-" if world[axis] < 0 else "") + "xyz"[axis]
        hint = ('declare frame = "Y-up" (a motion-capture room\'s, OptiTrack Motive\'s '
                'default)' if named == "y" and section.get("frame", "ENU") == "ENU" else
                "turn it into ENU or NED before declaring it")
        refuse(path, "recording.reference.frame", section.get("frame", "ENU"), "puts gravity "
               f"along the world's {named} axis (the accelerometer's median "
               f"{np.round(world, 2).tolist()} m/s² in it): it is not this frame; {hint}")
    if up < 0.0:
        frame = section.get("frame", "ENU")
        refuse(path, "recording.reference.frame", frame, "puts the accelerometer's gravity down "
               f"(its median {up:.3g} m/s² up, where gravity reads +9.8): declare frame = "
               f"\"{'ENU' if frame == 'NED' else 'NED'}\", or, if the reference is right, "
               "the accelerometer's axes = [\"-x\", \"-y\", \"-z\"] (a log of acceleration, "
               "not of specific force)")


def check_field_north(path: Path, reference: np.ndarray, field: np.ndarray) -> None:
    """Say where the reference's north is not the field's: the field turned
    into the world by the reference points, horizontally, more than
    :data:`NORTH_TOLERANCE_DEG` from north (a motion-capture room's axes),
    and every heading score includes that offset (30° of a 30.3° score)."""
    seen = np.isfinite(reference).all(axis=1) & readings_taken(field)
    if np.count_nonzero(seen) < 2:
        return
    from dynamics.quaternion import to_rotation
    horizontal = to_rotation(reference[seen]).apply(field[seen])[:, :2]
    east, north = np.median(horizontal, axis=0)
    azimuth = float(np.degrees(np.arctan2(east, north)))
    # A room's north is one azimuth; a magnetometer's own iron turns with the
    # body, and the field it reads, turned into the world, wanders with it.
    heading = np.exp(1j * np.arctan2(horizontal[:, 0], horizontal[:, 1]))
    wander = float(np.degrees(np.sqrt(-2.0 * np.log(max(abs(heading.mean()), 1e-12)))))
    if wander > NORTH_TOLERANCE_DEG:
        warnings.warn(f"{path.name}: recording.magnetometer: the field, turned into the "
                      f"world by the reference, wanders by {wander:.0f}° (circular spread) as "
                      "the body turns: the magnetometer's own iron (calibrate = true in "
                      "[recording.magnetometer] fits it), or a room of steel",
                      stacklevel=3)
    elif abs(azimuth) > NORTH_TOLERANCE_DEG:
        warnings.warn(f"{path.name}: recording.reference: the field points {azimuth:.0f}° "
                      "from its world's north (the magnetic declination, within "
                      f"±{NORTH_TOLERANCE_DEG:.0f}° almost everywhere, aside): its heading is "
                      "a room's, not north's, and every heading score includes the offset",
                      stacklevel=3)


def _reference_candidates(path: Path, section: dict, values: np.ndarray):
    """``(what to declare, the rotations it makes)`` for the declarations a
    logger most often gets wrong: the other quaternion order, or the Euler
    sequence extrinsic for intrinsic, reversed, or in the other unit; and
    an attitude world → body (its inverse)."""
    if "sequence" in section:
        sequence = section["sequence"]
        changes = ({"sequence": sequence.swapcase()}, {"sequence": sequence[::-1]},
                   {"sequence": sequence.swapcase()[::-1]},   # roll, pitch, yaw listed
                   {"unit": "rad" if section.get("unit", "deg") == "deg" else "deg"})
    else:
        changes = ({"order": "xyzw" if section.get("order", DEFAULTS["order"]) == "wxyz"
                    else "wxyz"},)
    for change in changes:
        (key, value), = change.items()
        try:
            rotations = _reference_rotations(path, values, {**section, **change})
        except InvalidParameterError:
            continue
        yield f'{key} = "{value}"', _in_enu(path, rotations, section)
    yield ("its inverse (an attitude world → body, which must be inverted)",
           _in_enu(path, _reference_rotations(path, values, section).inv(), section))


def _reference_rotations(path: Path, values: np.ndarray, section: dict):
    from scipy.spatial.transform import Rotation
    if "sequence" in section:
        unit = choice(path, "recording.reference.unit", section.get("unit", "deg"),
                       ("deg", "rad"))
        try:
            return Rotation.from_euler(str(section["sequence"]), values, degrees=unit == "deg")
        except ValueError as err:
            refuse(path, "recording.reference.sequence", section["sequence"],
                    f"is not an Euler sequence ({err})")
    order = choice(path, "recording.reference.order", section.get("order", "wxyz"),
                    ("wxyz", "xyzw"))
    norms = np.linalg.norm(values, axis=1)
    off = np.flatnonzero(np.abs(norms - 1.0) > 0.01)
    if len(off):
        refuse(path, "recording.reference.columns", section.get("columns"), f"row "
                f"{off[0]} has norm {norms[off[0]]:.4g}; a reference quaternion has norm 1")
    return Rotation.from_quat(values, scalar_first=order == "wxyz")
