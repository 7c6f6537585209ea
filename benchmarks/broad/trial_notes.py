"""What ``broad`` says of a trial as it loads it (:meth:`benchmarks.broad.
dataset.BroadDataset.load`), once per trial: readings that are exactly
zero, a channel at its rail, a sensor that reads nothing for a while
(:func:`note_silences`), and the samples before the first an attitude
can be taken at, which it leaves out (:func:`from_start`); and, once the
run's inputs are checked, how late its magnetometer reads against its gyro
(:func:`magnetometer_timed` takes the readings at their times as the trial
loads, :func:`note_magnetometer_delay` says so)."""
from __future__ import annotations

import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

from benchmarks.broad.inputs import heading_reference, runnable_rule, start_sample, \
    usable_readings
from sensors.delay import AUTO_ADVICE, at_sample_times, described, hard_iron_at, \
    recording_fit, timed_readings
from sensors.recording import Recording, reading_interval_s, true_runs

_NOTED = set()


def note_once(path: Path, note: str) -> None:
    """Warn ``note`` of the trial at ``path``, once: a trial loaded again is
    not noted again."""
    if (path, note) not in _NOTED:
        _NOTED.add((path, note))
        warnings.warn(note, stacklevel=3)


#: A gyro or accelerometer with at least this many readings at its rail is
#: said to clip (BROAD's magnetometer, held between its own slower
#: samples, sits three to nine readings at its extreme; no gyro or
#: accelerometer of its 30 trials reaches one).
CLIPPED_NOTE_READINGS = 20
#: What a clipped channel does to the filters.
CLIPPING_HARM = {"gyro": "every filter's turn there falls short of the body's",
                 "accelerometer": "the filters read less acceleration than there was"}


def note_clipping(recording: Recording, path: Path,
                  channels: tuple = ("gyro", "accelerometer")) -> None:
    """A note for a gyro or accelerometer (of ``channels``: those the run
    reads) that sits at its rail: clipped."""
    from benchmarks.experiments.inspection import clipped
    for name, values, unit in (("gyro", recording.gyro_radps, "rad/s"),
                               ("accelerometer", recording.accelerometer_mps2, "m/s²")):
        if name not in channels:
            continue
        count, extreme = clipped(values) if values is not None else (0, 0.0)
        note = (f"trial {recording.name}: {count} {name} readings at ±{extreme:.6g} {unit}, its "
                f"rail (clipped): {CLIPPING_HARM[name]}")
        if count >= CLIPPED_NOTE_READINGS:
            note_once(path, note)


def note_dropouts(recording: Recording, path: Path) -> None:
    """A note for readings that are exactly zero (:mod:`benchmarks.broad.inputs`)."""
    counts = {name: int(np.count_nonzero(~flags))
              for name, flags in usable_readings(recording).items()}
    if any(counts.values()):
        dropped = " and ".join(f"{count} {name} reading{'s' * (count > 1)}"
                               for name, count in counts.items() if count)
        note_once(path, f"trial {recording.name}: {dropped} exactly zero (dropouts), left out")


#: A vector sensor's stretch without a reading is said where it lasts at
#: least this long, s, and this many of the sensor's own reading intervals
#: (a sensor that stops, or a logger that lost it for a while: the filters
#: then run on the gyro alone, and a table would not show it).
SILENCE_MIN_S, SILENCE_MIN_INTERVALS = 1.0, 10
#: What a filter does while the sensor is silent.
SILENCE_HARM = {"accelerometer": "hold the inclination with the gyro alone",
                "magnetometer": "hold the heading with the gyro alone"}
#: At most this many of a sensor's silent stretches are named.
SILENCES_NAMED = 3


def silences(read: np.ndarray, dt: float) -> list[tuple[int, int]]:
    """``[(first, stop), ...]``: the stretches of samples without a reading
    (``read``: ``(N,)`` bool) long enough to say (:data:`SILENCE_MIN_S`,
    :data:`SILENCE_MIN_INTERVALS`), the longest first; one running to the
    end has ``stop = N``. Every stretch of a sensor that never reads."""
    stretches = true_runs(~read)
    if not read.any():
        return stretches
    shortest = max(SILENCE_MIN_S / dt, SILENCE_MIN_INTERVALS * reading_interval_s(read, dt) / dt)
    long = [(a, b) for a, b in stretches if b - a >= shortest]
    return sorted(long, key=lambda stretch: stretch[0] - stretch[1])


def note_silences(recording: Recording, path: Path) -> None:
    """A note for an accelerometer or magnetometer that reads nothing for a
    while (:func:`silences`): when, for how long, and what the filters do then."""
    dt, n = recording.dt, len(recording.gyro_radps)
    for name, read in usable_readings(recording).items():
        found = silences(read, dt)
        if not found:
            continue
        spans = [f"from {a * dt:.1f} s " + ("to the end" if b == n else f"to {b * dt:.1f} s")
                 + f" ({(b - a) * dt:.3g} s)" for a, b in found[:SILENCES_NAMED]]
        more = len(found) - SILENCES_NAMED
        silent = sum(b - a for a, b in found) / n
        note_once(path, f"trial {recording.name}: its {name} reads nothing "
                  f"{', '.join(spans)}{f' and {more} more stretches' if more > 0 else ''}: "
                  f"{silent:.0%} of the trial, where the filters {SILENCE_HARM[name]}")


def from_start(recording: Recording, path: Path, refuse) -> Recording:
    """``recording`` from the sample its start attitude is taken at
    (:func:`~benchmarks.broad.inputs.start_sample`): the samples before it
    (an accelerometer whose file begins later than the gyro's) have no
    attitude to start from, and a start taken later but used at sample 0
    would be off by the body's turn between the two; left out, and said."""
    start = start_sample(recording)
    if not start:
        return recording
    first = "its first sample" if start == 1 else f"its first {start} samples"
    where = ("both sensors have read and their latest readings are not parallel"
             if heading_reference(recording) else "the accelerometer has read")
    note_once(path, f"trial {recording.name}: {first} ({start / recording.rate_hz:.3g} s) "
              f"come{'s' * (start == 1)} before the first sample where {where}, which the "
              "start attitude is taken at: left out, every estimator starts there")
    recording = recording.from_sample(start)
    rule = runnable_rule(recording)
    if rule:
        refuse(rule)
    return recording


def _timing_note(recording: Recording, fit) -> str:
    return f"trial {recording.name}: its magnetometer {described(fit, recording.dt)}"


#: (path, trial) → the delay fitted to its magnetometer as it was last
#: loaded, with ``auto`` (None: too little turned), and whether it was
#: clear, so applied, for :func:`note_magnetometer_delay`; in the process
#: that loaded it (a file with gaps in its gyro's clock holds several trials).
_FITTED = {}


def magnetometer_timed(recording: Recording, delay, path: Path) -> Recording:
    """``recording`` with its magnetometer's readings taken at their samples'
    times (:func:`sensors.delay.at_sample_times`): ``delay`` ``"auto"``
    fits how late they are (where the fit is not clear, the readings are
    kept; :func:`note_magnetometer_delay` says which), a number is that many
    seconds late, 0 keeps the recording as it is."""
    key = (path, recording.name)
    _FITTED.pop(key, None)
    if recording.magnetometer_uT is None or (delay != "auto" and delay == 0.0):
        return recording
    field = recording.magnetometer_uT
    read = usable_readings(recording)["magnetometer"]
    if delay == "auto":
        fit, timed = timed_readings(recording.gyro_radps, field, read, recording.dt)
        _FITTED[key] = (fit, timed is not None)
        # a copy: the kept readings are read-only, a recording's channels are not
        return recording if timed is None else replace(
            recording, magnetometer_uT=timed.copy(), magnetometer_timed=True)
    # a delay given: the hard iron it is turned about, fitted at it
    offset = hard_iron_at(recording.gyro_radps, field, read, recording.dt, delay)
    timed = at_sample_times(recording.gyro_radps, field, read, recording.dt, delay, offset)
    return replace(recording, magnetometer_uT=timed, magnetometer_timed=True)


def applied_delay(path: Path, trial: str):
    """The delay applied to the magnetometer of ``trial`` (at ``path``) as
    it was last loaded in this process (a :class:`sensors.delay.DelayFit`;
    None where it was not loaded with ``auto``, or none was clear)."""
    fit, clear = _FITTED.get((path, trial), (None, False))
    return fit if clear else None


def note_magnetometer_delay(recording: Recording, path: Path, delay) -> None:
    """The note of how late ``recording``'s magnetometer reads, said once a
    run's inputs are checked (a refusal is then its one line): with
    ``delay`` ``"auto"``, the delay fitted as it was loaded, or that none
    was clear; left at 0, where it is clearly late or early; given in
    seconds, nothing."""
    if recording.magnetometer_uT is None:
        return
    if delay == "auto" and (path, recording.name) in _FITTED:
        fit, clear = _FITTED[(path, recording.name)]
        note_once(path, _timing_note(recording, fit) + (
            ": each reading taken at its sample's time" if clear else ": its readings kept"))
    elif delay != "auto" and delay == 0.0:
        fit = recording_fit(recording)
        if fit is not None and fit.clear(recording.dt):
            note_once(path, f"{_timing_note(recording, fit)}; {AUTO_ADVICE}")
        elif fit is not None and (fit.beyond or fit.unexplained >= 1.0):
            note_once(path, _timing_note(recording, fit))     # its timestamps or axes to check
