"""A scenario read by the sections of its file: ``scenario.gyro.arw_deg_per_rthr``
(issue 31), each key the flat field it sets, datasheet units converted back."""
import math
from pathlib import Path

import numpy as np
import pytest

from benchmarks.scenario import SECTIONS, UNVIEWED_SECTIONS, Scenario
from benchmarks.scenario.sections import SectionView, add_section_views
from dynamics.validation import InvalidParameterError

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


@pytest.mark.parametrize("name", ["default", "flight", "cubesat", "smallsat"])
def test_every_declared_key_is_reachable_and_reads_its_field(name):
    scenario = Scenario.from_toml(SCENARIOS / f"{name}.toml")
    for section, keys in SECTIONS.items():
        if section in UNVIEWED_SECTIONS:
            continue
        view = getattr(scenario, section)
        assert isinstance(view, SectionView) and sorted(dir(view)) == sorted(keys)
        for key, spec in keys.items():
            field = getattr(scenario, spec.field)
            if spec.read_back is None:
                assert getattr(view, key) is field, f"{section}.{key}"
            else:
                assert np.allclose(spec.convert(getattr(view, key)), field, rtol=1e-12, atol=0)


def test_datasheet_keys_read_back_in_their_own_units(tmp_path):
    path = tmp_path / "gyro.toml"
    path.write_text("[gyro]\narw_deg_per_rthr = 0.3\nbias_rw_deg_per_hr_rthr = 0.01\n"
                    "bias_instability_deg_per_hr = 2.0\n"
                    "initial_bias_deg_per_hr = [1.0, -2.0, 3.0]\n")
    gyro = Scenario.from_toml(path).gyro
    assert gyro.arw_deg_per_rthr == pytest.approx(0.3, rel=1e-14)
    assert gyro.bias_rw_deg_per_hr_rthr == pytest.approx(0.01, rel=1e-14)
    assert gyro.bias_instability_deg_per_hr == pytest.approx(2.0, rel=1e-14)
    assert np.allclose(gyro.initial_bias_deg_per_hr, [1.0, -2.0, 3.0], rtol=1e-14, atol=0)
    # The same σ_v as a rate noise density: ARW = 60 × density (√h = 60 √s).
    assert gyro.noise_density_deg_per_s_rthz == pytest.approx(0.3 / 60.0, rel=1e-14)


def test_the_workshop_gyro_reads_as_its_datasheet_figure():
    # sensors.noise: power 1e-5 rad²/s is an ARW of 10.871 deg/√h; by hand,
    # √(1e-5) rad/√s × (180/π) deg/rad × 60 √s/√h.
    gyro = Scenario().gyro
    assert gyro.noise_power == 1e-5
    assert gyro.arw_deg_per_rthr == pytest.approx(math.sqrt(1e-5) * 180.0 / math.pi * 60.0,
                                                  rel=1e-14)
    assert round(gyro.arw_deg_per_rthr, 3) == 10.871


def test_a_view_follows_the_scenario_and_only_reads():
    scenario = Scenario().replace(magnetometer_interval_s=0.5, orbit_altitude_km=500.0,
                                  magnetometer_sigma_nT=42.0)
    assert (scenario.magnetometer.sigma_nT, scenario.orbit.altitude_km) == (42.0, 500.0)
    assert scenario.star_tracker.interval_s == scenario.time_between_measurements == 0.2
    with pytest.raises(AttributeError, match=r"\[magnetometer\] has no key 'sigma'; its keys: "
                                             r"interval_s, sigma_nT, bias_nT, soft_iron"):
        scenario.magnetometer.sigma
    with pytest.raises(AttributeError,
                       match=r"read-only.*replace\(magnetometer=\{'sigma_nT': \.\.\.\}\)"):
        scenario.magnetometer.sigma_nT = 1.0
    assert scenario.magnetometer.sigma_nT == 42.0


def test_replace_reads_a_sections_keys_as_the_file_does(tmp_path):
    # The same change three ways from Python and once as a file: the scenario
    # is the same, field by field (datasheet units converted as the file's).
    path = tmp_path / "change.toml"
    path.write_text("[gyro]\narw_deg_per_rthr = 0.15\n[magnetometer]\ninterval_s = 0.5\n"
                    "sigma_nT = 42.0\n[orbit]\naltitude_km = 500.0\n")
    from_file = Scenario.from_toml(path).as_dict()
    base = Scenario()
    by_section = base.replace(gyro={"arw_deg_per_rthr": 0.15},
                              magnetometer={"interval_s": 0.5, "sigma_nT": 42.0},
                              orbit={"altitude_km": 500.0})
    by_key = base.replace(**{"gyro.arw_deg_per_rthr": 0.15, "magnetometer.interval_s": 0.5,
                             "magnetometer.sigma_nT": 42.0, "orbit.altitude_km": 500.0})
    by_field = base.replace(gyro_noise=by_section.gyro_noise, magnetometer_interval_s=0.5,
                            magnetometer_sigma_nT=42.0, orbit_altitude_km=500.0)
    assert by_section.as_dict() == by_key.as_dict() == by_field.as_dict() == from_file
    assert by_section.gyro.arw_deg_per_rthr == pytest.approx(0.15, rel=1e-14)
    assert by_section.gyro_noise != base.gyro_noise


@pytest.mark.parametrize("changes, message", [
    ({"gyro": 0.15}, r"gyro = 0.15: must be a dict of the section's keys"),
    ({"gyro": {"arw": 0.15}}, r"gyro.arw = 0.15: is not a setting of \[gyro\]; known: "),
    ({"gyro": {"arw_deg_per_rthr": 0.15}, "gyro_noise": 1e-5},
     r"sets gyro_noise, which another key already sets"),
    ({"gyro": {"arw_deg_per_rthr": 0.15}, "gyro.arw_deg_per_rthr": 0.2},
     r"gyro.arw_deg_per_rthr = 0.2: is given twice"),
    ({"gyro.arw_deg_per_rthr": -1.0}, r"gyro.arw_deg_per_rthr"),
])
def test_replace_names_a_bad_section_change(changes, message):
    with pytest.raises(InvalidParameterError, match=message):
        Scenario().replace(**changes)


def test_site_keeps_its_meaning_and_no_section_hides_a_member():
    assert UNVIEWED_SECTIONS == ("site",)
    assert Scenario().site is None
    assert Scenario(site_latitude_deg=45.0).site == (45.0, 0.0, 0.0)

    class Clash:
        gyro = "mine"

    with pytest.raises(TypeError, match=r"\[gyro\] would hide Clash.gyro"):
        add_section_views(Clash)
