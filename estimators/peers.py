"""The attitude filters of other libraries, as registry estimators, so that
every metric, figure and tuner of the toolkit applies to them unchanged.
Each needs its package, in the ``peers`` extra (``pip install
'attitude-bench[peers]'``); without it, the estimator is refused in one line.

* ``vqf``, ``vqf-6d`` — Laidig & Seel's VQF (``vqf``; "VQF: Highly accurate
  IMU orientation estimation with bias estimation and magnetic disturbance
  rejection", Information Fusion 91, 2023), with its default settings, causal
  (``VQF.update`` per sample, not the acausal ``offlineVQF``). It starts
  itself from its first readings; ``vqf-6d`` is its output without the
  magnetometer, whose heading is its own (score it by inclination).
* ``vqf-offline`` — VQF's offline variant (``offlineVQF``, §3.5 of the
  paper): acausal, forward and backward passes of its bias estimation and
  zero-phase filtering over the whole recording; it runs on whole
  recordings only, the peer of :class:`estimators.smoother.MekfSmoother`.
* ``fusion`` — x-io's Fusion (``imufusion``), the settings of its README
  example: gain 0.5, 2000 °/s gyro range, 10° acceleration and magnetic
  rejection, 5 s rejection timeout; in its NWU convention, turned to ENU
  (imufusion 1.3.3 answered in NWU whichever convention it was given).
  Fusion takes all three channels at every sample: where the
  accelerometer or the magnetometer reads slower than the gyro, its last
  reading is held (zeros before the first, which Fusion ignores). A
  magnetometer at a quarter of the gyro's rate scored 45.7° through
  ``update_no_magnetometer`` between readings, 8.4° with a zero field
  between them and 5.3° held; a sample without an accelerometer reading
  was skipped altogether, its rate never integrated.

All output body → ENU after each sample's update, turned by the
declination of the field's reference, as the complementary filters do
(:mod:`estimators.complementary`, :class:`~estimators.complementary.MagneticFrame`).
"""
from __future__ import annotations

import importlib

import numpy as np

from dynamics.environment import STANDARD_GRAVITY_MPS2
from dynamics.quaternion import IDENTITY, quat_multiply
from dynamics.validation import InvalidParameterError, boolean, finite_number
from estimators import sensing
from estimators.base import AttitudeEstimator, InvalidMeasurementError
from estimators.readings import checked_rates
from estimators.complementary import NWU_TO_ENU, MagneticFrame, acc_mag, field_reference
from estimators.settings import DEFAULT_DT_S


def _package(estimator: str, module: str):
    try:
        return importlib.import_module(module)
    except ImportError:
        raise InvalidParameterError("estimator", estimator, f"needs the {module} package: pip "
                                    "install 'attitude-bench[peers]'") from None


class PeerFilter(MagneticFrame, AttitudeEstimator):
    """What the adapters share: a peer filter made at each reset, fed each
    step's rate, accelerometer and magnetometer; its estimate (magnetic
    north) turned to the reference frame by the declination
    (:class:`~estimators.complementary.MagneticFrame`)."""

    uses_vector_readings = True
    #: Gravity gives them the inclination; the field, where read, the heading.
    reads = frozenset({sensing.ACCELEROMETER, sensing.MAGNETOMETER})
    needs = (frozenset({sensing.ACCELEROMETER}),)

    def __init__(self, *, dt: float = DEFAULT_DT_S, initial_attitude=IDENTITY,
                 on_invalid: str = "raise"):
        super().__init__(dt=dt, initial_attitude=initial_attitude, on_invalid=on_invalid)
        self.reset()

    def reset(self) -> None:
        self._turn, self._turn_learnt = None, False
        self._new_filter()
        self._q = self.initial_attitude.copy()

    def _new_filter(self) -> None:
        """Make the peer's filter afresh (``self.filter``)."""
        raise NotImplementedError

    def _step(self, omega_meas_radps, star_tracker_quat=None, vectors=()) -> np.ndarray:
        acc, mag = acc_mag(vectors)
        if mag is not None:
            self.learn_frame(field_reference(vectors))
        gyro = np.ascontiguousarray(omega_meas_radps, dtype=float)
        self._q = self.in_reference_frame(np.asarray(self.update(gyro, acc, mag), dtype=float))
        return self._q.copy()

    #: Whether the peer skips a reading of [0, 0, 0] as no reading (VQF's
    #: updateAcc and updateMag do): then a channel with readings missing
    #: runs at once too, zeros where it did not read.
    skips_zero_readings = False
    #: Whether the peer is given each channel's last reading where it did
    #: not read (Fusion): then such a channel runs at once too, held.
    holds_readings = False

    def run_batch(self, omega_meas_radps, vectors) -> np.ndarray | None:
        """``run``'s estimates at once when every sample has both the
        accelerometer and the magnetometer, or the accelerometer alone (a
        6-axis IMU; or the peer skips zero readings, :attr:`skips_zero_readings`)
        and nothing else (:meth:`run_readings`);
        None otherwise (the per-run path then)."""
        found = {v.sensor: v for v in vectors}
        if set(found) not in ({"accelerometer", "magnetometer"}, {"accelerometer"}) or \
                len(vectors) != len(found) or not (
                    self.skips_zero_readings or self.holds_readings
                    or all(np.all(v.available) for v in vectors)):
            return None
        n = len(omega_meas_radps)
        read = {name: np.asarray(vector.available, dtype=bool) for name, vector in found.items()}
        # a 6-axis IMU: no field reading at any sample, the zeros the peers ignore
        acc, mag = (np.zeros((n, 3)) if name not in found
                    else held_from_first(found[name].body, read[name]) if self.holds_readings
                    else np.where(read[name][:, None], found[name].body, 0.0)
                    for name in ("accelerometer", "magnetometer"))
        estimates = np.asarray(self.run_readings(omega_meas_radps, acc, mag), dtype=float)
        if "magnetometer" in found:
            self.learn_frame(found["magnetometer"].reference[0])
        return self.in_reference_frame(estimates)

    @property
    def attitude(self) -> np.ndarray:
        return self._q.copy()

    def state_is_finite(self) -> bool:
        return bool(np.isfinite(self._q).all())


class VQF9D(PeerFilter):
    """VQF, its defaults; ``accelerometer_interval_s`` and
    ``magnetometer_interval_s``: the time between the accelerometer's and
    the magnetometer's readings where they read slower than the gyro (VQF's
    ``accTs`` and ``magTs``, which set its filters' coefficients; default:
    the gyro's step. An accelerometer at a quarter of a 200 Hz gyro's rate
    scored 2.53° untold, 0.39° told)."""

    name = "vqf"
    label = "VQF"
    output = "getQuat9D"
    skips_zero_readings = True      # vqf.cpp, updateAcc/updateMag: "ignore [0 0 0] samples"

    def __init__(self, *, dt: float = DEFAULT_DT_S, initial_attitude=IDENTITY,
                 on_invalid: str = "raise", accelerometer_interval_s: float | None = None,
                 magnetometer_interval_s: float | None = None):
        self.accelerometer_interval_s, self.magnetometer_interval_s = (
            None if value is None else finite_number(name, value, strictly_positive=True)
            for name, value in (("accelerometer_interval_s", accelerometer_interval_s),
                                ("magnetometer_interval_s", magnetometer_interval_s)))
        super().__init__(dt=dt, initial_attitude=initial_attitude, on_invalid=on_invalid)

    def _new_filter(self) -> None:
        self.filter = _package(self.name, "vqf").VQF(
            self.dt, self.accelerometer_interval_s or self.dt,
            self.magnetometer_interval_s or self.dt)

    def run_readings(self, gyro: np.ndarray, acc: np.ndarray, mag: np.ndarray) -> np.ndarray:
        """``(N, 4)`` estimates over whole ``(N, 3)`` channels (each sample
        with all three), from a fresh filter: VQF's ``updateBatch``, its own
        loop over :meth:`update`'s calls, in compiled code."""
        self.reset()
        batch = self.filter.updateBatch(*(np.ascontiguousarray(x, dtype=float)
                                          for x in (gyro, acc, mag)))
        return batch["quat9D" if self.output == "getQuat9D" else "quat6D"]

    def update(self, gyro, acc, mag):
        self.filter.updateGyr(gyro)
        if acc is not None:
            self.filter.updateAcc(np.ascontiguousarray(acc, dtype=float))
        if mag is not None:
            self.filter.updateMag(np.ascontiguousarray(mag, dtype=float))
        return getattr(self.filter, self.output)()


class VQF6D(VQF9D):
    name = "vqf-6d"
    label = "VQF 6D"
    output = "getQuat6D"
    #: Its output leaves the magnetometer out: its heading is the gyro's.
    reads = frozenset({sensing.ACCELEROMETER})
    has_heading = False


class OfflineVQF(VQF9D):
    name = "vqf-offline"
    label = "VQF offline"
    #: It reads the whole recording before its first estimate.
    mode = "offline"
    needs = (frozenset({sensing.ACCELEROMETER, sensing.MAGNETOMETER}),)

    def __init__(self, *, dt: float = DEFAULT_DT_S, initial_attitude=IDENTITY,
                 fit_magnetometer_delay: bool = True, on_invalid: str = "raise"):
        # offlineVQF takes every channel at the gyro's rate (a slower one held).
        super().__init__(dt=dt, initial_attitude=initial_attitude, on_invalid=on_invalid)
        #: Whether its field is timed against the gyro first, as the
        #: smoother's (:func:`benchmarks.engine.recorded.field_timed`).
        self.fit_magnetometer_delay = boolean("fit_magnetometer_delay", fit_magnetometer_delay)

    def step(self, *args, **kwargs):
        raise TypeError(f"{self.name} is offline: it estimates from the whole recording "
                        "(run or run_batch), not step by step")

    def run_batch(self, omega_meas_radps, vectors) -> np.ndarray:
        """``offlineVQF`` over the whole recording; a sample without a usable
        accelerometer or magnetometer reading holds the channel's nearest
        earlier one (the first one before it), as the library takes every
        sample of every channel."""
        found = {v.sensor: v for v in vectors}
        if not {"accelerometer", "magnetometer"} <= set(found):
            raise InvalidParameterError("estimator", self.name, "needs the accelerometer's and "
                                        "the magnetometer's readings of a whole recording")
        omega = checked_rates(omega_meas_radps)
        bad = np.flatnonzero(~np.isfinite(omega).all(axis=1))
        if len(bad):
            raise InvalidMeasurementError(f"omega_meas_radps at step {bad[0]}", omega[bad[0]],
                                          "must be finite rates")
        acc, mag = (_held(found[name].body, found[name].available)
                    for name in ("accelerometer", "magnetometer"))
        self.reset()
        out = _package(self.name, "vqf").offlineVQF(np.ascontiguousarray(omega), acc, mag,
                                                     self.dt)
        self.learn_frame(found["magnetometer"].reference[0])
        return self.in_reference_frame(np.asarray(out["quat9D"], dtype=float))

    def run(self, omega_meas_radps, star_tracker_quat=None, available=None, offset_s=None, *,
            vectors=(), progress=None) -> np.ndarray:
        return self.run_batch(omega_meas_radps, vectors or ())


def held_from_first(channel: np.ndarray, available: np.ndarray) -> np.ndarray:
    """``channel`` with each unavailable row its last available one's, and
    zeros before the first (a peer that takes a reading at every sample
    and ignores [0, 0, 0]: Fusion)."""
    index = np.where(available, np.arange(len(channel)), -1)
    np.maximum.accumulate(index, out=index)
    held = np.asarray(channel, dtype=float)[np.maximum(index, 0)]
    held[index < 0] = 0.0
    return np.ascontiguousarray(held)


def _held(channel: np.ndarray, available: np.ndarray) -> np.ndarray:
    """``channel`` with each unavailable row replaced by the nearest earlier
    available one (the first available one before the first)."""
    channel, available = np.asarray(channel, dtype=float), np.asarray(available, dtype=bool)
    if not available.any():
        raise InvalidParameterError("readings", "none available", "the offline filter needs "
                                    "at least one reading of each channel")
    index = np.where(available, np.arange(len(channel)), 0)
    np.maximum.accumulate(index, out=index)
    index[:np.argmax(available)] = np.argmax(available)
    return np.ascontiguousarray(channel[index])


class Fusion(PeerFilter):
    name = "fusion"
    label = "Fusion"
    holds_readings = True

    def _new_filter(self) -> None:
        imufusion = _package(self.name, "imufusion")
        rate = 1.0 / self.dt
        self.filter = imufusion.Ahrs()
        self.filter.set_settings(imufusion.AhrsSettings(
            sample_rate=rate, convention=imufusion.CONVENTION_NWU, gain=0.5,
            gyroscope_range=2000.0, acceleration_rejection=10.0, magnetic_rejection=10.0,
            rejection_timeout=5.0))
        self._acc_g, self._mag = np.zeros(3), np.zeros(3)      # held: the module docstring

    def run_readings(self, gyro: np.ndarray, acc: np.ndarray, mag: np.ndarray) -> np.ndarray:
        """``(N, 4)`` estimates over whole ``(N, 3)`` channels (each sample
        with all three), from a fresh filter: :meth:`update`'s calls in a
        plain loop (imufusion has no batch call), the turn to ENU at once."""
        self.reset()
        # Fusion takes the accelerometer in g.
        gyro_dps, acc_g = np.degrees(gyro), np.asarray(acc, dtype=float) / STANDARD_GRAVITY_MPS2
        mag = np.asarray(mag, dtype=float)
        nwu = np.empty((len(gyro), 4))
        for k in range(len(gyro)):
            self.filter.update(gyro_dps[k], acc_g[k], mag[k])
            nwu[k] = self.filter.get_quaternion()
        return quat_multiply(NWU_TO_ENU, nwu)

    def update(self, gyro, acc, mag):
        # Fusion takes degrees per second and g; a channel not read is held.
        if acc is not None:
            self._acc_g = np.asarray(acc, dtype=float) / STANDARD_GRAVITY_MPS2
        if mag is not None:
            self._mag = np.asarray(mag, dtype=float)
        self.filter.update(np.degrees(gyro), self._acc_g, self._mag)
        return quat_multiply(NWU_TO_ENU, self.filter.get_quaternion())


PEER_ESTIMATORS = (VQF9D, VQF6D, OfflineVQF, Fusion)
