"""The ``[manoeuvres]`` table: valid schedules load, impossible ones are refused with one line naming the field
(and exit 2 on the command line)."""

import textwrap

import pytest
from scenario_text import MAGNETOMETER, PASSAGE, load_text, refused

from shipsense.cli import main
from shipsense.config import ScenarioError, load_scenario, to_toml, validate_scenario

BASE = """
name = "t"
period = 0.5
steps = 101            # 50 s
""" + MAGNETOMETER.format(x="0.0") + PASSAGE + """
[prior]
range = [100.0, 200.0]
speed = [3.0, 8.0]
moment = [1e5, 1e6]
"""


def load(tmp_path, text):
    return load_text(tmp_path, BASE + text)


def bad(tmp_path, text, *fragments):
    return refused(tmp_path, BASE + text, *fragments)


GOOD = """
[manoeuvres]
body_fixed_share = 0.5
[[manoeuvres.turns]]
start = 10.0
duration = 20.0
rate_deg_s = 4.5
[[manoeuvres.speed_changes]]
start = 30.0
duration = 5.0
acceleration = -0.5
[manoeuvres.random]
probability = 1.0
start = [0.0, 20.0]
"""


def test_a_schedule_loads_and_writes_back(tmp_path):
    sc = load(tmp_path, GOOD)
    assert [m.start for _, _, m in sc.manoeuvres.scheduled] == [10.0, 30.0]
    again = validate_scenario(__import__("tomllib").loads(to_toml(sc)), "again", strict=True)
    assert again == sc
    # a turn of 90 degrees that leaves the prior's area is allowed
    load(tmp_path, GOOD.replace("rate_deg_s = 4.5", "rate_deg_s = -4.5"))


@pytest.mark.parametrize("change, fragments", [
    (("duration = 20.0", "duration = -1.0"), ("manoeuvres.turns[0].duration", "must be > 0")),
    (("start = 30.0", "start = 25.0"), ("manoeuvres.speed_changes[0].start", "overlaps manoeuvres.turns[0]")),
    (("start = 30.0", "start = 50.0"), ("manoeuvres.speed_changes[0].start", "not before the passage ends")),
    (("start = 10.0", "start = -1.0"), ("manoeuvres.turns[0].start", "greater than or equal to 0")),
    (("acceleration = -0.5", "acceleration = -1.0"), ("manoeuvres.speed_changes[0].acceleration",
                                                       "to 0 m/s", "(0, 100] m/s")),
    (("acceleration = -0.5", "factor = 0.0"), ("manoeuvres.speed_changes[0].factor", "greater than 0")),
    (("acceleration = -0.5", "factor = 1.5\nacceleration = 0.1"), ("manoeuvres.speed_changes[0]",
                                                                   "exactly one of factor or acceleration")),
    (("rate_deg_s = 4.5", "rate_deg_s = 45.0"), ("manoeuvres.turns[0].rate_deg_s", "20 deg/s")),
    (("rate_deg_s = 4.5", "rate_deg_s = 0.0"), ("manoeuvres.turns[0].rate_deg_s", "nonzero")),
    (("body_fixed_share = 0.5", "body_fixed_share = 1.5"), ("manoeuvres.body_fixed_share",
                                                            "less than or equal to 1")),
    (("start = [0.0, 20.0]", "start = [60.0, 70.0]"), ("manoeuvres.random.start", "must begin in [0, 50)")),
    (("probability = 1.0", "probability = 1.0\nspeed_factor = [0.5, 20.0]"), ("manoeuvres.random.speed_factor",
                                                                              "10")),
    (("probability = 1.0", "probablity = 1.0"), ("manoeuvres.random.probablity", "unknown field")),
])
def test_impossible_schedules_are_refused_naming_the_field(tmp_path, change, fragments):
    bad(tmp_path, GOOD.replace(*change, 1), *fragments)


def test_the_clearance_of_a_manoeuvring_passage_is_its_own(tmp_path):
    # straight, the passage would pass 30 m from M1; the turn (to starboard, radius ~30 m) brings it over it
    turn = "\n[manoeuvres]\n[[manoeuvres.turns]]\nstart = 14.0\nduration = 30.0\nrate_deg_s = -9.55\n"
    text = BASE[:BASE.index("[prior]")].replace("z = -3.0", "z = -14.5")   # no prior: its plane would be refused
    path = tmp_path / "s.toml"
    path.write_text(textwrap.dedent(text + turn))
    with pytest.raises(ScenarioError, match="manoeuvres: the manoeuvring passage passes"):
        load_scenario(path)
    # and a straight line through a sensor is no objection when the ship turns away before it
    through = text.replace("start = [-100.0, 30.0]", "start = [-100.0, 0.0]")
    away = "\n[manoeuvres]\n[[manoeuvres.turns]]\nstart = 2.0\nduration = 10.0\nrate_deg_s = 9.0\n"
    path.write_text(textwrap.dedent(through + away))
    load_scenario(path)
    path.write_text(textwrap.dedent(through))
    with pytest.raises(ScenarioError, match="passage: the source passes"):
        load_scenario(path)


def test_random_manoeuvres_need_a_prior(tmp_path):
    text = BASE[:BASE.index("[prior]")] + "\n[manoeuvres.random]\nprobability = 0.3\n"
    path = tmp_path / "s.toml"
    path.write_text(textwrap.dedent(text))
    with pytest.raises(ScenarioError, match=r"manoeuvres.random: .*need a \[prior\]"):
        load_scenario(path)


def test_the_command_line_refuses_an_impossible_schedule_with_exit_2(tmp_path, capsys):
    path = tmp_path / "s.toml"
    path.write_text(textwrap.dedent(BASE + GOOD.replace("start = 30.0", "start = 25.0", 1)))
    out = tmp_path / "never.npz"
    assert main(["simulate", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "manoeuvres.speed_changes[0].start" in err and not out.exists()


def test_simulate_writes_a_manoeuvring_recording(tmp_path, capsys):
    import csv

    import numpy as np

    tidy, npz = tmp_path / "turn.csv", tmp_path / "turn.npz"
    assert main(["simulate", "S2-turn", "--runs", "1", "--out", str(tidy)]) == 0
    rows = list(csv.DictReader(tidy.open()))
    assert len(rows) == 160 * 7
    assert main(["simulate", "S2-turn", "--runs", "2", "--random", "--seed", "3", "--out", str(npz)]) == 0
    data = np.load(npz)
    assert data["heading"].shape == (2, 160) and "manoeuvre_schedule" in data
