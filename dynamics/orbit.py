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
import re
from dataclasses import dataclass
from datetime import date, datetime, timezone

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
#: Farthest from the Earth's centre an orbit may go, in Earth radii: the
#: magnetopause's usual sub-solar distance (about 10 R_E; Shue et al., J.
#: Geophys. Res. 103(A8), 1998). Beyond it the field is the solar wind's, and
#: IGRF (the field of the Earth's interior) or its dipole would describe
#: nothing a magnetometer reads; inside it are LEO, GNSS orbits, GEO (6.6 R_E)
#: and Molniya apogees (7.3 R_E).
MAX_RADIUS_EARTH_RADII = 10.0
#: Highest altitude accepted, km (57,403 km): :data:`MAX_RADIUS_EARTH_RADII`.
MAX_ALTITUDE_KM = (MAX_RADIUS_EARTH_RADII - 1.0) * EARTH_RADIUS_KM
#: The years an epoch may fall in: where the Sun's low-precision formula
#: holds to 0.01° (:mod:`dynamics.environment`, 1950-2050).
EPOCH_YEARS = (1950, 2049)
#: Farthest a scenario's epoch may be from its element set's, days: SGP4's
#: error grows by kilometres a day away from the elements' epoch.
MAX_TLE_AGE_DAYS = 30.0
#: Time zero of a scenario that names neither an epoch nor an element set.
DEFAULT_EPOCH = "2026-03-20T12:00:00+00:00"


def epoch_datetime(name: str, value) -> datetime:
    """An epoch given as an ISO 8601 text (UTC unless it names its zone), a
    datetime (a TOML date-time) or a date (a TOML date: its midnight, UTC).
    A number is refused, not read as digits: ``20260320`` is not a date."""
    if isinstance(value, datetime):
        moment = value
    elif isinstance(value, date):
        moment = datetime(value.year, value.month, value.day)
    elif isinstance(value, str):
        try:
            moment = datetime.fromisoformat(value.replace("Z", "+00:00"))
        except ValueError:
            raise InvalidParameterError(name, value, "must be an ISO 8601 date and time, "
                                        "e.g. 2026-03-20T12:00:00 (UTC)") from None
    else:
        raise InvalidParameterError(name, value, "must be a date and time: ISO 8601 text in "
                                    "quotes, e.g. \"2026-03-20T12:00:00Z\", or a TOML "
                                    "date-time")
    if moment.tzinfo is None:
        moment = moment.replace(tzinfo=timezone.utc)
    moment = moment.astimezone(timezone.utc)
    first, last = EPOCH_YEARS
    if not first <= moment.year <= last:
        raise InvalidParameterError(name, value, f"must be within {first}-{last}, where the "
                                    "solar ephemeris holds (the Sun's low-precision formula)")
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
        altitude = finite_number("orbit.altitude_km", self.altitude_km, minimum=MIN_ALTITUDE_KM)
        if altitude > MAX_ALTITUDE_KM:
            raise InvalidParameterError(
                "orbit.altitude_km", self.altitude_km, f"must be at most {MAX_ALTITUDE_KM:,.0f} "
                f"km ({MAX_RADIUS_EARTH_RADII:g} Earth radii from the centre, the "
                "magnetopause): beyond it the geomagnetic model describes nothing")
        for name, value, low, high in (
                ("inclination_deg", self.inclination_deg, 0.0, 180.0),
                # An angle beyond a turn only loses digits (cos(1e300) is noise).
                ("raan_deg", self.raan_deg, -360.0, 360.0),
                ("argument_of_latitude_deg", self.argument_of_latitude_deg, -360.0, 360.0)):
            if not low <= finite_number(f"orbit.{name}", value) <= high:
                raise InvalidParameterError(f"orbit.{name}", value,
                                            f"must be within {low:g} and {high:g} degrees")

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


#: A line of an element set: 68 columns and its checksum (NORAD's fixed
#: format; CelesTrak, "NORAD Two-Line Element Set Format").
TLE_LINE_LENGTH = 69
#: What SGP4's error codes mean (Vallado et al. 2006, ``sgp4init``/``sgp4``).
SGP4_ERRORS = {
    1: "the mean eccentricity left [0, 1) or the semi-major axis fell below 0.95 Earth radii",
    2: "the mean motion became negative",
    3: "the perturbed eccentricity left [0, 1]",
    4: "the semi-latus rectum became negative",
    5: "the epoch elements are sub-orbital",
    6: "the satellite has decayed, its orbit down to the Earth's surface",
}


def tle_checksum(line: str) -> int:
    """A TLE line's checksum: its digits' sum, each minus sign counting 1, modulo 10."""
    return sum(int(c) if c.isdigit() else c == "-" for c in line[:TLE_LINE_LENGTH - 1]) % 10


def element_set(value) -> tuple[str, str]:
    """An element set's two lines, checked where a misprint would otherwise
    pass unseen or fail deep inside SGP4: the lines (a title line may come
    first), their length, their checksums, one satellite number, the
    columns' format (``sgp4``'s own strict reader) and a day of the year
    that is one."""
    lines = [line.rstrip() for line in tle_lines("orbit.tle", value)]
    lines = [line for line in lines if line[:2] in ("1 ", "2 ")]
    if len(lines) != 2 or not (lines[0].startswith("1 ") and lines[1].startswith("2 ")):
        raise InvalidParameterError("orbit.tle", lines, "must be a two-line element set: "
                                    "a line starting '1 ' and one starting '2 '")
    for number, line in enumerate(lines, start=1):
        if len(line) != TLE_LINE_LENGTH:
            raise InvalidParameterError("orbit.tle", line, f"line {number} has {len(line)} "
                                        f"characters; an element set's lines have "
                                        f"{TLE_LINE_LENGTH}, the last its checksum")
        if not line[-1].isdigit() or int(line[-1]) != tle_checksum(line):
            raise InvalidParameterError("orbit.tle", line, f"line {number}'s checksum is "
                                        f"{line[-1]!r} but its columns add up to "
                                        f"{tle_checksum(line)}: a mistyped or damaged line")
    if lines[0][2:7] != lines[1][2:7]:
        raise InvalidParameterError("orbit.tle", lines, f"line 1 is of satellite "
                                    f"{lines[0][2:7].strip()} and line 2 of "
                                    f"{lines[1][2:7].strip()}: two halves of different "
                                    "element sets")
    try:
        mean_motion = float(lines[1][52:63])
    except ValueError:
        mean_motion = None             # the columns' check below names it
    if mean_motion is not None and not mean_motion > 0.0:
        # Checked before sgp4 reads it: its reader divides by it.
        raise InvalidParameterError("orbit.tle", lines[1], f"line 2's mean motion "
                                    f"{mean_motion:g} must be > 0 revolutions a day")
    from sgp4.io import twoline2rv
    from sgp4.earth_gravity import wgs72
    try:
        parsed = twoline2rv(lines[0], lines[1], wgs72)
    except ValueError as err:
        which = re.search(r"for line (\d)", str(err))
        raise InvalidParameterError(
            "orbit.tle", lines[int(which.group(1)) - 1] if which else lines,
            f"line {which.group(1)} does not follow the element set's fixed columns (a digit, "
            "point or space out of place)" if which else "has a field that is not a number "
            "where the element set's fixed columns expect one") from None
    # Day 366 of a common year ("December 32") occurs in published sets; sgp4 reads it.
    if not 1.0 <= parsed.epochdays < 367.0:
        raise InvalidParameterError("orbit.tle", lines[0], f"line 1's epoch day "
                                    f"{parsed.epochdays:g} is not a day of the year (from 1 "
                                    "to below 367)")
    return lines[0], lines[1]


class TLEOrbit:
    """An orbit from a two-line element set, propagated with SGP4.

    Parameters
    ----------
    lines : (str, str)
        The element set's two lines (a title line may come first), checked
        by :func:`element_set`; its elements must describe an orbit this
        toolkit models: an inclination of 0-180°, angles of 0-360°, a
        perigee above the Earth's surface, an apogee within
        :data:`MAX_ALTITUDE_KM`, an epoch within :data:`EPOCH_YEARS`.
    epoch : datetime (UTC), optional
        Time zero of the scenario, within :data:`MAX_TLE_AGE_DAYS` of the
        element set's own epoch; that epoch if None.
    """

    def __init__(self, lines, epoch: datetime | None = None):
        from sgp4.api import WGS72, Satrec
        lines = element_set(lines)
        self.satellite = Satrec.twoline2rv(lines[0], lines[1], WGS72)
        self.lines = tuple(lines)
        self._check_elements()
        element_epoch = self.satellite.jdsatepoch + self.satellite.jdsatepochF
        self.epoch_jd = element_epoch if epoch is None else julian_date(epoch)
        if abs(self.epoch_jd - element_epoch) > MAX_TLE_AGE_DAYS:
            raise InvalidParameterError(
                "environment.epoch", epoch.isoformat(), f"is {self.epoch_jd - element_epoch:+.1f} "
                f"days from the element set's epoch; at most {MAX_TLE_AGE_DAYS:g} days (SGP4 "
                "drifts by kilometres a day): leave the epoch out to start at the elements'")

    def _check_elements(self) -> None:
        """The elements describe an orbit about the Earth at a time the Sun's
        formula covers (:class:`TLEOrbit`), and SGP4 can start from them."""
        satellite, line2 = self.satellite, self.lines[1]
        for name, columns, high in (("inclination", slice(8, 16), 180.0),
                                    ("right ascension of the node", slice(17, 25), 360.0),
                                    ("argument of perigee", slice(34, 42), 360.0),
                                    ("mean anomaly", slice(43, 51), 360.0)):
            if not 0.0 <= float(line2[columns]) <= high:
                raise InvalidParameterError("orbit.tle", line2, f"line 2's {name} "
                                            f"{float(line2[columns]):g} deg must be within 0 "
                                            f"and {high:g} degrees")
        # sgp4 sets the perigee and apogee before its own checks: an orbit
        # through the Earth is named as one, not by an error code.
        perigee_km = satellite.altp * satellite.radiusearthkm
        apogee_km = satellite.alta * satellite.radiusearthkm
        if perigee_km < 0.0:
            raise InvalidParameterError("orbit.tle", line2, f"puts the perigee {-perigee_km:,.0f} "
                                        "km below the Earth's surface: not an orbit")
        if apogee_km > MAX_ALTITUDE_KM:
            raise InvalidParameterError(
                "orbit.tle", line2, f"puts the apogee {apogee_km:,.0f} km up; at most "
                f"{MAX_ALTITUDE_KM:,.0f} km ({MAX_RADIUS_EARTH_RADII:g} Earth radii from the "
                "centre, the magnetopause): beyond it the geomagnetic model describes nothing")
        first, last = EPOCH_YEARS
        # The two-digit year's rule (sgp4's, and the format's): 57-99 are 19xx.
        year = satellite.epochyr + (1900 if satellite.epochyr >= 57 else 2000)
        if not first <= year <= last:
            raise InvalidParameterError(
                "orbit.tle", self.lines[0], f"has its epoch in {year} (two-digit "
                f"years 57-99 are 1957-1999, 00-56 2000-2056); it must be within {first}-{last}, "
                "where the solar ephemeris holds")
        if satellite.error:
            raise InvalidParameterError("orbit.tle", self.lines, "cannot start SGP4 (error "
                                        f"{satellite.error}: "
                                        f"{SGP4_ERRORS.get(satellite.error, 'unknown')})")

    def check_propagation(self, time_s: np.ndarray) -> None:
        """Refuse, naming the first failing time, if SGP4 cannot propagate the
        elements to every one of ``time_s`` seconds after the epoch (a decay
        found while a scenario is checked, not steps into its run)."""
        self.positions_km(time_s)

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
            code = int(errors[first])
            raise InvalidParameterError("orbit.tle", self.lines[0], f"cannot be propagated to "
                                        f"t = {t[first]:g} s (SGP4 error {code}: "
                                        f"{SGP4_ERRORS.get(code, 'unknown')})")
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
