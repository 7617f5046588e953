"""The tracker's settings: one object, resolved once from the scenario's ``[tracker]`` table, overrides and the
family defaults; every option settable from the file and validated like the rest of it."""

import inspect
from importlib import resources

import pytest

from shipsense.config import MotionConfig, ScenarioError, TrackerConfig, TrackerOptions, load_scenario, to_toml
from shipsense.defaults import HUBER_GAMMA, N_PU
from shipsense.errors import ShipsenseError
from shipsense.trackers import Tracker
from shipsense.trackers.filters import huber_ukf, puekf
from shipsense.trackers.fit.robust import Huber
from shipsense.trackers.tracker.settings import FAMILY_SETTINGS, TrackerSettings, family_of, resolve_settings

# a valid value, different from the default, for every option of the [tracker] table
SET = {"method": "bank", "unit": "cdkf", "robust": True, "huber_gamma": 2.0, "window_s": 9.0, "snr_start": 7.0,
       "refine": (4, 9), "explore_samples": 11, "grid_samples": 12, "z_std": 2.5, "keep_init": 6, "keep": 4,
       "refit_every": 15, "through_peak": 0.4, "nis_window": 8, "nis_limit": 4.0, "max_restarts": 2,
       "collapse": 0.3, "ambiguity_nats": 9.0, "report_nats": 2.0, "report_distance_m": 25.0, "distinct_m": 12.0,
       "gof": 0.02, "inflate": 3.0, "history": 500, "gap_limit_s": 7.0, "consistency_window": 15,
       "consistency_level": 0.02, "rescan": True, "early_starts": False,
       "motion": MotionConfig(model="imm", turn_rate_deg_s=2.0, threshold=0.6)}


def _write(tmp_path, sc, **tracker):
    data = sc.tracker.model_dump(exclude_unset=True) if sc.tracker is not None else {}
    path = tmp_path / "scenario.toml"
    path.write_text(to_toml(sc.model_copy(update={"tracker": TrackerConfig.model_validate({**data, **tracker})})))
    return path


def test_every_option_is_settable_from_the_scenario_file(tmp_path):
    assert set(SET) == set(TrackerOptions.model_fields), "a new option needs a value here"
    sc = load_scenario(_write(tmp_path, load_scenario("S2"), **SET))
    settings = resolve_settings(sc)
    for name, value in SET.items():
        assert getattr(settings, name) == value, name
        assert getattr(settings, name) != TrackerOptions.model_fields[name].default, name


def test_overrides_win_over_the_file_and_defaults_fill_only_what_is_unset(tmp_path):
    sc = load_scenario(_write(tmp_path, load_scenario("S2"), snr_start=7.0, keep=2))
    s = resolve_settings(sc, snr_start=9.0)
    family = FAMILY_SETTINGS["magnetometers"]
    assert s.snr_start == 9.0 and s.keep == 2                      # override, then the file
    assert s.refine == family["refine"] and s.window_s == family["window_s"]   # the family's, where unset
    assert s.gap_limit_s == 10 * sc.period and s.robust is False and s.unit == "ukf"
    assert resolve_settings("S2", robust=True).unit == "huber_ukf"
    assert resolve_settings("S2", method="bank").unit == sc.tracker.filter     # the studies' filter
    assert resolve_settings("S0").snr_start == FAMILY_SETTINGS["one magnetometer"]["snr_start"]
    # the electrodes' depth prior is the bank's
    assert resolve_settings("S1-P2").z_std == load_scenario("S1-P2").tracker.bank.z_std


@pytest.mark.parametrize("types, family", [(["magnetometer"], "one magnetometer"),
                                           (["magnetometer", "magnetometer", "accelerometer"], "magnetometers"),
                                           (["electrode", "magnetometer"], "electrodes")])
def test_the_family_table_names_each_array(types, family):
    assert family_of(types) == family


@pytest.mark.parametrize("field, value, words", [("window_s", -1.0, "must be > 0"),
                                                 ("refine", [20, 5], "must increase"),
                                                 ("keep", 9, "cannot exceed keep_init"),
                                                 ("through_peak", 1.5, "less than 1"),
                                                 ("grid_samples", 2.5, "whole number")])
def test_a_bad_value_in_the_file_is_one_line_naming_the_field(tmp_path, field, value, words):
    path = tmp_path / "bad.toml"
    text = (resources.files("shipsense") / "scenarios" / "S2.toml").read_text()    # (a [tracker] table of its own)
    toml_value = str(value).lower() if not isinstance(value, list) else str(value)
    path.write_text(text.replace("[tracker]\n", f"[tracker]\n{field} = {toml_value}\n", 1))
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    message = str(err.value)
    assert "\n" not in message and "tracker" in message and field in message and words in message, message


def test_a_bad_override_names_the_option():
    with pytest.raises(ShipsenseError, match="tracker options: snr_start: must be > 0"):
        Tracker("S2", snr_start=-3.0)
    with pytest.raises(ShipsenseError, match="unknown field"):
        resolve_settings("S2", snr_begin=5.0)


def test_the_tracker_runs_on_the_settings_it_is_given():
    settings = resolve_settings("S2", keep_init=4, keep=2)
    tr = Tracker("S2", passages=2, settings=settings)
    assert tr.settings is settings and tr.H == 4
    with pytest.raises(TypeError, match="not both"):
        Tracker("S2", settings=settings, keep=1)
    assert isinstance(resolve_settings("S2"), TrackerSettings)


def test_one_home_for_the_huber_threshold_and_the_pu_ekf_sub_updates():
    """The filter's and the fits' Huber threshold are the setting's; a PU-EKF gets N_PU sub-updates whether or
    not its scenario has a [tracker] table (it got 1 with a table that did not say, 5 without one)."""
    assert inspect.signature(huber_ukf.update).parameters["gamma"].default == HUBER_GAMMA == Huber().gamma
    assert inspect.signature(puekf.update).parameters["n_pu"].default == N_PU
    s = resolve_settings("S2", robust=True, huber_gamma=2.0)
    assert s.filter_unit().options == {"gamma": 2.0} and s.huber(load_scenario("S2").noise).gamma == 2.0
    with_table = load_scenario("S2").with_updates(tracker={"filter": "puekf"})
    without = load_scenario("S2").with_updates(tracker=None)
    assert resolve_settings(with_table).study_unit().options == {"n_pu": N_PU}
    assert resolve_settings(without.with_updates(tracker={"filter": "puekf"})).study_unit().options == {"n_pu": N_PU}
