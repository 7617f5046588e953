"""Scenario validation: one test per class of bad configuration, each with a clear, single message."""

import pytest
from scenario_text import MAGNETOMETER, PASSAGE, load_text, refused

from shipsense.config import ScenarioError, load_scenario, shipped_scenarios

BASE = """
name = "t"
period = 0.5
steps = 20

[medium]
sigma_water = 4.0
sigma_seabed = 0.04
water_depth = 15.0
""" + MAGNETOMETER.format(x="-5.0") + """
[[sensors]]
id = "E1"
type = "electrode"
kind = "envelope"
position = [5.0, 0.0, -15.0]
noise_std = 1e-7
""" + PASSAGE + "p = 100.0\n"


def test_base_is_valid(tmp_path):
    sc = load_text(tmp_path, BASE)
    assert sc.array().n_channels == 6


def test_every_shipped_scenario_loads_and_names_are_case_insensitive():
    for name in shipped_scenarios():
        assert load_scenario(name).name == name
    assert load_scenario("s1-p2").name == "S1-P2"


def test_shipped_values_match_the_spec():
    s0 = load_scenario("S0")
    assert s0.sensors[0].channel_std == pytest.approx((8e-18**0.5,) * 3)
    assert s0.passage.moment == (8e7, 2e7, 4e7) and s0.steps == 300 and s0.period == 0.1
    assert s0.tracker.bank.levels == [1e6, 1e7, 1e8]
    p1, p2 = load_scenario("S1-P1"), load_scenario("S1-P2")
    assert [s.position[:2] for s in p1.sensors] == [(0, 5), (0, 0), (0, -5)]
    assert [s.position[:2] for s in p2.sensors] == [(0, 5), (0, -5), (5, 0)]
    assert p2.passage.z == -6.8 and p2.passage.p == 100.0
    s2 = load_scenario("S2")
    assert s2.passage.moment == (1e4, 1e4, 1e4) and s2.steps == 80


def test_nan_and_inf_are_rejected(tmp_path):
    refused(tmp_path, BASE.replace("[-5.0, 0.0, -15.0]", "[nan, 0.0, -15.0]"), "sensors[0].position", "finite")
    refused(tmp_path, BASE.replace("velocity = [5.0, 0.0]", "velocity = [inf, 0.0]"), "passage.velocity", "finite")


def test_coincident_sensors(tmp_path):
    text = BASE + """
[[sensors]]
id = "M2"
type = "magnetometer"
kind = "vector"
position = [-5.0, 0.0, -15.0]
noise_std = 1e-9
"""
    refused(tmp_path, text, "sensors[2].position", "coincides", "M1")


def test_sensors_of_different_types_may_share_a_node(tmp_path):
    text = BASE + """
[[sensors]]
id = "A1"
type = "accelerometer"
kind = "bearing"
position = [-5.0, 0.0, -15.0]
noise_std = 0.03
"""
    assert load_text(tmp_path, text).array().n_channels == 7


def test_sensor_outside_the_water(tmp_path):
    refused(tmp_path, BASE.replace("[5.0, 0.0, -15.0]", "[5.0, 0.0, 2.0]"), "sensors[1].position",
            "above the sea surface")
    refused(tmp_path, BASE.replace("[5.0, 0.0, -15.0]", "[5.0, 0.0, -16.0]"), "sensors[1].position", "below the seabed")


def test_source_outside_the_water(tmp_path):
    refused(tmp_path, BASE.replace("z = -3.0", "z = -20.0"), "passage.z", "below the seabed")
    refused(tmp_path, BASE.replace("z = -3.0", "z = 1.0"), "passage.z")
    refused(tmp_path, BASE.replace("z = -3.0", "z = 0.0"), "passage.z", "strictly inside the water")


def test_source_inside_a_sensor(tmp_path):
    text = BASE.replace("z = -3.0", "z = -14.5").replace("start = [-100.0, 30.0]", "start = [-30.0, 0.0]")
    refused(tmp_path, text, "passage", "inside the sensor", "M1")


def test_non_positive_conductivity(tmp_path):
    refused(tmp_path, BASE.replace("sigma_seabed = 0.04", "sigma_seabed = -0.04"), "medium.sigma_seabed", "> 0")
    refused(tmp_path, BASE.replace("sigma_water = 4.0", "sigma_water = 0.0"), "medium.sigma_water", "> 0")


def test_moment_of_the_wrong_shape(tmp_path):
    refused(tmp_path, BASE.replace("moment = [1e6, 0.0, 0.0]", "moment = [1e6, 0.0]"), "passage.moment")
    refused(tmp_path, BASE.replace("moment = [1e6, 0.0, 0.0]\n", ""), "passage.moment", "magnetometers need")


def test_unknown_measurement_kind(tmp_path):
    refused(tmp_path, BASE.replace('kind = "envelope"', 'kind = "tmi"'), "sensors[1]",
        "unknown measurement kind 'tmi' for a electrode", "vector, envelope, magnitude")
    refused(tmp_path, BASE.replace('type = "electrode"', 'type = "hydrophone"'), "sensors[1].type")


def test_magnitude_electrode_has_one_channel(tmp_path):
    sc = load_text(tmp_path, BASE.replace('kind = "envelope"', 'kind = "magnitude"'))
    assert sc.array().n_channels == 4 and sc.array().channels[-1] == ("E1", "e")
    refused(tmp_path, BASE.replace('kind = "envelope"', 'kind = "magnitude"').replace(
        "noise_std = 1e-7", "noise_std = [1e-7, 1e-7, 1e-7]"), "sensors[1]",
        "a magnitude electrode has 1 components, got 3 values")


def test_unknown_field_and_missing_field(tmp_path):
    refused(tmp_path, BASE.replace("steps = 20", "stepz = 20"), "stepz", "unknown field")
    refused(tmp_path, BASE.replace("steps = 20", "steps = 20\n").replace("period = 0.5\n", ""), "period", "missing")


def test_noise_given_twice_or_with_wrong_length(tmp_path):
    refused(tmp_path, BASE.replace("noise_std = 1e-9", "noise_std = 1e-9\nnoise_var = 1e-18"), "sensors[0]",
            "exactly one")
    refused(tmp_path, BASE.replace("noise_std = 1e-9", "noise_std = [1e-9, 1e-9]"), "sensors[0]", "3 components")


def test_electrodes_need_a_medium(tmp_path):
    text = BASE.replace("[medium]\nsigma_water = 4.0\nsigma_seabed = 0.04\nwater_depth = 15.0\n", "")
    refused(tmp_path, text, "medium", "electrode")


def test_not_toml_and_missing_file(tmp_path):
    refused(tmp_path, "name = [", "not valid TOML")
    with pytest.raises(ScenarioError, match="no such file"):
        load_scenario(tmp_path / "nope.toml")


def test_orientation_must_be_a_rotation(tmp_path):
    text = BASE.replace("noise_std = 1e-9", "noise_std = 1e-9\norientation = [[1, 0, 0], [0, 1, 0], [0, 0, 2]]")
    refused(tmp_path, text, "sensors[0]", "rotation matrix")


def test_with_updates_validates():
    sc = load_scenario("S0")
    assert sc.with_updates(runs=3).runs == 3
    with pytest.raises(ScenarioError, match="steps"):
        sc.with_updates(steps=1)


def test_values_beyond_the_physical_ranges_are_refused(tmp_path):
    """Values that passed as finite but overflow later (a speed of 1e308 m/s, a bank level of 1e308, a noise
    variance of 1e-320 whose inverse is infinite) are refused, naming the field and the range with its unit."""
    prior = "\n[prior]\nspeed = [4.0, 1e308]\nmoment = [1e6, 1e7]\np = [50.0, 200.0]\n"
    refused(tmp_path, BASE + prior, "prior.speed", "100 m/s")
    bank = "\n[tracker.bank]\nlevels = [1e308]\nbearings_deg = [0.0]\n"
    refused(tmp_path, BASE + bank, "tracker.bank.levels[0]", "1e+12")
    refused(tmp_path, BASE.replace("noise_std = 1e-9", "noise_var = 1e-320"), "sensors[0].noise_var", "at least 1e-30")
    refused(tmp_path, BASE.replace("noise_std = 1e-9", "noise_std = 1e-200"), "sensors[0].noise_std", "at least 1e-15")
    at_floor = load_text(tmp_path, BASE.replace("noise_std = 1e-9", "noise_var = 1e-30"))
    assert at_floor.sensors[0].channel_std == pytest.approx((1e-15,) * 3)


def test_the_conductivity_ratio_must_keep_the_image_series_bounded(tmp_path):
    """A seabed of 1e-308 S/m (the image series' reflection coefficient rounds to 1: no bounded stopping shell)
    is refused by the ratio range, at either end; the ends of the range themselves load."""
    from shipsense.physics.electric import CONDUCTIVITY_RATIO

    refused(tmp_path, BASE.replace("sigma_seabed = 0.04", "sigma_seabed = 1e-308"), "medium.sigma_seabed", "ratio")
    refused(tmp_path, BASE.replace("sigma_seabed = 0.04", "sigma_seabed = 100.0").replace("sigma_water = 4.0",
                                                                                     "sigma_water = 0.01"),
        "medium.sigma_seabed", "ratio")
    lo, hi = CONDUCTIVITY_RATIO
    for ratio in (lo, hi):
        sc = load_text(tmp_path, BASE.replace("sigma_seabed = 0.04", f"sigma_seabed = {ratio * 0.1!r}")
                       .replace("sigma_water = 4.0", "sigma_water = 0.1"))
        assert abs(sc.medium.physics().eta) < 1.0
