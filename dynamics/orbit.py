r"""Where the spacecraft is: a circular orbit, or a two-line element set.

The inertial frame of this toolkit's orbital scenarios is **TEME**, the
frame ``sgp4`` propagates in (true equator, mean equinox of date): it differs
from J2000 by precession and nutation (0.35° by 2026) but from the Earth-fixed
frame by one rotation about the pole through the Greenwich mean sidereal
time (:func:`gmst_rad`), which is how the geomagnetic field is looked up
(:mod:`dynamics.environment`); the Sun's direction is taken in the same
frame (of date). The truth's attitude ``q_true`` rotates the body frame into
this frame.

**Circular orbit** (:class:`CircularOrbit`): radius :math:`a = R_E + h`,
mean motion :math:`n = \sqrt{\mu / a^3}`, argument of latitude
:math:`u(t) = u_0 + n t` and, so that a sun-synchronous orbit stays one, the
node drifting with the :math:`J_2` nodal rate (Vallado, *Fundamentals of
Astrodynamics and Applications*, 4th ed., 2013, eq. 9-41)

.. math:: \dot\Omega = -\tfrac32\, n J_2 \left(\tfrac{R_E}{a}\right)^2 \cos i,
          \qquad
          r(t) = a \begin{bmatrix}
          \cos\Omega\cos u - \sin\Omega\sin u\cos i \\
          \sin\Omega\cos u + \cos\Omega\sin u\cos i \\
          \sin u \sin i\end{bmatrix}.

**Two-line elements** (:class:`TLEOrbit`): SGP4 through the ``sgp4``
package (Vallado et al. 2006, the reference implementation), positions in
TEME, km.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime, timezone

import numpy as np

from dynamics.validation import InvalidParameterError, finite_number

#: Earth's gravitational parameter, km³/s² (WGS-84).
MU_EARTH_KM3_S2 = 398600.4418
#: Earth's equatorial radius, km (WGS-84).
EARTH_RADIUS_KM = 6378.137
#: Earth's second zonal harmonic (EGM-96).
J2 = 1.08262668e-3
#: The Julian date of J2000.0 (2000 January 1, 12:00 TT, taken as UT here).
JD_J2000 = 2451545.0
#: Lowest altitude accepted, km: below it the orbit decays within hours.
MIN_ALTITUDE_KM = 100.0
#: Farthest a scenario's epoch may be from its element set's, days: SGP4's
#: error grows by kilometres a day away from the elements' epoch.
MAX_TLE_AGE_DAYS = 30.0
#: Time zero of a scenario that names neither an epoch nor an element set.
DEFAULT_EPOCH = "2026-03-20T12:00:00+00:00"


def epoch_datetime(name: str, value) -> datetime:
    """An epoch given as an ISO 8601 text (UTC unless it names its zone) or a datetime."""
    if isinstance(value, datetime):
        moment = value
    else:
        try:
            moment = datetime.fromisoformat(str(value).replace("Z", "+00:00"))
        except ValueError:
            raise InvalidParameterError(name, value, "must be an ISO 8601 date and time, "
                                        "e.g. 2026-03-20T12:00:00 (UTC)") from None
    if moment.tzinfo is None:
        moment = moment.replace(tzinfo=timezone.utc)
    moment = moment.astimezone(timezone.utc)
    if not 1950 <= moment.year < 2050:
        raise InvalidParameterError(name, value, "must be within 1950-2049, where the solar "
                                    "ephemeris and the geomagnetic model hold")
    return moment


def julian_date(moment: datetime) -> float:
    """The Julian date of a UTC datetime (UTC taken as UT1: 0.9 s at most)."""
    from sgp4.api import jday
    whole, fraction = jday(moment.year, moment.month, moment.day, moment.hour, moment.minute,
                           moment.second + moment.microsecond * 1e-6)
    return whole + fraction


def gmst_rad(jd_ut1: np.ndarray) -> np.ndarray:
    """Greenwich mean sidereal time, rad (IAU 1982; Vallado 2013, eq. 3-47):
    the angle from TEME's x axis to the Greenwich meridian."""
    t = (np.asarray(jd_ut1, dtype=float) - JD_J2000) / 36525.0
    seconds = (67310.54841 + (876600.0 * 3600.0 + 8640184.812866) * t + 0.093104 * t * t
               - 6.2e-6 * t * t * t)
    return np.mod(seconds, 86400.0) / 86400.0 * 2.0 * np.pi


def teme_to_ecef(vectors: np.ndarray, jd_ut1: np.ndarray) -> np.ndarray:
    """``(N, 3)`` TEME vectors in the Earth-fixed frame (polar motion, a few
    metres, neglected): the rotation ``R_z(GMST)``."""
    theta = gmst_rad(jd_ut1)
    c, s = np.cos(theta), np.sin(theta)
    x, y, z = np.asarray(vectors, dtype=float).T
    return np.stack([c * x + s * y, -s * x + c * y, z], axis=-1)


def ecef_to_teme(vectors: np.ndarray, jd_ut1: np.ndarray) -> np.ndarray:
    """The inverse of :func:`teme_to_ecef`."""
    theta = gmst_rad(jd_ut1)
    c, s = np.cos(theta), np.sin(theta)
    x, y, z = np.asarray(vectors, dtype=float).T
    return np.stack([c * x - s * y, s * x + c * y, z], axis=-1)


@dataclass(frozen=True)
class CircularOrbit:
    """A circular orbit with :math:`J_2` nodal drift (see the module docstring).

    Parameters
    ----------
    altitude_km, inclination_deg, raan_deg, argument_of_latitude_deg
        Height above the equatorial radius, inclination, right ascension of
        the ascending node and argument of latitude at the epoch.
    epoch : datetime (UTC)
    """

    altitude_km: float
    inclination_deg: float
    raan_deg: float
    argument_of_latitude_deg: float
    epoch: datetime

    def __post_init__(self):
        finite_number("orbit.altitude_km", self.altitude_km, minimum=MIN_ALTITUDE_KM)
        if not 0.0 <= finite_number("orbit.inclination_deg", self.inclination_deg) <= 180.0:
            raise InvalidParameterError("orbit.inclination_deg", self.inclination_deg,
                                        "must be within 0 and 180 degrees")
        finite_number("orbit.raan_deg", self.raan_deg)
        finite_number("orbit.argument_of_latitude_deg", self.argument_of_latitude_deg)

    @property
    def radius_km(self) -> float:
        return EARTH_RADIUS_KM + self.altitude_km

    @property
    def mean_motion_radps(self) -> float:
        return math.sqrt(MU_EARTH_KM3_S2 / self.radius_km ** 3)

    @property
    def period_s(self) -> float:
        return 2.0 * math.pi / self.mean_motion_radps

    @property
    def node_rate_radps(self) -> float:
        """:math:`\\dot\\Omega` from :math:`J_2`, rad/s."""
        ratio = EARTH_RADIUS_KM / self.radius_km
        return -1.5 * self.mean_motion_radps * J2 * ratio * ratio * \
            math.cos(math.radians(self.inclination_deg))

    def positions_km(self, time_s: np.ndarray) -> np.ndarray:
        """``(N, 3)`` TEME positions at ``time_s`` seconds after the epoch, km."""
        t = np.asarray(time_s, dtype=float)
        u = math.radians(self.argument_of_latitude_deg) + self.mean_motion_radps * t
        node = math.radians(self.raan_deg) + self.node_rate_radps * t
        i = math.radians(self.inclination_deg)
        cu, su, cn, sn = np.cos(u), np.sin(u), np.cos(node), np.sin(node)
        return self.radius_km * np.stack([cn * cu - sn * su * math.cos(i),
                                          sn * cu + cn * su * math.cos(i),
                                          su * math.sin(i)], axis=-1)


def tle_lines(name: str, value) -> tuple[str, ...]:
    """An element set as its lines: a text of several lines (as pasted into
    a TOML string), or a list of texts; anything else is refused by name."""
    if isinstance(value, str):
        return tuple(line for line in value.splitlines() if line.strip())
    if isinstance(value, (list, tuple)) and all(isinstance(line, str) for line in value):
        return tuple(value)
    raise InvalidParameterError(name, value, "must be a two-line element set: its lines as "
                                "a list of texts, or one text of several lines")


class TLEOrbit:
    """An orbit from a two-line element set, propagated with SGP4.

    Parameters
    ----------
    lines : (str, str)
        The element set's two lines (a title line may come first).
    epoch : datetime (UTC), optional
        Time zero of the scenario, within :data:`MAX_TLE_AGE_DAYS` of the
        element set's own epoch; that epoch if None.
    """

    def __init__(self, lines, epoch: datetime | None = None):
        from sgp4.api import WGS72, Satrec
        lines = [line.rstrip() for line in tle_lines("orbit.tle", lines)]
        lines = [line for line in lines if line[:2] in ("1 ", "2 ")]
        if len(lines) != 2 or not (lines[0].startswith("1 ") and lines[1].startswith("2 ")):
            raise InvalidParameterError("orbit.tle", lines, "must be a two-line element set: "
                                        "a line starting '1 ' and one starting '2 '")
        try:
            self.satellite = Satrec.twoline2rv(lines[0], lines[1], WGS72)
        except (ValueError, IndexError) as err:
            raise InvalidParameterError("orbit.tle", lines, f"cannot be read ({err})") from None
        self.lines = tuple(lines)
        element_epoch = self.satellite.jdsatepoch + self.satellite.jdsatepochF
        self.epoch_jd = element_epoch if epoch is None else julian_date(epoch)
        if abs(self.epoch_jd - element_epoch) > MAX_TLE_AGE_DAYS:
            raise InvalidParameterError(
                "environment.epoch", epoch.isoformat(), f"is {self.epoch_jd - element_epoch:+.1f} "
                f"days from the element set's epoch; at most {MAX_TLE_AGE_DAYS:g} days (SGP4 "
                "drifts by kilometres a day): leave the epoch out to start at the elements'")

    @property
    def element_epoch(self) -> datetime:
        """The element set's own epoch (UTC)."""
        from sgp4.conveniences import sat_epoch_datetime
        return sat_epoch_datetime(self.satellite)

    def positions_km(self, time_s: np.ndarray) -> np.ndarray:
        """``(N, 3)`` TEME positions at ``time_s`` seconds after the epoch, km;
        an error naming the first failing time if SGP4 cannot propagate."""
        t = np.asarray(time_s, dtype=float)
        jd = self.epoch_jd + t / 86400.0
        whole = np.floor(jd)
        errors, positions, _ = self.satellite.sgp4_array(whole, jd - whole)
        if np.any(errors):
            first = int(np.argmax(errors != 0))
            raise InvalidParameterError("orbit.tle", self.lines[0], f"cannot be propagated to "
                                        f"t = {t[first]:g} s (SGP4 error {errors[first]})")
        return positions


def make_orbit(*, epoch: datetime, tle=(), altitude_km=None, inclination_deg=97.4,
               raan_deg=0.0, argument_of_latitude_deg=0.0):
    """A :class:`TLEOrbit` if ``tle`` is given, else a :class:`CircularOrbit`
    if ``altitude_km`` is, else None (no orbit)."""
    if tle:
        return TLEOrbit(tle, epoch)
    if altitude_km is None:
        return None
    return CircularOrbit(altitude_km, inclination_deg, raan_deg, argument_of_latitude_deg,
                         epoch)
