"""Scenario files written from text for the configuration tests: the pieces they share and the two checks they
make (a text loads; a text is refused with one line naming the field)."""

import textwrap

import pytest

from shipsense.config import ScenarioError, load_scenario

MAGNETOMETER = """
[[sensors]]
id = "M1"
type = "magnetometer"
kind = "vector"
position = [{x}, 0.0, -15.0]
noise_std = 1e-9
"""

PASSAGE = """
[passage]
start = [-100.0, 30.0]
velocity = [5.0, 0.0]
z = -3.0
moment = [1e6, 0.0, 0.0]
"""


def load_text(tmp_path, text):
    """The scenario of ``text`` (dedented), written to a file and loaded as a user's would be."""
    path = tmp_path / "scenario.toml"
    path.write_text(textwrap.dedent(text))
    return load_scenario(path)


def refused(tmp_path, text, *fragments):
    """Assert that ``text`` is refused with one line (no traceback) holding every fragment; the message."""
    with pytest.raises(ScenarioError) as info:
        load_text(tmp_path, text)
    msg = str(info.value)
    assert "\n" not in msg and "Traceback" not in msg
    for f in fragments:
        assert f in msg, msg
    return msg
