"""Hostile scenario files: each gets one clean line naming its key, or the
right answer (issue 28).

A refusal is an :class:`~dynamics.validation.InvalidParameterError` named by
the file's ``section.key``, and on the command line one ``attitude-bench:
error:`` line, exit status 2, nothing written, for ``show-config`` as for
``compare``. A setting that is legitimate but suspicious is a warning (a
``note:`` line). What must work is checked against what it must give: the
polar site's references (finite, the same field whatever the meridian,
gravity up), a scale-free soft-iron matrix, a huge boresight normalised.
"""
import math
from datetime import datetime, timezone

import numpy as np
import pytest
from sgp4.io import fix_checksum

from benchmarks import Scenario
from benchmarks.cli import main
from benchmarks.scenario import SECTIONS, SWITCHES
from benchmarks.simulation import scenario_references, simulate_truth, vector_readings
from dynamics.environment import (STANDARD_GRAVITY_MPS2, geomagnetic_field_nT, igrf_span,
                                  local_level_field_nT)
from dynamics.orbit import MAX_ALTITUDE_KM, TLEOrbit
from dynamics.validation import InvalidParameterError, unit_vector
from sensors.magnetometer import Magnetometer
from sensors.sun_sensor import CoarseSunSensors, FineSunSensor
from sensors.vector import to_body

ISS_TLE = ("1 25544U 98067A   19343.69339541  .00001764  00000-0  38792-4 0  9991",
           "2 25544  51.6439 211.2001 0007417  17.6667  85.6398 15.50103472202482")
#: A magnetometer beside the orbit (the sections below need a vector sensor).
MAGNETOMETER = "[magnetometer]\ninterval_s = 0.5\n"
SHORT = "tstop = 5.0\ndt = 0.5\n[star_tracker]\ninterval_s = 0.5\n"


def edited(line: str, column: int, text: str) -> str:
    """A TLE line with ``text`` written from ``column`` (0-based), its checksum mended."""
    return fix_checksum(line[:column] + text + line[column + len(text):])


def tle_file(line1: str, line2: str, extra: str = "", run: str = SHORT) -> str:
    return f'{run}[orbit]\ntle = ["{line1}", "{line2}"]\n{extra}{MAGNETOMETER}'


def orbit_file(orbit: str = "altitude_km = 500.0\n", sensors: str = MAGNETOMETER) -> str:
    return f"{SHORT}[orbit]\n{orbit}{sensors}"


#: (case, file, the key its message names, a phrase of the rule)
REFUSED = [
    # Tracebacks before.
    ("altitude 1e300 (overflow)", orbit_file("altitude_km = 1e300\n"), "orbit.altitude_km",
     "at most 57,403 km"),
    ("TLE of garbage", tle_file("1 " + "a" * 67, "2 " + "b" * 67), "orbit.tle",
     "line 1's checksum"),
    ("TLE epoch day 0 (sgp4: month must be in 1..12)",
     tle_file(edited(ISS_TLE[0], 20, "000.00000000"), ISS_TLE[1]), "orbit.tle",
     "epoch day 0 is not a day of the year"),
    ("TLE with letters in its columns", tle_file(edited(ISS_TLE[0], 20, "34x.69339541"),
                                                 ISS_TLE[1]), "orbit.tle", "not a number"),
    ("TLE of mean motion 0 (division by zero)",
     tle_file(ISS_TLE[0], edited(ISS_TLE[1], 52, "00.00000000")), "orbit.tle",
     "mean motion 0 must be > 0"),
    # Nonsense accepted before.
    ("TLE checksum", tle_file(ISS_TLE[0][:-1] + "0", ISS_TLE[1]), "orbit.tle",
     "line 1's checksum is '0' but its columns add up to 1"),
    ("TLE inclination 200", tle_file(ISS_TLE[0], edited(ISS_TLE[1], 8, "200.0000")),
     "orbit.tle", "inclination 200 deg must be within 0 and 180"),
    ("TLE epoch 2056", tle_file(edited(ISS_TLE[0], 18, "56"), ISS_TLE[1]), "orbit.tle",
     "epoch in 2056"),
    ("TLE of two satellites", tle_file(ISS_TLE[0], edited(ISS_TLE[1], 2, "25545")),
     "orbit.tle", "satellite 25544 and line 2 of 25545"),
    ("TLE perigee inside the Earth, run of 5 s",
     tle_file(ISS_TLE[0], edited(ISS_TLE[1], 26, "9000000")), "orbit.tle",
     "perigee 5,698 km below the Earth's surface"),
    ("TLE mean motion 17.5/day, perigee inside the Earth",
     tle_file(ISS_TLE[0], edited(ISS_TLE[1], 52, "17.50000000")), "orbit.tle",
     "below the Earth's surface"),
    ("TLE apogee beyond the magnetopause",
     tle_file(ISS_TLE[0], edited(ISS_TLE[1], 52, "00.10000000")), "orbit.tle",
     "puts the apogee 189,833 km up"),
    ("TLE that decays during the run",
     tle_file(edited(ISS_TLE[0], 53, " 99999-1"), edited(ISS_TLE[1], 52, "16.00000000"),
              run="tstop = 30000.0\ndt = 10.0\n[star_tracker]\ninterval_s = 10.0\n"
              ).replace("interval_s = 0.5", "interval_s = 10.0"),
     "orbit.tle", "SGP4 error 6: the satellite has decayed"),
    ("altitude 1e9", orbit_file("altitude_km = 1e9\n"), "orbit.altitude_km",
     "the magnetopause"),
    ("altitude beside a TLE", tle_file(*ISS_TLE, extra="altitude_km = 500.0\n"),
     "orbit.altitude_km", "orbit.tle is given"),
    ("inclination beside a TLE", tle_file(*ISS_TLE, extra="inclination_deg = 51.6\n"),
     "orbit.inclination_deg", "orbit.tle is given"),
    ("RAAN 1e300", orbit_file("altitude_km = 500.0\nraan_deg = 1e300\n"), "orbit.raan_deg",
     "within -360 and 360 degrees"),
    ("argument of latitude -1e300",
     orbit_file("altitude_km = 500.0\nargument_of_latitude_deg = -1e300\n"),
     "orbit.argument_of_latitude_deg", "within -360 and 360 degrees"),
    ("[magnetometer] without interval_s",
     "[star_tracker]\nmodel = 'none'\n[orbit]\naltitude_km = 500.0\n"
     "[magnetometer]\nsigma_nT = 50.0\n",
     "magnetometer.interval_s", "[magnetometer] is in the file (sigma_nT) but without "
     "interval_s it is off"),
    ("an empty [magnetometer]", orbit_file(sensors="[magnetometer]\n"),
     "magnetometer.interval_s", "(no keys)"),
    ("a flat magnetometer key without its interval",
     "magnetometer_sigma_nT = 50.0\n" + orbit_file(sensors=""), "magnetometer.interval_s",
     "(sigma_nT)"),
    ("[orbit] without altitude_km or tle", orbit_file("inclination_deg = 51.6\n"),
     "orbit.altitude_km", "without altitude_km or tle it is off"),
    ("[site] without latitude_deg", f"{SHORT}[site]\nlongitude_deg = 10.0\n{MAGNETOMETER}",
     "site.latitude_deg", "without latitude_deg it is off"),
    ("sun sensor sigma 1000 deg",
     orbit_file(sensors="[sun_sensor]\ninterval_s = 0.5\nsigma_deg = 1000.0\n"),
     "sun_sensor.sigma_deg", "at most 180 degrees"),
    ("epoch as an integer", orbit_file() + "[environment]\nepoch = 20260320\n",
     "environment.epoch", "ISO 8601 text in quotes"),
    ("epoch as a TOML time of day", orbit_file() + "[environment]\nepoch = 12:00:00\n",
     "environment.epoch", "a TOML date-time"),
    ("a zero boresight",
     orbit_file(sensors="[sun_sensor]\ninterval_s = 0.5\nboresight = [0.0, 0.0, 0.0]\n"),
     "sun_sensor.boresight", "not all zero"),
    ("a singular soft-iron matrix",
     orbit_file(sensors=MAGNETOMETER + "soft_iron = [[1, 0, 0], [0, 1, 0], [0, 0, 1e-9]]\n"),
     "magnetometer.soft_iron", "condition number is 1e+09"),
    ("a soft-iron gain of 1e300",
     orbit_file(sensors=MAGNETOMETER + "soft_iron = [[1e300, 0, 0], [0, 1e300, 0], "
                "[0, 0, 1e300]]\n"), "magnetometer.soft_iron", "multiplies the field by up to"),
    ("a magnetometer bias of 1e300 nT", orbit_file(sensors=MAGNETOMETER + "bias_nT = [1e300, "
                                                   "0, 0]\n"), "magnetometer.bias_nT", "10 gauss"),
    ("a magnetometer sigma of 1e20 nT", orbit_file(sensors=MAGNETOMETER + "sigma_nT = 1e20\n"),
     "magnetometer.sigma_nT", "noise alone"),
    ("a coarse sun sensor sigma of 1e8",
     orbit_file(sensors="[coarse_sun_sensors]\ninterval_s = 0.5\nsigma = 1e8\n"),
     "coarse_sun_sensors.sigma", "the full-sun current"),
    ("an accelerometer bias of 1e300",
     f"{SHORT}[site]\nlatitude_deg = 45.0\n{MAGNETOMETER}"
     "[accelerometer]\ninterval_s = 0.5\nbias_mps2 = [0, 0, 1e300]\n",
     "accelerometer.bias_mps2", "16 g"),
    ("an accelerometer sigma of 1e20",
     f"{SHORT}[site]\nlatitude_deg = 45.0\n[accelerometer]\ninterval_s = 0.5\nsigma_mps2 = "
     "1e20\n", "accelerometer.sigma_mps2", "16 g"),
    ("tstop of 1e300 (a one-line count)", "tstop = 1e300\n", "tstop", "makes 1e+302 steps"),
]


@pytest.mark.parametrize("case, content, key, rule", REFUSED, ids=[case for case, *_ in REFUSED])
def test_a_hostile_file_is_refused_by_its_key(tmp_path, case, content, key, rule):
    path = tmp_path / "hostile.toml"
    path.write_text(content)
    with pytest.raises(InvalidParameterError) as raised:
        Scenario.from_toml(path)
    assert raised.value.name == key
    assert rule in str(raised.value)
    assert "\n" not in str(raised.value)


@pytest.mark.parametrize("command", ["show-config", "compare"])
@pytest.mark.parametrize("case, content, key, rule", REFUSED, ids=[case for case, *_ in REFUSED])
def test_the_command_line_says_it_in_one_line_and_writes_nothing(tmp_path, capsys, command,
                                                                 case, content, key, rule):
    path = tmp_path / "hostile.toml"
    path.write_text(content)
    out = tmp_path / "out"
    extra = ["--quiet", "--out", str(out)] if command == "compare" else []
    assert main([command, "--scenario", str(path), *extra]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.count("\n") == 1 and "Traceback" not in captured.err
    assert captured.err.startswith(f"attitude-bench: error: {key} = ")
    assert rule in captured.err
    assert not out.exists()


@pytest.mark.parametrize("section", sorted(SWITCHES))
def test_every_section_that_needs_a_switch_names_it(tmp_path, section):
    other = next(key for key in SECTIONS[section] if key not in SWITCHES[section])
    path = tmp_path / "off.toml"
    path.write_text(f"[{section}]\n{other} = 1.0\n")
    with pytest.raises(InvalidParameterError, match=f"without {' or '.join(SWITCHES[section])}"
                       " it is off") as raised:
        Scenario.from_toml(path)
    assert raised.value.name == f"{section}.{SWITCHES[section][0]}"


# The right answers.

@pytest.mark.parametrize("latitude_deg", [90.0, -90.0, 90.0 - 1e-9, -90.0 + 1e-9, 89.9])
@pytest.mark.parametrize("longitude_deg", [0.0, 37.0, -150.0])
def test_a_polar_site_has_finite_references_and_gravity_up(latitude_deg, longitude_deg):
    scenario = Scenario(tstop=2.0, dt=0.5, star_tracker_model="none",
                        time_between_measurements=0.5, site_latitude_deg=latitude_deg,
                        site_longitude_deg=longitude_deg, magnetometer_interval_s=0.5,
                        accelerometer_interval_s=0.5)
    references = scenario_references(scenario)
    field = references.magnetic_field_nT
    assert np.all(np.isfinite(field))
    # Near the magnetic poles the field is nearly vertical: down in the north, up in the south.
    assert math.copysign(1.0, field[0, 2]) == -math.copysign(1.0, latitude_deg)
    assert np.linalg.norm(field[0]) == pytest.approx(55000.0, rel=0.1)
    magnetometer, accelerometer = vector_readings(scenario, simulate_truth(scenario).q_true,
                                                  references, seed=0)
    assert np.all(np.isfinite(magnetometer.body)) and np.all(np.isfinite(accelerometer.body))
    assert np.all(accelerometer.reference == [0.0, 0.0, STANDARD_GRAVITY_MPS2])   # up


def enu_axes(latitude_deg: float, longitude_deg: float) -> np.ndarray:
    """Rows east, north, up of a place on a sphere, Earth-fixed; at a pole the
    limit along the meridian ``longitude_deg`` (the convention documented in
    :mod:`dynamics.environment`)."""
    phi, lam = math.radians(latitude_deg), math.radians(longitude_deg)
    east = [-math.sin(lam), math.cos(lam), 0.0]
    north = [-math.sin(phi) * math.cos(lam), -math.sin(phi) * math.sin(lam), math.cos(phi)]
    up = [math.cos(phi) * math.cos(lam), math.cos(phi) * math.sin(lam), math.sin(phi)]
    return np.array([east, north, up])


@pytest.mark.parametrize("pole", [90.0, -90.0])
def test_the_field_at_a_pole_is_one_vector_whatever_the_meridian(pole):
    # Exact tier: the field is one Earth-fixed vector; each meridian's
    # convention only names its components differently.
    moment = datetime(2026, 3, 20, 12, tzinfo=timezone.utc)
    vectors = [local_level_field_nT(pole, longitude, 0.0, moment) @ enu_axes(pole, longitude)
               for longitude in (0.0, 37.0, 90.0, -150.0, 359.0)]
    assert np.allclose(vectors, vectors[0], rtol=0.0, atol=1e-6)
    # Cross-check: the limit along the meridian is the field a hair's breadth from the pole.
    for longitude in (0.0, 37.0, -150.0):
        near = local_level_field_nT(pole - math.copysign(1e-9, pole), longitude, 0.0, moment)
        assert np.allclose(local_level_field_nT(pole, longitude, 0.0, moment), near,
                           rtol=0.0, atol=0.01)


def test_a_polar_site_runs_on_the_command_line(tmp_path, capsys):
    path = tmp_path / "pole.toml"
    path.write_text("tstop = 2.0\ndt = 0.5\n[star_tracker]\nmodel = 'none'\ninterval_s = 0.5\n"
                    "[site]\nlatitude_deg = 90.0\n[magnetometer]\ninterval_s = 0.5\n"
                    "[accelerometer]\ninterval_s = 0.5\n")
    assert main(["compare", "--scenario", str(path), "--estimators", "quest,mekf", "--quiet",
                 "--out", str(tmp_path / "out")]) == 0
    assert "note" not in capsys.readouterr().err          # no NaN division on the way
    rows = (tmp_path / "out" / "summary.csv").read_text().splitlines()[1:]
    assert len(rows) == 2 and all("nan" not in row.lower() for row in rows)


def test_a_soft_iron_matrix_is_judged_by_its_condition_not_its_scale(rng):
    rotation = np.linalg.qr(rng.standard_normal((3, 3)))[0]
    for scale in (1e-3, 1.0, 5.0):
        sensor = Magnetometer(100.0, 1.0, 1.0, soft_iron=scale * rotation)
        assert np.array_equal(sensor.soft_iron, scale * rotation)
    with pytest.raises(InvalidParameterError, match="condition number is 1e\\+07"):
        Magnetometer(100.0, 1.0, 1.0, soft_iron=np.diag([1.0, 1.0, 1e-7]))


def test_a_thousandth_soft_iron_matrix_runs_and_scales_the_readings(tmp_path):
    path = tmp_path / "soft.toml"
    path.write_text(orbit_file(sensors=MAGNETOMETER + "sigma_nT = 1e-6\nsoft_iron = "
                               "[[0.001, 0, 0], [0, 0.001, 0], [0, 0, 0.001]]\n"))
    scenario = Scenario.from_toml(path)
    references = scenario_references(scenario)
    q_true = simulate_truth(scenario).q_true
    (readings,) = vector_readings(scenario, q_true, references, seed=0)
    # The field in the body frame, a thousandth of it, and noise of 1e-6 nT.
    assert np.allclose(readings.body, 1e-3 * to_body(q_true, references.magnetic_field_nT),
                       rtol=0.0, atol=1e-4)


def test_huge_and_tiny_directions_normalise(rng):
    sensor = FineSunSensor(0.1, 1.0, 1.0, boresight=[1e300, 0.0, 0.0])
    assert np.array_equal(sensor.boresight, [1.0, 0.0, 0.0])
    assert np.allclose(unit_vector("v", [1e-300, 1e-300, 0.0]), [0.5 ** 0.5, 0.5 ** 0.5, 0.0])
    assert np.allclose(unit_vector("v", [1.7e308, -1.7e308, 0.0]), [0.5 ** 0.5, -0.5 ** 0.5, 0.0])
    faces = np.array([[1e300, 0, 0], [-1, 0, 0], [0, 1e-300, 0], [0, -1, 0], [0, 0, 1],
                      [0, 0, -1]], dtype=float)
    assert np.array_equal(CoarseSunSensors(0.01, 1.0, 1.0, normals=faces).normals,
                          np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1],
                                    [0, 0, -1]], dtype=float))
    # An ordinary direction's unit vector is the same bits as v / |v| (scaled by powers of two).
    for vector in rng.standard_normal((1000, 3)) * 10.0 ** rng.uniform(-8, 8, (1000, 1)):
        assert np.array_equal(unit_vector("v", vector), vector / np.linalg.norm(vector))


@pytest.mark.parametrize("given", ['"2026-03-20T12:00:00Z"', "2026-03-20T12:00:00Z",
                                   "2026-03-20T12:00:00", "2026-03-20 12:00:00+00:00"])
def test_an_epoch_is_text_or_a_toml_date_time(tmp_path, given):
    path = tmp_path / "epoch.toml"
    path.write_text(orbit_file() + f"[environment]\nepoch = {given}\n")
    assert Scenario.from_toml(path).epoch == "2026-03-20T12:00:00+00:00"


def test_a_toml_date_is_its_midnight(tmp_path):
    path = tmp_path / "epoch.toml"
    path.write_text(orbit_file() + "[environment]\nepoch = 2026-03-20\n")
    assert Scenario.from_toml(path).epoch == "2026-03-20T00:00:00+00:00"


def test_a_later_file_s_element_set_replaces_an_earlier_circular_orbit(tmp_path):
    circular, tle = tmp_path / "circular.toml", tmp_path / "tle.toml"
    circular.write_text(orbit_file("altitude_km = 500.0\ninclination_deg = 97.4\n"))
    tle.write_text(f'[orbit]\ntle = ["{ISS_TLE[0]}", "{ISS_TLE[1]}"]\n')
    scenario = Scenario.from_toml([circular, tle])
    assert scenario.orbit_altitude_km is None and scenario.orbit_tle == ISS_TLE
    back = Scenario.from_toml([circular, tle, circular])
    assert back.orbit_altitude_km == 500.0 and back.orbit_tle == ()


def test_an_altitude_beside_an_element_set_is_refused_from_python_too():
    with pytest.raises(InvalidParameterError, match="not both") as raised:
        Scenario(star_tracker_model="none", magnetometer_interval_s=0.01, orbit_tle=ISS_TLE,
                 orbit_altitude_km=500.0)
    assert raised.value.name == "orbit.altitude_km"


def test_an_altitude_up_to_the_magnetopause_is_an_orbit():
    scenario = Scenario(tstop=1.0, dt=0.5, star_tracker_model="none",
                        time_between_measurements=0.5, magnetometer_interval_s=0.5,
                        orbit_altitude_km=MAX_ALTITUDE_KM)
    assert np.all(np.isfinite(scenario_references(scenario).magnetic_field_nT))
    with pytest.raises(InvalidParameterError, match="magnetopause"):
        scenario.replace(orbit_altitude_km=MAX_ALTITUDE_KM * 1.001)


def test_a_sensor_slower_than_the_run_is_a_warning_not_a_refusal():
    # Legitimate (a run shortened for a quick look) but suspicious: it reads once, at t = 0.
    with pytest.warns(UserWarning, match=r"magnetometer.interval_s = 10 s is longer than the "
                      r"run \(tstop = 5 s\): that sensor reads once, at t = 0"):
        scenario = Scenario(tstop=5.0, dt=0.5, star_tracker_model="none",
                            time_between_measurements=0.5, orbit_altitude_km=500.0,
                            magnetometer_interval_s=10.0)
    (readings,) = vector_readings(scenario, simulate_truth(scenario).q_true,
                                  scenario_references(scenario), seed=0)
    assert np.flatnonzero(readings.available).tolist() == [0]


def test_a_sensor_slower_than_the_run_is_one_note_on_the_command_line(tmp_path, capsys):
    path = tmp_path / "slow.toml"
    path.write_text(orbit_file(sensors="[magnetometer]\ninterval_s = 10.0\n"))
    assert main(["show-config", "--scenario", str(path), "--estimators", "mekf"]) == 0
    err = capsys.readouterr().err
    assert err == ("attitude-bench: note: magnetometer.interval_s = 10 s is longer than the run "
                   "(tstop = 5 s): that sensor reads once, at t = 0\n")


def test_an_epoch_past_igrf_holds_the_field_at_its_end_and_says_so_once(capsys):
    first, last = igrf_span()
    assert (first.year, last.year) == (1900, 2030)
    position = np.array([[7000.0, 0.0, 0.0]])
    for late, end in ((datetime(2040, 1, 1), last), (datetime(1890, 6, 1), first)):
        with pytest.warns(UserWarning, match=f"outside IGRF's 1900-2030: the geomagnetic field "
                          f"is that of {end:%Y-%m-%d}"):
            held = geomagnetic_field_nT(position, np.array([2451545.0]), late)
            site = local_level_field_nT(45.0, 10.0, 0.0, late)
        assert np.all(np.isfinite(held)) and np.all(np.isfinite(site))
        assert np.array_equal(held, geomagnetic_field_nT(position, np.array([2451545.0]), end))
        assert np.array_equal(site, local_level_field_nT(45.0, 10.0, 0.0, end))
    assert capsys.readouterr().out == ""            # ppigrf's own print kept off stdout


def test_an_epoch_past_igrf_is_one_note_and_nothing_on_stdout(tmp_path, capsys):
    path = tmp_path / "late.toml"
    path.write_text(orbit_file() + '[environment]\nepoch = "2040-01-01T00:00:00Z"\n')
    assert main(["compare", "--scenario", str(path), "--estimators", "mekf", "--quiet",
                 "--out", str(tmp_path / "out")]) == 0
    captured = capsys.readouterr()
    notes = [line for line in captured.err.splitlines() if "IGRF" in line]
    assert notes == ["attitude-bench: note: the epoch 2040-01-01 is outside IGRF's 1900-2030: "
                     "the geomagnetic field is that of 2030-01-01, not of the epoch (it drifts "
                     "by tens of nT a year)"]
    assert "Warning" not in captured.out and "coefficient file" not in captured.out


def test_a_tle_still_reads_the_published_december_32():
    # Day 366 of a common year occurs in published element sets; sgp4 reads it.
    line1 = edited(ISS_TLE[0], 18, "19366.50000000")
    assert TLEOrbit((line1, ISS_TLE[1])).element_epoch.year == 2020


#: Every numeric key of the sections this change owns, with a value far beyond
#: its range: refused by its own name, or (a direction) normalised and run.
OWN_SECTIONS = ("orbit", "site", "magnetometer", "sun_sensor", "coarse_sun_sensors",
                "accelerometer")
SHAPES = {"bias_nT": [0.0, 0.0, 0.0], "bias_mps2": [0.0, 0.0, 0.0],
          "boresight": [0.0, 0.0, 1.0], "soft_iron": [[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]],
          "normals": [[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0], [0, 0, 1.0],
                      [0, 0, -1.0]]}
EXTREMES = [(section, key, value) for section in OWN_SECTIONS for key in SECTIONS[section]
            if key != "tle" for value in (1e300, -1e300)]


def with_first(shape, value):
    """``shape`` (a number, a vector or a matrix) with its first number ``value``."""
    if shape is None:
        return value
    if isinstance(shape[0], list):
        return [with_first(shape[0], value), *shape[1:]]
    return [value, *shape[1:]]


@pytest.mark.parametrize("section, key, value", EXTREMES,
                         ids=[f"{s}.{k}={v:g}" for s, k, v in EXTREMES])
def test_an_extreme_value_is_refused_by_name_or_runs_finite(tmp_path, section, key, value):
    on_ground = section in ("site", "accelerometer")
    sections = {"site": {"latitude_deg": 45.0}} if on_ground else \
        {"orbit": {"altitude_km": 500.0}}
    sections["magnetometer"] = {"interval_s": 0.5}
    sections.setdefault(section, {"interval_s": 0.5})[key] = with_first(SHAPES.get(key), value)
    path = tmp_path / "extreme.toml"
    path.write_text(SHORT + "".join(
        f"[{name}]\n" + "".join(f"{item} = {given!r}\n" for item, given in keys.items())
        for name, keys in sections.items()))
    try:
        scenario = Scenario.from_toml(path)
    except InvalidParameterError as err:
        assert err.name == f"{section}.{key}", str(err)
        return
    assert key in ("boresight", "normals"), f"{section}.{key} = {value:g} was accepted"
    references = scenario_references(scenario)
    for readings in vector_readings(scenario, simulate_truth(scenario).q_true, references, 0):
        assert np.all(np.isfinite(readings.body)) and np.all(np.isfinite(readings.reference))
